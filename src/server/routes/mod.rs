//! Request handlers (everything except the SSE stream, see `sse.rs`), one file per group of
//! endpoints: `submit` (`POST /jobs`), `jobs` (read, list, cancel), `results` (SVG, PNG preview,
//! snapshots), `health` (health, readiness, metrics) and `access` (API keys, request metrics,
//! unknown routes). Errors map to status codes in `error.rs` only.

mod access;
mod health;
mod jobs;
mod results;
mod submit;

pub(super) use access::{auth_and_count, method_not_allowed, no_route};
pub(super) use health::{healthz, metrics, readyz};
pub(super) use jobs::{cancel, check_other_params, get_job, job_id, list, load_job};
pub(super) use results::{result_pdf, result_png, result_svg, result_variation, snapshot};
pub(super) use submit::submit;
