//! What every request passes through: the caller resolved from its API key, the response
//! counted under its route's label, and the answers for unknown routes and methods.

use crate::server::AppState;
use crate::server::error::ApiError;
use crate::server::tenant::Caller;
use axum::extract::{Request, State};
use axum::http::header;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

pub(in crate::server) async fn no_route(req: Request) -> ApiError {
    ApiError::NoRoute {
        method: req.method().to_string(),
        path: req.uri().path().to_string(),
    }
}

pub(in crate::server) async fn method_not_allowed(req: Request) -> ApiError {
    ApiError::MethodNotAllowed(req.method().to_string())
}

/// Resolves the caller from its API key (`server::tenant`; every route except `/healthz`,
/// `/readyz` and the page needs one when keys are configured), then counts the response.
pub(in crate::server) async fn auth_and_count(
    State(state): State<AppState>,
    mut req: Request,
    next: Next,
) -> Response {
    let started = std::time::Instant::now();
    let path = req.uri().path();
    let route = route_label(req.method().as_str(), path);
    let open = matches!(path, "/healthz" | "/readyz") || crate::server::page::is_page(path);
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
        crate::server::tenant::resolve(&state.cfg.server, given, metrics)
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
