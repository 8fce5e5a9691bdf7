//! The one seam through which long-running stages report progress and learn of cancellation.
//!
//! Stages emit [`Progress`] events into a [`ProgressSink`]; the CLI renders them as progress bars,
//! the service stores them, forwards them over server-sent events and shows them in job views
//! (built `From` a [`Progress`]). Stages poll a [`CancelToken`] between steps.

use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// The stage a [`Progress`] event comes from; its name (`"sds"`) is what the API shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Drawing the K images from the teacher.
    Sample,
    /// Scoring the samples against the caption and keeping the best.
    Rerank,
    /// Tracing an image with LIVE.
    Live,
    /// Score distillation.
    Sds,
    /// The run's end (carries the final SVG).
    Done,
    /// The service's test double (`worker::test_executor`).
    Test,
}

impl Stage {
    pub const ALL: [Stage; 6] = [
        Stage::Sample,
        Stage::Rerank,
        Stage::Live,
        Stage::Sds,
        Stage::Done,
        Stage::Test,
    ];

    /// The stage named `name` ([`Self::as_str`]), if any.
    pub fn from_name(name: &str) -> Option<Stage> {
        Stage::ALL.into_iter().find(|s| s.as_str() == name)
    }

    /// The stage's name as in the API and the store (`"sds"`).
    pub fn as_str(self) -> &'static str {
        match self {
            Stage::Sample => "sample",
            Stage::Rerank => "rerank",
            Stage::Live => "live",
            Stage::Sds => "sds",
            Stage::Done => "done",
            Stage::Test => "test",
        }
    }
}

/// One progress report from a stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Progress {
    pub stage: Stage,
    /// Step within the stage (1-based once work has started).
    pub step: u32,
    /// Total steps of the stage, if known.
    pub total: u32,
    /// Current loss, if the stage has one.
    pub loss: Option<f64>,
    /// Current SVG, sent only every so often (stages decide; sinks may rate-limit further).
    pub svg: Option<String>,
    /// Structured details of the stage (e.g. the rerank's scores).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub detail: Option<serde_json::Value>,
}

impl Progress {
    pub fn new(stage: Stage, step: u32, total: u32) -> Self {
        Self {
            stage,
            step,
            total,
            loss: None,
            svg: None,
            detail: None,
        }
    }
}
/// Receives progress events. Implementations must be cheap and never block for long.
pub trait ProgressSink: Send + Sync {
    fn report(&self, event: Progress);
}

/// A sink that drops everything.
pub struct NullSink;

impl ProgressSink for NullSink {
    fn report(&self, _event: Progress) {}
}

impl<F: Fn(Progress) + Send + Sync> ProgressSink for F {
    fn report(&self, event: Progress) {
        self(event)
    }
}

/// A cheap, clonable cancellation flag.
#[derive(Clone, Debug, Default)]
pub struct CancelToken(Arc<AtomicBool>);

impl CancelToken {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn cancel(&self) {
        self.0.store(true, Ordering::SeqCst);
    }

    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }
}

/// Why a checkpoint was not saved (a stage's run goes on or stops as its caller decides; the
/// service retries the job).
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// The state does not serialise.
    #[error("cannot encode the checkpoint: {0}")]
    Encode(#[from] serde_json::Error),
    /// The job's lease is gone: another attempt owns the job now.
    #[error("the job's lease was lost; checkpoint refused")]
    LeaseLost,
    /// Where checkpoints go failed (the database, the pipe to the server).
    #[error("storing the checkpoint failed: {0}")]
    Store(#[source] Box<dyn std::error::Error + Send + Sync>),
}
