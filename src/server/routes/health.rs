//! `/healthz`, `/readyz` and `/metrics`.

use crate::server::AppState;
use crate::server::error::ApiError;
use axum::Json;
use axum::extract::State;
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};

pub(in crate::server) async fn healthz() -> Json<serde_json::Value> {
    Json(serde_json::json!({ "status": "ok" }))
}

pub(in crate::server) async fn readyz(State(state): State<AppState>) -> Response {
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
            Err(m) => crate::server::error::without_paths(&m.to_string()),
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

pub(in crate::server) async fn metrics(
    State(state): State<AppState>,
) -> Result<Response, ApiError> {
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
