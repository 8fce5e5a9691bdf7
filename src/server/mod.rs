//! The HTTP service (axum): job submission, status, listing, cancellation, results, SSE progress,
//! health, readiness and Prometheus metrics. `openapi.yaml` at the crate root documents it; a
//! test keeps the two in sync.
//!
//! [`run`] opens the store, starts the worker pool and serves until the shutdown future
//! resolves; then it stops accepting connections, ends event streams, interrupts running jobs
//! (they checkpoint and return to the queue) and waits for the workers.

pub mod error;
pub mod listen;
mod page;
mod routes;
mod sse;
pub mod tenant;
pub mod types;
mod wakeups;

use crate::config::Config;
use crate::pipeline::{Executor, Limits};
use crate::store::{DbLocation, Store, StoreError};
use crate::worker::events::Hub;
use crate::worker::metrics::Metrics;
use crate::worker::{WorkerPool, WorkerSettings};
use axum::Router;
use axum::extract::DefaultBodyLimit;
use axum::http::Method;
use axum::routing::{MethodRouter, delete, get, post};
use std::future::Future;
use std::sync::Arc;
use std::sync::atomic::{AtomicI64, Ordering};
use std::time::Duration;
use tokio::net::TcpListener;
use tokio::sync::watch;
use tracing::{info, warn};

/// Errors that stop the server.
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error("I/O error: {0}")]
    Io(#[from] std::io::Error),
    #[error("invalid configuration: {0}")]
    Config(String),
}

/// What a node does. Every node shares the queue in the database; any API node serves any job.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// The API and `queue.workers` workers (`vectorfusion serve`; `--workers 0`: API only).
    Server,
    /// Workers only (`vectorfusion worker`): health, readiness and metrics, no job API.
    Worker,
}

impl Role {
    /// Routes a node of this role serves.
    fn serves(self, path: &str) -> bool {
        match self {
            Role::Server => true,
            Role::Worker => matches!(path, "/healthz" | "/readyz" | "/metrics"),
        }
    }
}

#[doc(hidden)]
pub struct Inner {
    pub store: Store,
    pub hub: Hub,
    pub metrics: Arc<Metrics>,
    pub executor: Arc<dyn Executor>,
    pub pool: WorkerPool,
    pub cfg: Config,
    pub limits: Limits,
    pub shutdown: watch::Receiver<bool>,
    /// Queued jobs as last counted plus jobs submitted since: admission control reads this and
    /// only counts exactly (one SQL query) when it says the queue is full.
    pub queued_estimate: AtomicI64,
    /// Admission for upload validation (`server.max_concurrent_decodes` permits), so concurrent
    /// submits cannot multiply decode memory.
    pub decode_permits: Arc<tokio::sync::Semaphore>,
    /// One permit per open event stream (`server.max_sse_streams`).
    pub sse_permits: Arc<tokio::sync::Semaphore>,
}

/// Shared state of all handlers.
#[derive(Clone)]
pub struct AppState(Arc<Inner>);

impl std::ops::Deref for AppState {
    type Target = Inner;
    fn deref(&self) -> &Inner {
        &self.0
    }
}

/// Every route of the API: (method, path, handler). The router is built from this table and the
/// OpenAPI sync test compares it with `openapi.yaml`.
fn route_table() -> Vec<(Method, &'static str, MethodRouter<AppState>)> {
    use routes::{
        cancel, get_job, healthz, list, metrics, readyz, result_pdf, result_png, result_svg,
        result_variation, snapshot, submit,
    };
    const GET: Method = Method::GET;
    vec![
        (Method::POST, "/jobs", post(submit)),
        (GET, "/jobs", get(list)),
        (GET, "/jobs/{id}", get(get_job)),
        (Method::DELETE, "/jobs/{id}", delete(cancel)),
        (GET, "/jobs/{id}/events", get(sse::events)),
        (GET, "/jobs/{id}/result.svg", get(result_svg)),
        (GET, "/jobs/{id}/result.png", get(result_png)),
        (GET, "/jobs/{id}/result.pdf", get(result_pdf)),
        (GET, "/jobs/{id}/snapshots/{file}", get(snapshot)),
        (GET, "/jobs/{id}/result/{file}", get(result_variation)),
        (GET, "/healthz", get(healthz)),
        (GET, "/readyz", get(readyz)),
        (GET, "/metrics", get(metrics)),
        (GET, "/", get(page::index)),
        (GET, "/app.js", get(page::app_js)),
        (GET, "/js/{module}", get(page::module)),
        (GET, "/style.css", get(page::style_css)),
    ]
}

