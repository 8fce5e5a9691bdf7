//! The one error type of the HTTP layer and its mapping to status codes and JSON bodies
//! `{"error": {"code", "field", "reason"}}`.

use axum::Json;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;

/// Every way a request can fail.
#[derive(Debug, thiserror::Error)]
pub enum ApiError {
    #[error("request body is not valid JSON: {0}")]
    MalformedJson(String),
    #[error("{field}: {reason}")]
    Invalid { field: String, reason: String },
    #[error("invalid query parameter {field}: {reason}")]
    InvalidQuery { field: String, reason: String },
    #[error("request body is larger than {limit} bytes")]
    PayloadTooLarge { limit: usize },
    #[error("expected Content-Type: application/json")]
    UnsupportedMediaType,
    #[error("missing or wrong API key")]
    Unauthorized,
    #[error("no {what} with id {id:?}")]
    NotFound { what: &'static str, id: String },
    #[error("no such route: {method} {path}")]
    NoRoute { method: String, path: String },
    #[error("method {0} is not allowed here")]
    MethodNotAllowed(String),
    #[error("{0}")]
    Conflict(String),
    #[error("the idempotency key was used for a different request")]
    IdempotencyConflict,
    #[error("the queue is full ({depth} jobs waiting); retry later")]
    QueueFull { depth: i64, retry_after_secs: u64 },
    #[error(
        "this key already has {limit} queued or running jobs (its max_active_jobs); retry later"
    )]
    QuotaExceeded { limit: u32, retry_after_secs: u64 },
    #[error(
        "stored uploads would pass {limit} bytes (max_stored_upload_bytes or the key's max_upload_bytes); retry when running jobs finish"
    )]
    UploadQuota { limit: i64, retry_after_secs: u64 },
    #[error("the request body did not arrive within {secs} s")]
    BodyTimeout { secs: u64 },
    #[error("the server is busy ({what}); retry later")]
    Busy {
        what: &'static str,
        retry_after_secs: u64,
    },
    #[error("{0}")]
    ModelsNotConfigured(String),
    #[error("the server is shutting down")]
    ShuttingDown,
    #[error("the database is unreachable ({0}); retry shortly")]
    DatabaseUnavailable(String),
    #[error("internal error: {0}")]
    Internal(String),
}

#[derive(Serialize)]
struct Body<'a> {
    error: Detail<'a>,
}

#[derive(Serialize)]
struct Detail<'a> {
    code: &'a str,
    field: Option<&'a str>,
    reason: String,
}

impl ApiError {
    pub fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        ApiError::Invalid {
            field: field.into(),
            reason: reason.into(),
        }
    }

    pub fn status(&self) -> StatusCode {
        match self {
            ApiError::MalformedJson(_)
            | ApiError::Invalid { .. }
            | ApiError::InvalidQuery { .. } => StatusCode::BAD_REQUEST,
            ApiError::PayloadTooLarge { .. } => StatusCode::PAYLOAD_TOO_LARGE,
            ApiError::UnsupportedMediaType => StatusCode::UNSUPPORTED_MEDIA_TYPE,
            ApiError::Unauthorized => StatusCode::UNAUTHORIZED,
            ApiError::NotFound { .. } | ApiError::NoRoute { .. } => StatusCode::NOT_FOUND,
            ApiError::MethodNotAllowed(_) => StatusCode::METHOD_NOT_ALLOWED,
            ApiError::Conflict(_) | ApiError::IdempotencyConflict => StatusCode::CONFLICT,
            ApiError::QueueFull { .. }
            | ApiError::Busy { .. }
            | ApiError::QuotaExceeded { .. }
            | ApiError::UploadQuota { .. } => StatusCode::TOO_MANY_REQUESTS,
            ApiError::BodyTimeout { .. } => StatusCode::REQUEST_TIMEOUT,
            ApiError::ModelsNotConfigured(_)
            | ApiError::ShuttingDown
            | ApiError::DatabaseUnavailable(_) => StatusCode::SERVICE_UNAVAILABLE,
            ApiError::Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }

    pub fn code(&self) -> &'static str {
        match self {
            ApiError::MalformedJson(_) => "malformed_json",
            ApiError::Invalid { .. } => "invalid_field",
            ApiError::InvalidQuery { .. } => "invalid_query",
            ApiError::PayloadTooLarge { .. } => "payload_too_large",
            ApiError::UnsupportedMediaType => "unsupported_media_type",
            ApiError::Unauthorized => "unauthorized",
            ApiError::NotFound { .. } => "not_found",
            ApiError::NoRoute { .. } => "no_such_route",
            ApiError::MethodNotAllowed(_) => "method_not_allowed",
            ApiError::Conflict(_) => "conflict",
            ApiError::IdempotencyConflict => "idempotency_conflict",
            ApiError::QueueFull { .. } => "queue_full",
            ApiError::Busy { .. } => "busy",
            ApiError::QuotaExceeded { .. } => "quota_exceeded",
            ApiError::UploadQuota { .. } => "upload_quota_exceeded",
            ApiError::BodyTimeout { .. } => "body_timeout",
            ApiError::ModelsNotConfigured(_) => "models_not_configured",
            ApiError::ShuttingDown => "shutting_down",
            ApiError::DatabaseUnavailable(_) => "database_unavailable",
            ApiError::Internal(_) => "internal",
        }
    }

    /// Seconds a client should wait before trying again (`Retry-After`), for errors that pass.
    fn retry_after_secs(&self) -> Option<u64> {
        match self {
            ApiError::QueueFull {
                retry_after_secs, ..
            }
            | ApiError::Busy {
                retry_after_secs, ..
            }
            | ApiError::QuotaExceeded {
                retry_after_secs, ..
            }
            | ApiError::UploadQuota {
                retry_after_secs, ..
            } => Some(*retry_after_secs),
            ApiError::DatabaseUnavailable(_) => Some(2),
            _ => None,
        }
    }

    fn field(&self) -> Option<&str> {
        match self {
            ApiError::Invalid { field, .. } | ApiError::InvalidQuery { field, .. } => Some(field),
            _ => None,
        }
    }

    fn reason(&self) -> String {
        match self {
            ApiError::Invalid { reason, .. } | ApiError::InvalidQuery { reason, .. } => {
                reason.clone()
            }
            // never leak internals to clients; they are logged instead
            ApiError::Internal(_) => "internal error; see the server log".to_string(),
            // the settings to change, not where this server keeps its files
            ApiError::ModelsNotConfigured(m) => without_paths(m),
            other => other.to_string(),
        }
    }
}

