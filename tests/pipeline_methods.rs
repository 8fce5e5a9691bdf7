//! The shared pipeline (the executor and its plans) on the tiny Stable Diffusion and CLIP fixtures:
//! every method × style, starts from an image or SVG, the `generate` binary, the real
//! `DefaultExecutor` on vectorize and text jobs, and a text job through the real service.

mod common;

use common::http::{get, post_json, sse};
use common::runs;
use common::wait_status;
use serde_json::json;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use vectorfusion::image::Image;
use vectorfusion::pipeline::{
    DefaultExecutor, Executor, JobContext, JobKind, JobSpec, Method, ModelDirs, PlanRequest,
    Preset, RunInput, StartKind, Style, Tuning,
};
use vectorfusion::progress::{CancelToken, Progress, Stage};
use vectorfusion::scene::{Scene, ShapeKind};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn models() -> DefaultExecutor {
    runs::executor(fixture("sd-tiny"), Some(fixture("clip-tiny")))
}

fn assert_finite_svg(svg: &str) {
    assert!(svg.starts_with("<svg"), "{svg}");
    assert!(!svg.contains("NaN") && !svg.contains("inf"), "{svg}");
    let scene = vectorfusion::svg::from_svg(svg).unwrap();
    scene.validate().unwrap();
    resvg::usvg::Tree::from_str(svg, &resvg::usvg::Options::default()).unwrap();
}

fn req(method: Method, style: Style, start: StartKind) -> PlanRequest {
    PlanRequest {
        style,
        method,
        start,
        preset: Preset::Draft,
        steps: Some(4),
        samples: Some(2),
        seed: 7,
        ..PlanRequest::text("a crown")
    }
}

/// Runs `r` from `input` (image or SVG).
fn run_from(
    m: &DefaultExecutor,
    r: &PlanRequest,
    image: Option<Image>,
    svg: Option<Scene>,
) -> vectorfusion::pipeline::RunOutput {
    let input = RunInput {
        caption: r.caption.clone(),
        image,
        svg,
    };
    runs::run_with(m, r, &input, |_| {}, CancelToken::new()).unwrap()
}

#[test]
fn every_method_and_style_runs_on_the_tiny_model_without_nan() {
    let m = models();
    for method in Method::ALL {
        for style in Style::ALL {
            let out = runs::run(&m, &req(*method, style, StartKind::Method))
                .unwrap_or_else(|e| panic!("{method:?} {style:?}: {e}"));
            assert_finite_svg(&out.svg);
            assert!(out.paths > 0, "{method:?} {style:?}: empty scene");
            assert_eq!(out.scene.width, 32);
            for s in &out.scene.shapes {
                assert!(s.points.iter().all(|p| p.x.is_finite() && p.y.is_finite()));
            }
            let d = &out.report;
            assert_eq!(d.paths_needed, Some(out.paths));
            let scores = d.rerank.as_ref().map(|r| r.scores.len());
            let sds = d.sds.as_ref().map(|s| (s.stats.steps_done, s.augment));
            match method {
                Method::Scratch => {
                    assert_eq!(scores, None);
                    assert_eq!(sds, Some((4, true)));
                }
                Method::SdLive => {
                    assert_eq!(scores, Some(2));
                    assert_eq!(sds, None, "sd_live has no SDS: {d:?}");
                }
                Method::SdLiveSds => {
                    assert_eq!(scores, Some(2));
                    assert_eq!(sds, Some((4, false)));
                }
            }
            if style == Style::PixelArt {
                // The grid's cells, those of one colour side by side merged into one outline.
                let f = d.finish.as_ref().unwrap();
                assert_eq!(out.paths + f.merged + f.dropped, 32 * 32, "{f:?}");
                assert!(
                    out.scene
                        .shapes
                        .iter()
                        .all(|s| s.kind == ShapeKind::Polygon)
                );
            }
        }
    }
}

#[test]
fn rerank_keeps_the_highest_clip_score() {
    let m = models();
    let out = runs::run(
        &m,
        &PlanRequest {
            samples: Some(3),
            ..req(Method::SdLive, Style::Iconography, StartKind::Method)
        },
    )
    .unwrap();
    let rerank = out.report.rerank.unwrap();
    let (scores, best) = (rerank.scores, rerank.chosen);
    assert_eq!(scores.len(), 3);
    assert!(scores.iter().all(|s| *s <= scores[best]), "{scores:?}");
}

