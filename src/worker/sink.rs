//! The progress sink handed to executors (`WorkerSink`).

use super::Shared;
use super::events::{Hub, JobEvent};
use super::metrics::Metrics;
use crate::progress::{Progress, ProgressSink, Stage};
use crate::store::{Lease, Store, now_ms};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::runtime::Handle;
use tracing::warn;

#[derive(Default)]
struct SinkState {
    last_progress: Option<Instant>,
    last_snapshot: Option<Instant>,
    pending_snapshot: Option<(Stage, u32, String)>,
    pending_progress: Option<Progress>,
    stage: Option<(Stage, Instant)>,
}

/// The progress sink handed to executors: rate-limits progress and snapshots, stores them and
/// publishes them to SSE subscribers. Runs on the worker thread; database writes are short.
pub(super) struct WorkerSink {
    store: Store,
    hub: Hub,
    metrics: Arc<Metrics>,
    runtime: Handle,
    lease: Lease,
    progress_interval: Duration,
    snapshot_interval: Duration,
    keep_snapshots: i64,
    state: Mutex<SinkState>,
}

impl WorkerSink {
    pub(super) fn new(s: &Shared, lease: &Lease) -> Self {
        WorkerSink {
            store: s.store.clone(),
            hub: s.hub.clone(),
            metrics: s.metrics.clone(),
            runtime: s.runtime.clone(),
            lease: lease.clone(),
            progress_interval: s.settings.progress_interval,
            snapshot_interval: s.settings.snapshot_interval,
            keep_snapshots: s.settings.max_snapshots_per_job.max(1) as i64,
            state: Mutex::new(SinkState::default()),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, SinkState> {
        match self.state.lock() {
            Ok(g) => g,
            Err(p) => p.into_inner(),
        }
    }

    fn emit_progress(&self, p: &Progress) {
        let r = self.runtime.block_on(self.store.update_progress(
            &self.lease,
            p.stage.as_str(),
            p.step,
            p.total,
            p.loss,
            now_ms(),
        ));
        if let Err(e) = r {
            warn!(error = %e, "storing progress failed");
        }
        self.hub.publish(
            &self.lease.job_id,
            JobEvent::Progress(Progress {
                loss: p.loss.filter(|l| l.is_finite()),
                svg: None,
                ..p.clone()
            }),
        );
    }

    fn emit_snapshot(&self, stage: Stage, step: u32, svg: String) {
        match self.runtime.block_on(self.store.add_snapshot(
            &self.lease,
            stage.as_str(),
            step,
            &svg,
            now_ms(),
            self.keep_snapshots,
        )) {
            Ok(Some(n)) => self.hub.publish(
                &self.lease.job_id,
                JobEvent::Snapshot {
                    n,
                    stage,
                    step,
                    svg: svg.into(),
                },
            ),
            Ok(None) => {}
            Err(e) => warn!(error = %e, "storing a snapshot failed"),
        }
    }

    /// Writes whatever the rate limits held back, and closes the stage timer.
    pub(super) fn flush(&self) {
        let (progress, snap) = {
            let mut st = self.lock();
            if let Some((stage, t0)) = st.stage.take() {
                self.metrics
                    .observe_stage(stage.as_str(), t0.elapsed().as_secs_f64());
            }
            (st.pending_progress.take(), st.pending_snapshot.take())
        };
        if let Some(p) = progress {
            self.emit_progress(&p);
        }
        if let Some((stage, step, svg)) = snap {
            self.emit_snapshot(stage, step, svg);
        }
    }
}

impl ProgressSink for WorkerSink {
    fn report(&self, mut event: Progress) {
        let now = Instant::now();
        let svg = event.svg.take();
        let (do_progress, do_snapshot) = {
            let mut st = self.lock();
            let stage_changed = st.stage.as_ref().is_none_or(|(s, _)| *s != event.stage);
            if stage_changed {
                if let Some((old, t0)) = st.stage.take() {
                    self.metrics
                        .observe_stage(old.as_str(), t0.elapsed().as_secs_f64());
                }
                st.stage = Some((event.stage, now));
            }
            let last = event.total > 0 && event.step >= event.total;
            let due = |t: Option<Instant>, every: Duration| {
                t.is_none_or(|t| now.duration_since(t) >= every)
            };
            let do_progress =
                stage_changed || last || due(st.last_progress, self.progress_interval);
            if do_progress {
                st.last_progress = Some(now);
                st.pending_progress = None;
            } else {
                st.pending_progress = Some(event.clone());
            }
            let mut do_snapshot = None;
            if let Some(svg) = svg {
                if last || due(st.last_snapshot, self.snapshot_interval) {
                    st.last_snapshot = Some(now);
                    st.pending_snapshot = None;
                    do_snapshot = Some(svg);
                } else {
                    st.pending_snapshot = Some((event.stage, event.step, svg));
                }
            }
            (do_progress, do_snapshot)
        };
        if do_progress {
            self.emit_progress(&event);
        }
        if let Some(svg) = do_snapshot {
            self.emit_snapshot(event.stage, event.step, svg);
        }
    }
}