/// `text` with every absolute filesystem path replaced by `<path>`, for messages that reach
/// clients (the full message goes to the log).
pub fn without_paths(text: &str) -> String {
    text.split(' ')
        .map(|w| {
            if w.starts_with('/') || w.starts_with("~/") {
                let tail: String = w
                    .chars()
                    .rev()
                    .take_while(|c| matches!(c, ')' | ',' | ';' | ':' | '.'))
                    .collect();
                format!("<path>{}", tail.chars().rev().collect::<String>())
            } else {
                w.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

impl From<crate::store::StoreError> for ApiError {
    fn from(e: crate::store::StoreError) -> Self {
        match e {
            crate::store::StoreError::UploadQuota { limit } => ApiError::UploadQuota {
                limit,
                retry_after_secs: 30,
            },
            other if other.is_unavailable() => ApiError::DatabaseUnavailable(other.to_string()),
            other => ApiError::Internal(other.to_string()),
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let status = self.status();
        if status.is_server_error() && status != StatusCode::SERVICE_UNAVAILABLE {
            tracing::error!(error = %self, "request failed");
        }
        let body = Body {
            error: Detail {
                code: self.code(),
                field: self.field(),
                reason: self.reason(),
            },
        };
        let mut resp = (status, Json(body)).into_response();
        if let Some(secs) = self.retry_after_secs()
            && let Ok(v) = HeaderValue::from_str(&secs.to_string())
        {
            resp.headers_mut().insert(header::RETRY_AFTER, v);
        }
        if let ApiError::Unauthorized = &self {
            resp.headers_mut().insert(
                header::WWW_AUTHENTICATE,
                HeaderValue::from_static("Bearer realm=\"vectorfusion\""),
            );
        }
        resp
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn paths_are_removed_from_client_messages() {
        assert_eq!(
            super::without_paths(
                "the directory /srv/models/sd (from sd_dir) does not exist: set ~/x."
            ),
            "the directory <path> (from sd_dir) does not exist: set <path>."
        );
    }

    #[test]
    fn an_unreachable_database_is_503_with_retry_after() {
        use axum::response::IntoResponse;
        let unreachable = crate::store::StoreError::Db(sqlx::Error::PoolTimedOut);
        let resp = super::ApiError::from(unreachable).into_response();
        assert_eq!(resp.status(), axum::http::StatusCode::SERVICE_UNAVAILABLE);
        assert_eq!(resp.headers()[axum::http::header::RETRY_AFTER], "2");
        // Other store errors stay internal errors, with no Retry-After.
        let corrupt = crate::store::StoreError::Corrupt("bad row".into());
        let resp = super::ApiError::from(corrupt).into_response();
        assert_eq!(resp.status(), axum::http::StatusCode::INTERNAL_SERVER_ERROR);
        assert!(
            resp.headers()
                .get(axum::http::header::RETRY_AFTER)
                .is_none()
        );
    }
}
