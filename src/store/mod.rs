//! The job store: SQLite (embedded, WAL) or PostgreSQL (shared by many nodes) through sqlx,
//! schema in `migrations/<backend>/`, every statement in a file: `src/store/sql/` when both
//! backends run the same text, `src/store/sql/<backend>/` when their dialects differ
//! (`backend.rs` picks them).
//!
//! Jobs move `queued → running → succeeded | failed | cancelled` (a CHECK constraint keeps the
//! status honest). A worker *claims* a job with one atomic `UPDATE … RETURNING`, which gives it a
//! lease (`lease_owner`, `lease_expires_at`) that it extends with heartbeats. Every write a worker
//! makes afterwards is guarded by `(lease_owner, attempts)`, so a worker that lost its lease (it
//! stalled, the job was reclaimed) can no longer touch the job: a job completes exactly once.
//! Each claim opens a row in `attempts`, closed with its outcome.

mod backend;
mod columns;
mod failure;
mod lease;
mod rows;
mod uploads;

pub use backend::{Backend, DbLocation, LocationError, create_test_database};
pub use columns::UnknownName;
pub use failure::FailureCode;
pub use rows::{AttemptRow, JobRow, NewJob, ResultRow, SnapshotRow};
pub use uploads::{NewUpload, UploadRow};

use backend::sql;
use serde::Serialize;
use sqlx::AnyPool;
use std::path::Path;

/// Errors from the store.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("database error: {0}")]
    Db(#[from] sqlx::Error),
    #[error("database migration failed: {0}")]
    Migrate(#[from] sqlx::migrate::MigrateError),
    #[error("corrupt row in database: {0}")]
    Corrupt(String),
    /// A submit whose upload would take the stored uploads past a quota (nothing was inserted).
    #[error("stored uploads would exceed {limit} bytes")]
    UploadQuota { limit: i64 },
    /// A submit with [`NewJob::max_queued`] found that many jobs queued (nothing was inserted).
    #[error("the queue already holds {limit} jobs")]
    QueueFull { limit: i64 },
}

impl StoreError {
    /// The database cannot be reached right now (connection refused or lost, pool exhausted,
    /// server shutting down or starting): worth retrying, unlike a bad statement or row.
    pub fn is_unavailable(&self) -> bool {
        match self {
            StoreError::Db(
                sqlx::Error::Io(_)
                | sqlx::Error::PoolTimedOut
                | sqlx::Error::PoolClosed
                | sqlx::Error::Tls(_),
            ) => true,
            StoreError::Db(sqlx::Error::Database(e)) => e.code().is_some_and(|c| {
                // PostgreSQL: connection exceptions (08…), shutdown / cannot connect now (57P…).
                c.starts_with("08") || c.starts_with("57P")
            }),
            _ => false,
        }
    }
}

/// What a job produces: caption → SVG, or image → SVG (mirrors the CHECK constraint on
/// `jobs.kind`; the job contract in `pipeline::spec` uses this type).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JobKind {
    Text,
    Vectorize,
}

impl JobKind {
    pub const ALL: &[JobKind] = &[JobKind::Text, JobKind::Vectorize];

    pub fn as_str(self) -> &'static str {
        match self {
            JobKind::Text => "text",
            JobKind::Vectorize => "vectorize",
        }
    }
}

/// Job lifecycle states (mirrors the CHECK constraint in `migrations/*/0001_jobs.sql`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JobStatus {
    Queued,
    Running,
    Succeeded,
    Failed,
    Cancelled,
}

impl JobStatus {
    pub const ALL: [JobStatus; 5] = [
        JobStatus::Queued,
        JobStatus::Running,
        JobStatus::Succeeded,
        JobStatus::Failed,
        JobStatus::Cancelled,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            JobStatus::Queued => "queued",
            JobStatus::Running => "running",
            JobStatus::Succeeded => "succeeded",
            JobStatus::Failed => "failed",
            JobStatus::Cancelled => "cancelled",
        }
    }

    pub fn is_terminal(self) -> bool {
        matches!(
            self,
            JobStatus::Succeeded | JobStatus::Failed | JobStatus::Cancelled
        )
    }
}

/// Identifies one attempt of one job held by one worker; every worker write carries it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Lease {
    pub job_id: String,
    pub worker: String,
    pub attempt: i64,
}

/// Outcome of a heartbeat.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Heartbeat {
    /// Lease extended; `cancel` tells whether a cancel was requested.
    Held { cancel: bool },
    /// Another worker holds the job now, or it was finished: stop working on it.
    Lost,
}

