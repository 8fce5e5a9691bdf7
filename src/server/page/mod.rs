//! The playground page at `/` (README, "HTTP service"): plain HTML, CSS and JS embedded in the
//! binary, using the public API alone. Served without an API key (the page asks for one), with a
//! strict Content-Security-Policy: scripts and styles from this origin only, images from this
//! origin or `blob:` (SVG results are shown as `<img>`, where their scripts cannot run).

use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};

const INDEX_HTML: &str = include_str!("index.html");
const APP_JS: &str = include_str!("app.js");
/// The ES modules `app.js` imports, served at `/js/<name>`.
const MODULES: [(&str, &str); 3] = [
    ("common.js", include_str!("common.js")),
    ("form.js", include_str!("form.js")),
    ("view.js", include_str!("view.js")),
];
const STYLE_CSS: &str = include_str!("style.css");

/// The page's Content-Security-Policy.
pub const CSP: &str = "default-src 'none'; script-src 'self'; style-src 'self'; \
    img-src 'self' blob: data:; connect-src 'self' blob:; base-uri 'none'; form-action 'none'; \
    frame-ancestors 'none'";

/// Paths of the page's files (served without an API key).
pub fn is_page(path: &str) -> bool {
    matches!(path, "/" | "/app.js" | "/style.css") || path.starts_with("/js/")
}

fn file(body: &'static str, content_type: &'static str) -> Response {
    let mut resp = ([(header::CONTENT_TYPE, content_type)], body).into_response();
    let h = resp.headers_mut();
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(CSP),
    );
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    resp
}

pub(super) async fn index() -> Response {
    file(INDEX_HTML, "text/html; charset=utf-8")
}

pub(super) async fn app_js() -> Response {
    file(APP_JS, "text/javascript; charset=utf-8")
}

/// `/js/{module}`: one of the page's script modules; 404 for any other name.
pub(super) async fn module(axum::extract::Path(name): axum::extract::Path<String>) -> Response {
    match MODULES.iter().find(|(n, _)| *n == name) {
        Some((_, body)) => file(body, "text/javascript; charset=utf-8"),
        None => crate::server::error::ApiError::NotFound {
            what: "page module",
            id: name,
        }
        .into_response(),
    }
}

pub(super) async fn style_css() -> Response {
    file(STYLE_CSS, "text/css; charset=utf-8")
}
