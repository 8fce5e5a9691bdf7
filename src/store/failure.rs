//! Why a job failed: the stable codes stored in `jobs.error_code` (see [`FailureCode`]).

use serde::{Deserialize, Serialize};

/// Why a job failed, as stored with it (`jobs.error_code`), shown in its view (`error.code`)
/// and counted in the metrics (`vectorfusion_job_failures_total{code}`). The names are stable: stored jobs
/// keep them across versions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FailureCode {
    /// The request cannot run as given (a bad image or SVG, a plan its inputs do not fit).
    InvalidInput,
    /// The stored job could not be read back (its spec or its upload).
    InvalidSpec,
    /// Text jobs need models that are not configured or do not load.
    ModelsNotConfigured,
    /// The job was cancelled (the job's status says so; kept for completeness).
    Cancelled,
    /// A failure worth retrying (I/O, a lost checkpoint), after its last attempt.
    Transient,
    /// The job's process passed its memory or wall-clock limit.
    ResourceLimit,
    /// The executor panicked, or the job's process died without a result.
    Crashed,
    /// The job's worker was lost and its lease expired on its last attempt (set by the store).
    LeaseExpired,
    /// The job's worker was lost `max_lost_attempts` times (set by the store): the input may be
    /// what kills it.
    Poison,
    /// Any other failure of the computation.
    Failed,
}

impl FailureCode {
    /// Every code, in declaration order.
    pub const ALL: [FailureCode; 10] = [
        FailureCode::InvalidInput,
        FailureCode::InvalidSpec,
        FailureCode::ModelsNotConfigured,
        FailureCode::Cancelled,
        FailureCode::Transient,
        FailureCode::ResourceLimit,
        FailureCode::Crashed,
        FailureCode::LeaseExpired,
        FailureCode::Poison,
        FailureCode::Failed,
    ];

    /// The stored name (the serde name).
    pub fn as_str(self) -> &'static str {
        match self {
            FailureCode::InvalidInput => "invalid_input",
            FailureCode::InvalidSpec => "invalid_spec",
            FailureCode::ModelsNotConfigured => "models_not_configured",
            FailureCode::Cancelled => "cancelled",
            FailureCode::Transient => "transient",
            FailureCode::ResourceLimit => "resource_limit",
            FailureCode::Crashed => "crashed",
            FailureCode::LeaseExpired => "lease_expired",
            FailureCode::Poison => "poison",
            FailureCode::Failed => "failed",
        }
    }

    /// The code a stored name means. Names older versions stored read as what they meant now:
    /// `internal` (a panic in the worker's own process) is `crashed`; `not_implemented` and any
    /// name this version does not know are `failed`.
    pub fn from_stored(name: &str) -> FailureCode {
        match name {
            "internal" => FailureCode::Crashed,
            _ => FailureCode::ALL
                .into_iter()
                .find(|c| c.as_str() == name)
                .unwrap_or(FailureCode::Failed),
        }
    }
}

impl std::fmt::Display for FailureCode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}