/// How an attempt ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AttemptOutcome {
    Succeeded,
    Failed,
    Retry,
    Cancelled,
    Interrupted,
}

impl AttemptOutcome {
    fn as_str(self) -> &'static str {
        match self {
            AttemptOutcome::Succeeded => "succeeded",
            AttemptOutcome::Failed => "failed",
            AttemptOutcome::Retry => "retry",
            AttemptOutcome::Cancelled => "cancelled",
            AttemptOutcome::Interrupted => "interrupted",
        }
    }
}

/// Milliseconds since the Unix epoch, the time unit of the store.
pub fn now_ms() -> i64 {
    chrono::Utc::now().timestamp_millis()
}

/// Handle to the database; cheap to clone. SQLite: one writer connection (also the worker's
/// lease writes) and a pool of readers; PostgreSQL: one pool for reads and durable writes and one
/// with asynchronous commits for the worker's lease writes (`backend.rs` says why).
#[derive(Clone, Debug)]
pub struct Store {
    pool: AnyPool,
    writer: AnyPool,
    lease_writer: AnyPool,
    hints: Option<backend::Hints>,
    backend: Backend,
}

impl Store {
    /// Opens (creating if needed) the SQLite file at `path` in WAL mode and runs the migrations.
    pub async fn open(path: &Path, max_connections: u32) -> Result<Self, StoreError> {
        Self::connect(&DbLocation::Sqlite(path.to_path_buf()), max_connections).await
    }

    /// Opens the database at `loc` (SQLite or PostgreSQL) and runs its migrations.
    pub async fn connect(loc: &DbLocation, max_connections: u32) -> Result<Self, StoreError> {
        let pools = backend::connect(loc, max_connections).await?;
        Ok(Store {
            pool: pools.pool,
            writer: pools.writer,
            lease_writer: pools.lease_writer,
            hints: pools.hints,
            backend: loc.backend(),
        })
    }

    /// A job became claimable: tell idle workers on other nodes (PostgreSQL; coalesced).
    fn hint_queued(&self) {
        if let Some(h) = &self.hints {
            h.queued();
        }
    }

    /// What job `id`'s event stream shows changed: tell its streams on other nodes
    /// (PostgreSQL; coalesced).
    fn hint_job(&self, id: &str) {
        if let Some(h) = &self.hints {
            h.job(id);
        }
    }

    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// For tests and tools that read the tables directly.
    pub fn pool(&self) -> &AnyPool {
        &self.pool
    }

