//! Open-loop load helpers shared by the service benches.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};
use vectorfusion::config::Config;
use vectorfusion::worker::test_executor::TestExecutor;

/// An in-process server on 127.0.0.1 over `cfg`'s database with 2 workers running the service
/// test double (no sleeping): the benches measure the service, not the pipeline.
pub struct BenchServer {
    pub addr: SocketAddr,
    stop: tokio::sync::oneshot::Sender<()>,
    task: tokio::task::JoinHandle<Result<(), vectorfusion::server::ServerError>>,
}

impl BenchServer {
    pub async fn start(mut cfg: Config) -> BenchServer {
        cfg.server.max_queue_depth = 1_000_000;
        cfg.queue.workers = 2;
        cfg.queue.poll_interval_ms = 20;
        let listener = vectorfusion::server::listen::bind("127.0.0.1:0")
            .await
            .expect("bind");
        let addr: SocketAddr = listener.local_addr().expect("addr");
        let (stop, rx) = tokio::sync::oneshot::channel::<()>();
        let task = tokio::spawn(vectorfusion::server::run(
            cfg,
            Arc::new(TestExecutor::new(0)),
            listener,
            async move {
                let _ = rx.await;
            },
        ));
        // The socket accepts connections before the server has opened its database (migrations,
        // pools): wait until it answers, so the measured requests do not queue behind start-up.
        while crate::http::get(addr, "/readyz").await.status != 200 {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        BenchServer { addr, stop, task }
    }

    pub async fn stop(self) {
        let _ = self.stop.send(());
        let _ = self.task.await;
    }
}

pub struct Stats {
    pub sent: usize,
    pub ok: usize,
    /// Sorted ascending.
    pub lat_ms: Vec<f64>,
    pub wall: f64,
}

impl Stats {
    pub fn pct(&self, p: f64) -> f64 {
        pct(&self.lat_ms, p)
    }
}

pub fn pct(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    sorted[i]
}

/// Fires `n` requests at `rate` per second (open loop: sends do not wait for answers).
pub async fn run_rate<F, Fut>(rate: u32, n: usize, make: F) -> Stats
where
    F: Fn(usize) -> Fut,
    Fut: std::future::Future<Output = bool> + Send + 'static,
{
    let interval = Duration::from_secs_f64(1.0 / rate as f64);
    let t0 = Instant::now();
    let mut tasks = Vec::with_capacity(n);
    for i in 0..n {
        let due = t0 + interval * i as u32;
        tokio::time::sleep_until(due.into()).await;
        let fut = make(i);
        tasks.push(tokio::spawn(async move {
            let s = Instant::now();
            let ok = fut.await;
            (ok, s.elapsed().as_secs_f64() * 1000.0)
        }));
    }
    let mut lat = Vec::with_capacity(n);
    let mut ok = 0;
    for t in tasks {
        if let Ok((good, ms)) = t.await {
            ok += good as usize;
            lat.push(ms);
        }
    }
    lat.sort_by(|a, b| a.total_cmp(b));
    Stats {
        sent: n,
        ok,
        lat_ms: lat,
        wall: t0.elapsed().as_secs_f64(),
    }
}