#[test]
fn same_seed_same_svg() {
    let m = models();
    let r = req(Method::SdLiveSds, Style::Iconography, StartKind::Method);
    let a = runs::run(&m, &r).unwrap();
    let b = runs::run(&m, &r).unwrap();
    assert_eq!(a.svg, b.svg);
    // An explicit SDS guidance replaces the model's default (100): another drawing.
    let g = PlanRequest {
        tuning: Tuning {
            guidance: Some(1.0),
            ..Tuning::default()
        },
        ..r.clone()
    };
    let c = runs::run(&m, &g).unwrap();
    assert_ne!(a.svg, c.svg);
    // A learning-rate scale moves the paths further: another drawing; 1 is the schedule as it is.
    let lr = |lr_scale| PlanRequest {
        tuning: Tuning {
            lr_scale: Some(lr_scale),
            ..Tuning::default()
        },
        ..r.clone()
    };
    assert_eq!(runs::run(&m, &lr(1.0)).unwrap().svg, a.svg);
    assert_ne!(runs::run(&m, &lr(4.0)).unwrap().svg, a.svg);
}

fn disc_image(side: u32) -> Image {
    let mut im = Image::filled(side, side, [1.0, 1.0, 1.0, 1.0]);
    let c = side as f32 / 2.0;
    for y in 0..side {
        for x in 0..side {
            let (dx, dy) = (x as f32 + 0.5 - c, y as f32 + 0.5 - c);
            if dx * dx + dy * dy < (side as f32 * 0.3).powi(2) {
                let i = 4 * (y * side + x) as usize;
                im.data[i..i + 4].copy_from_slice(&[0.9, 0.2, 0.1, 1.0]);
            }
        }
    }
    im
}

#[test]
fn starts_from_a_user_image_or_svg() {
    let m = models();
    let out = run_from(
        &m,
        &req(Method::SdLiveSds, Style::Iconography, StartKind::Image),
        Some(disc_image(48)),
        None,
    );
    assert_finite_svg(&out.svg);
    assert!(out.report.live.as_ref().unwrap().psnr > 10.0);
    assert!(out.report.rerank.is_none(), "no sampling from an image");
    assert_eq!(out.report.sds.as_ref().unwrap().stats.steps_done, 4);

    let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64">
        <rect width="64" height="64" fill="#ffffff"/>
        <path d="M10 10 L50 10 L50 50 L10 50 Z" fill="#3366cc"/></svg>"##;
    let scene = vectorfusion::svg::from_svg(svg).unwrap();
    let out = run_from(
        &m,
        &req(Method::Scratch, Style::Iconography, StartKind::Svg),
        None,
        Some(scene),
    );
    assert_finite_svg(&out.svg);
    assert_eq!(out.scene.width, 32, "scaled to the teacher size");
    assert_eq!(out.paths, 1);
}

#[test]
fn cancellation_stops_a_run() {
    let m = models();
    let cancel = CancelToken::new();
    let c2 = cancel.clone();
    let sink = move |p: Progress| {
        if p.stage == Stage::Sample {
            c2.cancel();
        }
    };
    let r = runs::run_with(
        &m,
        &req(Method::SdLiveSds, Style::Iconography, StartKind::Method),
        &RunInput {
            caption: Some("a crown".into()),
            ..RunInput::default()
        },
        sink,
        cancel,
    );
    assert!(
        matches!(r, Err(vectorfusion::pipeline::PipelineError::Cancelled)),
        "{r:?}"
    );
}

