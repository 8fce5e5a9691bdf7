//! What the server and a job process say to each other: one JSON object per line. The server
//! writes a [`Start`] and then, to stop the job, the line `cancel`; the job process writes
//! [`FromChild`] messages and exits after `done` or `error`.

use crate::pipeline::{FailureCode, JobSpec, ModelDirs, RunOutput};
use crate::progress::Progress;
use serde::{Deserialize, Serialize};

/// The executor a job process builds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ChildExecutor {
    /// The pipeline (`DefaultExecutor`) with these models.
    Pipeline { models: ModelDirs },
    /// The service test double (`worker::test_executor`), sleeping `step_ms` per step.
    Test { step_ms: u64 },
}

/// The first line the server writes.
#[derive(Debug, Serialize, Deserialize)]
pub struct Start {
    pub executor: ChildExecutor,
    pub spec: JobSpec,
    pub resume: Option<serde_json::Value>,
    pub checkpoint_every: u32,
}

/// A line the job process writes.
#[derive(Debug, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FromChild {
    Progress(Progress),
    Checkpoint(serde_json::Value),
    Done(Box<RunOutput>),
    /// A `PipelineError` as its code and message (`PipelineError::reported` rebuilds it).
    Error {
        code: FailureCode,
        message: String,
    },
}

/// The line that asks the job to stop (it checkpoints and answers `cancelled`).
pub const CANCEL: &str = "cancel";
