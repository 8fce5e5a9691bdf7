//! The one seam through which long-running stages report progress and learn of cancellation.
//!
//! Stages emit [`Progress`] events into a [`ProgressSink`]; the CLI renders them as progress bars,
//! the service stores snapshots and forwards them over server-sent events. Stages poll a
//! [`CancelToken`] between steps.

use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// One progress report from a stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Progress {
    /// Stage name, e.g. `"sample"`, `"rerank"`, `"live"`, `"sds"`.
    pub stage: String,
    /// Step within the stage (1-based once work has started).
    pub step: u32,
    /// Total steps of the stage, if known.
    pub total: u32,
    /// Current loss, if the stage has one.
    pub loss: Option<f64>,
    /// Current SVG, sent only every so often (stages decide; sinks may rate-limit further).
    pub svg: Option<String>,
    /// Free-form structured details (e.g. rerank scores).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub detail: Option<serde_json::Value>,
}

impl Progress {
    pub fn new(stage: &str, step: u32, total: u32) -> Self {
        Self {
            stage: stage.to_string(),
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
