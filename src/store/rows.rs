//! The store's rows: what a read returns ([`JobRow`], [`AttemptRow`], [`SnapshotRow`],
//! [`ResultRow`]) and what an insert takes ([`NewJob`]).

use super::{FailureCode, JobKind, JobStatus, NewUpload};
use serde::Serialize;

/// One row of `jobs`.
#[derive(Clone, Debug, sqlx::FromRow)]
pub struct JobRow {
    pub seq: i64,
    pub id: String,
    pub kind: JobKind,
    pub spec: String,
    pub priority: i64,
    pub status: JobStatus,
    pub idempotency_key: Option<String>,
    pub request_hash: Option<String>,
    pub stage: Option<String>,
    pub step: i64,
    pub total: i64,
    pub loss: Option<f64>,
    pub attempts: i64,
    pub max_attempts: i64,
    pub lost_attempts: i64,
    pub max_lost_attempts: i64,
    pub run_after: i64,
    pub lease_owner: Option<String>,
    pub lease_expires_at: Option<i64>,
    pub heartbeat_at: Option<i64>,
    pub cancel_requested: i64,
    pub checkpoint: Option<String>,
    pub checkpoint_at: Option<i64>,
    pub error_code: Option<FailureCode>,
    pub error_message: Option<String>,
    pub created_at: i64,
    pub started_at: Option<i64>,
    pub finished_at: Option<i64>,
    pub updated_at: i64,
    /// The tenant that submitted it (`server::tenant`); `None`: the operator.
    pub tenant: Option<String>,
}

/// One row of `attempts`.
#[derive(Clone, Debug, Serialize, sqlx::FromRow)]
pub struct AttemptRow {
    pub job_id: String,
    pub attempt: i64,
    pub worker: String,
    pub outcome: String,
    pub error: Option<String>,
    pub started_at: i64,
    pub finished_at: Option<i64>,
}

/// One stored SVG snapshot.
#[derive(Clone, Debug, sqlx::FromRow)]
pub struct SnapshotRow {
    pub job_id: String,
    pub n: i64,
    pub stage: String,
    pub step: i64,
    pub svg: String,
    pub created_at: i64,
}

/// The final result of a job.
#[derive(Clone, Debug, sqlx::FromRow)]
pub struct ResultRow {
    pub job_id: String,
    pub svg: String,
    pub paths: i64,
    pub detail: String,
    pub created_at: i64,
}

/// A job to insert.
#[derive(Clone, Debug)]
pub struct NewJob {
    pub id: String,
    pub kind: JobKind,
    pub spec: String,
    pub priority: i64,
    pub idempotency_key: Option<String>,
    pub request_hash: Option<String>,
    pub max_attempts: i64,
    /// Lost attempts (worker died) after which the job fails as `poison`; at least 1.
    pub max_lost_attempts: i64,
    pub tenant: Option<String>,
    /// Its image and starting SVG, stored apart from the row (the spec holds "" markers).
    pub upload: Option<NewUpload>,
    /// Insert only while fewer jobs than this are queued, checked in the insert itself (the
    /// server sets it when its estimate says the queue is nearly full); `None`: no check.
    pub max_queued: Option<i64>,
}

impl NewJob {
    /// A job with the defaults of tests and tools: priority 0, 3 attempts, 2 lost attempts, no
    /// idempotency key, tenant, upload or queue limit.
    pub fn new(id: impl Into<String>, kind: JobKind, spec: impl Into<String>) -> NewJob {
        NewJob {
            id: id.into(),
            kind,
            spec: spec.into(),
            priority: 0,
            idempotency_key: None,
            request_hash: None,
            max_attempts: 3,
            max_lost_attempts: 2,
            tenant: None,
            upload: None,
            max_queued: None,
        }
    }
}
