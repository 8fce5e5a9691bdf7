//! The worker pool: N dedicated OS threads, each claiming one job at a time from the store and
//! running it through the [`Executor`] off the async runtime.
//!
//! Per job a worker: claims it (atomic, with a lease); starts a heartbeat task on the runtime that
//! extends the lease and picks up cancel requests; hands the executor a [`JobContext`] whose
//! progress sink rate-limits progress and snapshots into the database and the event [`Hub`], and
//! whose checkpointer stores resumable state; then records the outcome, guarded by the lease, so
//! a job completes exactly once. Retryable failures are re-queued with exponential backoff. On
//! shutdown the pool stops claiming, cancels running jobs with reason "shutdown" and hands them
//! back to the queue with their last checkpoint.

pub mod events;
pub mod isolate;
pub mod metrics;
mod sink;
pub mod test_executor;
mod upload;

use crate::pipeline::{Executor, FailureCode, JobContext, JobSpec, PipelineError, RunOutput};
use crate::progress::{CancelToken, CheckpointError};
use crate::store::{Heartbeat, JobRow, JobStatus, Lease, Store, now_ms};
use events::{Hub, JobEvent};
use metrics::Metrics;
use std::collections::HashMap;
use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tokio::runtime::Handle;
use tracing::{Instrument, error, info, info_span, warn};

/// Worker settings (from the `[queue]` and `[server]` config sections).
#[derive(Clone, Debug)]
pub struct WorkerSettings {
    pub workers: usize,
    pub lease: Duration,
    pub heartbeat: Duration,
    pub poll: Duration,
    pub max_attempts: u32,
    pub retry_backoff: Duration,
    pub retry_backoff_max: Duration,
    pub checkpoint_every_steps: u32,
    pub progress_interval: Duration,
    pub snapshot_interval: Duration,
    pub max_snapshots_per_job: u32,
}

impl WorkerSettings {
    pub fn from_config(cfg: &crate::config::Config) -> Self {
        let q = &cfg.queue;
        WorkerSettings {
            workers: q.workers,
            lease: Duration::from_secs(q.lease_secs),
            heartbeat: Duration::from_secs(q.heartbeat_secs),
            poll: Duration::from_millis(q.poll_interval_ms),
            max_attempts: q.max_attempts,
            retry_backoff: Duration::from_millis(q.retry_backoff_ms),
            retry_backoff_max: Duration::from_millis(q.retry_backoff_max_ms),
            checkpoint_every_steps: q.checkpoint_every_steps,
            progress_interval: Duration::from_millis(cfg.server.progress_interval_ms),
            snapshot_interval: Duration::from_millis(cfg.server.snapshot_interval_ms),
            max_snapshots_per_job: q.max_snapshots_per_job,
        }
    }

    /// Backoff before attempt `attempt + 1`: base · 2^(attempt-1), capped.
    pub fn backoff(&self, attempt: i64) -> Duration {
        let exp = attempt.clamp(1, 30) as u32 - 1;
        let ms = (self.retry_backoff.as_millis() as u64).saturating_mul(1u64 << exp);
        Duration::from_millis(ms).min(self.retry_backoff_max)
    }
}

/// Why a running job's cancel token fired.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum StopReason {
    User,
    Shutdown,
    LeaseLost,
}

struct Running {
    cancel: CancelToken,
    reason: Arc<Mutex<Option<StopReason>>>,
}

fn set_reason(slot: &Mutex<Option<StopReason>>, r: StopReason) {
    let mut g = match slot.lock() {
        Ok(g) => g,
        Err(p) => p.into_inner(),
    };
    if g.is_none() {
        *g = Some(r);
    }
}

fn get_reason(slot: &Mutex<Option<StopReason>>) -> Option<StopReason> {
    match slot.lock() {
        Ok(g) => *g,
        Err(p) => *p.into_inner(),
    }
}

struct Shared {
    store: Store,
    executor: Arc<dyn Executor>,
    hub: Hub,
    metrics: Arc<Metrics>,
    settings: WorkerSettings,
    runtime: Handle,
    shutdown: AtomicBool,
    busy: AtomicUsize,
    running: Mutex<HashMap<String, Running>>,
    threads: Mutex<Vec<std::thread::Thread>>,
}

impl Shared {
    fn running(&self) -> std::sync::MutexGuard<'_, HashMap<String, Running>> {
        match self.running.lock() {
            Ok(g) => g,
            Err(p) => p.into_inner(),
        }
    }
}

/// Handle to the running pool.
pub struct WorkerPool {
    shared: Arc<Shared>,
    handles: Mutex<Vec<JoinHandle<()>>>,
    workers: usize,
}

