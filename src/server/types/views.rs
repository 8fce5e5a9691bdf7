//! The progress and attempts of a job as the API shows them (times in RFC 3339).

use crate::progress::{Progress, Stage};
use crate::store::{AttemptRow, JobRow, JobStatus};
use serde::Serialize;
use serde_json::Value;

pub(super) fn rfc3339(ms: Option<i64>) -> Option<String> {
    ms.and_then(chrono::DateTime::from_timestamp_millis)
        .map(|t| t.to_rfc3339_opts(chrono::SecondsFormat::Millis, true))
}

/// One attempt of a job as the API shows it: times in RFC 3339, as every other time.
#[derive(Serialize)]
pub struct AttemptView {
    pub attempt: i64,
    pub worker: String,
    pub outcome: String,
    pub error: Option<String>,
    pub started_at: Option<String>,
    pub finished_at: Option<String>,
}

impl From<&AttemptRow> for AttemptView {
    fn from(row: &AttemptRow) -> Self {
        AttemptView {
            attempt: row.attempt,
            worker: row.worker.clone(),
            outcome: row.outcome.clone(),
            error: row.error.clone(),
            started_at: rfc3339(Some(row.started_at)),
            finished_at: rfc3339(row.finished_at),
        }
    }
}

/// A job's progress as the API shows it: the job's `progress` and the `progress` event.
#[derive(Serialize)]
pub struct ProgressView {
    pub stage: Option<Stage>,
    pub step: i64,
    pub total: i64,
    /// `step / total` in `0..=1` (0 while the total is unknown, 1 for a succeeded job).
    pub fraction: f64,
    pub loss: Option<f64>,
    /// The stage's details (the rerank's scores), on live events only.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub detail: Option<Value>,
}

impl ProgressView {
    fn new(stage: Option<Stage>, step: i64, total: i64, loss: Option<f64>) -> Self {
        let fraction = if total > 0 {
            (step as f64 / total as f64).clamp(0.0, 1.0)
        } else {
            0.0
        };
        ProgressView {
            stage,
            step,
            total,
            fraction,
            loss,
            detail: None,
        }
    }
}

impl From<&Progress> for ProgressView {
    fn from(p: &Progress) -> Self {
        ProgressView {
            detail: p.detail.clone(),
            ..ProgressView::new(Some(p.stage), i64::from(p.step), i64::from(p.total), p.loss)
        }
    }
}

/// The progress stored in the job's row.
impl From<&JobRow> for ProgressView {
    fn from(row: &JobRow) -> Self {
        let stage = row.stage.as_deref().and_then(Stage::from_name);
        let mut view = ProgressView::new(stage, row.step, row.total, row.loss);
        if row.total <= 0 && row.status == JobStatus::Succeeded {
            view.fraction = 1.0;
        }
        view
    }
}
