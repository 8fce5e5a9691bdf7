//! What can go wrong running a job, with the stable codes stored with failed jobs.

/// Errors from running a job.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error("not implemented yet: {0}")]
    NotImplemented(String),
    #[error("invalid input: {0}")]
    InvalidInput(String),
    #[error("models are not configured: {0}")]
    ModelsNotConfigured(String),
    #[error("cancelled")]
    Cancelled,
    /// A failure worth retrying (resource exhaustion, I/O hiccup).
    #[error("transient failure: {0}")]
    Transient(String),
    /// The job's process passed its memory or wall-clock limit (`worker::isolate`).
    #[error("resource limit: {0}")]
    ResourceLimit(String),
    /// The job's process died without a result (a crash, a signal).
    #[error("the job's process died: {0}")]
    Crashed(String),
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
            PipelineError::ResourceLimit(_) => "resource_limit",
            PipelineError::Crashed(_) => "crashed",
            PipelineError::Failed(_) => "failed",
        }
    }

    /// The variant's own message (without the prefix `Display` adds); with [`Self::code`] it
    /// is what [`Self::from_parts`] rebuilds the error from.
    pub fn detail(&self) -> String {
        match self {
            PipelineError::Cancelled => String::new(),
            PipelineError::NotImplemented(m)
            | PipelineError::InvalidInput(m)
            | PipelineError::ModelsNotConfigured(m)
            | PipelineError::Transient(m)
            | PipelineError::ResourceLimit(m)
            | PipelineError::Crashed(m)
            | PipelineError::Failed(m) => m.clone(),
        }
    }

    /// The error with this [`Self::code`] and [`Self::detail`] (an unknown code is `Failed`).
    pub fn from_parts(code: &str, detail: String) -> Self {
        match code {
            "not_implemented" => PipelineError::NotImplemented(detail),
            "invalid_input" => PipelineError::InvalidInput(detail),
            "models_not_configured" => PipelineError::ModelsNotConfigured(detail),
            "cancelled" => PipelineError::Cancelled,
            "transient" => PipelineError::Transient(detail),
            "resource_limit" => PipelineError::ResourceLimit(detail),
            "crashed" => PipelineError::Crashed(detail),
            _ => PipelineError::Failed(detail),
        }
    }

    /// Whether the worker should retry the job (with backoff).
    pub fn is_retryable(&self) -> bool {
        matches!(self, PipelineError::Transient(_))
    }
}
