//! The API works through a client generated from `openapi.yaml`, without edits: the test
//! generates a Python client with openapi-python-client (0 warnings allowed), then
//! `scripts/clients/python_e2e.py` submits a vectorize and a text job with it, follows their
//! events with httpx-sse and downloads the SVG, the PNG preview and a snapshot.
//!
//! It needs a Python virtual environment with `openapi-python-client`, `httpx-sse` and
//! `python-dateutil`, named by `VF_CLIENT_VENV` (`.ci/run` makes one); without it the test prints
//! SKIP (and fails where `.ci/run` sets `VF_REQUIRE_ALL`).

mod common;

use common::server::TestServer;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Arc;
use vectorfusion::worker::test_executor::TestExecutor;

fn venv() -> Option<PathBuf> {
    let dir = PathBuf::from(std::env::var_os("VF_CLIENT_VENV")?);
    dir.join("bin/openapi-python-client")
        .is_file()
        .then_some(dir)
}

fn text(out: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// Generates the client package into `dir`; fails on any generator warning.
fn generate_python_client(venv: &Path, dir: &Path) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let _ = std::fs::remove_dir_all(dir);
    let out = Command::new(venv.join("bin/openapi-python-client"))
        .arg("generate")
        .arg("--path")
        .arg(root.join("openapi.yaml"))
        .arg("--config")
        .arg(root.join("scripts/clients/openapi-python-client.yaml"))
        .arg("--output-path")
        .arg(dir)
        .output()
        .expect("openapi-python-client runs");
    let log = text(&out);
    assert!(out.status.success(), "the generator failed:\n{log}");
    for bad in ["WARNING", "Cannot parse", "Unsupported", "Error"] {
        assert!(!log.contains(bad), "the generator warned ({bad}):\n{log}");
    }
    assert!(
        dir.join("vectorfusion_client/api/default/result_svg.py")
            .is_file()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_generated_python_client_submits_follows_and_downloads() {
    let Some(venv) = venv() else {
        common::skip(
            "a_generated_python_client_submits_follows_and_downloads",
            "VF_CLIENT_VENV (openapi-python-client, httpx-sse, python-dateutil) is not set",
        );
        return;
    };
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("python-client");
    generate_python_client(&venv, &dir);
    let srv = TestServer::start(Arc::new(TestExecutor::new(5)), |_| {}).await;
    let url = format!("http://{}", srv.addr);
    let png = common::png_b64(16);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/clients/python_e2e.py");
    let out = tokio::task::spawn_blocking(move || {
        Command::new(venv.join("bin/python"))
            .arg(script)
            .arg(&url)
            .arg(&png)
            .env("PYTHONPATH", &dir)
            .output()
    })
    .await
    .expect("join")
    .expect("python runs");
    srv.stop().await;
    let log = text(&out);
    assert!(out.status.success(), "the generated client failed:\n{log}");
    assert_eq!(log.matches(" events, svg ").count(), 2, "{log}");
}
