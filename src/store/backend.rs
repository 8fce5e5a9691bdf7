//! Where the store lives and how to talk to it: SQLite (a file; the embedded default) or
//! PostgreSQL (a URL; many nodes on one queue). Both are reached through sqlx's `Any` driver, so
//! one `Store` API runs on either; what differs is the SQL of the statements whose dialects
//! differ (`sql/sqlite/`, `sql/postgres/`, picked by [`sql!`]), the migrations
//! (`migrations/sqlite/`, `migrations/postgres/`) and the connection set-up here.

use super::StoreError;
use sqlx::any::{AnyConnectOptions, AnyPoolOptions};
use sqlx::{AnyPool, Executor};
use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::Notify;

/// The database engine behind a [`super::Store`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    Sqlite,
    Postgres,
}

/// A database to open: a SQLite file, or a PostgreSQL server by URL.
#[derive(Clone, PartialEq, Eq)]
pub enum DbLocation {
    Sqlite(PathBuf),
    /// `postgres://user:password@host:port/db?options` (libpq URL syntax, as sqlx reads it).
    Postgres(String),
}

/// Why a database location does not name a database.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LocationError {
    #[error("the database location is empty")]
    Empty,
    #[error("invalid PostgreSQL URL: {0}")]
    Url(#[source] url::ParseError),
    #[error("a sqlite:// location takes a file path and no options")]
    SqliteOptions,
    #[error("unsupported database URL scheme in {0:?}: use postgres://… or a SQLite file path")]
    Scheme(String),
}

impl DbLocation {
    /// `postgres://…` or `postgresql://…` is PostgreSQL; `sqlite://PATH`, `sqlite:PATH` or a plain
    /// path is a SQLite file.
    pub fn parse(s: &str) -> Result<Self, LocationError> {
        let s = s.trim();
        if s.is_empty() {
            return Err(LocationError::Empty);
        }
        if s.starts_with("postgres://") || s.starts_with("postgresql://") {
            url::Url::parse(s).map_err(LocationError::Url)?;
            return Ok(DbLocation::Postgres(s.to_string()));
        }
        if let Some(rest) = s
            .strip_prefix("sqlite://")
            .or_else(|| s.strip_prefix("sqlite:"))
        {
            if rest.is_empty() || rest.contains('?') {
                return Err(LocationError::SqliteOptions);
            }
            return Ok(DbLocation::Sqlite(PathBuf::from(rest)));
        }
        if s.contains("://") {
            return Err(LocationError::Scheme(
                s.split("://").next().unwrap_or_default().to_string(),
            ));
        }
        Ok(DbLocation::Sqlite(PathBuf::from(s)))
    }

    pub fn backend(&self) -> Backend {
        match self {
            DbLocation::Sqlite(_) => Backend::Sqlite,
            DbLocation::Postgres(_) => Backend::Postgres,
        }
    }
}

/// Shown in logs and errors: a PostgreSQL password is masked.
impl fmt::Display for DbLocation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DbLocation::Sqlite(p) => write!(f, "{}", p.display()),
            DbLocation::Postgres(u) => match url::Url::parse(u) {
                Ok(mut url) => {
                    if url.password().is_some() {
                        let _ = url.set_password(Some("***"));
                    }
                    write!(f, "{url}")
                }
                Err(_) => f.write_str("postgres://(unparsable)"),
            },
        }
    }
}

impl fmt::Debug for DbLocation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "DbLocation({self})")
    }
}

/// Connection pools of one store: `writer` takes the writes, `pool` the reads, `lease_writer`
/// the worker's frequent fenced writes (claim, heartbeat, progress, checkpoint, snapshot).
pub(super) struct Pools {
    pub pool: AnyPool,
    pub writer: AnyPool,
    pub lease_writer: AnyPool,
    /// PostgreSQL: the wake-up hints sent after commits (see [`Hints`]).
    pub hints: Option<Hints>,
}