/// (method, path) of every route, in OpenAPI spelling (`/jobs/{id}/snapshots/{n}.svg`; the
/// one route of the variations is `/jobs/{id}/result/{i}.svg`, `.png` and `.pdf` there).
pub fn routes() -> Vec<(String, String)> {
    route_table()
        .into_iter()
        .flat_map(|(m, p, _)| {
            let m = m.as_str().to_ascii_lowercase();
            let paths = match p.strip_suffix("/result/{file}") {
                Some(base) => ["svg", "png", "pdf"]
                    .map(|ext| format!("{base}/result/{{i}}.{ext}"))
                    .to_vec(),
                None => vec![p.replace("{file}", "{n}.svg")],
            };
            paths.into_iter().map(move |p| (m.clone(), p))
        })
        .collect()
}

fn router(state: AppState, role: Role) -> Router {
    let mut r = Router::new();
    for (_, path, handler) in route_table() {
        if role.serves(path) {
            r = r.route(path, handler);
        }
    }
    r.method_not_allowed_fallback(routes::method_not_allowed)
        .fallback(routes::no_route)
        .layer(axum::middleware::from_fn_with_state(
            state.clone(),
            routes::auth_and_count,
        ))
        .layer(DefaultBodyLimit::max(state.cfg.server.max_body_bytes))
        .with_state(state)
}

