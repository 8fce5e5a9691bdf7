//! What can go wrong running a job, with the stable codes stored with failed jobs.

/// Errors from running a job.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error("not implemented yet: {0}")]
    NotImplemented(&'static str),
    #[error("invalid input: {0}")]
    InvalidInput(String),
    #[error("models are not configured: {0}")]
    ModelsNotConfigured(String),
    #[error("cancelled")]
    Cancelled,
    /// A failure worth retrying (resource exhaustion, I/O hiccup).
    #[error("transient failure: {0}")]
    Transient(String),
    #[error("{0}")]
    Failed(String),
}

impl PipelineError {
    /// Stable machine-readable code stored with failed jobs.
    pub fn code(&self) -> &'static str {
        match self {
            PipelineError::NotImplemented(_) => "not_implemented",
            PipelineError::InvalidInput(_) => "invalid_input",
            PipelineError::ModelsNotConfigured(_) => "models_not_configured",
            PipelineError::Cancelled => "cancelled",
            PipelineError::Transient(_) => "transient",
            PipelineError::Failed(_) => "failed",
        }
    }

    /// Whether the worker should retry the job (with backoff).
    pub fn is_retryable(&self) -> bool {
        matches!(self, PipelineError::Transient(_))
    }
}