/// Opens `loc` and runs its backend's migrations.
pub(super) async fn connect(loc: &DbLocation, max_connections: u32) -> Result<Pools, StoreError> {
    sqlx::any::install_default_drivers();
    match loc {
        DbLocation::Sqlite(path) => connect_sqlite(path, max_connections).await,
        DbLocation::Postgres(url) => {
            let options = AnyConnectOptions::from_str(url)?;
            // One plain connection first: a pool that cannot connect reports only "timed out",
            // this says why (refused, unknown host, authentication, no such database).
            use sqlx::Connection;
            sqlx::AnyConnection::connect_with(&options)
                .await?
                .close()
                .await?;
            let max = max_connections.max(2);
            let open = |asynchronous: bool| {
                AnyPoolOptions::new()
                    .max_connections(max)
                    // Opened up front: a connection opened under load costs a round trip of
                    // authentication and statement preparation on the request that waits.
                    .min_connections(max)
                    .acquire_timeout(Duration::from_secs(10))
                    .after_connect(move |conn, _meta| {
                        Box::pin(async move {
                            if asynchronous {
                                conn.execute("SET synchronous_commit = off").await?;
                            }
                            Ok(())
                        })
                    })
                    .connect_with(options.clone())
            };
            let pool = open(false).await?;
            sqlx::migrate!("./migrations/postgres").run(&pool).await?;
            // PostgreSQL takes concurrent writers itself: one pool reads and writes what must
            // be durable when the call returns (submits, cancels, outcomes). The worker's
            // progress writes commit asynchronously (no WAL flush wait): a database crash may
            // lose the last fraction of a second of them, which the lease fencing makes safe
            // (a lost claim or heartbeat only ends that attempt early; see docs/SERVICE.md).
            let lease_writer = open(true).await?;
            let hints = Hints::start(lease_writer.clone());
            Ok(Pools {
                writer: pool.clone(),
                pool,
                lease_writer,
                hints: Some(hints),
            })
        }
    }
}

/// Writes go through a single connection (`writer`) so that in-process writers queue fairly in
/// the pool instead of contending for SQLite's lock (whose busy handler sleeps for
/// milliseconds); reads use a pool of connections (WAL readers never block the writer). The SQL
/// stays safe with several processes on one file: every claim and fenced write is atomic in
/// SQLite itself.
async fn connect_sqlite(path: &Path, max_connections: u32) -> Result<Pools, StoreError> {
    if let Some(parent) = path.parent()
        && !parent.as_os_str().is_empty()
    {
        std::fs::create_dir_all(parent).map_err(|e| {
            config_error(format!(
                "cannot create database directory {}: {e}",
                parent.display()
            ))
        })?;
    }
    let options = AnyConnectOptions::from_str(&sqlite_url(path)?)?;
    let open = |max: u32| {
        AnyPoolOptions::new()
            .max_connections(max)
            .after_connect(|conn, _meta| {
                Box::pin(async move {
                    for pragma in [
                        "PRAGMA journal_mode = WAL",
                        "PRAGMA synchronous = NORMAL",
                        "PRAGMA foreign_keys = ON",
                        "PRAGMA busy_timeout = 10000",
                        // No checkpoint inside a commit (it fsyncs and would stall every queued
                        // write); the owner calls `checkpoint` from a background task instead.
                        "PRAGMA wal_autocheckpoint = 0",
                    ] {
                        conn.execute(pragma).await?;
                    }
                    Ok(())
                })
            })
            .connect_with(options.clone())
    };
    let writer = open(1).await?;
    sqlx::migrate!("./migrations/sqlite").run(&writer).await?;
    let pool = open(max_connections.max(1)).await?;
    Ok(Pools {
        pool,
        lease_writer: writer.clone(),
        writer,
        hints: None,
    })
}

/// PostgreSQL wake-up hints, sent after the write they announce has committed, on the
/// asynchronous-commit pool (a NOTIFY inside a durable commit would hold a database-wide lock
/// through its flush): `vf_queue` (a job became claimable; idle workers on every node try a
/// claim), at most one per 20 ms however many jobs were queued, and `vf_job` with a job id (its
/// event streams re-read it), at most one per job per 20 ms. Both are hints: workers poll and event
/// streams re-read on a timer whatever happens. The task ends with the pool.
#[derive(Clone, Debug)]
pub(super) struct Hints {
    queue: Arc<Notify>,
    jobs: tokio::sync::mpsc::Sender<String>,
}

