//! In-process fan-out of job events to SSE subscribers: one `tokio::sync::broadcast` channel per
//! watched job. Publishing never blocks (a slow subscriber lags and resynchronises from the
//! database instead), so workers are never held up by clients.

use crate::progress::{Progress, Stage};
use crate::store::JobStatus;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use tokio::sync::broadcast;

/// Events per job buffered for each subscriber before it lags.
const CHANNEL_CAPACITY: usize = 256;

/// A live event about one job.
#[derive(Clone, Debug)]
pub enum JobEvent {
    /// The job's latest progress (rate-limited by the worker; without its SVG, which goes to
    /// snapshots).
    Progress(Progress),
    /// A stored snapshot, numbered as in the database.
    Snapshot {
        n: i64,
        stage: Stage,
        step: u32,
        svg: Arc<str>,
    },
    /// A non-terminal status change (claimed, re-queued for retry or after shutdown).
    Status(JobStatus),
    /// The job reached a terminal status; no further events follow.
    Finished(JobStatus),
    /// Its row or snapshots changed in the database, maybe on another node (a PostgreSQL
    /// notification): subscribers re-read it.
    Changed,
}

/// Per-job broadcast channels.
#[derive(Clone, Default)]
pub struct Hub {
    channels: Arc<Mutex<HashMap<String, broadcast::Sender<JobEvent>>>>,
}

impl Hub {
    pub fn new() -> Self {
        Self::default()
    }

    /// Subscribes to `job_id`'s events from now on.
    pub fn subscribe(&self, job_id: &str) -> broadcast::Receiver<JobEvent> {
        let mut map = match self.channels.lock() {
            Ok(m) => m,
            Err(poisoned) => poisoned.into_inner(),
        };
        map.retain(|_, tx| tx.receiver_count() > 0);
        map.entry(job_id.to_string())
            .or_insert_with(|| broadcast::channel(CHANNEL_CAPACITY).0)
            .subscribe()
    }

    /// Sends `event` to current subscribers of `job_id` (if any). Never blocks.
    pub fn publish(&self, job_id: &str, event: JobEvent) {
        let mut map = match self.channels.lock() {
            Ok(m) => m,
            Err(poisoned) => poisoned.into_inner(),
        };
        let finished = matches!(event, JobEvent::Finished(_));
        if let Some(tx) = map.get(job_id) {
            // Err only means nobody is listening.
            let _ = tx.send(event);
        }
        if finished {
            map.remove(job_id);
        }
    }

    /// Number of jobs with live subscribers (for metrics).
    pub fn watched_jobs(&self) -> usize {
        match self.channels.lock() {
            Ok(m) => m.values().filter(|tx| tx.receiver_count() > 0).count(),
            Err(p) => p.into_inner().len(),
        }
    }
}
