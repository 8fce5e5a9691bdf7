//! Load bench for the HTTP service (not a test): an in-process server on 127.0.0.1 with a real
//! SQLite file in a temp dir; open-loop `POST /jobs` and then `GET /jobs/{id}` at increasing
//! request rates, one TCP connection per request. Reports p50/p99/max latency and achieved
//! throughput per rate, and how many of the submitted jobs the workers finished.
//!
//! Bounded: each rate runs for at most `SECONDS` seconds and `MAX_REQUESTS` requests.
//!
//!     cargo bench --profile dev --bench service_load
//!
//! Jobs run through the service test double (tiny text jobs: 4 paths, 2 steps, no sleeping),
//! so the numbers measure the service (HTTP, validation, SQLite queue), not the pipeline.

#[path = "../tests/common/http.rs"]
mod http;
#[path = "common/load.rs"]
mod load;

use load::{Stats, run_rate};
use serde_json::json;
use std::sync::Arc;
use std::time::{Duration, Instant};
use vectorfusion::config::Config;

const RATES: [u32; 4] = [100, 250, 500, 1000];
const SECONDS: f64 = 4.0;
const MAX_REQUESTS: usize = 4000;

fn captions() -> Vec<String> {
    std::fs::read_to_string("../shared/bench/svg_bench_prompts.txt")
        .map(|t| {
            t.lines()
                .map(str::to_string)
                .filter(|l| !l.is_empty())
                .collect::<Vec<_>>()
        })
        .unwrap_or_default()
        .into_iter()
        .chain(["自転車".to_string()])
        .collect()
}

fn report(what: &str, rate: u32, s: &Stats) {
    println!(
        "| {what} | {rate} | {} | {} | {:.0} | {:.2} | {:.2} | {:.2} |",
        s.sent,
        s.ok,
        s.sent as f64 / s.wall,
        s.pct(0.5),
        s.pct(0.99),
        s.lat_ms.last().copied().unwrap_or(f64::NAN),
    );
}

fn main() {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    rt.block_on(async {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut cfg = Config::default();
        cfg.database.path = dir.path().join("load.db");
        let server = load::BenchServer::start(cfg).await;
        let addr = server.addr;
        let caps = Arc::new(captions());
        let ids = Arc::new(std::sync::Mutex::new(Vec::<String>::new()));
        println!("| request | target rate (req/s) | sent | 2xx | achieved (req/s) | p50 ms | p99 ms | max ms |");
        println!("|---|---|---|---|---|---|---|---|");
        let started = Instant::now();
        for rate in RATES {
            let n = ((rate as f64 * SECONDS) as usize).min(MAX_REQUESTS);
            let (caps2, ids2) = (caps.clone(), ids.clone());
            let s = run_rate(rate, n, move |i| {
                let body = json!({
                    "kind": "text",
                    "caption": caps2[i % caps2.len()],
                    "paths": 4, "steps": 2, "seed": i,
                });
                let ids3 = ids2.clone();
                async move {
                    let r = http::post_json(addr, "/jobs", &body).await;
                    if r.status == 202
                        && let Some(id) = r.json()["id"].as_str()
                        && let Ok(mut v) = ids3.lock()
                    {
                        v.push(id.to_string());
                    }
                    r.status == 202
                }
            })
            .await;
            report("POST /jobs", rate, &s);
            let all: Arc<Vec<String>> = Arc::new(ids.lock().map(|v| v.clone()).unwrap_or_default());
            let s = run_rate(rate, n, move |i| {
                let path = format!("/jobs/{}", all[i % all.len().max(1)]);
                async move { http::get(addr, &path).await.status == 200 }
            })
            .await;
            report("GET /jobs/{id}", rate, &s);
        }
        let submitted = ids.lock().map(|v| v.len()).unwrap_or(0);
        // let the workers drain, bounded
        let deadline = Instant::now() + Duration::from_secs(60);
        let mut done = 0;
        while Instant::now() < deadline {
            let m = http::get(addr, "/metrics").await.text();
            done = m
                .lines()
                .find_map(|l| l.strip_prefix("vectorfusion_jobs{status=\"succeeded\"} "))
                .and_then(|v| v.parse::<usize>().ok())
                .unwrap_or(0);
            if done >= submitted {
                break;
            }
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
        let secs = started.elapsed().as_secs_f64();
        println!(
            "\njobs submitted: {submitted}, succeeded: {done}, wall {secs:.1} s ({:.0} jobs/s end to end with 2 workers)",
            done as f64 / secs
        );
        // server-side view: share of requests handled within each bucket bound
        let m = http::get(addr, "/metrics").await.text();
        println!("\nserver-side handling time (vectorfusion_http_request_duration_seconds), all rates together:");
        for route in ["POST /jobs", "GET /jobs/{id}"] {
            let prefix = format!("vectorfusion_http_request_duration_seconds_bucket{{route=\"{route}\",le=\"");
            let buckets: Vec<(String, f64)> = m
                .lines()
                .filter_map(|l| l.strip_prefix(prefix.as_str()))
                .filter_map(|rest| {
                    let (le, n) = rest.split_once("\"} ")?;
                    Some((le.to_string(), n.parse::<f64>().ok()?))
                })
                .collect();
            let total = buckets.last().map_or(0.0, |b| b.1).max(1.0);
            let shares: Vec<String> = buckets
                .iter()
                .map(|(le, n)| format!("<={le}s: {:.2}%", 100.0 * n / total))
                .collect();
            println!("{route}: {}", shares.join(", "));
        }
        server.stop().await;
    });
}
