//! Multi-node fault test on one PostgreSQL (issue #22): 2 API processes (`serve --workers 0`) and
//! 3 worker processes (`worker`) on loopback, 300 small vectorize jobs (service test double),
//! 20 `kill -9`s of random workers (each replaced), one `kill -9` of an API node (restarted) and
//! one immediate PostgreSQL restart mid-run. Every accepted job must end succeeded exactly once
//! (the attempts history proves it) with the drawing an uninterrupted run makes, and an SSE
//! client on an API node must see every stored snapshot and the end of jobs run elsewhere.
//!
//! It starts its own cluster with `scripts/pg_cluster.sh` (Debian's PostgreSQL server); without
//! the server binaries it prints SKIP (and
//! fails where `.ci/run` sets `VF_REQUIRE_ALL`). `VF_MULTINODE_JOBS` and `VF_MULTINODE_KILLS` scale it.

mod common;

use common::http::{SseEvent, get, post_json, sse};
use common::node::spawn_listening;
use common::png_b64;
use serde_json::json;
use std::collections::BTreeSet;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::{Duration, Instant};
use vectorfusion::store::{DbLocation, JobStatus, Store};
use vectorfusion::worker::test_executor::{scene_at, scene_svg};

const STEPS: u32 = 24;

fn script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/pg_cluster.sh")
}

/// The cluster and every node process; stops them all when dropped (also on a failed assert).
struct Fleet {
    dir: tempfile::TempDir,
    url: String,
    apis: Vec<(Child, SocketAddr)>,
    workers: Vec<Child>,
}

impl Drop for Fleet {
    fn drop(&mut self) {
        for (c, _) in &mut self.apis {
            let _ = c.kill();
            let _ = c.wait();
        }
        for c in &mut self.workers {
            let _ = c.kill();
            let _ = c.wait();
        }
        let _ = Command::new(script())
            .arg("stop")
            .arg(self.dir.path())
            .status();
    }
}

/// A `serve` or `worker` node on a port it picks (`common::node`), jobs through the test double.
fn node(url: &str, args: &[&str]) -> (Child, SocketAddr) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_vectorfusion"));
    cmd.args(args)
        .args(["--db", url, "--test-executor", "15"])
        .env("VECTORFUSION_QUEUE_LEASE_SECS", "2")
        .env("VECTORFUSION_QUEUE_HEARTBEAT_SECS", "1")
        .env("VECTORFUSION_QUEUE_CHECKPOINT_EVERY_STEPS", "4")
        .env("VECTORFUSION_QUEUE_POLL_INTERVAL_MS", "200")
        .env("VECTORFUSION_QUEUE_MAX_ATTEMPTS", "40")
        .env("VECTORFUSION_QUEUE_MAX_LOST_ATTEMPTS", "40")
        .env("VECTORFUSION_QUEUE_ISOLATION", "thread")
        .env("VECTORFUSION_SERVER_PROGRESS_INTERVAL_MS", "0")
        .env("VECTORFUSION_SERVER_SNAPSHOT_INTERVAL_MS", "0")
        .env("VECTORFUSION_SERVER_MAX_QUEUE_DEPTH", "10000")
        .env("VECTORFUSION_DATABASE_MAX_CONNECTIONS", "6");
    spawn_listening(cmd, "error", false)
}

fn api(url: &str) -> (Child, SocketAddr) {
    node(url, &["serve", "--workers", "0"])
}

fn worker(url: &str) -> Child {
    node(url, &["worker", "--workers", "2"]).0
}

