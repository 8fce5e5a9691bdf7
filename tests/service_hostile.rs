//! Issue #21's hostile inputs, sent to a real server: each is refused with a 4xx JSON error,
//! quickly, without growing the process (peak RSS read from /proc).

mod common;

use common::http::post_json;
use common::server::TestServer;
use serde_json::json;
use std::sync::Arc;
use std::time::{Duration, Instant};
use vectorfusion::worker::test_executor::TestExecutor;

/// The tests of this file measure the process's peak RSS, so they run one at a time.
static ONE_AT_A_TIME: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// Peak resident set of this process (the server runs in it), in MiB; `None` off Linux.
fn peak_rss_mib() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

fn hostile_svgs() -> Vec<(&'static str, String)> {
    let svg = |body: &str| {
        format!(r#"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64">{body}</svg>"#)
    };
    // Two nested <use> levels per doubling: 2^40 elements once expanded, 3 KB of text.
    let mut uses = String::from(r#"<defs><path id="u0" d="M0 0L1 1"/>"#);
    for i in 1..=40 {
        uses.push_str(&format!(
            r##"<g id="u{i}"><use href="#u{p}"/><use href="#u{p}"/></g>"##,
            p = i - 1
        ));
    }
    uses.push_str(r##"</defs><use href="#u40"/>"##);
    vec![
        (
            // 157 KB: one 100 KB entity used 19,000 times (≈1.9 GB once expanded).
            "entity expansion",
            format!(
                r#"<!DOCTYPE svg [<!ENTITY a "{}">]>{}"#,
                "x".repeat(100_000),
                svg(&format!("<text>{}</text>", "&a;".repeat(19_000)))
            ),
        ),
        (
            "40 huge circles",
            svg(&r#"<circle cx="32" cy="32" r="1e38" stroke="red" stroke-width="3"/>"#.repeat(40)),
        ),
        (
            "poison job",
            r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 10 10"><circle cx="1e38" cy="-1e38" r="1e38"/></svg>"#.into(),
        ),
        ("use doubling", svg(&uses)),
        (
            "nested scales",
            svg(&format!(
                "{}<rect width=\"10\" height=\"10\"/>{}",
                r#"<g transform="scale(60)">"#.repeat(8),
                "</g>".repeat(8)
            )),
        ),
        ("overflowing number", svg(r#"<path d="M0 0L1e999 0Z"/>"#)),
        ("stroke in style", svg(r#"<path d="M0 0L9 9" style="stroke:red;stroke-width:1e30"/>"#)),
    ]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn hostile_svg_submissions_are_refused_fast_and_small() {
    let _serial = ONE_AT_A_TIME.lock().await;
    let srv = TestServer::start(Arc::new(TestExecutor::new(1)), |_| {}).await;
    let before = peak_rss_mib();
    for (name, svg) in hostile_svgs() {
        let t = Instant::now();
        let r = post_json(
            srv.addr,
            "/jobs",
            &json!({"kind": "text", "caption": "a cat", "svg": svg, "steps": 2, "paths": 2}),
        )
        .await;
        let took = t.elapsed();
        assert_eq!(r.status, 400, "{name}: {}", r.text());
        let v = r.json();
        assert_eq!(v["error"]["code"], "invalid_field", "{name}: {v}");
        assert_eq!(v["error"]["field"], "svg", "{name}: {v}");
        // A bound on harm (the issue: "every request answered within 10 s"), not a speed target.
        assert!(took < Duration::from_secs(10), "{name} took {took:?}");
    }
    if let (Some(a), Some(b)) = (before, peak_rss_mib()) {
        assert!(b - a < 500.0, "peak RSS grew {a:.0} -> {b:.0} MiB");
    }
    // The server still works.
    let ok = r##"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 24 24"><path d="M2 2h20v20H2z" fill="#1e3838"/></svg>"##;
    let r = post_json(
        srv.addr,
        "/jobs",
        &json!({"kind": "text", "caption": "a cat", "svg": ok, "steps": 2, "paths": 2}),
    )
    .await;
    assert_eq!(r.status, 202, "{}", r.text());
    srv.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn concurrent_image_uploads_are_decoded_one_permit_at_a_time() {
    let _serial = ONE_AT_A_TIME.lock().await;
    // The jobs themselves decode nothing (Noop), so what grows is the submit-time validation.
    let srv = TestServer::start(Arc::new(NoopExecutor), |c| {
        c.server.max_concurrent_decodes = 1;
    })
    .await;
    // 4096² PNGs (the largest side accepted), 8 at once: each costs ~100 MB to decode. With one
    // permit the peak grew 131 MiB here; unbounded (8 permits), 583 MiB.
    let mut rgba = image::RgbaImage::new(4096, 4096);
    for (x, y, p) in rgba.enumerate_pixels_mut() {
        *p = image::Rgba([(x / 64) as u8, (y / 64) as u8, 128, 255]);
    }
    let mut png = Vec::new();
    image::DynamicImage::ImageRgba8(rgba)
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    let b64 = {
        use base64::Engine;
        base64::engine::general_purpose::STANDARD.encode(&png)
    };
    let body = json!({"kind": "vectorize", "image": b64, "steps": 1, "paths": 1});
    let before = peak_rss_mib();
    let addr = srv.addr;
    let tasks: Vec<_> = (0..8)
        .map(|_| {
            let b = body.clone();
            tokio::spawn(async move { post_json(addr, "/jobs", &b).await })
        })
        .collect();
    let mut accepted = 0;
    for t in tasks {
        let r = t.await.unwrap();
        match r.status {
            202 => accepted += 1,
            429 => {
                assert_eq!(r.json()["error"]["code"], "busy", "{}", r.text());
                assert!(r.header("retry-after").is_some());
            }
            s => panic!("status {s}: {}", r.text()),
        }
    }
    assert!(accepted >= 1);
    if let (Some(a), Some(b)) = (before, peak_rss_mib()) {
        assert!(b - a < 350.0, "peak RSS grew {a:.0} -> {b:.0} MiB");
    }
    srv.stop().await;
}

/// Finishes every job at once without looking at its input.
struct NoopExecutor;

impl vectorfusion::pipeline::Executor for NoopExecutor {
    fn run(
        &self,
        _spec: &vectorfusion::pipeline::JobSpec,
        _ctx: &vectorfusion::pipeline::JobContext,
    ) -> Result<vectorfusion::pipeline::RunOutput, vectorfusion::pipeline::PipelineError> {
        Ok(common::runs::blank_output())
    }
    fn text_ready(&self) -> Result<(), vectorfusion::pipeline::NotReady> {
        Ok(())
    }
}

/// A job stuck inside one long step that never checks for cancellation.
struct StuckExecutor;

impl vectorfusion::pipeline::Executor for StuckExecutor {
    fn run(
        &self,
        _spec: &vectorfusion::pipeline::JobSpec,
        ctx: &vectorfusion::pipeline::JobContext,
    ) -> Result<vectorfusion::pipeline::RunOutput, vectorfusion::pipeline::PipelineError> {
        ctx.report(vectorfusion::progress::Progress::new(
            vectorfusion::progress::Stage::Test,
            0,
            1,
        ));
        std::thread::sleep(Duration::from_secs(12));
        Err(vectorfusion::pipeline::PipelineError::Transient(
            "woke up".into(),
        ))
    }
    fn text_ready(&self) -> Result<(), vectorfusion::pipeline::NotReady> {
        Ok(())
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shutdown_ends_within_the_grace_period_with_a_stuck_worker_and_an_open_stream() {
    let _serial = ONE_AT_A_TIME.lock().await;
    let srv = TestServer::start(Arc::new(StuckExecutor), |c| {
        c.queue.workers = 1;
        c.server.shutdown_grace_secs = 2;
        c.server.max_sse_streams = 2;
    })
    .await;
    let body = json!({"kind": "vectorize", "image": common::png_b64(8), "steps": 1, "paths": 1});
    let r = post_json(srv.addr, "/jobs", &body).await;
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    common::wait_status(srv.addr, &id, &["running"], Duration::from_secs(10)).await;
    // Two event streams fill `max_sse_streams`; a third is refused with 429, not held.
    let path = format!("/jobs/{id}/events");
    let streams: Vec<_> = (0..2)
        .map(|_| {
            let (addr, path) = (srv.addr, path.clone());
            tokio::spawn(async move {
                common::http::sse(addr, &path, &[], Duration::from_secs(15), |_| false).await
            })
        })
        .collect();
    tokio::time::sleep(Duration::from_millis(500)).await;
    let r = common::http::get(srv.addr, &path).await;
    assert_eq!(r.status, 429, "{}", r.text());
    assert_eq!(r.json()["error"]["code"], "busy");
    // A client that sent half a request and went quiet.
    let mut idle = tokio::net::TcpStream::connect(srv.addr).await.unwrap();
    tokio::io::AsyncWriteExt::write_all(&mut idle, b"GET /jobs HTTP/1.1\r\nHost: x\r\n")
        .await
        .unwrap();
    let t = Instant::now();
    srv.stop().await;
    let took = t.elapsed();
    assert!(
        took < Duration::from_secs(6),
        "shutdown took {took:?} (grace 2 s)"
    );
    for s in streams {
        assert_eq!(s.await.unwrap().0, 200, "the open streams were served");
    }
}
