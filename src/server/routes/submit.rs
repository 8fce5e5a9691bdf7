//! `POST /jobs`: admission (media type, body size and read time, Idempotency-Key, upload
//! validation, tenant quota, queue depth), then the insert or the replay of a known key.

use crate::pipeline::JobSpec;
use crate::server::AppState;
use crate::server::error::ApiError;
use crate::server::tenant::Caller;
use crate::server::types::{JobView, Submission, check_image, check_svg, parse_submit};
use crate::store::{JobRow, NewJob, NewUpload, StoreError, now_ms};
use crate::worker::metrics::Metrics;
use axum::Json;
use axum::body::Body;
use axum::extract::{Extension, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use std::sync::atomic::Ordering;

const IDEMPOTENCY_HEADER: &str = "idempotency-key";
/// Request bodies up to this size are parsed on the async thread.
const INLINE_PARSE_BYTES: usize = 16 * 1024;

/// Within this many jobs of `max_queue_depth` (by the estimate), a submit's insert counts the
/// queued jobs itself.
const QUEUE_MARGIN: i64 = 64;

/// How long a submit waits for an upload-validation permit before answering 429 `busy`.
const DECODE_WAIT: std::time::Duration = std::time::Duration::from_secs(10);

pub(in crate::server) async fn submit(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    headers: HeaderMap,
    body: Body,
) -> Result<Response, ApiError> {
    if *state.shutdown.borrow() {
        return Err(ApiError::ShuttingDown);
    }
    if !is_json(&headers) {
        return Err(ApiError::UnsupportedMediaType);
    }
    let body = read_body(&state, &headers, body).await?;
    let key = idempotency_key(&headers, &caller)?;
    let id = uuid::Uuid::new_v4();
    let default_seed = u64::from_le_bytes(
        id.as_bytes()[..8]
            .try_into()
            .map_err(|_| ApiError::Internal("uuid has 16 bytes".into()))?,
    ) & crate::pipeline::MAX_SEED;
    let Submission { spec, digest } = parse(&state, &body, default_seed).await?;
    let (spec, upload) = check_upload(&state, spec).await?;
    let hash = key.as_ref().map(|_| digest);
    if let Some(replayed) = admit(&state, &caller, &key, &hash).await? {
        return Ok(replayed);
    }
    let spec_json = serde_json::to_string(&spec).map_err(|e| ApiError::Internal(e.to_string()))?;
    let max_depth = state.cfg.server.max_queue_depth;
    let new = NewJob {
        id: id.hyphenated().to_string(),
        kind: spec.kind,
        spec: spec_json,
        priority: spec.priority as i64,
        idempotency_key: key,
        request_hash: hash.clone(),
        max_attempts: state.cfg.queue.max_attempts as i64,
        max_lost_attempts: state.cfg.queue.max_lost_attempts as i64,
        tenant: caller.tenant().map(str::to_string),
        upload: upload.map(|u| with_quotas(u, &state, &caller)),
        // Near a full queue the insert counts the queue itself, so concurrent submits cannot
        // overshoot `max_queue_depth` together.
        max_queued: (state.queued_estimate.load(Ordering::Relaxed)
            >= max_depth.saturating_sub(QUEUE_MARGIN))
        .then_some(max_depth),
    };
    let (row, created) = match state.store.insert_job(&new, now_ms()).await {
        Err(StoreError::QueueFull { limit }) => return Err(queue_full(&state, limit)),
        inserted => inserted?,
    };
    if !created {
        return replay(row, &hash);
    }
    Metrics::inc(&state.metrics.jobs_submitted);
    state.queued_estimate.fetch_add(1, Ordering::Relaxed);
    state.pool.notify();
    tracing::info!(job = %row.id, kind = %row.kind, "job submitted");
    Ok(accepted(&row))
}

/// Whether the request says its body is JSON (`application/json` or `application/*+json`).
fn is_json(headers: &HeaderMap) -> bool {
    headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|ct| {
            let mime = ct
                .split(';')
                .next()
                .unwrap_or("")
                .trim()
                .to_ascii_lowercase();
            mime == "application/json"
                || (mime.starts_with("application/") && mime.ends_with("+json"))
        })
}

