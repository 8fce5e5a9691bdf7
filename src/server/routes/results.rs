//! A finished job's output: `result.svg`, the `result.png` preview, `result.pdf`, each
//! variation's (`result/{i}.svg|png|pdf`) and the snapshots.

use super::jobs::{check_other_params, job_id, load_job};
use crate::server::AppState;
use crate::server::error::ApiError;
use crate::server::tenant::Caller;
use crate::store::JobStatus;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Extension, Path, Query, State};
use axum::http::{HeaderMap, header};
use axum::response::{IntoResponse, Response};

/// Longest side of `result.png`.
const PREVIEW_MAX_SIDE: f32 = 1024.0;

/// The longest side a PNG may be asked for with `?size=` (px).
pub const PNG_SIDES: std::ops::RangeInclusive<u32> = 16..=4096;

/// The query of a PNG download: `size`, the PNG's longest side in px ([`PNG_SIDES`]; without
/// it, the preview: the SVG's own size, at most [`PREVIEW_MAX_SIDE`]).
#[derive(serde::Deserialize)]
pub(in crate::server) struct PngQuery {
    size: Option<String>,
    /// Every other parameter: see [`check_other_params`].
    #[serde(flatten)]
    other: std::collections::BTreeMap<String, String>,
}

impl PngQuery {
    /// The query of a request, checked: the longest side asked for, if any.
    fn side(query: Result<Query<PngQuery>, QueryRejection>) -> Result<Option<u32>, ApiError> {
        let Query(q) = query.map_err(|e| ApiError::InvalidQuery {
            field: "query".into(),
            reason: e.body_text(),
        })?;
        check_other_params(&q.other, "size")?;
        let Some(raw) = q.size else { return Ok(None) };
        raw.parse::<u32>()
            .ok()
            .filter(|n| PNG_SIDES.contains(n))
            .map(Some)
            .ok_or_else(|| ApiError::InvalidQuery {
                field: "size".into(),
                reason: format!(
                    "must be a whole number from {} to {} (the PNG's longest side in px)",
                    PNG_SIDES.start(),
                    PNG_SIDES.end()
                ),
            })
    }
}

/// The generic binary type every download is also served as, for clients that cannot name
/// `image/svg+xml` or `image/png` (code generators map it to a file).
const OCTET_STREAM: &str = "application/octet-stream";