async fn wait_healthy(addr: SocketAddr) {
    let deadline = Instant::now() + Duration::from_secs(30);
    while !(tokio::net::TcpStream::connect(addr).await.is_ok()
        && get(addr, "/healthz").await.status == 200)
    {
        assert!(Instant::now() < deadline, "node did not come up on {addr}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// A tiny deterministic generator for the chaos schedule.
struct Lcg(u64);
impl Lcg {
    fn next(&mut self, n: u64) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 33) % n
    }
}

/// Follows one job's event stream on `addr` until its terminal event, reconnecting with
/// `Last-Event-ID` when the stream ends early (as EventSource does). Returns the snapshot
/// numbers seen and the terminal event's name.
async fn follow(addr: SocketAddr, id: String) -> (BTreeSet<i64>, String) {
    let mut seen = BTreeSet::new();
    let deadline = Instant::now() + Duration::from_secs(240);
    loop {
        let last = seen.last().map(|n: &i64| n.to_string());
        let headers: Vec<(&str, &str)> = match &last {
            Some(n) => vec![("Last-Event-ID", n.as_str())],
            None => Vec::new(),
        };
        let (_, events) = sse(
            addr,
            &format!("/jobs/{id}/events"),
            &headers,
            Duration::from_secs(60),
            |e: &SseEvent| matches!(e.event.as_str(), "done" | "failed" | "cancelled"),
        )
        .await;
        for e in &events {
            if e.event == "snapshot" {
                seen.insert(e.json()["n"].as_i64().unwrap());
            }
            if matches!(e.event.as_str(), "done" | "failed" | "cancelled") {
                return (seen, e.event.clone());
            }
        }
        assert!(Instant::now() < deadline, "no end event for {id}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn api_and_worker_nodes_survive_kills_and_a_database_restart() {
    let jobs: usize = std::env::var("VF_MULTINODE_JOBS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(300);
    let kills: usize = std::env::var("VF_MULTINODE_KILLS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(20);
    let dir = tempfile::tempdir().unwrap();
    // Port 0: the script finds one that binds and names it in the URL it prints.
    let out = Command::new(script())
        .args(["start", dir.path().to_str().unwrap(), "0"])
        .env("PG_FAST", "1")
        .output()
        .expect("run scripts/pg_cluster.sh");
    if out.status.code() == Some(3) {
        common::skip(
            "multinode PostgreSQL",
            "no PostgreSQL server binaries (apt-get install postgresql)",
        );
        return;
    }
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let admin = String::from_utf8_lossy(&out.stdout).trim().to_string();
    let mut fleet = Fleet {
        dir,
        url: String::new(),
        apis: Vec::new(),
        workers: Vec::new(),
    };
    fleet.url = vectorfusion::store::create_test_database(&admin)
        .await
        .unwrap();
    let url = fleet.url.clone();
    // Migrate once before the nodes race to do it.
    let store = Store::connect(&DbLocation::Postgres(url.clone()), 4)
        .await
        .unwrap();
    for _ in 0..2 {
        fleet.apis.push(api(&url));
    }
    for _ in 0..3 {
        fleet.workers.push(worker(&url));
    }
    for (_, a) in &fleet.apis {
        wait_healthy(*a).await;
    }

    let mut ids = Vec::new();
    for i in 0..jobs {
        let addr = fleet.apis[i % 2].1;
        let r = post_json(
            addr,
            "/jobs",
            &json!({"kind": "vectorize", "image": png_b64(8), "paths": 3, "steps": STEPS, "seed": i}),
        )
        .await;
        assert_eq!(r.status, 202, "{}", r.text());
        ids.push(r.json()["id"].as_str().unwrap().to_string());
    }
    // Watch two jobs from API node 1 (node 0 is the one killed); no worker runs there.
    let watched = [ids[jobs / 2].clone(), ids[jobs - 1].clone()];
    let api1 = fleet.apis[1].1;
    let watchers: Vec<_> = watched
        .iter()
        .map(|id| tokio::spawn(follow(api1, id.clone())))
        .collect();

    let mut rng = Lcg(0x5eed);
    for k in 0..kills {
        tokio::time::sleep(Duration::from_millis(300 + rng.next(700))).await;
        let w = rng.next(fleet.workers.len() as u64) as usize;
        fleet.workers[w].kill().unwrap(); // SIGKILL
        fleet.workers[w].wait().unwrap();
        fleet.workers[w] = worker(&url);
        if k == kills / 3 {
            fleet.apis[0].0.kill().unwrap();
            fleet.apis[0].0.wait().unwrap();
            fleet.apis[0] = api(&url);
            wait_healthy(fleet.apis[0].1).await;
        }
        if k == 2 * kills / 3 {
            let ok = Command::new(script())
                .args(["restart", fleet.dir.path().to_str().unwrap()])
                .status()
                .unwrap();
            assert!(ok.success(), "PostgreSQL restart");
        }
    }

    // Everything ends: poll the shared database (any node would answer the same).
    let deadline = Instant::now() + Duration::from_secs(300);
    loop {
        // An error (the pool reconnecting after the restart) counts as nothing yet.
        let counts = store.count_by_status().await.unwrap_or_default();
        let done: i64 = counts
            .iter()
            .filter(|(s, _)| s == "succeeded")
            .map(|(_, n)| n)
            .sum();
        let bad: i64 = counts
            .iter()
            .filter(|(s, _)| s == "failed" || s == "cancelled")
            .map(|(_, n)| n)
            .sum();
        assert_eq!(bad, 0, "no job may fail: {counts:?}");
        if done == jobs as i64 {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "jobs left unfinished: {counts:?}"
        );
        tokio::time::sleep(Duration::from_millis(250)).await;
    }

    let mut lost = 0;
    for (seed, id) in ids.iter().enumerate() {
        let row = store.get_job(id).await.unwrap().unwrap();
        assert_eq!(row.status, JobStatus::Succeeded);
        let attempts = store.attempts(id).await.unwrap();
        let wins = attempts.iter().filter(|a| a.outcome == "succeeded").count();
        assert_eq!(wins, 1, "job {id} succeeded exactly once: {attempts:?}");
        assert!(
            attempts.iter().all(|a| a.outcome != "running"),
            "{attempts:?}"
        );
        lost += attempts.iter().filter(|a| a.outcome == "lost").count();
        let result = store.result(id).await.unwrap().expect("result stored");
        let expected = scene_svg(&scene_at(seed as u64, 3, STEPS, STEPS).unwrap());
        assert_eq!(
            result.svg, expected,
            "job {id} drew what an uninterrupted run draws"
        );
    }
    let total: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM results")
        .fetch_one(store.pool())
        .await
        .unwrap();
    assert_eq!(total, jobs as i64, "nothing lost, nothing duplicated");
    assert!(
        lost >= 1,
        "the kills hit running jobs ({lost} lost attempts)"
    );

    for (id, w) in watched.iter().zip(watchers) {
        let (seen, end) = w.await.unwrap();
        assert_eq!(end, "done", "job {id}");
        let stored: BTreeSet<i64> = store
            .snapshots_after(id, 0, 10_000)
            .await
            .unwrap()
            .iter()
            .map(|s| s.n)
            .collect();
        assert!(!stored.is_empty());
        assert!(
            stored.is_subset(&seen),
            "job {id}: the stream on another node missed snapshots {:?}",
            stored.difference(&seen).collect::<Vec<_>>()
        );
    }
    store.close().await;
}
