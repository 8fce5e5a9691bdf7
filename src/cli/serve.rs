//! `vectorfusion serve`: run the HTTP service.

use super::CliError;
use crate::config::Config;
use crate::pipeline::{DefaultExecutor, Executor};
use crate::server::Role;
use crate::worker::isolate::{ChildExecutor, JobLimits, ProcessExecutor};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;

/// Run the HTTP job service (see docs/SERVICE.md). Without flags: 127.0.0.1:8080, ./vectorfusion.db.
#[derive(clap::Args, Debug)]
pub struct ServeArgs {
    /// Listen address, overrides server.bind.
    #[arg(long, value_name = "ADDR:PORT")]
    pub bind: Option<SocketAddr>,
    #[command(flatten)]
    pub node: NodeArgs,
}

/// Run a worker-only node (see docs/SERVICE.md): it claims jobs from the shared queue and serves
/// only /healthz, /readyz and /metrics.
#[derive(clap::Args, Debug)]
pub struct WorkerArgs {
    /// Listen address of the health and metrics endpoints. Default: a free port on localhost,
    /// logged at start (`listening addr=…`), so several workers share a host without clashing;
    /// name one for health checks and scraping.
    #[arg(long, value_name = "ADDR:PORT", default_value = "127.0.0.1:0")]
    pub bind: SocketAddr,
    #[command(flatten)]
    pub node: NodeArgs,
}

/// What every node takes.
#[derive(clap::Args, Debug)]
pub struct NodeArgs {
    /// Configuration file (TOML; see config.toml for every setting).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// The queue: a SQLite file (overrides database.path) or postgres://user@host/db (overrides
    /// database.url; env VECTORFUSION_DATABASE_URL).
    #[arg(long, value_name = "PATH|URL")]
    pub db: Option<String>,
    /// Worker threads, overrides queue.workers (0: an API-only node).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(0..=256))]
    pub workers: Option<u16>,
    /// Testing only: replace the pipeline with the service test double, sleeping STEP_MS per
    /// step. Not a product feature.
    #[arg(long, value_name = "STEP_MS", hide = true)]
    pub test_executor: Option<u64>,
}

pub fn run(args: NodeArgs, bind: Option<SocketAddr>, role: Role) -> Result<(), CliError> {
    let mut cfg =
        Config::load(args.config.as_deref()).map_err(|e| CliError::Usage(e.to_string()))?;
    if let Some(b) = bind {
        cfg.server.bind = b.to_string();
    }
    if let Some(db) = args.db {
        match crate::store::DbLocation::parse(&db).map_err(|e| CliError::Usage(e.to_string()))? {
            crate::store::DbLocation::Sqlite(path) => {
                cfg.database.path = path;
                cfg.database.url.clear();
            }
            crate::store::DbLocation::Postgres(url) => cfg.database.url = url,
        }
    }
    if let Some(n) = args.workers {
        cfg.queue.workers = n as usize;
    }
    if role == Role::Worker && cfg.queue.workers == 0 {
        return Err(CliError::Usage(
            "a worker node needs at least one worker (--workers N, N ≥ 1)".into(),
        ));
    }
    cfg.validate().map_err(|e| CliError::Usage(e.to_string()))?;
    init_logging(&cfg);
    let (inner, child): (Arc<dyn Executor>, ChildExecutor) = match args.test_executor {
        Some(ms) => {
            tracing::warn!(
                "running with the TEST executor (service test double), not the pipeline"
            );
            (
                Arc::new(crate::worker::test_executor::TestExecutor::new(ms)),
                ChildExecutor::Test { step_ms: ms },
            )
        }
        None => {
            let mut dirs = cfg.model_dirs();
            if dirs.sd_dir.is_none() {
                let default = crate::pipeline::default_model_dir()
                    .map_err(|e| CliError::Usage(e.to_string()))?;
                dirs = dirs.or_default_model(default);
            }
            (
                Arc::new(DefaultExecutor::new(dirs.clone())),
                ChildExecutor::Pipeline { models: dirs },
            )
        }
    };
    let executor: Arc<dyn Executor> = if cfg.queue.isolation == "process" {
        let exe = std::env::current_exe().map_err(|e| {
            CliError::Usage(format!(
                "cannot find this program to start job processes ({e}); set queue.isolation = \"thread\""
            ))
        })?;
        let limits = JobLimits {
            max_rss_bytes: cfg.queue.job_memory_mb.saturating_mul(1 << 20),
            max_wall: std::time::Duration::from_secs(cfg.queue.job_wall_secs),
        };
        Arc::new(ProcessExecutor::new(exe, child, inner, limits))
    } else {
        inner
    };
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name("vf-http")
        .build()
        .map_err(|e| CliError::Other(e.into()))?;
    let result = rt.block_on(async move {
        let listener = crate::server::listen::bind(&cfg.server.bind)
            .await
            .map_err(|e| CliError::Usage(format!("cannot listen on {}: {e}", cfg.server.bind)))?;
        crate::server::run_node(cfg, executor, listener, shutdown_signal(), role)
            .await
            .map_err(|e| CliError::Other(e.into()))
    });
    // A worker still inside a long step after the grace period holds a blocking task; dropping
    // the runtime would wait for it. Its lease expires and the job is reclaimed after restart.
    rt.shutdown_timeout(std::time::Duration::from_secs(1));
    result
}

fn init_logging(cfg: &Config) {
    use tracing_subscriber::EnvFilter;
    let filter = EnvFilter::try_from_default_env()
        .or_else(|_| EnvFilter::try_new(&cfg.log.level))
        .unwrap_or_else(|_| EnvFilter::new("info"));
    // Colours only on a terminal: logs piped to a file, journald or a container runtime carry
    // no escape codes (and none where NO_COLOR is set).
    let colour = std::io::IsTerminal::is_terminal(&std::io::stderr())
        && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty());
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(colour)
        .with_writer(std::io::stderr);
    let _ = if cfg.log.format == "json" {
        builder.json().try_init()
    } else {
        builder.try_init()
    };
}

/// Resolves on Ctrl-C or SIGTERM.
async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
    }
}

#[cfg(test)]
mod tests {
    use super::WorkerArgs;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        worker: WorkerArgs,
    }

    #[test]
    fn a_worker_binds_a_free_port_unless_told() {
        let default = Cli::try_parse_from(["worker"]).unwrap().worker.bind;
        assert_eq!(default.port(), 0, "two workers on one host must not clash");
        assert!(default.ip().is_loopback());
        let told = Cli::try_parse_from(["worker", "--bind", "0.0.0.0:9100"]).unwrap();
        assert_eq!(told.worker.bind.port(), 9100);
    }
}
