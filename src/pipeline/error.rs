//! What can go wrong running a job ([`PipelineError`]), and the stable [`FailureCode`] stored
//! with a failed job.
//!
//! A stage's typed error becomes a [`PipelineError`] through `From` and stays its source; the
//! one decision of what it means for the job (bad input, retry, failure) is
//! [`PipelineError::code`]. The worker, the store, the job view and the metrics all speak
//! [`FailureCode`], so a code means the same thing in a worker thread and in a job's child
//! process: a panic of the executor is [`FailureCode::Crashed`] in both, like a child process
//! that died. (`FailureCode` lives with the store, like `JobKind`, because the store's own
//! statements set two of its codes; imports flow from the pipeline to the store.)

use super::NotReady;
use crate::image::ImageError;
use crate::progress::CheckpointError;
use crate::scene::SceneError;
use crate::stages::live::LiveError;
use crate::stages::sds::SdsError;
pub use crate::store::FailureCode;
use crate::svg::SvgError;
use crate::teacher::SampleError;

/// Errors from running a job. A stage's error keeps its own type as the source; [`Self::code`]
/// says what it means for the job.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// The stored job (spec or upload) could not be read back.
    #[error("the stored job is unreadable: {0}")]
    InvalidSpec(String),
    /// Text jobs cannot run here ([`NotReady`] says what to configure).
    #[error("models are not configured: {0}")]
    NotReady(#[from] NotReady),
    /// A configured model failed to load (`what`: which one, from where).
    #[error("models are not configured: {what}: {source}")]
    ModelLoad {
        what: String,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    #[error("cancelled")]
    Cancelled,
    /// A failure worth retrying (resource exhaustion, I/O hiccup).
    #[error("transient failure: {0}")]
    Transient(String),
    /// The job's process passed its memory or wall-clock limit (`worker::isolate`).
    #[error("resource limit: {0}")]
    ResourceLimit(String),
    /// The executor panicked, or the job's process died without a result (a crash, a signal).
    #[error("the job crashed: {0}")]
    Crashed(String),
    /// LIVE (tracing) failed; a bad target or settings are the input's fault.
    #[error("LIVE: {0}")]
    Live(#[source] LiveError),
    /// Score distillation failed.
    #[error("score distillation: {0}")]
    Sds(#[source] SdsError),
    /// Sampling or reranking the raster samples failed.
    #[error("sampling: {0}")]
    Sample(#[source] SampleError),
    /// A scene built along the way is not valid.
    #[error("{stage} scene: {source}")]
    Scene {
        /// Which scene: `initial`, `final`.
        stage: &'static str,
        #[source]
        source: SceneError,
    },
    /// The job's image cannot be decoded (the input's fault).
    #[error("image: {0}")]
    Image(#[from] ImageError),
    /// The job's SVG cannot be imported (the input's fault).
    #[error("svg: {0}")]
    Svg(#[from] SvgError),
    /// A checkpoint could not be saved (worth retrying the job).
    #[error("transient failure: {0}")]
    Checkpoint(#[from] CheckpointError),
    /// A failure a job's child process reported, as its code and message (the source stayed
    /// in that process).
    #[error("{message}")]
    Reported { code: FailureCode, message: String },
    #[error("{0}")]
    Failed(String),
}

impl PipelineError {
    /// What the failure means for the job: the code stored with it.
    pub fn code(&self) -> FailureCode {
        match self {
            PipelineError::InvalidInput(_) | PipelineError::Image(_) | PipelineError::Svg(_) => {
                FailureCode::InvalidInput
            }
            PipelineError::InvalidSpec(_) => FailureCode::InvalidSpec,
            PipelineError::NotReady(_) | PipelineError::ModelLoad { .. } => {
                FailureCode::ModelsNotConfigured
            }
            PipelineError::Cancelled => FailureCode::Cancelled,
            PipelineError::Transient(_) | PipelineError::Checkpoint(_) => FailureCode::Transient,
            PipelineError::ResourceLimit(_) => FailureCode::ResourceLimit,
            PipelineError::Crashed(_) => FailureCode::Crashed,
            PipelineError::Live(e) => match e {
                LiveError::Cancelled => FailureCode::Cancelled,
                LiveError::Target(_) | LiveError::Config(_) => FailureCode::InvalidInput,
                LiveError::Checkpoint(_) | LiveError::Save(_) => FailureCode::Transient,
                _ => FailureCode::Failed,
            },
            PipelineError::Sds(e) => match e {
                SdsError::Config(_) => FailureCode::InvalidInput,
                SdsError::Checkpoint(_) | SdsError::Save(_) => FailureCode::Transient,
                _ => FailureCode::Failed,
            },
            PipelineError::Sample(SampleError::Cancelled) => FailureCode::Cancelled,
            PipelineError::Reported { code, .. } => *code,
            PipelineError::Sample(_) | PipelineError::Scene { .. } | PipelineError::Failed(_) => {
                FailureCode::Failed
            }
        }
    }

    /// The error a job's child process reported as `code` and `message` (its `Display`).
    pub fn reported(code: FailureCode, message: String) -> Self {
        match code {
            FailureCode::Cancelled => PipelineError::Cancelled,
            code => PipelineError::Reported { code, message },
        }
    }

    /// A panic of the executor (in a worker thread or a job's process): `crashed`.
    pub fn panicked(panic: &(dyn std::any::Any + Send)) -> Self {
        let msg = panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into());
        PipelineError::Crashed(format!("the executor panicked: {msg}"))
    }

    /// A scene that failed validation at `stage` (`initial`, `final`).
    pub fn scene(stage: &'static str) -> impl FnOnce(SceneError) -> Self {
        move |source| PipelineError::Scene { stage, source }
    }

    /// Whether the worker should retry the job (with backoff).
    pub fn is_retryable(&self) -> bool {
        self.code() == FailureCode::Transient
    }
}

impl From<LiveError> for PipelineError {
    fn from(e: LiveError) -> Self {
        match e {
            LiveError::Cancelled => PipelineError::Cancelled,
            e => PipelineError::Live(e),
        }
    }
}

impl From<SdsError> for PipelineError {
    fn from(e: SdsError) -> Self {
        PipelineError::Sds(e)
    }
}

impl From<SampleError> for PipelineError {
    fn from(e: SampleError) -> Self {
        match e {
            SampleError::Cancelled => PipelineError::Cancelled,
            e => PipelineError::Sample(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_through_their_stored_names() {
        for c in FailureCode::ALL {
            assert_eq!(FailureCode::from_stored(c.as_str()), c);
            let json = serde_json::to_string(&c).unwrap();
            assert_eq!(json, format!("\"{}\"", c.as_str()));
        }
        assert_eq!(FailureCode::from_stored("internal"), FailureCode::Crashed);
        assert_eq!(
            FailureCode::from_stored("not_implemented"),
            FailureCode::Failed
        );
    }

    #[test]
    fn a_bad_target_is_invalid_input_and_keeps_its_source() {
        let e = PipelineError::from(LiveError::Target("empty".into()));
        assert_eq!(e.code(), FailureCode::InvalidInput);
        assert!(std::error::Error::source(&e).is_some());
        assert!(matches!(
            PipelineError::from(LiveError::Cancelled),
            PipelineError::Cancelled
        ));
        let e = PipelineError::from(LiveError::Checkpoint("gone".into()));
        assert!(e.is_retryable());
    }

    #[test]
    fn a_reported_error_keeps_code_and_message() {
        let e = PipelineError::from(LiveError::Target("empty".into()));
        let r = PipelineError::reported(e.code(), e.to_string());
        assert_eq!(r.code(), FailureCode::InvalidInput);
        assert_eq!(r.to_string(), e.to_string());
        assert!(matches!(
            PipelineError::reported(FailureCode::Cancelled, String::new()),
            PipelineError::Cancelled
        ));
    }
}