/// The body, within the server's size limit and read time. Oversized bodies are refused from
/// their declared length, before reading (and before a client that sent
/// `Expect: 100-continue` uploads anything).
async fn read_body(
    state: &AppState,
    headers: &HeaderMap,
    body: Body,
) -> Result<axum::body::Bytes, ApiError> {
    let limit = state.cfg.server.max_body_bytes;
    let declared = headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|s| s.trim().parse::<u64>().ok());
    if declared.is_some_and(|n| n > limit as u64) {
        return Err(ApiError::PayloadTooLarge { limit });
    }
    let read_for = std::time::Duration::from_secs(state.cfg.server.body_read_timeout_secs);
    tokio::time::timeout(read_for, axum::body::to_bytes(body, limit))
        .await
        .map_err(|_| ApiError::BodyTimeout {
            secs: read_for.as_secs(),
        })?
        .map_err(|e| {
            let msg = format!("{e:#}");
            if msg.contains("length limit") {
                ApiError::PayloadTooLarge { limit }
            } else {
                ApiError::MalformedJson(format!("could not read the request body: {msg}"))
            }
        })
}

/// The caller's Idempotency-Key, scoped to the caller.
fn idempotency_key(headers: &HeaderMap, caller: &Caller) -> Result<Option<String>, ApiError> {
    let Some(v) = headers.get(IDEMPOTENCY_HEADER) else {
        return Ok(None);
    };
    let s = v
        .to_str()
        .ok()
        .filter(|s| !s.is_empty() && s.len() <= 255)
        .ok_or_else(|| {
            ApiError::invalid(
                "Idempotency-Key",
                "must be 1 to 255 visible ASCII characters",
            )
        })?;
    Ok(Some(caller.scoped_key(s)))
}

/// [`parse_submit`]: small bodies in place (microseconds), big ones off the async threads.
async fn parse(
    state: &AppState,
    body: &axum::body::Bytes,
    default_seed: u64,
) -> Result<Submission, ApiError> {
    let limits = state.limits.clone();
    let executor = state.executor.clone();
    if body.len() <= INLINE_PARSE_BYTES {
        return parse_submit(body, &limits, default_seed, executor.as_ref());
    }
    let b = body.clone();
    tokio::task::spawn_blocking(move || parse_submit(&b, &limits, default_seed, executor.as_ref()))
        .await
        .map_err(|e| ApiError::Internal(format!("validation task failed: {e}")))?
}

/// Checks a spec's image (decoded) and SVG (parsed) off the async threads, under an
/// upload-validation permit, and moves them out of it: the spec to store and its upload.
async fn check_upload(
    state: &AppState,
    spec: JobSpec,
) -> Result<(JobSpec, Option<NewUpload>), ApiError> {
    if spec.image.is_none() && spec.svg.is_none() {
        return Ok((spec, None));
    }
    let permit = tokio::time::timeout(DECODE_WAIT, state.decode_permits.clone().acquire_owned())
        .await
        .ok()
        .and_then(Result::ok)
        .ok_or(ApiError::Busy {
            what: "too many uploads are being validated at once",
            retry_after_secs: 2,
        })?;
    let limits = state.limits.clone();
    // The permit moves into the task: it is held until decoding ends, even if the client goes
    // away meanwhile. The upload leaves the spec there too (base64 of a large image is CPU
    // work as well).
    tokio::task::spawn_blocking(move || {
        let _permit = permit;
        let mut spec = spec;
        if let Some(img) = &spec.image {
            check_image(img, &limits)?;
        }
        if let Some(svg) = &spec.svg {
            check_svg(svg)?;
        }
        let upload = take_upload(&mut spec);
        Ok::<_, ApiError>((spec, Some(upload)))
    })
    .await
    .map_err(|e| ApiError::Internal(format!("validation task failed: {e}")))?
}

