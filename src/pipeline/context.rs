//! The seam between the worker and the computation: an [`Executor`] runs a [`JobSpec`] and talks
//! back only through its [`JobContext`] (progress, cancellation, checkpoints).

use super::{JobSpec, Limits, NotReady, PipelineError, PlanRequest, RunOutput, RunPlan, SpecError};
use crate::progress::{CancelToken, CheckpointError, NullSink, Progress, ProgressSink};
use serde::Serialize;
use std::sync::Arc;

type Checkpointer = dyn Fn(serde_json::Value) -> Result<(), CheckpointError> + Send + Sync;

/// What an executor gets besides the spec: where to report, when to stop, how to checkpoint.
pub struct JobContext {
    progress: Arc<dyn ProgressSink>,
    cancel: CancelToken,
    checkpoint_every: u32,
    checkpointer: Box<Checkpointer>,
    resume: Option<serde_json::Value>,
}

impl JobContext {
    /// A context that reports to `progress`, stops on `cancel`, saves checkpoints through
    /// `checkpointer` (advised every `checkpoint_every` steps) and resumes from `resume`.
    pub fn new(
        progress: Arc<dyn ProgressSink>,
        cancel: CancelToken,
        checkpoint_every: u32,
        checkpointer: Box<Checkpointer>,
        resume: Option<serde_json::Value>,
    ) -> Self {
        JobContext {
            progress,
            cancel,
            checkpoint_every: checkpoint_every.max(1),
            checkpointer,
            resume,
        }
    }

    /// A context for running outside the service: no progress, no checkpoints.
    pub fn detached(cancel: CancelToken) -> Self {
        JobContext::new(
            Arc::new(NullSink),
            cancel,
            u32::MAX,
            Box::new(|_| Ok(())),
            None,
        )
    }

    pub fn report(&self, event: Progress) {
        self.progress.report(event);
    }

    pub fn sink(&self) -> &dyn ProgressSink {
        self.progress.as_ref()
    }

    pub fn cancel_token(&self) -> &CancelToken {
        &self.cancel
    }

    pub fn is_cancelled(&self) -> bool {
        self.cancel.is_cancelled()
    }

    /// `Err(Cancelled)` once cancellation was requested; call between steps. Executors that
    /// checkpoint should save one when they see the cancellation, before returning
    /// [`PipelineError::Cancelled`]: on shutdown the job resumes from it.
    pub fn check_cancelled(&self) -> Result<(), PipelineError> {
        if self.is_cancelled() {
            Err(PipelineError::Cancelled)
        } else {
            Ok(())
        }
    }

    /// Steps between advised checkpoints.
    pub fn checkpoint_every(&self) -> u32 {
        self.checkpoint_every
    }

    /// Whether `step` (1-based) is one at which a checkpoint is due.
    pub fn checkpoint_due(&self, step: u32) -> bool {
        step > 0 && step.is_multiple_of(self.checkpoint_every)
    }

    /// Saves resumable state (current SVG, step, optimiser state). A failure to save is a
    /// transient failure of the job ([`PipelineError::Checkpoint`]).
    pub fn checkpoint(&self, state: serde_json::Value) -> Result<(), CheckpointError> {
        (self.checkpointer)(state)
    }

    /// State from the last checkpoint of an earlier, interrupted attempt.
    pub fn resume_state(&self) -> Option<serde_json::Value> {
        self.resume.clone()
    }
}

/// Runs jobs. Called on a dedicated worker thread, never on the async runtime.
pub trait Executor: Send + Sync {
    fn run(&self, spec: &JobSpec, ctx: &JobContext) -> Result<RunOutput, PipelineError>;

    /// `Ok` when `text` jobs can run (models configured and loadable); otherwise a message
    /// telling the operator how to configure them. Text jobs are refused at submit time while
    /// this is an error.
    fn text_ready(&self) -> Result<(), NotReady>;

    /// Resolves a request into the [`RunPlan`] this executor would run (presets, the model's
    /// hints and the limits applied once). The service calls it at submit time and stores the
    /// plan with the job.
    /// The default resolves text requests, when they can run, with [`Executor::model_facts`].
    fn plan(&self, request: &PlanRequest, limits: &Limits) -> Result<RunPlan, SpecError> {
        let facts = self.text_ready().is_ok().then(|| self.model_facts());
        super::plan::resolve(request, facts.as_ref(), limits)
    }

    /// What the default [`Executor::plan`] knows of the model: the paper's model hints (Stable
    /// Diffusion's presets and its sample shapes, a negative prompt accepted), as an executor
    /// that is not backed by a model directory would.
    fn model_facts(&self) -> super::ModelFacts {
        super::ModelFacts::stable_diffusion("executor")
    }
}

/// Stores `state` as the job's checkpoint (JSON through `ctx`).
pub(super) fn save_checkpoint(
    ctx: &JobContext,
    state: &impl Serialize,
) -> Result<(), CheckpointError> {
    ctx.checkpoint(serde_json::to_value(state)?)
}

/// The state an interrupted attempt saved, when it is a `T`; none, garbage or a checkpoint of
/// another kind of run give `None` (the run starts over).
pub(super) fn resume_as<T: serde::de::DeserializeOwned>(ctx: Option<&JobContext>) -> Option<T> {
    ctx.and_then(JobContext::resume_state)
        .and_then(|v| serde_json::from_value(v).ok())
}
