//! SQLite and PostgreSQL side by side in one run (issue #22; not a test):
//! 1. `POST /jobs` open-loop at 500 req/s for 4 s against an in-process server (2 workers running
//!    the service test double), one TCP connection per request: p50 / p99 / max latency;
//! 2. claims per second: 4,000 queued jobs drained by 8 concurrent workers, each on its own
//!    `Store` handle, doing claim → complete as fast as the store allows.
//!
//!     cargo bench --profile dev --bench queue_backends
//!
//! PostgreSQL: `VF_BENCH_POSTGRES_URL` (a user that may create databases), else a throwaway
//! cluster from `scripts/pg_cluster.sh` with default durability (fsync and synchronous commit
//! on). Without either, only SQLite is measured.

#[path = "../tests/common/http.rs"]
mod http;
#[path = "common/load.rs"]
mod load;

use serde_json::json;
use std::time::Instant;
use vectorfusion::config::Config;
use vectorfusion::store::{DbLocation, JobKind, NewJob, Store, create_test_database, now_ms};

const RATE: u32 = 500;
const SECONDS: f64 = 4.0;
const CLAIM_JOBS: usize = 4000;
const CLAIMERS: usize = 8;

async fn submit_latency(loc: &DbLocation) -> load::Stats {
    let mut cfg = Config::default();
    match loc {
        DbLocation::Sqlite(p) => cfg.database.path = p.clone(),
        DbLocation::Postgres(u) => cfg.database.url = u.clone(),
    }
    let server = load::BenchServer::start(cfg).await;
    let addr = server.addr;
    let n = (RATE as f64 * SECONDS) as usize;
    let s = load::run_rate(RATE, n, move |i| {
        let body = json!({"kind": "text", "caption": format!("a red bicycle {i}"),
                          "paths": 4, "steps": 2, "seed": i});
        async move { http::post_json(addr, "/jobs", &body).await.status == 202 }
    })
    .await;
    server.stop().await;
    s
}

fn job(i: usize) -> NewJob {
    NewJob::new(
        uuid::Uuid::new_v4().to_string(),
        JobKind::Vectorize,
        format!("{{\"i\":{i}}}"),
    )
}

/// Claims per second with `CLAIMERS` concurrent claim → complete loops.
async fn claim_rate(loc: &DbLocation) -> (f64, usize) {
    let store = Store::connect(loc, 4).await.expect("open");
    for i in 0..CLAIM_JOBS {
        store.insert_job(&job(i), 1).await.expect("insert");
    }
    let t0 = Instant::now();
    let mut tasks = Vec::new();
    for w in 0..CLAIMERS {
        let s = Store::connect(loc, 1).await.expect("open");
        tasks.push(tokio::spawn(async move {
            let me = format!("bench-w{w}");
            let mut n = 0usize;
            while let Ok(Some((_, lease))) = s.claim(&me, now_ms(), 60_000).await {
                if s.complete(&lease, "<svg/>", 1, "{}", now_ms())
                    .await
                    .unwrap_or(false)
                {
                    n += 1;
                }
            }
            n
        }));
    }
    let mut done = 0;
    for t in tasks {
        done += t.await.unwrap_or(0);
    }
    (done as f64 / t0.elapsed().as_secs_f64(), done)
}

fn pg_admin_url(dir: &std::path::Path) -> Option<String> {
    if let Ok(u) = std::env::var("VF_BENCH_POSTGRES_URL") {
        return Some(u);
    }
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .ok()?
        .local_addr()
        .ok()?
        .port();
    let out = std::process::Command::new("scripts/pg_cluster.sh")
        .args(["start", dir.to_str()?, &port.to_string()])
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

fn main() {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    let dir = tempfile::tempdir().expect("tempdir");
    let pg_dir = dir.path().join("pg");
    let started_cluster = std::env::var("VF_BENCH_POSTGRES_URL").is_err();
    rt.block_on(async {
        let mut backends = vec![
            ("SQLite", DbLocation::Sqlite(dir.path().join("a.db"))),
            ("SQLite", DbLocation::Sqlite(dir.path().join("b.db"))),
        ];
        match pg_admin_url(&pg_dir) {
            Some(admin) => {
                for _ in 0..2 {
                    let url = create_test_database(&admin).await.expect("create database");
                    backends.push(("PostgreSQL", DbLocation::Postgres(url)));
                }
            }
            None => eprintln!("no PostgreSQL (VF_BENCH_POSTGRES_URL or scripts/pg_cluster.sh): SQLite only"),
        }
        println!("| backend | POST /jobs at {RATE} req/s: 2xx | achieved req/s | p50 ms | p99 ms | max ms | claims/s ({CLAIMERS} workers, claim+complete) |");
        println!("|---|---|---|---|---|---|---|");
        // One database for the submit run, a fresh one for the claim run, per backend.
        for pair in backends.chunks(2) {
            let (name, submit_db) = &pair[0];
            let s = submit_latency(submit_db).await;
            let (rate, done) = claim_rate(&pair[1].1).await;
            println!(
                "| {name} | {}/{} | {:.0} | {:.2} | {:.2} | {:.2} | {rate:.0} ({done} jobs) |",
                s.ok,
                s.sent,
                s.sent as f64 / s.wall,
                s.pct(0.5),
                s.pct(0.99),
                s.lat_ms.last().copied().unwrap_or(f64::NAN),
            );
        }
    });
    if started_cluster {
        let _ = std::process::Command::new("scripts/pg_cluster.sh")
            .args(["stop", pg_dir.to_str().unwrap_or_default()])
            .status();
    }
}
