//! `variations`: a text job returns the N best distinct results on the tiny Stable Diffusion and
//! CLIP fixtures, each served at `result/{i}.svg|png|pdf`; variation 1 is the SVG of the same
//! job without variations; `?size=N` sets a PNG's longest side; on a 16:9 canvas each variation
//! is placed on it; bad counts are a 400 naming the field and a CLI usage error.

mod common;

use common::http::{get, post_json};
use common::server::TestServer;
use common::wait_status;
use serde_json::json;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use vectorfusion::pipeline::{DefaultExecutor, Executor};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn tiny(cfg: &mut vectorfusion::config::Config) {
    cfg.models.sd_dir = fixture("sd-tiny").display().to_string();
    cfg.models.clip_dir = fixture("clip-tiny").display().to_string();
}

async fn finished(a: std::net::SocketAddr, body: serde_json::Value) -> serde_json::Value {
    let r = post_json(a, "/jobs", &body).await;
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    wait_status(a, &id, &["succeeded"], Duration::from_secs(180)).await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn three_variations_are_distinct_and_the_first_is_the_single_result() {
    let mut cfg = vectorfusion::config::Config::default();
    tiny(&mut cfg);
    let exec: Arc<dyn Executor> = Arc::new(DefaultExecutor::new(cfg.model_dirs()));
    let server = TestServer::start(exec, tiny).await;
    let a = server.addr;
    let base = json!({"kind": "text", "caption": "a crown", "preset": "draft", "paths": 8,
        "steps": 4, "samples": 2, "seed": 5});
    let mut three = base.clone();
    three["variations"] = json!(3);
    let job = finished(a, three).await;
    let id = job["id"].as_str().unwrap();
    // K was raised to 3 for three distinct picks.
    assert_eq!(job["params"]["samples"], 3, "{job}");
    assert_eq!(job["params"]["variations"], 3, "{job}");
    let list = job["result"]["variations"].as_array().unwrap();
    assert_eq!(list.len(), 3, "{job}");
    let mut svgs = Vec::new();
    for (i, v) in list.iter().enumerate() {
        assert_eq!(v["variation"], i + 1);
        let r = get(a, v["svg"].as_str().unwrap()).await;
        assert_eq!(r.status, 200, "{}", r.text());
        assert!(r.text().starts_with("<svg"));
        assert_eq!(get(a, v["png"].as_str().unwrap()).await.status, 200);
        assert_eq!(get(a, v["pdf"].as_str().unwrap()).await.status, 200);
        svgs.push(r.text());
    }
    let samples: Vec<_> = list.iter().map(|v| v["sample"].as_u64().unwrap()).collect();
    assert!(samples[0] != samples[1] && samples[1] != samples[2] && samples[0] != samples[2]);
    assert!(svgs[0] != svgs[1] && svgs[1] != svgs[2] && svgs[0] != svgs[2]);
    assert_eq!(
        get(a, &format!("/jobs/{id}/result.svg")).await.text(),
        svgs[0]
    );
    assert_eq!(
        get(a, &format!("/jobs/{id}/result/4.svg")).await.status,
        404
    );
    // `?size=N`: the PNG's longest side (enlarged or reduced); out of range, unknown or on an
    // SVG, a 400 naming the parameter.
    for (url, side) in [("result.png?size=300", 300), ("result/2.png?size=40", 40)] {
        let r = get(a, &format!("/jobs/{id}/{url}")).await;
        assert_eq!(r.status, 200, "{}", r.text());
        let dim = |at: usize| u32::from_be_bytes(r.body[at..at + 4].try_into().unwrap());
        assert_eq!(dim(16).max(dim(20)), side, "{url}");
    }
    for (url, field) in [
        ("result.png?size=8", "size"),
        ("result/2.png?size=big", "size"),
        ("result/2.svg?size=100", "size"),
        ("result.png?scale=2", "scale"),
    ] {
        let r = get(a, &format!("/jobs/{id}/{url}")).await;
        assert_eq!(r.status, 400, "{url}: {}", r.text());
        assert_eq!(r.json()["error"]["field"], field, "{url}: {}", r.text());
    }
    assert_eq!(
        get(a, &format!("/jobs/{id}/result/1.gif")).await.status,
        404
    );
    // Variation 1 is the SVG of the same request without variations, with K = 3 too.
    let mut single = base.clone();
    single["samples"] = json!(3);
    let one = finished(a, single).await;
    let one_svg = get(
        a,
        &format!("/jobs/{}/result.svg", one["id"].as_str().unwrap()),
    )
    .await;
    assert_eq!(one_svg.text(), svgs[0]);
    assert_eq!(one["result"]["variations"].as_array().unwrap().len(), 1);
    // Out of range, or on a vectorize job: a 400 naming the field.
    for bad in [json!(0), json!(7), json!("two")] {
        let mut b = base.clone();
        b["variations"] = bad;
        let r = post_json(a, "/jobs", &b).await;
        assert_eq!(r.status, 400, "{}", r.text());
        assert!(r.text().contains("variations"), "{}", r.text());
    }
    let v = json!({"kind": "vectorize", "image": common::png_b64(16), "variations": 2});
    let r = post_json(a, "/jobs", &v).await;
    assert_eq!(r.status, 400, "{}", r.text());
    assert!(r.text().contains("variations"), "{}", r.text());
    server.stop().await;
}

/// `generate "a crown"` on the tiny fixtures (draft, 2 steps, 4 paths, K = 2) into `out`, with
/// `extra` arguments.
fn generate(out: &std::path::Path, extra: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
        .args(["generate", "a crown", "--model"])
        .arg(fixture("sd-tiny"))
        .arg("--scorer")
        .arg(fixture("clip-tiny"))
        .args([
            "--preset",
            "draft",
            "--steps",
            "2",
            "--paths",
            "4",
            "--samples",
            "2",
        ])
        .args(extra)
        .arg("-o")
        .arg(out)
        .output()
        .unwrap()
}

#[test]
fn generate_writes_one_file_per_variation_and_refuses_a_bad_count() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.svg");
    let run = |n: &str| generate(&out, &["--variations", n]);
    let st = run("2");
    assert!(st.status.success(), "{st:?}");
    for i in 1..=2 {
        let p = dir.path().join(format!("out-{i}.svg"));
        assert!(std::fs::read_to_string(&p).unwrap().starts_with("<svg"));
    }
    assert!(!out.exists());
    let summary: serde_json::Value = serde_json::from_slice(&st.stdout).unwrap();
    assert_eq!(summary["outputs"].as_array().unwrap().len(), 2, "{summary}");
    assert_eq!(summary["detail"]["variations"].as_array().unwrap().len(), 2);
    for bad in ["0", "7"] {
        let st = run(bad);
        assert_eq!(st.status.code(), Some(2), "{st:?}");
        assert!(String::from_utf8_lossy(&st.stderr).contains("variations"));
    }
}

/// Every variation of a 16:9 job is placed on the 16:9 canvas, each its own drawing.
#[test]
fn variations_on_a_16_9_canvas_are_each_placed_on_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("wide.svg");
    let st = generate(&out, &["--variations", "2", "--aspect", "16:9"]);
    assert!(st.status.success(), "{st:?}");
    let svgs: Vec<String> = (1..=2)
        .map(|i| std::fs::read_to_string(dir.path().join(format!("wide-{i}.svg"))).unwrap())
        .collect();
    assert_ne!(svgs[0], svgs[1]);
    for svg in &svgs {
        let vb = svg.split("viewBox=\"").nth(1).unwrap();
        let v: Vec<f64> = vb
            .split('"')
            .next()
            .unwrap()
            .split(' ')
            .map(|x| x.parse().unwrap())
            .collect();
        assert!((v[2] / v[3] - 16.0 / 9.0).abs() < 1e-9, "viewBox {v:?}");
    }
}
