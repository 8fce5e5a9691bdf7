//! Request handlers (everything except the SSE stream, see `sse.rs`).

use super::AppState;
use super::error::ApiError;
use super::tenant::Caller;
use super::types::{JobList, JobView, check_image, check_svg, parse_submit};
use crate::pipeline::{JobKind, JobSpec};
use crate::store::{JobRow, JobStatus, NewJob, NewUpload, StoreError, now_ms};
use crate::worker::events::JobEvent;
use crate::worker::metrics::Metrics;
use axum::Json;
use axum::body::Body;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Extension, Path, Query, Request, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use sha2::Digest;
use std::sync::atomic::Ordering;

/// Parses a job id path segment; anything that is not a UUID cannot name a job.
pub(super) fn job_id(raw: &str) -> Result<String, ApiError> {
    uuid::Uuid::parse_str(raw)
        .map(|u| u.hyphenated().to_string())
        .map_err(|_| ApiError::NotFound {
            what: "job",
            id: raw.to_string(),
        })
}

/// The job `id` as `caller` may see it: another tenant's job is not found.
pub(super) async fn load_job(
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

const IDEMPOTENCY_HEADER: &str = "idempotency-key";
/// Request bodies up to this size are parsed on the async thread.
const INLINE_PARSE_BYTES: usize = 16 * 1024;

/// Within this many jobs of `max_queue_depth` (by the estimate), a submit's insert counts the
/// queued jobs itself.
const QUEUE_MARGIN: i64 = 64;

/// How long a submit waits for an upload-validation permit before answering 429 `busy`.
const DECODE_WAIT: std::time::Duration = std::time::Duration::from_secs(10);

pub(super) async fn submit(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    headers: HeaderMap,
    body: Body,
) -> Result<Response, ApiError> {
    if *state.shutdown.borrow() {
        return Err(ApiError::ShuttingDown);
    }
    let is_json = headers
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
        });
    if !is_json {
        return Err(ApiError::UnsupportedMediaType);
    }
    // Refuse oversized bodies from their declared length, before reading (and before a client
    // that sent `Expect: 100-continue` uploads anything).
    let limit = state.cfg.server.max_body_bytes;
    let declared = headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|s| s.trim().parse::<u64>().ok());
    if declared.is_some_and(|n| n > limit as u64) {
        return Err(ApiError::PayloadTooLarge { limit });
    }
    let read_for = std::time::Duration::from_secs(state.cfg.server.body_read_timeout_secs);
    let body = tokio::time::timeout(read_for, axum::body::to_bytes(body, limit))
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
        })?;
    let key = match headers.get(IDEMPOTENCY_HEADER) {
        None => None,
        Some(v) => {
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
            Some(caller.scoped_key(s))
        }
    };
    let id = uuid::Uuid::new_v4();
    let default_seed = u64::from_le_bytes(
        id.as_bytes()[..8]
            .try_into()
            .map_err(|_| ApiError::Internal("uuid has 16 bytes".into()))?,
    );
    let limits = state.limits.clone();
    let executor = state.executor.clone();
    // Small bodies are parsed in place (microseconds); big ones, and image decoding and SVG
    // parsing, are CPU work that runs off the async threads.
    let spec = if body.len() <= INLINE_PARSE_BYTES {
        parse_submit(&body, &limits, default_seed, executor.as_ref())?
    } else {
        let b = body.clone();
        let l = limits.clone();
        tokio::task::spawn_blocking(move || parse_submit(&b, &l, default_seed, executor.as_ref()))
            .await
            .map_err(|e| ApiError::Internal(format!("validation task failed: {e}")))??
    };
    let (spec, upload) = if spec.image.is_some() || spec.svg.is_some() {
        let permit =
            tokio::time::timeout(DECODE_WAIT, state.decode_permits.clone().acquire_owned())
                .await
                .ok()
                .and_then(Result::ok)
                .ok_or(ApiError::Busy {
                    what: "too many uploads are being validated at once",
                    retry_after_secs: 2,
                })?;
        // The permit moves into the task: it is held until decoding ends, even if the client
        // goes away meanwhile. The upload leaves the spec there too (base64 of a large image
        // is CPU work as well).
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
        .map_err(|e| ApiError::Internal(format!("validation task failed: {e}")))??
    } else {
        (spec, None)
    };

    if spec.kind == JobKind::Text
        && let Err(msg) = state.executor.text_ready()
    {
        tracing::warn!(reason = %msg, "text job refused: text models are not configured");
        return Err(ApiError::ModelsNotConfigured(msg));
    }
    let hash = key
        .as_ref()
        .map(|_| format!("{:x}", sha2::Sha256::digest(&body)));
    if let Caller::Tenant {
        name,
        max_active_jobs,
        ..
    } = &caller
        && *max_active_jobs > 0
    {
        let active = state.store.active_jobs(name).await?;
        if active >= i64::from(*max_active_jobs) {
            if let Some(resp) = replay_known(&state, &key, &hash).await? {
                return Ok(resp);
            }
            return Err(ApiError::QuotaExceeded {
                limit: *max_active_jobs,
                retry_after_secs: 5,
            });
        }
    }
    let max_depth = state.cfg.server.max_queue_depth;
    if state.queued_estimate.load(Ordering::Relaxed) >= max_depth {
        if let Some(resp) = replay_known(&state, &key, &hash).await? {
            return Ok(resp);
        }
        let depth = state.store.queue_depth().await?;
        state.queued_estimate.store(depth, Ordering::Relaxed);
        if depth >= max_depth {
            return Err(queue_full(&state, depth));
        }
    }
    let spec_json = serde_json::to_string(&spec).map_err(|e| ApiError::Internal(e.to_string()))?;
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

