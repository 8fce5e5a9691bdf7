//! Connection and storage limits of issue #21, on a real server: half-sent headers, idle
//! keep-alive connections and slow bodies are cut off in bounded time, connections past
//! `max_connections` are closed at once, and uploads live in their own table under a quota.

mod common;

use common::http::{get, post_json, request};
use common::server::TestServer;
use serde_json::json;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use vectorfusion::worker::test_executor::TestExecutor;

/// Reads until the server closes the connection; what it sent, or `None` if it still had not
/// closed it after `limit`.
async fn until_closed(s: &mut TcpStream, limit: Duration) -> Option<Vec<u8>> {
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    let deadline = Instant::now() + limit;
    loop {
        let left = deadline.checked_duration_since(Instant::now())?;
        match tokio::time::timeout(left, s.read(&mut buf)).await {
            Err(_) => return None,
            Ok(Ok(0)) | Ok(Err(_)) => return Some(got),
            Ok(Ok(n)) => got.extend_from_slice(&buf[..n]),
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn half_sent_headers_and_idle_keep_alive_connections_are_closed() {
    let srv = TestServer::start(Arc::new(TestExecutor::new(1)), |c| {
        c.server.header_read_timeout_secs = 1;
    })
    .await;
    // Half a request head, then nothing.
    let mut s = TcpStream::connect(srv.addr).await.unwrap();
    s.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\nX-Slow: ")
        .await
        .unwrap();
    let t = Instant::now();
    let got = until_closed(&mut s, Duration::from_secs(15)).await;
    assert!(got.is_some(), "a half-sent head was held open for 15 s");
    assert!(t.elapsed() < Duration::from_secs(4), "{:?}", t.elapsed());

    // A kept-alive connection after one answered request is closed once idle as long.
    let mut s = TcpStream::connect(srv.addr).await.unwrap();
    s.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")
        .await
        .unwrap();
    let t = Instant::now();
    let got = until_closed(&mut s, Duration::from_secs(15))
        .await
        .expect("an idle keep-alive connection was held open for 15 s");
    assert!(
        String::from_utf8_lossy(&got).starts_with("HTTP/1.1 200"),
        "{}",
        String::from_utf8_lossy(&got)
    );
    assert!(t.elapsed() < Duration::from_secs(4), "{:?}", t.elapsed());
    srv.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn connections_past_the_cap_are_closed_at_once() {
    let srv = TestServer::start(Arc::new(TestExecutor::new(1)), |c| {
        c.server.max_connections = 2;
    })
    .await;
    let a = TcpStream::connect(srv.addr).await.unwrap();
    let _b = TcpStream::connect(srv.addr).await.unwrap();
    tokio::time::sleep(Duration::from_millis(200)).await;
    let mut c = TcpStream::connect(srv.addr).await.unwrap();
    let _ = c
        .write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
        .await;
    let got = until_closed(&mut c, Duration::from_secs(3))
        .await
        .expect("the third connection was kept open");
    assert!(got.is_empty(), "{}", String::from_utf8_lossy(&got));
    // A closed connection frees its place.
    drop(a);
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(get(srv.addr, "/healthz").await.status, 200);
    srv.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_body_sent_too_slowly_gets_408() {
    let srv = TestServer::start(Arc::new(TestExecutor::new(1)), |c| {
        c.server.body_read_timeout_secs = 1;
    })
    .await;
    let mut s = TcpStream::connect(srv.addr).await.unwrap();
    s.write_all(
        b"POST /jobs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n\
          Content-Length: 100\r\nConnection: close\r\n\r\n{\"kind\"",
    )
    .await
    .unwrap();
    let t = Instant::now();
    let got = until_closed(&mut s, Duration::from_secs(15))
        .await
        .expect("a stalled body was held open for 15 s");
    let text = String::from_utf8_lossy(&got);
    assert!(text.starts_with("HTTP/1.1 408"), "{text}");
    assert!(text.contains("\"body_timeout\""), "{text}");
    assert!(t.elapsed() < Duration::from_secs(4), "{:?}", t.elapsed());
    srv.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uploads_are_stored_apart_under_a_quota_that_finished_jobs_free() {
    let image = common::png_b64(48);
    // Uploads are stored (and counted against the quota) as the image's bytes, not its base64.
    let n = base64::Engine::decode(&base64::engine::general_purpose::STANDARD, &image)
        .unwrap()
        .len();
    let body_len = image.len();
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("jobs.db");
    let db_path = db.clone();
    // One worker on a slow executor: the first job runs, the others wait with their uploads.
    let srv = TestServer::start(Arc::new(TestExecutor::new(2_000)), move |c| {
        c.database.path = db_path;
        c.queue.workers = 1;
        // Room for three uploads of n bytes, not four.
        c.server.max_body_bytes = body_len + 1024;
        c.server.max_stored_upload_bytes = (3 * n + n / 2) as u64;
    })
    .await;
    let body = json!({"kind": "vectorize", "image": image, "steps": 50});
    let submit = || post_json(srv.addr, "/jobs", &body);
    let mut ids = Vec::new();
    for _ in 0..3 {
        let r = submit().await;
        assert_eq!(r.status, 202, "{}", r.text());
        ids.push(r.json()["id"].as_str().unwrap().to_string());
    }
    let r = submit().await;
    assert_eq!(r.status, 429, "{}", r.text());
    assert_eq!(r.json()["error"]["code"], "upload_quota_exceeded");
    assert!(r.header("retry-after").is_some());
    // The job rows stay small: the image is in `uploads`, once.
    let store = vectorfusion::store::Store::open(&db, 1).await.unwrap();
    let (spec_bytes, upload_bytes): (i64, i64) = sqlx::query_as(
        "SELECT (SELECT MAX(length(CAST(spec AS BLOB))) FROM jobs), \
                (SELECT SUM(bytes) FROM uploads)",
    )
    .fetch_one(store.pool())
    .await
    .unwrap();
    assert!(
        spec_bytes < 2048,
        "a job row holds {spec_bytes} bytes of spec"
    );
    assert_eq!(upload_bytes, 3 * n as i64);
    let v = get(srv.addr, &format!("/jobs/{}", ids[2])).await.json();
    assert_eq!(v["params"]["has_image"], true, "{v}");
    // Cancelling a waiting job deletes its upload; the next submit fits again.
    let r = request(srv.addr, "DELETE", &format!("/jobs/{}", ids[2]), &[], None).await;
    assert_eq!(r.status, 200, "{}", r.text());
    let r = submit().await;
    assert_eq!(r.status, 202, "{}", r.text());
    store.close().await;
    srv.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn concurrent_submits_never_overshoot_the_queue_depth() {
    // One worker, held by a slow job; everything else waits in the queue.
    let srv = TestServer::start(Arc::new(TestExecutor::new(5_000)), |c| {
        c.queue.workers = 1;
        c.server.max_queue_depth = 20;
    })
    .await;
    let body = json!({"kind": "text", "caption": "a cat", "steps": 5, "paths": 2});
    let tasks: Vec<_> = (0..48)
        .map(|_| {
            let (b, addr) = (body.clone(), srv.addr);
            tokio::spawn(async move { post_json(addr, "/jobs", &b).await.status })
        })
        .collect();
    let (mut accepted, mut full) = (0, 0);
    for t in tasks {
        match t.await.unwrap() {
            202 => accepted += 1,
            429 => full += 1,
            s => panic!("unexpected status {s}"),
        }
    }
    let list = get(srv.addr, "/jobs?status=queued&limit=500").await.json();
    let queued = list["jobs"].as_array().unwrap().len();
    assert!(queued <= 20, "{queued} jobs queued, max_queue_depth is 20");
    // 20 queued, plus at most the one the worker took.
    assert!((20..=21).contains(&accepted), "{accepted} accepted");
    assert_eq!(accepted + full, 48);
    srv.stop().await;
}
