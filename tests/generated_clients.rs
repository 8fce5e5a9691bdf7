//! The API works through clients generated from `openapi.yaml`, without edits:
//!
//! - Python: openapi-python-client (0 warnings allowed) generates a package, and
//!   `scripts/clients/python_e2e.py` submits a vectorize and a text job with it, follows their
//!   events with httpx-sse and downloads the SVG, the PNG preview, a PNG at a chosen size, the
//!   PDF and a snapshot, and the SVG, PNG and PDF of the text job's second variation. It needs a
//!   virtual environment with `openapi-python-client`, `httpx-sse` and `python-dateutil`, named
//!   by `VF_CLIENT_VENV` (`.ci/run` makes one).
//! - TypeScript: openapi-typescript (`--default-non-nullable false`, so fields with a default
//!   stay optional in requests) generates the types, `tsc` checks `scripts/clients/ts/e2e.ts`
//!   (openapi-fetch calls) against them, and Node runs the same journey. It needs `node` and
//!   `npm` (the pinned packages come from the npm registry).
//!
//! Without their tools the tests print SKIP (and fail where `.ci/run` sets `VF_REQUIRE_ALL`).

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

/// Runs `cmd` in `dir`; `Err(log)` when it cannot start or fails.
fn run_in(dir: &Path, cmd: &str, args: &[&str]) -> Result<String, String> {
    let out = Command::new(cmd)
        .args(args)
        .current_dir(dir)
        .output()
        .map_err(|e| format!("{cmd}: {e}"))?;
    let log = text(&out);
    if out.status.success() {
        Ok(log)
    } else {
        Err(format!("{cmd} {args:?} failed:\n{log}"))
    }
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
    assert!(log.contains("variation 2 of "), "{log}");
}

/// The TypeScript project in `dir` with its pinned packages installed, or why not.
fn typescript_project(dir: &Path) -> Result<(), String> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/clients/ts");
    std::fs::create_dir_all(dir).map_err(|e| e.to_string())?;
    for f in ["package.json", "tsconfig.json", "e2e.ts"] {
        std::fs::copy(src.join(f), dir.join(f)).map_err(|e| format!("{f}: {e}"))?;
    }
    run_in(
        dir,
        "npm",
        &["install", "--no-audit", "--no-fund", "--silent"],
    )
    .map(|_| ())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_generated_typescript_client_type_checks_submits_follows_and_downloads() {
    let name = "a_generated_typescript_client_type_checks_submits_follows_and_downloads";
    if run_in(Path::new("."), "node", &["--version"]).is_err() {
        common::skip(name, "node is not installed (apt-get install nodejs npm)");
        return;
    }
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("ts-client");
    if let Err(why) = typescript_project(&dir) {
        common::skip(
            name,
            &format!("the npm packages could not be installed: {why}"),
        );
        return;
    }
    let spec = concat!(env!("CARGO_MANIFEST_DIR"), "/openapi.yaml");
    let generator = "node_modules/.bin/openapi-typescript";
    let args = [spec, "-o", "api.d.ts", "--default-non-nullable", "false"];
    let log = run_in(&dir, generator, &args).unwrap_or_else(|e| panic!("{e}"));
    for bad in ["warn", "WARN", "⚠", "error"] {
        assert!(!log.contains(bad), "the generator warned ({bad}):\n{log}");
    }
    run_in(&dir, "node_modules/.bin/tsc", &["-p", "."]).unwrap_or_else(|e| panic!("{e}"));
    let srv = TestServer::start(Arc::new(TestExecutor::new(5)), |_| {}).await;
    let url = format!("http://{}", srv.addr);
    let png = common::png_b64(16);
    let out =
        tokio::task::spawn_blocking(move || run_in(&dir, "node", &["dist/e2e.js", &url, &png]))
            .await
            .expect("join");
    srv.stop().await;
    let log = out.unwrap_or_else(|e| panic!("the generated client failed: {e}"));
    assert_eq!(log.matches(" events, svg ").count(), 2, "{log}");
    assert!(log.contains("variation 2 of "), "{log}");
}
