//! Reading and cancelling jobs: `GET /jobs/{id}`, `GET /jobs` and `DELETE /jobs/{id}`, and
//! the job lookup every per-job route shares.

use crate::server::AppState;
use crate::server::error::ApiError;
use crate::server::tenant::Caller;
use crate::server::types::{AttemptView, JobList, JobView};
use crate::store::{JobRow, JobStatus, now_ms};
use crate::worker::events::JobEvent;
use axum::Json;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Extension, Path, Query, State};
use serde::Deserialize;

/// Parses a job id path segment; anything that is not a UUID cannot name a job.
pub(in crate::server) fn job_id(raw: &str) -> Result<String, ApiError> {
    uuid::Uuid::parse_str(raw)
        .map(|u| u.hyphenated().to_string())
        .map_err(|_| ApiError::NotFound {
            what: "job",
            id: raw.to_string(),
        })
}

/// The job `id` as `caller` may see it: another tenant's job is not found.
pub(in crate::server) async fn load_job(
    state: &AppState,
    id: &str,
    caller: &Caller,
) -> Result<JobRow, ApiError> {
    state
        .store
        .get_job(id)
        .await?
        .filter(|row| caller.may_see(row.tenant.as_deref()))
        .ok_or_else(|| ApiError::NotFound {
            what: "job",
            id: id.to_string(),
        })
}

pub(in crate::server) async fn get_job(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(raw): Path<String>,
) -> Result<Json<JobView>, ApiError> {
    let id = job_id(&raw)?;
    let row = load_job(&state, &id, &caller).await?;
    let mut view = JobView::from_row(&row);
    if row.status == JobStatus::Succeeded
        && let Some(result) = state.store.result(&id).await?
    {
        view = view.with_result(&result);
    } else if let Some(ck) = &row.checkpoint {
        view = view.with_checkpoint(ck);
    }
    let attempts = state.store.attempts(&id).await?;
    view.attempt_history = Some(attempts.iter().map(AttemptView::from).collect());
    Ok(Json(view))
}

#[derive(Deserialize)]
pub(in crate::server) struct ListQuery {
    status: Option<String>,
    limit: Option<String>,
    cursor: Option<String>,
    /// Every other parameter: see [`check_other_params`].
    #[serde(flatten)]
    other: std::collections::BTreeMap<String, String>,
}

/// The one rule for query parameters a route does not know: a name starting with `_` (a
/// cache-buster such as `_=1712`) is ignored; any other is a 400 naming it, so a typo
/// (`?stauts=running`) is not silently ignored. `accepted` lists the route's own parameters.
pub(in crate::server) fn check_other_params(
    other: &std::collections::BTreeMap<String, String>,
    accepted: &str,
) -> Result<(), ApiError> {
    match other.keys().find(|k| !k.starts_with('_')) {
        None => Ok(()),
        Some(k) => Err(ApiError::InvalidQuery {
            field: k.clone(),
            reason: format!(
                "unknown query parameter; accepted: {accepted} (names starting with _ are ignored)"
            ),
        }),
    }
}

pub(in crate::server) async fn list(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    query: Result<Query<ListQuery>, QueryRejection>,
) -> Result<Json<JobList>, ApiError> {
    let Query(q) = query.map_err(|e| ApiError::InvalidQuery {
        field: "query".into(),
        reason: format!(
            "{}; accepted parameters: status, limit, cursor",
            e.body_text()
        ),
    })?;
    check_other_params(&q.other, "status, limit, cursor")?;
    let bad = |field: &str, reason: String| ApiError::InvalidQuery {
        field: field.into(),
        reason,
    };
    let status = match q.status.as_deref() {
        None => None,
        Some(s) => Some(s.parse::<JobStatus>().map_err(|_| {
            bad(
                "status",
                format!("must be one of queued, running, succeeded, failed, cancelled; got {s:?}"),
            )
        })?),
    };
    let limit = match q.limit.as_deref() {
        None => 50,
        Some(s) => match s.parse::<i64>() {
            Ok(n) if (1..=500).contains(&n) => n,
            _ => {
                return Err(bad(
                    "limit",
                    format!("must be an integer from 1 to 500; got {s:?}"),
                ));
            }
        },
    };
    let cursor = match q.cursor.as_deref() {
        None => None,
        Some(s) => Some(s.parse::<i64>().ok().filter(|n| *n > 0).ok_or_else(|| {
            bad(
                "cursor",
                format!("is not a cursor from a previous page: {s:?}"),
            )
        })?),
    };
    let rows = state
        .store
        .list_jobs(status, cursor, limit, caller.tenant())
        .await?;
    let next_cursor = if rows.len() as i64 == limit {
        rows.last().map(|r| r.seq.to_string())
    } else {
        None
    };
    Ok(Json(JobList {
        jobs: rows.iter().map(JobView::from_row).collect(),
        next_cursor,
    }))
}

pub(in crate::server) async fn cancel(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(raw): Path<String>,
) -> Result<Json<JobView>, ApiError> {
    let id = job_id(&raw)?;
    let before = load_job(&state, &id, &caller).await?;
    match before.status {
        JobStatus::Succeeded | JobStatus::Failed => {
            return Err(ApiError::Conflict(format!(
                "job {id} already finished with status {}",
                before.status
            )));
        }
        JobStatus::Cancelled => return Ok(Json(JobView::from_row(&before))),
        JobStatus::Queued | JobStatus::Running => {}
    }
    let row = state
        .store
        .request_cancel(&id, now_ms())
        .await?
        .ok_or_else(|| ApiError::NotFound {
            what: "job",
            id: id.clone(),
        })?;
    match row.status {
        JobStatus::Cancelled => state
            .hub
            .publish(&id, JobEvent::Finished(JobStatus::Cancelled)),
        JobStatus::Running => {
            // Fast path when this process runs it; otherwise the heartbeat picks the flag up.
            state.pool.cancel_local(&id);
        }
        _ => {}
    }
    tracing::info!(job = %id, "cancel requested");
    Ok(Json(JobView::from_row(&row)))
}