impl Hints {
    fn start(pool: AnyPool) -> Hints {
        let queue = Arc::new(Notify::new());
        let wait = queue.clone();
        let p = pool.clone();
        tokio::spawn(async move {
            loop {
                wait.notified().await;
                if p.is_closed() || !notify(&p, "vf_queue", "").await {
                    return;
                }
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        });
        // Bounded: when the database is slower than the hints, the newest are dropped (the
        // streams' timers cover them).
        let (jobs, mut rx) = tokio::sync::mpsc::channel::<String>(1024);
        tokio::spawn(async move {
            let mut batch = std::collections::BTreeSet::new();
            while let Some(id) = rx.recv().await {
                batch.insert(id);
                tokio::time::sleep(Duration::from_millis(20)).await;
                while let Ok(id) = rx.try_recv() {
                    batch.insert(id);
                }
                for id in std::mem::take(&mut batch) {
                    if pool.is_closed() || !notify(&pool, "vf_job", &id).await {
                        return;
                    }
                }
            }
        });
        Hints { queue, jobs }
    }

    pub(super) fn queued(&self) {
        self.queue.notify_one();
    }

    pub(super) fn job(&self, id: &str) {
        let _ = self.jobs.try_send(id.to_string());
    }

    /// Lets the queue task see the closed pool and end.
    pub(super) fn close(&self) {
        self.queue.notify_one();
    }
}

/// `pg_notify(channel, payload)`; `false` once the pool is closed.
async fn notify(pool: &AnyPool, channel: &str, payload: &str) -> bool {
    match sqlx::query("SELECT pg_notify($1, $2)")
        .bind(channel)
        .bind(payload)
        .execute(pool)
        .await
    {
        Ok(_) => true,
        Err(e) => {
            if pool.is_closed() {
                return false;
            }
            tracing::debug!(error = %e, channel, "notification failed (a hint; polling covers it)");
            true
        }
    }
}

/// A database that cannot be opened as configured.
fn config_error(msg: String) -> StoreError {
    StoreError::Db(sqlx::Error::Configuration(msg.into()))
}

/// `sqlite:///absolute/path?mode=rwc`, the path percent-encoded (the driver decodes it).
fn sqlite_url(path: &Path) -> Result<String, StoreError> {
    let abs = std::path::absolute(path).map_err(|e| {
        config_error(format!(
            "cannot resolve database path {}: {e}",
            path.display()
        ))
    })?;
    let Some(text) = abs.to_str() else {
        return Err(config_error(format!(
            "database path {} is not UTF-8",
            abs.display()
        )));
    };
    let mut url = String::from("sqlite://");
    for b in text.bytes() {
        if b.is_ascii_alphanumeric() || b"/-_.~".contains(&b) {
            url.push(b as char);
        } else {
            url.push_str(&format!("%{b:02X}"));
        }
    }
    url.push_str("?mode=rwc");
    Ok(url)
}

/// Tests: creates an empty database on the PostgreSQL server of `admin_url` (a URL whose user
/// may `CREATE DATABASE`) and returns the URL of the new database.
#[doc(hidden)]
pub async fn create_test_database(admin_url: &str) -> Result<String, StoreError> {
    use sqlx::Connection;
    let mut url = url::Url::parse(admin_url).map_err(|e| config_error(e.to_string()))?;
    let name = format!("vf_test_{}", uuid::Uuid::new_v4().simple());
    let mut conn = sqlx::postgres::PgConnection::connect(admin_url).await?;
    // The name is ours (a UUID), not input: safe to put in the statement.
    sqlx::raw_sql(sqlx::AssertSqlSafe(format!("CREATE DATABASE {name}")))
        .execute(&mut conn)
        .await?;
    let _ = conn.close().await;
    url.set_path(&name);
    Ok(url.to_string())
}

/// The text of one statement: `sql!("get_job.sql")` is `sql/get_job.sql`, written once for both
/// backends (`$N` placeholders, which SQLite binds by number as PostgreSQL does);
/// `sql!(self, "claim.sql")` is `sql/sqlite/claim.sql` or `sql/postgres/claim.sql`, for a
/// statement whose dialects differ.
macro_rules! sql {
    ($file:literal) => {
        include_str!(concat!("sql/", $file))
    };
    ($store:expr, $file:literal) => {
        match $store.backend {
            $crate::store::Backend::Sqlite => include_str!(concat!("sql/sqlite/", $file)),
            $crate::store::Backend::Postgres => include_str!(concat!("sql/postgres/", $file)),
        }
    };
}
pub(super) use sql;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locations_parse_by_scheme() {
        assert_eq!(
            DbLocation::parse("jobs.db").unwrap(),
            DbLocation::Sqlite("jobs.db".into())
        );
        assert_eq!(
            DbLocation::parse("sqlite:///var/vf/jobs.db").unwrap(),
            DbLocation::Sqlite("/var/vf/jobs.db".into())
        );
        let pg = DbLocation::parse("postgres://vf:secret@db:5432/vf").unwrap();
        assert_eq!(pg.backend(), Backend::Postgres);
        assert!(!pg.to_string().contains("secret"), "{pg}");
        assert!(DbLocation::parse("mysql://x/y").is_err());
        assert!(DbLocation::parse("  ").is_err());
        assert!(DbLocation::parse("postgres://[bad").is_err());
    }

    #[tokio::test]
    async fn an_unreachable_database_is_unavailable_not_corrupt() {
        // Port 1 on loopback: nothing listens, the connection is refused.
        let loc = DbLocation::parse("postgres://vf@127.0.0.1:1/vf?connect_timeout=2").unwrap();
        let err = super::super::Store::connect(&loc, 1).await.unwrap_err();
        assert!(err.is_unavailable(), "{err:?}");
        let bad = super::super::StoreError::Corrupt("x".into());
        assert!(!bad.is_unavailable());
    }

    #[test]
    fn sqlite_urls_survive_odd_paths() {
        let url = sqlite_url(Path::new("/tmp/a b?c#d.db")).unwrap();
        assert_eq!(url, "sqlite:///tmp/a%20b%3Fc%23d.db?mode=rwc");
    }
}