/// Whether the client asked for [`OCTET_STREAM`] rather than the native type `native`: its
/// `Accept` names `application/octet-stream` and not `native` (without an `Accept`, or with
/// `*/*`, the native type is served).
fn wants_octet_stream(headers: &HeaderMap, native: &str) -> bool {
    let accept = headers
        .get_all(header::ACCEPT)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .map(|t| {
            t.split(';')
                .next()
                .unwrap_or("")
                .trim()
                .to_ascii_lowercase()
        })
        .collect::<Vec<_>>();
    accept.iter().any(|t| t == OCTET_STREAM) && !accept.iter().any(|t| t == native)
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
/// never sniffed as another type. Served as [`OCTET_STREAM`] when the client asks for that.
fn svg_response(headers: &HeaderMap, svg: String) -> Response {
    let content_type = if wants_octet_stream(headers, "image/svg+xml") {
        OCTET_STREAM
    } else {
        "image/svg+xml; charset=utf-8"
    };
    (
        [
            (header::CONTENT_TYPE, content_type),
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

pub(in crate::server) async fn result_svg(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(raw): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let id = job_id(&raw)?;
    Ok(svg_response(
        &headers,
        finished_result(&state, &id, &caller).await?.svg,
    ))
}

pub(in crate::server) async fn result_png(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(raw): Path<String>,
    query: Result<Query<PngQuery>, QueryRejection>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let id = job_id(&raw)?;
    let side = PngQuery::side(query)?;
    let svg = finished_result(&state, &id, &caller).await?.svg;
    png_response(&headers, svg, side).await
}

/// `svg` rendered as a PNG: its longest side `side` px, or the preview without it.
async fn png_response(
    headers: &HeaderMap,
    svg: String,
    side: Option<u32>,
) -> Result<Response, ApiError> {
    converted(headers, "image/png", move || {
        match side {
            Some(side) => crate::svg::render_png_at(&svg, side),
            None => crate::svg::render_png(&svg, PREVIEW_MAX_SIDE),
        }
        .map_err(|e| ApiError::Internal(format!("rendering the PNG failed: {e}")))
    })
    .await
}

/// `result.pdf`: the final SVG as a one-page vector PDF ([`crate::pdf`]).
pub(in crate::server) async fn result_pdf(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(raw): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let id = job_id(&raw)?;
    let svg = finished_result(&state, &id, &caller).await?.svg;
    pdf_response(&headers, svg).await
}

/// `svg` as a one-page vector PDF.
async fn pdf_response(headers: &HeaderMap, svg: String) -> Result<Response, ApiError> {
    converted(headers, "application/pdf", move || {
        crate::svg::from_svg(&svg)
            .map(|scene| crate::pdf::to_pdf(&scene))
            .map_err(|e| ApiError::Internal(format!("converting the result to PDF failed: {e}")))
    })
    .await
}

/// `result/{i}.svg|png|pdf`: variation `i` (1-based; 1 is `result.svg`) of a succeeded job.
pub(in crate::server) async fn result_variation(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path((raw, file)): Path<(String, String)>,
    query: Result<Query<PngQuery>, QueryRejection>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let id = job_id(&raw)?;
    let side = PngQuery::side(query)?;
    let not_found = || ApiError::NotFound {
        what: "result variation",
        id: format!(
            "{id}/result/{file} (variations are named I.svg, I.png or I.pdf, I = 1, 2, ...)"
        ),
    };
    let (n, ext) = numbered(&file, &["svg", "png", "pdf"]).ok_or_else(not_found)?;
    if side.is_some() && ext != "png" {
        return Err(ApiError::InvalidQuery {
            field: "size".into(),
            reason: "only applies to a PNG".into(),
        });
    }
    let first = finished_result(&state, &id, &caller).await?;
    let svg = if n == 1 {
        first.svg
    } else {
        state
            .store
            .result_variation(&id, n)
            .await?
            .ok_or_else(not_found)?
    };
    match ext {
        "png" => png_response(&headers, svg, side).await,
        "pdf" => pdf_response(&headers, svg).await,
        _ => Ok(svg_response(&headers, svg)),
    }
}

/// `N.ext` (N = 1, 2, ...; `ext` one of `exts`) as N and its extension.
fn numbered<'a>(file: &'a str, exts: &[&str]) -> Option<(i64, &'a str)> {
    let (n, ext) = file.rsplit_once('.')?;
    let n = n.parse::<i64>().ok().filter(|n| *n >= 1)?;
    exts.contains(&ext).then_some((n, ext))
}

/// The bytes `convert` makes (CPU work, off the async threads), served as `native` or as
/// [`OCTET_STREAM`] when the client asks for that.
async fn converted(
    headers: &HeaderMap,
    native: &'static str,
    convert: impl FnOnce() -> Result<Vec<u8>, ApiError> + Send + 'static,
) -> Result<Response, ApiError> {
    let bytes = tokio::task::spawn_blocking(convert)
        .await
        .map_err(|e| ApiError::Internal(e.to_string()))??;
    let content_type = if wants_octet_stream(headers, native) {
        OCTET_STREAM
    } else {
        native
    };
    Ok(([(header::CONTENT_TYPE, content_type)], bytes).into_response())
}

pub(in crate::server) async fn snapshot(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path((raw, file)): Path<(String, String)>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let id = job_id(&raw)?;
    let (n, _) = numbered(&file, &["svg"]).ok_or_else(|| ApiError::NotFound {
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
    Ok(svg_response(&headers, snap.svg))
}