impl WorkerPool {
    /// Starts `settings.workers` threads. `runtime` is the tokio runtime used for database I/O.
    pub fn start(
        store: Store,
        executor: Arc<dyn Executor>,
        hub: Hub,
        metrics: Arc<Metrics>,
        settings: WorkerSettings,
        runtime: Handle,
    ) -> std::io::Result<WorkerPool> {
        let instance = uuid::Uuid::new_v4().simple().to_string();
        let shared = Arc::new(Shared {
            store,
            executor,
            hub,
            metrics,
            settings,
            runtime,
            shutdown: AtomicBool::new(false),
            busy: AtomicUsize::new(0),
            running: Mutex::new(HashMap::new()),
            threads: Mutex::new(Vec::new()),
        });
        let mut handles = Vec::new();
        for i in 0..shared.settings.workers {
            let s = shared.clone();
            let worker_id = format!("{}-{}-w{i}", std::process::id(), &instance[..8]);
            let h = std::thread::Builder::new()
                .name(format!("vf-worker-{i}"))
                .spawn(move || worker_loop(&s, &worker_id))?;
            if let Ok(mut t) = shared.threads.lock() {
                t.push(h.thread().clone());
            }
            handles.push(h);
        }
        let workers = handles.len();
        Ok(WorkerPool {
            shared,
            handles: Mutex::new(handles),
            workers,
        })
    }

    /// Wakes idle workers (a job was just submitted).
    pub fn notify(&self) {
        if let Ok(t) = self.shared.threads.lock() {
            for th in t.iter() {
                th.unpark();
            }
        }
    }

    /// Cancels `job_id` if a worker of this process runs it; returns whether one did.
    pub fn cancel_local(&self, job_id: &str) -> bool {
        let map = self.shared.running();
        match map.get(job_id) {
            Some(r) => {
                set_reason(&r.reason, StopReason::User);
                r.cancel.cancel();
                true
            }
            None => false,
        }
    }

    pub fn workers(&self) -> usize {
        self.workers
    }

    pub fn busy(&self) -> usize {
        self.shared.busy.load(Ordering::Relaxed)
    }

    /// Stops claiming and interrupts running jobs (they checkpoint and go back to the queue).
    /// Call [`WorkerPool::join`] afterwards, off the runtime.
    pub fn begin_shutdown(&self) {
        self.shared.shutdown.store(true, Ordering::SeqCst);
        for r in self.shared.running().values() {
            set_reason(&r.reason, StopReason::Shutdown);
            r.cancel.cancel();
        }
        self.notify();
    }

    /// Waits for every worker thread to finish (blocking).
    pub fn join(&self) {
        let handles = match self.handles.lock() {
            Ok(mut h) => std::mem::take(&mut *h),
            Err(p) => std::mem::take(&mut *p.into_inner()),
        };
        for h in handles {
            if h.join().is_err() {
                error!("a worker thread panicked during shutdown");
            }
        }
    }
}

fn worker_loop(s: &Shared, worker_id: &str) {
    info!(worker = worker_id, "worker started");
    let lease_ms = s.settings.lease.as_millis() as i64;
    let mut last_reap: Option<Instant> = None;
    while !s.shutdown.load(Ordering::SeqCst) {
        let now = now_ms();
        // Reaping takes SQLite's write lock even when nothing expired: once a second is plenty.
        let reap_due = last_reap.is_none_or(|t| t.elapsed() >= Duration::from_secs(1));
        if reap_due {
            last_reap = Some(Instant::now());
        }
        match if reap_due {
            s.runtime.block_on(s.store.reap_expired(now))
        } else {
            Ok(Vec::new())
        } {
            Ok(rows) => {
                for row in rows {
                    warn!(job = %row.id, status = %row.status, "job's lease expired for good");
                    s.hub.publish(&row.id, JobEvent::Finished(row.status));
                    if row.status == JobStatus::Failed {
                        s.metrics
                            .job_failed(row.error_code.unwrap_or(FailureCode::LeaseExpired));
                    }
                }
            }
            Err(e) => warn!(error = %e, "reaping expired leases failed"),
        }
        match s.runtime.block_on(s.store.claim(worker_id, now, lease_ms)) {
            Ok(Some((row, lease))) => {
                s.busy.fetch_add(1, Ordering::Relaxed);
                let span =
                    info_span!("job", id = %row.id, attempt = lease.attempt, worker = worker_id);
                let _g = span.enter();
                run_job(s, row, lease);
                s.busy.fetch_sub(1, Ordering::Relaxed);
            }
            Ok(None) => std::thread::park_timeout(s.settings.poll),
            Err(e) => {
                warn!(error = %e, "claiming a job failed");
                std::thread::park_timeout(s.settings.poll);
            }
        }
    }
    info!(worker = worker_id, "worker stopped");
}