/// Admission past the tenant's quota and the queue depth: `Ok(None)` admits the job,
/// `Ok(Some(_))` is the replay of a known Idempotency-Key (which adds nothing to the queue),
/// otherwise the 429.
async fn admit(
    state: &AppState,
    caller: &Caller,
    key: &Option<String>,
    hash: &Option<String>,
) -> Result<Option<Response>, ApiError> {
    if let Caller::Tenant {
        name,
        max_active_jobs,
        ..
    } = caller
        && *max_active_jobs > 0
    {
        let active = state.store.active_jobs(name).await?;
        if active >= i64::from(*max_active_jobs) {
            if let Some(resp) = replay_known(state, key, hash).await? {
                return Ok(Some(resp));
            }
            return Err(ApiError::QuotaExceeded {
                limit: *max_active_jobs,
                retry_after_secs: 5,
            });
        }
    }
    let max_depth = state.cfg.server.max_queue_depth;
    if state.queued_estimate.load(Ordering::Relaxed) >= max_depth {
        if let Some(resp) = replay_known(state, key, hash).await? {
            return Ok(Some(resp));
        }
        let depth = state.store.queue_depth().await?;
        state.queued_estimate.store(depth, Ordering::Relaxed);
        if depth >= max_depth {
            return Err(queue_full(state, depth));
        }
    }
    Ok(None)
}

/// Moves a validated spec's upload out of it (the image as the bytes decoded from the request,
/// the SVG), leaving the "" markers the stored job keeps in their place (`store::uploads`; the
/// worker puts it back).
fn take_upload(spec: &mut JobSpec) -> NewUpload {
    NewUpload {
        image: spec.image.as_mut().map(std::mem::take),
        svg: spec.svg.as_mut().map(std::mem::take),
        ..NewUpload::default()
    }
}

/// `upload` under the server's quota and the caller's own.
fn with_quotas(upload: NewUpload, state: &AppState, caller: &Caller) -> NewUpload {
    let cap = |b: u64| i64::try_from(b).unwrap_or(i64::MAX);
    NewUpload {
        max_total_bytes: cap(state.cfg.server.max_stored_upload_bytes),
        max_tenant_bytes: match caller {
            Caller::Tenant {
                max_upload_bytes, ..
            } => cap(*max_upload_bytes),
            Caller::Operator => 0,
        },
        ..upload
    }
}

/// The 429 of a full queue (`depth` jobs waiting), counted, with the estimate corrected.
fn queue_full(state: &AppState, depth: i64) -> ApiError {
    Metrics::inc(&state.metrics.jobs_rejected_queue_full);
    state.queued_estimate.store(depth, Ordering::Relaxed);
    ApiError::QueueFull {
        depth,
        retry_after_secs: 5,
    }
}

/// 202 with the job and its `Location`.
fn accepted(row: &JobRow) -> Response {
    let mut resp = (StatusCode::ACCEPTED, Json(JobView::from_row(row))).into_response();
    if let Ok(loc) = HeaderValue::from_str(&format!("/jobs/{}", row.id)) {
        resp.headers_mut().insert(header::LOCATION, loc);
    }
    resp
}

/// A retried submit (a known Idempotency-Key) adds nothing to the queue, so it gets its job back
/// even past an admission limit (queue depth, a tenant's quota): the replay, or `None` when the
/// key is new (or absent). Admission calls it only once a limit is hit, to spare the lookup.
async fn replay_known(
    state: &AppState,
    key: &Option<String>,
    hash: &Option<String>,
) -> Result<Option<Response>, ApiError> {
    let Some(k) = key else { return Ok(None) };
    match state.store.get_job_by_key(k).await? {
        Some(row) => replay(row, hash).map(Some),
        None => Ok(None),
    }
}

/// The answer to a submit whose Idempotency-Key is known: the same job (marked replayed), or a
/// conflict when the body differs.
fn replay(row: JobRow, hash: &Option<String>) -> Result<Response, ApiError> {
    if row.request_hash != *hash {
        return Err(ApiError::IdempotencyConflict);
    }
    let mut resp = accepted(&row);
    resp.headers_mut()
        .insert("idempotent-replayed", HeaderValue::from_static("true"));
    Ok(resp)
}
