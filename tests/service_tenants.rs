//! Tenants (issue #21): each API key sees, streams, downloads and cancels only its own jobs;
//! idempotency keys are per key; `/metrics` is the operator's; quotas cap a key's active jobs.

mod common;

use common::http::request;
use common::server::TestServer;
use serde_json::{Value, json};
use std::sync::Arc;
use std::time::Duration;
use vectorfusion::config::TenantConfig;
use vectorfusion::worker::test_executor::TestExecutor;

const OPERATOR: &str = "operator-key-0123456789";
const A: &str = "tenant-a-key-0123456789";
const B: &str = "tenant-b-key-0123456789";

fn tenant(name: &str, key: &str, max_active_jobs: u32) -> TenantConfig {
    TenantConfig {
        name: name.into(),
        key: key.into(),
        max_active_jobs,
        max_upload_bytes: 0,
    }
}

async fn call(
    addr: std::net::SocketAddr,
    method: &str,
    path: &str,
    key: &str,
    extra: &[(&str, &str)],
    body: Option<&Value>,
) -> common::http::Resp {
    let auth = format!("Bearer {key}");
    let mut headers = vec![("Authorization", auth.as_str())];
    headers.extend_from_slice(extra);
    let bytes = body.map(|b| b.to_string().into_bytes());
    if bytes.is_some() {
        headers.push(("Content-Type", "application/json"));
    }
    request(addr, method, path, &headers, bytes.as_deref()).await
}

fn job(seed: u64) -> Value {
    json!({"kind": "vectorize", "image": common::png_b64(8), "paths": 2, "steps": 2, "seed": seed})
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn each_key_sees_only_its_own_jobs() {
    let srv = TestServer::start(Arc::new(TestExecutor::new(1)), |c| {
        c.server.api_key = OPERATOR.into();
        c.server.tenants = vec![tenant("a", A, 0), tenant("b", B, 0)];
    })
    .await;
    let addr = srv.addr;
    let r = call(
        addr,
        "POST",
        "/jobs",
        A,
        &[("Idempotency-Key", "k1")],
        Some(&job(1)),
    )
    .await;
    assert_eq!(r.status, 202, "{}", r.text());
    let a_id = r.json()["id"].as_str().unwrap().to_string();
    // The same idempotency key from another tenant makes another job.
    let r = call(
        addr,
        "POST",
        "/jobs",
        B,
        &[("Idempotency-Key", "k1")],
        Some(&job(2)),
    )
    .await;
    assert_eq!(r.status, 202, "{}", r.text());
    let b_id = r.json()["id"].as_str().unwrap().to_string();
    assert_ne!(a_id, b_id);
    // ...and the same key from the same tenant replays its job.
    let r = call(
        addr,
        "POST",
        "/jobs",
        A,
        &[("Idempotency-Key", "k1")],
        Some(&job(1)),
    )
    .await;
    assert_eq!(r.json()["id"], a_id.as_str());
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    while call(addr, "GET", &format!("/jobs/{a_id}"), A, &[], None)
        .await
        .json()["status"]
        != "succeeded"
    {
        assert!(
            std::time::Instant::now() < deadline,
            "job {a_id} did not finish"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }

    for path in [
        format!("/jobs/{a_id}"),
        format!("/jobs/{a_id}/result.svg"),
        format!("/jobs/{a_id}/result.png"),
        format!("/jobs/{a_id}/events"),
        format!("/jobs/{a_id}/snapshots/1.svg"),
    ] {
        let r = call(addr, "GET", &path, B, &[], None).await;
        assert_eq!(r.status, 404, "B reads {path}: {}", r.text());
        let r = call(addr, "GET", &path, A, &[], None).await;
        assert_ne!(r.status, 404, "A reads {path}: {}", r.text());
    }
    let r = call(addr, "DELETE", &format!("/jobs/{a_id}"), B, &[], None).await;
    assert_eq!(r.status, 404);
    let ids = |r: common::http::Resp| -> Vec<String> {
        r.json()["jobs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|j| j["id"].as_str().unwrap().to_string())
            .collect()
    };
    let list = call(addr, "GET", "/jobs", A, &[], None).await;
    // The listing leaves the upload in the database but still says there was one.
    assert_eq!(
        list.json()["jobs"][0]["params"]["has_image"],
        true,
        "{}",
        list.text()
    );
    assert_eq!(ids(list), vec![a_id.clone()]);
    assert_eq!(
        ids(call(addr, "GET", "/jobs", B, &[], None).await),
        vec![b_id.clone()]
    );
    let all = ids(call(addr, "GET", "/jobs", OPERATOR, &[], None).await);
    assert!(all.contains(&a_id) && all.contains(&b_id), "{all:?}");
    // /metrics is the operator's; a wrong key is 401 everywhere but health and the page.
    assert_eq!(
        call(addr, "GET", "/metrics", A, &[], None).await.status,
        401
    );
    assert_eq!(
        call(addr, "GET", "/metrics", OPERATOR, &[], None)
            .await
            .status,
        200
    );
    assert_eq!(
        call(addr, "GET", "/jobs", "wrong-key-0123456789", &[], None)
            .await
            .status,
        401
    );
    assert_eq!(
        request(addr, "GET", "/healthz", &[], None).await.status,
        200
    );
    let page = request(addr, "GET", "/", &[], None).await;
    assert_eq!(page.status, 200);
    assert!(
        page.header("content-security-policy")
            .is_some_and(|c| c.contains("script-src 'self'"))
    );
    srv.stop().await;
}

/// Holds each job for a second, so a quota sees it active.
struct SlowExecutor;

impl vectorfusion::pipeline::Executor for SlowExecutor {
    fn run(
        &self,
        _spec: &vectorfusion::pipeline::JobSpec,
        _ctx: &vectorfusion::pipeline::JobContext,
    ) -> Result<vectorfusion::pipeline::RunOutput, vectorfusion::pipeline::PipelineError> {
        std::thread::sleep(Duration::from_secs(1));
        Ok(common::runs::blank_output())
    }
    fn text_ready(&self) -> Result<(), vectorfusion::pipeline::NotReady> {
        Ok(())
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_quota_caps_a_keys_active_jobs() {
    let srv = TestServer::start(Arc::new(SlowExecutor), |c| {
        c.queue.workers = 1;
        c.server.tenants = vec![tenant("a", A, 2), tenant("b", B, 0)];
    })
    .await;
    let addr = srv.addr;
    for seed in 0..2 {
        let r = call(addr, "POST", "/jobs", A, &[], Some(&job(seed))).await;
        assert_eq!(r.status, 202, "{}", r.text());
    }
    let r = call(addr, "POST", "/jobs", A, &[], Some(&job(3))).await;
    assert_eq!(r.status, 429, "{}", r.text());
    assert_eq!(r.json()["error"]["code"], "quota_exceeded");
    assert!(r.header("retry-after").is_some());
    // Another key is not held back by a's quota.
    assert_eq!(
        call(addr, "POST", "/jobs", B, &[], Some(&job(4)))
            .await
            .status,
        202
    );
    // Without an operator key, /metrics is closed to tenants.
    assert_eq!(
        call(addr, "GET", "/metrics", A, &[], None).await.status,
        401
    );
    srv.stop().await;
}