fn run_job(s: &Shared, row: JobRow, lease: Lease) {
    let Some(spec) = read_job(s, &row, &lease) else {
        return;
    };
    let job_id = row.id.clone();
    let resume = row
        .checkpoint
        .as_deref()
        .and_then(|c| serde_json::from_str::<serde_json::Value>(c).ok());
    info!(kind = %row.kind, resumed = resume.is_some(), "job started");
    s.hub.publish(&job_id, JobEvent::Status(JobStatus::Running));

    let (cancel, reason) = register(s, &job_id);
    let heartbeat = s.runtime.spawn(
        heartbeat_loop(
            s.store.clone(),
            lease.clone(),
            cancel.clone(),
            reason.clone(),
            s.settings.heartbeat,
            s.settings.lease,
        )
        .instrument(tracing::Span::current()),
    );
    let sink = Arc::new(sink::WorkerSink::new(s, &lease));
    let ctx = JobContext::new(
        sink.clone(),
        cancel,
        s.settings.checkpoint_every_steps,
        checkpointer(s, &lease),
        resume,
    );
    let started = Instant::now();
    let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| s.executor.run(&spec, &ctx)));
    heartbeat.abort();
    sink.flush();
    s.running().remove(&job_id);
    let stop = get_reason(&reason);
    if stop == Some(StopReason::LeaseLost) {
        Metrics::inc(&s.metrics.leases_lost);
        warn!("lease lost while running; outcome discarded");
        return;
    }
    let now = now_ms();
    match outcome {
        Ok(Ok(out)) => complete(s, &lease, &out, started),
        Ok(Err(PipelineError::Cancelled)) => stopped(s, &lease, stop, now),
        Ok(Err(e)) => fail_attempt(s, &lease, &e, now),
        Err(panic) => {
            let e = PipelineError::panicked(panic.as_ref());
            error!(error = %e, "executor panicked");
            fail_attempt(s, &lease, &e, now);
        }
    }
}

/// The claimed job's spec with its upload put back; `None` when it cannot be read (the attempt
/// is recorded as failed: `invalid_spec`, or `transient` when the database did not answer).
fn read_job(s: &Shared, row: &JobRow, lease: &Lease) -> Option<JobSpec> {
    let mut spec: JobSpec = match serde_json::from_str(&row.spec) {
        Ok(spec) => spec,
        Err(e) => {
            let e = PipelineError::InvalidSpec(format!("its spec: {e}"));
            error!(error = %e, "job cannot run");
            fail_attempt(s, lease, &e, now_ms());
            return None;
        }
    };
    let e = match upload::attach(&s.store, &s.runtime, &row.id, &mut spec) {
        Ok(()) => return Some(spec),
        // A database hiccup (more likely with a networked PostgreSQL): another attempt may
        // read it, as after a transient pipeline error.
        Err(upload::AttachError::Store(msg)) => PipelineError::Transient(msg),
        Err(upload::AttachError::Invalid(msg)) => {
            let e = PipelineError::InvalidSpec(msg);
            error!(error = %e, "job cannot run");
            e
        }
    };
    fail_attempt(s, lease, &e, now_ms());
    None
}

/// Registers `job_id` as running on this node: its cancel token and the slot for why it stops
/// (already cancelled when the pool is shutting down).
fn register(s: &Shared, job_id: &str) -> (CancelToken, Arc<Mutex<Option<StopReason>>>) {
    let cancel = CancelToken::new();
    let reason = Arc::new(Mutex::new(None));
    s.running().insert(
        job_id.to_string(),
        Running {
            cancel: cancel.clone(),
            reason: reason.clone(),
        },
    );
    if s.shutdown.load(Ordering::SeqCst) {
        set_reason(&reason, StopReason::Shutdown);
        cancel.cancel();
    }
    (cancel, reason)
}

/// Saves a running job's checkpoints in the store, under its lease.
fn checkpointer(
    s: &Shared,
    lease: &Lease,
) -> Box<dyn Fn(serde_json::Value) -> Result<(), CheckpointError> + Send + Sync> {
    let store = s.store.clone();
    let lease = lease.clone();
    let rt = s.runtime.clone();
    Box::new(move |state: serde_json::Value| {
        let text = serde_json::to_string(&state)?;
        match rt.block_on(store.save_checkpoint(&lease, &text, now_ms())) {
            Ok(true) => Ok(()),
            Ok(false) => Err(CheckpointError::LeaseLost),
            Err(e) => Err(CheckpointError::Store(Box::new(e))),
        }
    })
}