#[test]
fn generate_binary_sd_live_sds_writes_a_valid_svg() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("crown.svg");
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
        .args(["generate", "a crown", "--method", "sd_live_sds"])
        .args([
            "--style",
            "iconography",
            "--preset",
            "draft",
            "--steps",
            "4",
        ])
        .arg("--model")
        .arg(fixture("sd-tiny"))
        .arg("--scorer")
        .arg(fixture("clip-tiny"))
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let svg = std::fs::read_to_string(&out).unwrap();
    assert_finite_svg(&svg);
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(err.contains("rerank"), "{err}");

    // A bad method is a usage error (exit code 2), not a crash.
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
        .args(["generate", "x", "--method", "diffuse", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(st.status.code(), Some(2), "{st:?}");
}

fn spec(kind: JobKind) -> JobSpec {
    JobSpec {
        kind,
        caption: None,
        image: None,
        svg: None,
        style: Style::Iconography,
        method: Method::SdLiveSds,
        paths: Some(8),
        steps: Some(4),
        seed: 3,
        samples: Some(2),
        preset: Preset::Draft,
        priority: 0,
        retrieval: true,
        vector: Default::default(),
        canvas: Default::default(),
        negative_prompt: None,
        size_conditioning: None,
        plan: None,
        variations: None,
    }
}

#[test]
fn default_executor_vectorizes_an_image() {
    let exec = DefaultExecutor::default();
    let mut s = spec(JobKind::Vectorize);
    s.image = Some(disc_image(32).encode_png().unwrap());
    let out = exec
        .run(&s, &JobContext::detached(CancelToken::new()))
        .unwrap();
    assert_finite_svg(&out.svg);
    assert!(out.paths >= 1 && out.paths <= 8, "{}", out.paths);
    assert!(out.report.psnr.unwrap() > 15.0, "{:?}", out.report);
    // Text jobs are refused with a hint while no models are configured.
    assert!(
        exec.text_ready()
            .unwrap_err()
            .to_string()
            .contains("sd_dir")
    );
}

#[test]
fn default_executor_text_ready_follows_the_model_config() {
    let exec = DefaultExecutor::new(ModelDirs {
        sd_dir: Some(fixture("sd-tiny")),
        clip_dir: Some(fixture("clip-tiny")),
        ..ModelDirs::default()
    });
    exec.text_ready().unwrap();
    let missing = DefaultExecutor::new(ModelDirs {
        sd_dir: Some(fixture("no-such-model")),
        ..ModelDirs::default()
    });
    assert!(
        missing
            .text_ready()
            .unwrap_err()
            .to_string()
            .contains("no-such-model")
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn text_job_through_the_service_streams_snapshots_and_records_rerank_scores() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("jobs.db");
    let mut cfg = vectorfusion::config::Config::default();
    cfg.database.path = db.clone();
    cfg.queue.workers = 1;
    cfg.queue.poll_interval_ms = 20;
    cfg.server.progress_interval_ms = 0;
    cfg.server.snapshot_interval_ms = 0;
    cfg.server.shutdown_grace_secs = 5;
    cfg.models.sd_dir = fixture("sd-tiny").display().to_string();
    cfg.models.clip_dir = fixture("clip-tiny").display().to_string();
    let exec: Arc<dyn Executor> = Arc::new(DefaultExecutor::new(cfg.model_dirs()));
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let a = listener.local_addr().unwrap();
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(vectorfusion::server::run(cfg, exec, listener, async move {
        let _ = rx.await;
    }));

    let r = get(a, "/readyz").await;
    assert!(r.text().contains("ready"), "{}", r.text());
    let body = json!({"kind": "text", "caption": "a crown", "style": "iconography",
        "method": "sd_live_sds", "preset": "draft", "paths": 8, "steps": 6, "samples": 2,
        "seed": 5});
    let r = post_json(a, "/jobs", &body).await;
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let (status, events) = sse(
        a,
        &format!("/jobs/{id}/events"),
        &[],
        Duration::from_secs(120),
        |e| e.event == "done" || e.event == "failed",
    )
    .await;
    assert_eq!(status, 200);
    let names: Vec<&str> = events.iter().map(|e| e.event.as_str()).collect();
    assert_eq!(*names.last().unwrap(), "done", "{names:?}");
    let snaps: Vec<_> = events.iter().filter(|e| e.event == "snapshot").collect();
    assert!(!snaps.is_empty(), "{names:?}");
    for s in &snaps {
        assert!(s.json()["svg"].as_str().unwrap().starts_with("<svg"));
    }
    wait_status(a, &id, &["succeeded"], Duration::from_secs(10)).await;
    // GET /jobs/{id} shows the rejection sampling: one CLIP score per sample, the kept index.
    let job = get(a, &format!("/jobs/{id}")).await.json();
    let rerank = &job["rerank"];
    let scores: Vec<f64> = rerank["scores"]
        .as_array()
        .unwrap_or_else(|| panic!("{job}"))
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(scores.len(), 2, "{job}");
    assert!(
        scores.iter().all(|s| (-1.0..=1.0).contains(s)),
        "{scores:?}"
    );
    let chosen = rerank["chosen"].as_u64().unwrap() as usize;
    assert!(scores.iter().all(|s| *s <= scores[chosen]), "{rerank}");
    assert_eq!(rerank["samples"], 2);
    assert!(rerank["scorer"].is_string(), "{rerank}");
    assert!(job["result"]["paths"].as_u64().unwrap() >= 1, "{job}");
    // The SSE rerank progress event carried the same scores.
    let live: Vec<_> = events
        .iter()
        .filter(|e| e.event == "progress" && e.json()["stage"] == "rerank")
        .collect();
    assert_eq!(live.len(), 1, "{names:?}");
    assert_eq!(live[0].json()["detail"]["scores"], rerank["scores"]);
    let r = get(a, &format!("/jobs/{id}/result.svg")).await;
    assert_eq!(r.status, 200);
    assert_finite_svg(&r.text());

    let _ = tx.send(());
    tokio::time::timeout(Duration::from_secs(20), task)
        .await
        .unwrap()
        .unwrap()
        .unwrap();
    // The stored result detail holds the rerank scores.
    let store = vectorfusion::store::Store::open(&db, 1).await.unwrap();
    let res = store.result(&id).await.unwrap().unwrap();
    let detail: serde_json::Value = serde_json::from_str(&res.detail).unwrap();
    assert_eq!(
        detail["rerank"]["scores"].as_array().unwrap().len(),
        2,
        "{detail}"
    );
    assert_eq!(detail["method"], "sd_live_sds");
    assert!(detail["paths_needed"].as_u64().unwrap() >= 1);
}

#[test]
fn bench_stability_reports_every_method_and_style_as_json() {
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
        .args([
            "bench",
            "stability",
            "--seeds",
            "2",
            "--steps",
            "5",
            "--json",
        ])
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&st.stdout).unwrap();
    let cells = v["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 3 * vectorfusion::pipeline::Style::ALL.len());
    for c in cells {
        assert_eq!(c["runs"], 2);
        assert_eq!(c["errors"], 0, "{c}");
        assert_eq!(c["nan"], 0, "{c}");
        let rate = c["failure_rate"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&rate));
    }
    // Sampling from the analytic teacher draws one of its targets; LIVE traces it closely.
    let live = cells
        .iter()
        .find(|c| c["method"] == "sd_live" && c["style"] == "iconography")
        .unwrap();
    assert!(live["psnr_median"].as_f64().unwrap() > 20.0, "{live}");
}

/// A job runs the plan stored with it, whatever its preset (and the preset table) says now.
#[test]
fn a_stored_plan_runs_as_stored() {
    let exec = DefaultExecutor::new(ModelDirs {
        sd_dir: Some(fixture("sd-tiny")),
        clip_dir: Some(fixture("clip-tiny")),
        ..ModelDirs::default()
    });
    let body = json!({"kind": "text", "caption": "a crown", "method": "scratch",
        "preset": "draft", "steps": 3, "seed": 5});
    let mut spec = vectorfusion::server::types::parse_submit(
        body.to_string().as_bytes(),
        &vectorfusion::pipeline::Limits::default(),
        1,
        &exec,
    )
    .unwrap()
    .spec;
    let plan = spec.plan.clone().expect("a plan is resolved at submit");
    let text = plan.text.as_ref().unwrap();
    assert_eq!((text.size, text.sds.as_ref().unwrap().steps), (32, 3));
    // The spec's own fields say "fast" and 1000 steps now; the stored plan still decides.
    spec.preset = Preset::Fast;
    spec.steps = Some(1000);
    let out = exec
        .run(&spec, &JobContext::detached(CancelToken::new()))
        .unwrap();
    assert_eq!(out.report.sds.as_ref().unwrap().stats.steps_done, 3);
    assert_eq!(out.report.size, Some(32));
    // Without a stored plan (a job from before plans) the spec's fields are resolved.
    spec.plan = None;
    spec.steps = Some(2);
    let out = exec
        .run(&spec, &JobContext::detached(CancelToken::new()))
        .unwrap();
    assert_eq!(out.report.sds.as_ref().unwrap().stats.steps_done, 2);
    assert_eq!(out.report.size, Some(64), "the fast preset's size");
}
