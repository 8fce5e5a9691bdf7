//! A real server on 127.0.0.1 (ephemeral port) with a SQLite file in a temp dir, for the service
//! tests.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use vectorfusion::config::Config;
use vectorfusion::pipeline::Executor;

pub struct TestServer {
    pub addr: SocketAddr,
    _dir: tempfile::TempDir,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<Result<(), vectorfusion::server::ServerError>>,
}

impl TestServer {
    pub async fn start(exec: Arc<dyn Executor>, tweak: impl FnOnce(&mut Config)) -> TestServer {
        let dir = tempfile::tempdir().unwrap();
        let mut cfg = Config::default();
        cfg.database.path = dir.path().join("jobs.db");
        cfg.queue.workers = 2;
        cfg.queue.poll_interval_ms = 20;
        cfg.queue.heartbeat_secs = 1;
        cfg.queue.lease_secs = 5;
        cfg.queue.retry_backoff_ms = 50;
        cfg.server.progress_interval_ms = 0;
        cfg.server.snapshot_interval_ms = 0;
        cfg.server.shutdown_grace_secs = 5;
        tweak(&mut cfg);
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        let task = tokio::spawn(vectorfusion::server::run(cfg, exec, listener, async move {
            let _ = rx.await;
        }));
        TestServer {
            addr,
            _dir: dir,
            stop: Some(tx),
            task,
        }
    }

    /// A server with one worker running the diffusers model in `sd_dir` (no scorer).
    pub async fn with_model(sd_dir: std::path::PathBuf) -> TestServer {
        let exec =
            vectorfusion::pipeline::DefaultExecutor::new(vectorfusion::pipeline::ModelDirs {
                sd_dir: Some(sd_dir),
                ..Default::default()
            });
        TestServer::start(Arc::new(exec), |c| c.queue.workers = 1).await
    }

    /// Submits `body` to `POST /jobs`, which must accept it (202); the job view.
    pub async fn submit(&self, body: &serde_json::Value) -> serde_json::Value {
        let r = super::http::post_json(self.addr, "/jobs", body).await;
        assert_eq!(r.status, 202, "{}", r.text());
        r.json()
    }

    pub async fn stop(mut self) {
        if let Some(tx) = self.stop.take() {
            let _ = tx.send(());
        }
        tokio::time::timeout(Duration::from_secs(20), &mut self.task)
            .await
            .expect("server stops")
            .unwrap()
            .unwrap();
    }
}