/// Moves a validated spec's upload out of it (the image as base64, the SVG), leaving the ""
/// markers the stored job keeps in their place (`store::uploads`; the worker puts it back).
fn take_upload(spec: &mut JobSpec) -> NewUpload {
    use base64::Engine as _;
    NewUpload {
        image: spec
            .image
            .as_mut()
            .map(|b| base64::engine::general_purpose::STANDARD.encode(std::mem::take(b))),
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

pub(super) async fn get_job(
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
    view.attempt_history = Some(state.store.attempts(&id).await?);
    Ok(Json(view))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ListQuery {
    status: Option<String>,
    limit: Option<String>,
    cursor: Option<String>,
}

pub(super) async fn list(
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

pub(super) async fn cancel(
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

async fn finished_result(
    state: &AppState,
    id: &str,
    caller: &Caller,
) -> Result<crate::store::ResultRow, ApiError> {
    let row = load_job(state, id, caller).await?;
    if row.status != JobStatus::Succeeded {
        return Err(ApiError::Conflict(format!(
            "job {id} has no result: its status is {}",
            row.status
        )));
    }
    state
        .store
        .result(id)
        .await?
        .ok_or_else(|| ApiError::NotFound {
            what: "result for job",
            id: id.to_string(),
        })
}

/// An SVG body. Opened directly in a browser it can run nothing and load nothing (the
/// safe-output profile already keeps scripts out; the policy is the second wall), and it is
/// never sniffed as another type.
fn svg_response(svg: String) -> Response {
    (
        [
            (header::CONTENT_TYPE, "image/svg+xml; charset=utf-8"),
            (
                header::CONTENT_SECURITY_POLICY,
                "default-src 'none'; style-src 'unsafe-inline'",
            ),
            (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
        ],
        svg,
    )
        .into_response()
}

pub(super) async fn result_svg(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(raw): Path<String>,
) -> Result<Response, ApiError> {
    let id = job_id(&raw)?;
    Ok(svg_response(
        finished_result(&state, &id, &caller).await?.svg,
    ))
}

/// Longest side of PNG previews.
const PREVIEW_MAX_SIDE: f32 = 1024.0;

/// Renders `svg` to PNG with resvg, scaled so the longest side is at most [`PREVIEW_MAX_SIDE`].
pub fn render_png(svg: &str) -> Result<Vec<u8>, String> {
    use resvg::tiny_skia;
    let tree = crate::svg::parse_usvg(svg)?;
    let size = tree.size();
    let scale = (PREVIEW_MAX_SIDE / size.width().max(size.height())).min(1.0);
    let w = (size.width() * scale).ceil().max(1.0) as u32;
    let h = (size.height() * scale).ceil().max(1.0) as u32;
    let mut pixmap =
        tiny_skia::Pixmap::new(w, h).ok_or_else(|| format!("cannot allocate {w}x{h}"))?;
    resvg::render(
        &tree,
        tiny_skia::Transform::from_scale(scale, scale),
        &mut pixmap.as_mut(),
    );
    pixmap.encode_png().map_err(|e| e.to_string())
}

pub(super) async fn result_png(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(raw): Path<String>,
) -> Result<Response, ApiError> {
    let id = job_id(&raw)?;
    let result = finished_result(&state, &id, &caller).await?;
    let png = tokio::task::spawn_blocking(move || render_png(&result.svg))
        .await
        .map_err(|e| ApiError::Internal(e.to_string()))?
        .map_err(|e| ApiError::Internal(format!("rendering the preview failed: {e}")))?;
    Ok(([(header::CONTENT_TYPE, "image/png")], png).into_response())
}

pub(super) async fn snapshot(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path((raw, file)): Path<(String, String)>,
) -> Result<Response, ApiError> {
    let id = job_id(&raw)?;
    let n = file
        .strip_suffix(".svg")
        .and_then(|s| s.parse::<i64>().ok())
        .filter(|n| *n >= 1)
        .ok_or_else(|| ApiError::NotFound {
            what: "snapshot",
            id: format!("{id}/{file} (snapshots are named N.svg, N = 1, 2, ...)"),
        })?;
    load_job(&state, &id, &caller).await?;
    let snap = state
        .store
        .snapshot(&id, n)
        .await?
        .ok_or_else(|| ApiError::NotFound {
            what: "snapshot",
            id: format!("{id}/{n} (it may have been pruned)"),
        })?;
    Ok(svg_response(snap.svg))
}

pub(super) async fn healthz() -> Json<serde_json::Value> {
    Json(serde_json::json!({ "status": "ok" }))
}

pub(super) async fn readyz(State(state): State<AppState>) -> Response {
    let db = state.store.ping().await;
    let shutting_down = *state.shutdown.borrow();
    let text = state.executor.text_ready();
    let ready = db.is_ok() && !shutting_down;
    let body = serde_json::json!({
        "status": if ready { "ready" } else { "not_ready" },
        "database": match &db { Ok(()) => "ok".to_string(), Err(e) => e.to_string() },
        "shutting_down": shutting_down,
        "workers": state.pool.workers(),
        "text_models": match &text {
            Ok(()) => "ready".to_string(),
            Err(m) => super::error::without_paths(m),
        },
        "text_jobs_accepted": text.is_ok(),
    });
    let status = if ready {
        StatusCode::OK
    } else {
        StatusCode::SERVICE_UNAVAILABLE
    };
    (status, Json(body)).into_response()
}

pub(super) async fn metrics(State(state): State<AppState>) -> Result<Response, ApiError> {
    let counts = state.store.count_by_status().await?;
    let text = state
        .metrics
        .render(&counts, state.pool.workers(), state.pool.busy());
    Ok((
        [(
            header::CONTENT_TYPE,
            "text/plain; version=0.0.4; charset=utf-8",
        )],
        text,
    )
        .into_response())
}

pub(super) async fn no_route(req: Request) -> ApiError {
    ApiError::NoRoute {
        method: req.method().to_string(),
        path: req.uri().path().to_string(),
    }
}

pub(super) async fn method_not_allowed(req: Request) -> ApiError {
    ApiError::MethodNotAllowed(req.method().to_string())
}

/// Resolves the caller from its API key (`server::tenant`; every route except `/healthz`,
/// `/readyz` and the page needs one when keys are configured), then counts the response.
pub(super) async fn auth_and_count(
    State(state): State<AppState>,
    mut req: Request,
    next: Next,
) -> Response {
    let started = std::time::Instant::now();
    let path = req.uri().path();
    let route = route_label(req.method().as_str(), path);
    let open = matches!(path, "/healthz" | "/readyz") || super::page::is_page(path);
    let metrics = path == "/metrics";
    let h = req.headers();
    let given = h
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .or_else(|| h.get("x-api-key").and_then(|v| v.to_str().ok()));
    let caller = if open {
        Some(Caller::Operator)
    } else {
        super::tenant::resolve(&state.cfg.server, given, metrics)
    };
    let resp = match caller {
        Some(c) => {
            req.extensions_mut().insert(c);
            next.run(req).await
        }
        None => ApiError::Unauthorized.into_response(),
    };
    state.metrics.http_response(resp.status().as_u16());
    state
        .metrics
        .observe_http(&route, started.elapsed().as_secs_f64());
    resp
}

/// `METHOD /path/template` for metrics: job ids and snapshot numbers collapse, unknown paths
/// share one label.
fn route_label(method: &str, path: &str) -> String {
    let segs: Vec<&str> = path.trim_start_matches('/').split('/').collect();
    let template = match segs.as_slice() {
        ["jobs"] => "/jobs".to_string(),
        ["jobs", _] => "/jobs/{id}".to_string(),
        ["jobs", _, "snapshots", _] => "/jobs/{id}/snapshots/{n}.svg".to_string(),
        ["jobs", _, leaf @ ("events" | "result.svg" | "result.png")] => {
            format!("/jobs/{{id}}/{leaf}")
        }
        [one @ ("healthz" | "readyz" | "metrics")] => format!("/{one}"),
        _ => "other".to_string(),
    };
    let method = match method {
        "GET" | "POST" | "DELETE" | "PUT" | "PATCH" | "HEAD" | "OPTIONS" => method,
        _ => "OTHER",
    };
    format!("{method} {template}")
}