/// Stores a finished job's result (guarded by the lease).
fn complete(s: &Shared, lease: &Lease, out: &RunOutput, started: Instant) {
    // A report always serialises; `{}` only guards the impossible.
    let detail = serde_json::to_string(&out.report).unwrap_or_else(|_| "{}".into());
    let variations: Vec<(&str, i64)> = out
        .variations
        .iter()
        .map(|v| (v.svg.as_str(), v.paths as i64))
        .collect();
    let stored = s.runtime.block_on(s.store.complete_variations(
        lease,
        &out.svg,
        out.paths as i64,
        &detail,
        &variations,
        now_ms(),
    ));
    match stored {
        Ok(true) => {
            let secs = started.elapsed().as_secs_f64();
            s.metrics.observe_job(secs);
            Metrics::inc(&s.metrics.jobs_succeeded);
            info!(seconds = secs, paths = out.paths, "job succeeded");
            s.hub
                .publish(&lease.job_id, JobEvent::Finished(JobStatus::Succeeded));
        }
        Ok(false) => {
            Metrics::inc(&s.metrics.leases_lost);
            warn!("lease lost before completion; result discarded");
        }
        Err(e) => {
            error!(error = %e, "storing the result failed; the lease will expire and the job rerun")
        }
    }
}

/// Records a job that stopped when asked: back in the queue on shutdown, else cancelled.
fn stopped(s: &Shared, lease: &Lease, stop: Option<StopReason>, now: i64) {
    let job_id = &lease.job_id;
    if stop == Some(StopReason::Shutdown) {
        match s.runtime.block_on(s.store.release(lease, now)) {
            Ok(Some(_)) => {
                info!("job interrupted by shutdown; back in the queue");
                s.hub.publish(job_id, JobEvent::Status(JobStatus::Queued));
            }
            Ok(None) => warn!("lease lost before release"),
            Err(e) => error!(error = %e, "releasing the job failed; its lease will expire"),
        }
        return;
    }
    match s.runtime.block_on(s.store.finish_cancelled(lease, now)) {
        Ok(Some(_)) => {
            Metrics::inc(&s.metrics.jobs_cancelled);
            info!("job cancelled");
            s.hub
                .publish(job_id, JobEvent::Finished(JobStatus::Cancelled));
        }
        Ok(None) => warn!("lease lost before cancellation was recorded"),
        Err(e) => error!(error = %e, "recording the cancellation failed"),
    }
}

/// Records an attempt that failed with `e`: re-queued after the backoff when `e` is retryable and
/// attempts remain, else failed for good.
fn fail_attempt(s: &Shared, lease: &Lease, e: &PipelineError, now: i64) {
    let retry_at = (e.is_retryable() && lease.attempt < s.settings.max_attempts as i64)
        .then(|| now + s.settings.backoff(lease.attempt).as_millis() as i64);
    warn!(error = %e, retry = retry_at.is_some(), "job attempt failed");
    finish_failed(s, lease, e.code(), &e.to_string(), retry_at);
}

fn finish_failed(
    s: &Shared,
    lease: &Lease,
    code: FailureCode,
    message: &str,
    retry_at: Option<i64>,
) {
    match s
        .runtime
        .block_on(s.store.fail(lease, code, message, retry_at, now_ms()))
    {
        Ok(Some(row)) => {
            if retry_at.is_some() {
                Metrics::inc(&s.metrics.jobs_retried);
                s.hub.publish(&row.id, JobEvent::Status(JobStatus::Queued));
            } else {
                s.metrics.job_failed(code);
                s.hub
                    .publish(&row.id, JobEvent::Finished(JobStatus::Failed));
            }
        }
        Ok(None) => warn!("lease lost before the failure was recorded"),
        Err(e) => error!(error = %e, "recording the failure failed"),
    }
}

async fn heartbeat_loop(
    store: Store,
    lease: Lease,
    cancel: CancelToken,
    reason: Arc<Mutex<Option<StopReason>>>,
    every: Duration,
    lease_len: Duration,
) {
    let lease_ms = lease_len.as_millis() as i64;
    loop {
        tokio::time::sleep(every).await;
        match store.heartbeat(&lease, now_ms(), lease_ms).await {
            Ok(Heartbeat::Held { cancel: true }) => {
                set_reason(&reason, StopReason::User);
                cancel.cancel();
            }
            Ok(Heartbeat::Held { cancel: false }) => {}
            Ok(Heartbeat::Lost) => {
                warn!("lease lost; stopping the job");
                set_reason(&reason, StopReason::LeaseLost);
                cancel.cancel();
                return;
            }
            Err(e) => warn!(error = %e, "heartbeat failed; will retry"),
        }
    }
}