/// Serves the API on `listener` until `shutdown` resolves, then shuts down gracefully.
pub async fn run(
    cfg: Config,
    executor: Arc<dyn Executor>,
    listener: TcpListener,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<(), ServerError> {
    run_node(cfg, executor, listener, shutdown, Role::Server).await
}

/// Runs one node of `role` on `listener` until `shutdown` resolves, then shuts down gracefully.
pub async fn run_node(
    cfg: Config,
    executor: Arc<dyn Executor>,
    listener: TcpListener,
    shutdown: impl Future<Output = ()> + Send + 'static,
    role: Role,
) -> Result<(), ServerError> {
    let location = cfg
        .database
        .location()
        .map_err(|e| ServerError::Config(e.to_string()))?;
    let store = Store::connect(&location, cfg.database.max_connections).await?;
    let (state, stop_tx) = app_state(cfg, executor, store.clone())?;
    let mut background = vec![
        tokio::spawn(prune_loop(state.clone())),
        tokio::spawn(depth_loop(state.clone())),
    ];
    if let DbLocation::Postgres(url) = &location {
        background.push(tokio::spawn(wakeups::listen(state.clone(), url.clone())));
    }
    let app = router(state.clone(), role);
    let addr = listener.local_addr()?;
    info!(%addr, ?role, workers = state.pool.workers(), db = %location, "listening");

    // Shutdown is bounded: open connections (SSE streams end on the stop signal; a half-sent
    // request may not) and then the workers share one `shutdown_grace_secs` deadline, counted
    // from the signal. `cli::serve` then gives abandoned blocking tasks a second at most.
    let grace = Duration::from_secs(state.cfg.server.shutdown_grace_secs);
    let stop_at = Arc::new(std::sync::OnceLock::new());
    let st = state.clone();
    let at = stop_at.clone();
    let graceful = async move {
        shutdown.await;
        let _ = at.set(std::time::Instant::now());
        info!("shutdown requested: no new jobs are claimed, running jobs checkpoint and requeue");
        let _ = stop_tx.send(true);
        st.pool.begin_shutdown();
    };
    serve_until_stopped(&state, listener, app, graceful, grace).await;
    for task in background {
        task.abort();
    }
    // Workers finish their current step, record the interruption and exit.
    let left = stop_at.get().map_or(grace, |t: &std::time::Instant| {
        grace.saturating_sub(t.elapsed())
    });
    join_workers(&state, left, grace).await;
    store.close().await;
    info!("stopped");
    Ok(())
}

/// The node's shared state over `store` (its worker pool started) and the sender of its stop
/// signal.
fn app_state(
    cfg: Config,
    executor: Arc<dyn Executor>,
    store: Store,
) -> Result<(AppState, watch::Sender<bool>), ServerError> {
    let hub = Hub::new();
    let metrics = Arc::new(Metrics::default());
    let pool = WorkerPool::start(
        store.clone(),
        executor.clone(),
        hub.clone(),
        metrics.clone(),
        WorkerSettings::from_config(&cfg),
        tokio::runtime::Handle::current(),
    )?;
    let (stop_tx, stop_rx) = watch::channel(false);
    let decode_permits = Arc::new(tokio::sync::Semaphore::new(
        cfg.server.max_concurrent_decodes,
    ));
    let sse_permits = Arc::new(tokio::sync::Semaphore::new(cfg.server.max_sse_streams));
    let state = AppState(Arc::new(Inner {
        store,
        hub,
        metrics,
        executor,
        pool,
        limits: cfg.limits(),
        cfg,
        shutdown: stop_rx,
        queued_estimate: AtomicI64::new(0),
        decode_permits,
        sse_permits,
    }));
    Ok((state, stop_tx))
}

/// Serves `app` on `listener` until `graceful` has run and the connections closed, or `grace`
/// after the stop signal (then the connections left are closed).
async fn serve_until_stopped(
    state: &AppState,
    listener: TcpListener,
    app: Router,
    graceful: impl Future<Output = ()> + Send + 'static,
    grace: Duration,
) {
    let conn_limits = listen::ConnLimits {
        max_connections: state.cfg.server.max_connections,
        header_read_timeout: Duration::from_secs(state.cfg.server.header_read_timeout_secs),
    };
    let serve = listen::serve(listener, app, conn_limits, graceful);
    tokio::pin!(serve);
    let mut stop_seen = state.shutdown.clone();
    tokio::select! {
        () = &mut serve => {}
        _ = async {
            let _ = stop_seen.wait_for(|s| *s).await;
            tokio::time::sleep(grace).await;
        } => {
            warn!("connections still open {}s after the shutdown request; closing them", grace.as_secs());
        }
    };
}

/// Waits up to `left` for the worker threads (`grace` is the whole deadline, for the log).
async fn join_workers(state: &AppState, left: Duration, grace: Duration) {
    let st = state.clone();
    let joined =
        tokio::time::timeout(left, tokio::task::spawn_blocking(move || st.pool.join())).await;
    if joined.is_err() {
        warn!(
            "workers did not stop within {}s; their leases will expire and the jobs will be reclaimed",
            grace.as_secs()
        );
    }
}

async fn prune_loop(state: AppState) {
    let every = Duration::from_secs(state.cfg.queue.prune_interval_secs.max(1));
    let keep_ms = (state.cfg.queue.retention_hours as i64).saturating_mul(3_600_000);
    loop {
        let cutoff = crate::store::now_ms().saturating_sub(keep_ms);
        match state.store.prune(cutoff).await {
            Ok(0) => {}
            Ok(n) => info!(jobs = n, "pruned finished jobs past retention"),
            Err(e) => warn!(error = %e, "pruning failed"),
        }
        tokio::time::sleep(every).await;
    }
}

/// Refreshes the queue-depth estimate used for admission control, and checkpoints the WAL
/// (off the write path) about once a second.
async fn depth_loop(state: AppState) {
    let mut ticks = 0u32;
    loop {
        ticks = ticks.wrapping_add(1);
        if ticks.is_multiple_of(5)
            && let Err(e) = state.store.checkpoint().await
        {
            warn!(error = %e, "WAL checkpoint failed");
        }
        if let Ok(n) = state.store.queue_depth().await {
            state.queued_estimate.store(n, Ordering::Relaxed);
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}