    /// A write transaction. SQLite takes its write lock at `BEGIN IMMEDIATE`, so the statements
    /// inside never fail half-way on a busy lock.
    async fn begin(&self) -> Result<sqlx::Transaction<'static, sqlx::Any>, StoreError> {
        Ok(match self.backend {
            Backend::Sqlite => self.writer.begin_with("BEGIN IMMEDIATE").await?,
            Backend::Postgres => self.writer.begin().await?,
        })
    }

    /// Closes every connection (SQLite: checkpoints the WAL).
    pub async fn close(&self) {
        if self.backend == Backend::Sqlite {
            let _ = sqlx::query("PRAGMA wal_checkpoint(TRUNCATE)")
                .execute(&self.writer)
                .await;
        }
        self.pool.close().await;
        self.writer.close().await;
        self.lease_writer.close().await;
        if let Some(h) = &self.hints {
            h.close();
        }
    }

    /// SQLite: copies the WAL back into the database file without blocking readers or the writer
    /// (`PRAGMA wal_checkpoint(PASSIVE)`). Automatic checkpoints are off: long-lived owners
    /// (the server) call this periodically; [`Store::close`] truncates the WAL. PostgreSQL: nothing.
    pub async fn checkpoint(&self) -> Result<(), StoreError> {
        if self.backend == Backend::Sqlite {
            sqlx::query("PRAGMA wal_checkpoint(PASSIVE)")
                .execute(&self.pool)
                .await?;
        }
        Ok(())
    }

    /// A trivial query, for readiness checks.
    pub async fn ping(&self) -> Result<(), StoreError> {
        sqlx::query("SELECT 1").execute(&self.pool).await?;
        Ok(())
    }

    /// Inserts a job (and its upload, in one transaction). With an idempotency key already in
    /// use, returns the existing job and `false`. An upload past its quotas inserts nothing and
    /// fails with [`StoreError::UploadQuota`].
    pub async fn insert_job(&self, job: &NewJob, now: i64) -> Result<(JobRow, bool), StoreError> {
        let Some(up) = &job.upload else {
            let inserted = if self.backend == Backend::Postgres && job.max_queued.is_some() {
                // The count in the insert must see every earlier insert: take the admission
                // lock in a transaction first (SQLite's single writer does this for free).
                let mut tx = self.begin().await?;
                self.admission_lock(&mut tx).await?;
                let inserted = self
                    .insert_job_query(job, now)
                    .fetch_optional(&mut *tx)
                    .await?;
                tx.commit().await?;
                inserted
            } else {
                // One autocommit statement, one round trip on the writer.
                self.insert_job_query(job, now)
                    .fetch_optional(&self.writer)
                    .await?
            };
            return match inserted {
                Some(row) => {
                    self.hint_queued();
                    Ok((row, true))
                }
                None => self.not_inserted(job).await,
            };
        };
        let mut tx = self.begin().await?;
        self.admission_lock(&mut tx).await?;
        let inserted = self
            .insert_job_query(job, now)
            .fetch_optional(&mut *tx)
            .await?;
        let Some(row) = inserted else {
            tx.rollback().await?;
            return self.not_inserted(job).await;
        };
        let stored = sqlx::query(sql!(self, "insert_upload.sql"))
            .bind(&job.id)
            .bind(&job.tenant)
            .bind(up.image.as_deref())
            .bind(&up.svg)
            .bind(up.bytes())
            .bind(now)
            .bind(up.max_total_bytes)
            .bind(up.max_tenant_bytes)
            .execute(&mut *tx)
            .await?;
        if stored.rows_affected() == 0 {
            tx.rollback().await?;
            let over_tenant = up.max_tenant_bytes > 0
                && self.upload_bytes(Some(job.tenant.as_deref())).await? + up.bytes()
                    > up.max_tenant_bytes;
            return Err(StoreError::UploadQuota {
                limit: if over_tenant {
                    up.max_tenant_bytes
                } else {
                    up.max_total_bytes
                },
            });
        }
        tx.commit().await?;
        self.hint_queued();
        Ok((row, true))
    }

    /// PostgreSQL: serialises the inserts that count (queue depth, upload quotas) until `tx`
    /// ends. SQLite: nothing (its single writer already does).
    async fn admission_lock(
        &self,
        tx: &mut sqlx::Transaction<'static, sqlx::Any>,
    ) -> Result<(), StoreError> {
        if self.backend == Backend::Postgres {
            sqlx::query(include_str!("sql/postgres/admission_lock.sql"))
                .execute(&mut **tx)
                .await?;
        }
        Ok(())
    }

    /// Why `job`'s insert did nothing: its idempotency key is taken (that job, and `false`), or
    /// the queue was full ([`NewJob::max_queued`]).
    async fn not_inserted(&self, job: &NewJob) -> Result<(JobRow, bool), StoreError> {
        let existing: Option<JobRow> = match &job.idempotency_key {
            Some(key) => {
                sqlx::query_as(sql!("get_job_by_key.sql"))
                    .bind(key)
                    .fetch_optional(&self.writer)
                    .await?
            }
            None => None,
        };
        match (existing, job.max_queued) {
            (Some(r), _) => Ok((r, false)),
            (None, Some(limit)) => Err(StoreError::QueueFull { limit }),
            (None, None) => Err(StoreError::Corrupt(
                "idempotency key conflict without a row".into(),
            )),
        }
    }

    /// The job submitted with this idempotency key, if any.
    pub async fn get_job_by_key(&self, key: &str) -> Result<Option<JobRow>, StoreError> {
        self.row_by(sql!("get_job_by_key.sql"), key).await
    }

    pub async fn get_job(&self, id: &str) -> Result<Option<JobRow>, StoreError> {
        self.row_by(sql!("get_job.sql"), id).await
    }

    /// The row, if any, that a read of one key (`$1`) returns, from the reader pool.
    async fn row_by<T>(&self, statement: &'static str, key: &str) -> Result<Option<T>, StoreError>
    where
        T: for<'r> sqlx::FromRow<'r, sqlx::any::AnyRow> + Send + Unpin,
    {
        Ok(sqlx::query_as(statement)
            .bind(key)
            .fetch_optional(&self.pool)
            .await?)
    }

    /// Newest first; `before_seq` is the cursor; `tenant` filters (`None`: every job). The rows
    /// leave the upload and the checkpoint in the database (see `sql/list_jobs.sql`).
    pub async fn list_jobs(
        &self,
        status: Option<JobStatus>,
        before_seq: Option<i64>,
        limit: i64,
        tenant: Option<&str>,
    ) -> Result<Vec<JobRow>, StoreError> {
        Ok(sqlx::query_as(sql!(self, "list_jobs.sql"))
            .bind(status.map(JobStatus::as_str))
            .bind(before_seq)
            .bind(limit)
            .bind(tenant)
            .fetch_all(&self.pool)
            .await?)
    }

    /// Queued and running jobs of `tenant`.
    pub async fn active_jobs(&self, tenant: &str) -> Result<i64, StoreError> {
        Ok(sqlx::query_scalar(sql!("active_jobs.sql"))
            .bind(tenant)
            .fetch_one(&self.pool)
            .await?)
    }

    pub async fn queue_depth(&self) -> Result<i64, StoreError> {
        Ok(sqlx::query_scalar(sql!("queue_depth.sql"))
            .fetch_one(&self.pool)
            .await?)
    }

    pub async fn count_by_status(&self) -> Result<Vec<(String, i64)>, StoreError> {
        Ok(sqlx::query_as(sql!("count_by_status.sql"))
            .fetch_all(&self.pool)
            .await?)
    }

    /// Cancels a queued job at once or flags a running one. `None` if the id is unknown.
    pub async fn request_cancel(&self, id: &str, now: i64) -> Result<Option<JobRow>, StoreError> {
        let row: Option<JobRow> = sqlx::query_as(sql!(self, "request_cancel.sql"))
            .bind(id)
            .bind(now)
            .fetch_optional(&self.writer)
            .await?;
        if row.is_some() {
            self.hint_job(id);
        }
        Ok(row)
    }

    pub async fn attempts(&self, job_id: &str) -> Result<Vec<AttemptRow>, StoreError> {
        Ok(sqlx::query_as(sql!("list_attempts.sql"))
            .bind(job_id)
            .fetch_all(&self.pool)
            .await?)
    }

    pub async fn snapshots_after(
        &self,
        job_id: &str,
        after: i64,
        limit: i64,
    ) -> Result<Vec<SnapshotRow>, StoreError> {
        Ok(sqlx::query_as(sql!("snapshots_after.sql"))
            .bind(job_id)
            .bind(after)
            .bind(limit)
            .fetch_all(&self.pool)
            .await?)
    }

    pub async fn latest_snapshot(&self, job_id: &str) -> Result<Option<SnapshotRow>, StoreError> {
        self.row_by(sql!("latest_snapshot.sql"), job_id).await
    }

    pub async fn snapshot(&self, job_id: &str, n: i64) -> Result<Option<SnapshotRow>, StoreError> {
        Ok(sqlx::query_as(sql!("get_snapshot.sql"))
            .bind(job_id)
            .bind(n)
            .fetch_optional(&self.pool)
            .await?)
    }

    pub async fn result(&self, job_id: &str) -> Result<Option<ResultRow>, StoreError> {
        self.row_by(sql!("get_result.sql"), job_id).await
    }

    /// The SVG of variation `n` (2, 3, ...) of a job's result ([`Store::complete_variations`];
    /// variation 1 is [`Store::result`]'s), `None` when the job has no such variation.
    pub async fn result_variation(
        &self,
        job_id: &str,
        n: i64,
    ) -> Result<Option<String>, StoreError> {
        Ok(sqlx::query_scalar(sql!("get_result_variation.sql"))
            .bind(job_id)
            .bind(n)
            .fetch_optional(&self.pool)
            .await?)
    }

    /// The insert of `job`'s row (`RETURNING *`; nothing when its idempotency key is taken).
    fn insert_job_query<'q>(
        &self,
        job: &'q NewJob,
        now: i64,
    ) -> sqlx::query::QueryAs<'q, sqlx::Any, JobRow, sqlx::any::AnyArguments> {
        sqlx::query_as(sql!(self, "insert_job.sql"))
            .bind(&job.id)
            .bind(job.kind)
            .bind(&job.spec)
            .bind(job.priority)
            .bind(&job.idempotency_key)
            .bind(&job.request_hash)
            .bind(job.max_attempts)
            .bind(now)
            .bind(job.max_lost_attempts)
            .bind(&job.tenant)
            .bind(job.max_queued)
    }

    /// Deletes finished jobs (and their snapshots, results, attempts) finished before `before`.
    pub async fn prune(&self, before: i64) -> Result<u64, StoreError> {
        let r = sqlx::query(sql!("prune.sql"))
            .bind(before)
            .execute(&self.writer)
            .await?;
        Ok(r.rows_affected())
    }
}

#[cfg(test)]
mod tests;
