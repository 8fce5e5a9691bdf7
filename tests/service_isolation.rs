//! Jobs in child processes (issue #21, `worker::isolate`): the same results as in-process, and a
//! job past its memory or wall-clock limit fails `resource_limit` while the server and the other
//! jobs go on.

mod common;

use common::http::{get, post_json};
use common::server::TestServer;
use common::wait_status;
use serde_json::json;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use vectorfusion::pipeline::{Executor, ModelDirs};
use vectorfusion::worker::isolate::{ChildExecutor, JobLimits, ProcessExecutor};
use vectorfusion::worker::test_executor::TestExecutor;

fn exe() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_vectorfusion"))
}

fn isolated_test_executor(step_ms: u64, limits: JobLimits) -> Arc<dyn Executor> {
    Arc::new(ProcessExecutor::new(
        exe(),
        ChildExecutor::Test { step_ms },
        Arc::new(TestExecutor::new(step_ms)),
        limits,
    ))
}

async fn submit(addr: std::net::SocketAddr, body: serde_json::Value) -> String {
    let r = post_json(addr, "/jobs", &body).await;
    assert_eq!(r.status, 202, "{}", r.text());
    r.json()["id"].as_str().unwrap().to_string()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_job_in_a_child_process_gives_the_in_process_result_and_events() {
    let job =
        json!({"kind": "text", "caption": "a red square", "steps": 12, "paths": 5, "seed": 7});
    let mut svgs = Vec::new();
    for exec in [
        isolated_test_executor(1, JobLimits::default()),
        Arc::new(TestExecutor::new(1)) as Arc<dyn Executor>,
    ] {
        let srv = TestServer::start(exec, |_| {}).await;
        let id = submit(srv.addr, job.clone()).await;
        let v = wait_status(
            srv.addr,
            &id,
            &["succeeded", "failed"],
            Duration::from_secs(60),
        )
        .await;
        assert_eq!(v["status"], "succeeded", "{v}");
        // progress and snapshots crossed the process boundary
        assert_eq!(v["progress"]["step"], 12, "{v}");
        let snap = get(srv.addr, &format!("/jobs/{id}/snapshots/1.svg")).await;
        assert_eq!(snap.status, 200, "{}", snap.text());
        svgs.push(
            get(srv.addr, &format!("/jobs/{id}/result.svg"))
                .await
                .text(),
        );
        srv.stop().await;
    }
    assert_eq!(svgs[0], svgs[1]);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_job_past_its_wall_limit_fails_and_the_next_one_runs() {
    let limits = JobLimits {
        max_rss_bytes: 0,
        max_wall: Duration::from_secs(1),
    };
    let srv = TestServer::start(isolated_test_executor(300, limits), |_| {}).await;
    let slow = submit(
        srv.addr,
        json!({"kind": "text", "caption": "a cat", "steps": 100, "paths": 2}),
    )
    .await;
    let v = wait_status(
        srv.addr,
        &slow,
        &["succeeded", "failed"],
        Duration::from_secs(30),
    )
    .await;
    assert_eq!(v["status"], "failed", "{v}");
    assert_eq!(v["error"]["code"], "resource_limit", "{v}");
    let quick = submit(
        srv.addr,
        json!({"kind": "text", "caption": "a cat", "steps": 2, "paths": 2}),
    )
    .await;
    let v = wait_status(
        srv.addr,
        &quick,
        &["succeeded", "failed"],
        Duration::from_secs(30),
    )
    .await;
    assert_eq!(v["status"], "succeeded", "{v}");
    srv.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_job_past_its_memory_limit_fails_while_a_small_one_succeeds() {
    let limits = JobLimits {
        max_rss_bytes: 100 << 20,
        max_wall: Duration::ZERO,
    };
    let exec: Arc<dyn Executor> = Arc::new(ProcessExecutor::new(
        exe(),
        ChildExecutor::Pipeline {
            models: ModelDirs::default(),
        },
        Arc::new(TestExecutor::new(1)),
        limits,
    ));
    let srv = TestServer::start(exec, |c| c.queue.workers = 2).await;
    // 3000 x 3000: the job decodes it to 144 MB of f32 RGBA.
    let big = submit(
        srv.addr,
        json!({"kind": "vectorize", "image": common::png_b64(3000), "paths": 4, "steps": 20}),
    )
    .await;
    let small = submit(
        srv.addr,
        json!({"kind": "vectorize", "image": common::png_b64(32), "paths": 4, "steps": 20}),
    )
    .await;
    let v = wait_status(
        srv.addr,
        &big,
        &["succeeded", "failed"],
        Duration::from_secs(120),
    )
    .await;
    assert_eq!(v["status"], "failed", "{v}");
    assert_eq!(v["error"]["code"], "resource_limit", "{v}");
    let v = wait_status(
        srv.addr,
        &small,
        &["succeeded", "failed"],
        Duration::from_secs(120),
    )
    .await;
    assert_eq!(v["status"], "succeeded", "{v}");
    assert_eq!(get(srv.addr, "/healthz").await.status, 200);
    srv.stop().await;
}
