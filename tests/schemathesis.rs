//! `openapi.yaml` against the live server, by schemathesis (PyPI): every check it has but one, a
//! bounded number of examples per operation, no failures allowed. The one: `use_after_free`
//! assumes a successful `DELETE` removes the resource, but `DELETE /jobs/{id}` cancels a job,
//! which stays readable (status `cancelled`) until retention removes it, as the spec says. `scripts/schemathesis/hooks.py` teaches it the two string
//! formats JSON Schema cannot describe (a base64 PNG, an SVG document). `.ci/run` installs schemathesis into a
//! virtual environment and names it in `VF_SCHEMATHESIS`; without it (or `schemathesis` on PATH)
//! the test prints SKIP (and
//! fails where `.ci/run` sets `VF_REQUIRE_ALL`).

mod common;

use common::server::TestServer;
use std::process::Command;
use std::sync::Arc;
use vectorfusion::worker::test_executor::TestExecutor;

fn schemathesis() -> Option<String> {
    if let Ok(p) = std::env::var("VF_SCHEMATHESIS") {
        return Some(p);
    }
    let on_path = Command::new("schemathesis")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    on_path.then(|| "schemathesis".to_string())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_server_agrees_with_its_openapi_spec() {
    let Some(st) = schemathesis() else {
        common::skip(
            "the_server_agrees_with_its_openapi_spec",
            "schemathesis is not installed",
        );
        return;
    };
    let srv = TestServer::start(Arc::new(TestExecutor::new(1)), |c| {
        c.server.max_queue_depth = 100_000;
    })
    .await;
    let spec = concat!(env!("CARGO_MANIFEST_DIR"), "/openapi.yaml");
    let url = format!("http://{}", srv.addr);
    let max_examples = std::env::var("VF_SCHEMATHESIS_EXAMPLES").unwrap_or_else(|_| "30".into());
    // One worker: with two, Hypothesis parses lambda sources on two threads at once, and
    // CPython 3.11's AST recursion counter is shared between threads ("AST constructor recursion
    // depth mismatch", a KeyError in the lambda-source cache). A run that still ends in the
    // tool's own error (🚫) and no failed check (❌) is the tool crashing, not a finding: it runs
    // once more. A failed check is never retried.
    let mut text = String::new();
    let mut ok = false;
    for _ in 0..2 {
        let (success, out) =
            run_schemathesis(st.clone(), spec, url.clone(), max_examples.clone()).await;
        text = out;
        ok = success;
        if ok || text.contains('❌') || !text.contains('🚫') {
            break;
        }
    }
    srv.stop().await;
    assert!(ok, "schemathesis found problems:\n{text}");
}

/// One schemathesis run against `url`: whether it passed, and its stdout and stderr.
async fn run_schemathesis(
    st: String,
    spec: &'static str,
    url: String,
    max_examples: String,
) -> (bool, String) {
    let out = tokio::task::spawn_blocking(move || {
        Command::new(st)
            .args([
                "run",
                spec,
                "--url",
                &url,
                "--checks",
                "all",
                "--workers",
                "1",
            ])
            .args(["--exclude-checks", "use_after_free"])
            .args(["--max-examples", &max_examples, "--seed", "1", "--no-color"])
            .args(["--generation-codec", "utf-8"])
            .args(["--phases", "examples,coverage,fuzzing,stateful"])
            .args([
                "--request-timeout",
                "20",
                "--suppress-health-check",
                "too_slow",
            ])
            .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/schemathesis"))
            .env("SCHEMATHESIS_HOOKS", "hooks")
            .output()
    })
    .await
    .unwrap()
    .expect("schemathesis runs");
    let text = format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}
