//! Crash safety with the real server binary: `kill -9` mid-job and restart (every job completes
//! exactly once, nothing is lost, interrupted jobs resume from their checkpoints), and SIGTERM
//! (running jobs checkpoint and go back to the queue). Jobs run through the service test double
//! (hidden `--test-executor STEP_MS` flag).

mod common;

use common::http::{get, post_json};
use common::node::spawn_listening;
use common::png_b64;
use serde_json::{Value, json};
use std::net::SocketAddr;
use std::path::Path;
use std::process::{Child, Command};
use std::time::{Duration, Instant};

/// The server binary on a port it picks (`common::node`), jobs through the test double.
fn spawn_server(db: &Path) -> (Child, SocketAddr) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_vectorfusion"));
    cmd.arg("serve")
        .args(["--db", db.to_str().unwrap()])
        .args(["--workers", "2", "--test-executor", "25"])
        .env("VECTORFUSION_QUEUE_LEASE_SECS", "2")
        .env("VECTORFUSION_QUEUE_HEARTBEAT_SECS", "1")
        .env("VECTORFUSION_QUEUE_CHECKPOINT_EVERY_STEPS", "5")
        .env("VECTORFUSION_QUEUE_POLL_INTERVAL_MS", "50")
        .env("VECTORFUSION_SERVER_PROGRESS_INTERVAL_MS", "0");
    spawn_listening(cmd, "warn", true)
}

async fn wait_healthy(addr: SocketAddr) {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        // A server still starting can accept a connection and reset it: a probe that fails so
        // (its task panics in `get`) counts as not up yet, until the deadline.
        if tokio::net::TcpStream::connect(addr).await.is_ok()
            && tokio::spawn(get(addr, "/healthz"))
                .await
                .is_ok_and(|r| r.status == 200)
        {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "server did not come up on {addr}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

async fn job(addr: SocketAddr, id: &str) -> Value {
    get(addr, &format!("/jobs/{id}")).await.json()
}

async fn submit(addr: SocketAddr, steps: u32, seed: u64) -> String {
    let r = post_json(
        addr,
        "/jobs",
        &json!({"kind": "vectorize", "image": png_b64(8), "paths": 3, "steps": steps, "seed": seed}),
    )
    .await;
    assert_eq!(r.status, 202, "{}", r.text());
    r.json()["id"].as_str().unwrap().to_string()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn kill_9_mid_job_then_restart_completes_every_job_exactly_once() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("crash.db");
    let (mut child, addr) = spawn_server(&db);
    wait_healthy(addr).await;
    let mut ids = Vec::new();
    for seed in 0..6 {
        ids.push(submit(addr, 60, seed).await);
    }
    // wait until two jobs are mid-way, past a checkpoint
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let mut mid = 0;
        for id in &ids {
            let v = job(addr, id).await;
            if v["status"] == "running" && v["progress"]["step"].as_i64().unwrap_or(0) >= 12 {
                mid += 1;
            }
        }
        if mid >= 2 {
            break;
        }
        assert!(Instant::now() < deadline, "jobs never got going");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();

    let (mut child, addr2) = spawn_server(&db);
    wait_healthy(addr2).await;
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let mut done = 0;
        for id in &ids {
            let v = job(addr2, id).await;
            assert_ne!(v["status"], "failed", "{v}");
            assert_ne!(v["status"], "cancelled", "{v}");
            if v["status"] == "succeeded" {
                done += 1;
            }
        }
        if done == ids.len() {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "jobs did not all finish after restart"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    child.kill().unwrap();
    child.wait().unwrap();

    let store = vectorfusion::store::Store::open(&db, 1).await.unwrap();
    let mut resumed = 0;
    let mut reclaimed = 0;
    for (seed, id) in ids.iter().enumerate() {
        let attempts = store.attempts(id).await.unwrap();
        let wins = attempts.iter().filter(|a| a.outcome == "succeeded").count();
        assert_eq!(wins, 1, "job {id} succeeded exactly once: {attempts:?}");
        assert!(
            attempts.iter().all(|a| a.outcome != "running"),
            "{attempts:?}"
        );
        if attempts.len() > 1 {
            reclaimed += 1;
            assert_eq!(attempts[0].outcome, "lost", "{attempts:?}");
        }
        let result = store.result(id).await.unwrap().expect("result stored");
        let detail: Value = serde_json::from_str(&result.detail).unwrap();
        if detail["resumed_from"].as_u64().unwrap() > 0 {
            resumed += 1;
        }
        // same drawing as an uninterrupted run
        let expected = vectorfusion::worker::test_executor::scene_svg(
            &vectorfusion::worker::test_executor::scene_at(seed as u64, 3, 60, 60).unwrap(),
        );
        assert_eq!(result.svg, expected);
    }
    assert!(
        reclaimed >= 2,
        "the jobs killed mid-way were reclaimed ({reclaimed})"
    );
    assert!(
        resumed >= 2,
        "reclaimed jobs resumed from checkpoints ({resumed})"
    );
    let total: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM results")
        .fetch_one(store.pool())
        .await
        .unwrap();
    assert_eq!(total, ids.len() as i64, "nothing lost, nothing duplicated");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_checkpoints_and_requeues_then_restart_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("term.db");
    // --config with a file: the settings come from it (here the database path is in the file)
    let cfg = dir.path().join("config.toml");
    std::fs::write(
        &cfg,
        format!(
            "[database]\npath = {:?}\n[queue]\nworkers = 1\n",
            db.to_str().unwrap()
        ),
    )
    .unwrap();
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_vectorfusion"));
    cmd.args(["serve", "--config", cfg.to_str().unwrap()])
        .args(["--test-executor", "25"])
        .env("VECTORFUSION_QUEUE_CHECKPOINT_EVERY_STEPS", "5");
    let (mut child, addr) = spawn_listening(cmd, "warn", true);
    wait_healthy(addr).await;
    let id = submit(addr, 400, 11).await;
    loop {
        let v = job(addr, &id).await;
        if v["progress"]["step"].as_i64().unwrap_or(0) >= 12 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let ok = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(ok.success());
    let t0 = Instant::now();
    let status = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break st;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(15),
            "server ignored SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(status.success(), "clean exit on SIGTERM: {status:?}");

    {
        let store = vectorfusion::store::Store::open(&db, 1).await.unwrap();
        let row = store.get_job(&id).await.unwrap().unwrap();
        assert_eq!(row.status, vectorfusion::store::JobStatus::Queued);
        assert!(row.checkpoint.is_some());
        assert_eq!(store.attempts(&id).await.unwrap()[0].outcome, "interrupted");
        store.close().await;
    }

    let (mut child, addr2) = spawn_server(&db);
    wait_healthy(addr2).await;
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let v = job(addr2, &id).await;
        if v["status"] == "succeeded" {
            break;
        }
        assert!(Instant::now() < deadline, "{v}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let store = vectorfusion::store::Store::open(&db, 1).await.unwrap();
    let detail: Value =
        serde_json::from_str(&store.result(&id).await.unwrap().unwrap().detail).unwrap();
    // the job checkpointed when SIGTERM stopped it (it had passed step 12)
    assert!(detail["resumed_from"].as_u64().unwrap() >= 12, "{detail}");
}
