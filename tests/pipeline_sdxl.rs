//! The pipeline on the tiny random-weight SDXL fixture (`tests/fixtures/sdxl-tiny`, the real
//! SDXL architecture at tiny widths): every method samples, reranks, traces and distils with the
//! dual text encoders and the pooled/size conditioning, at the canvas's aspect; `generate`
//! writes the SVG.

mod common;

use common::fixture;
use common::http::post_json;
use common::recording::run_recorded;
use common::runs::{self, assert_valid_svg};
use common::server::TestServer;
use common::wait_status;
use serde_json::json;
use std::path::Path;
use std::time::Duration;
use vectorfusion::models::guided::SizeConditioning;
use vectorfusion::pipeline::{Aspect, Method, PlanRequest, Preset, SizeConditioningRequest};
use vectorfusion::progress::{CancelToken, NullSink};
use vectorfusion::teacher::{SampleConfig, SdTeacher, Teacher};

/// A draft request (32 px samples), 2 samples, 3 SDS steps.
fn req(method: Method) -> PlanRequest {
    let mut r = PlanRequest::text("a crown");
    (r.method, r.preset) = (method, Preset::Draft);
    (r.steps, r.samples, r.seed) = (Some(3), Some(2), 5);
    r
}

#[test]
fn every_method_runs_on_the_sdxl_fixture_deterministically() {
    let m = runs::executor(fixture("sdxl-tiny"), Some(fixture("clip-tiny")));
    for method in Method::ALL {
        let out = runs::run(&m, &req(*method)).unwrap_or_else(|e| panic!("{method:?}: {e}"));
        assert_valid_svg(&out.svg);
        assert!(out.paths > 0, "{method:?}");
        let teacher = out.report.teacher.as_deref().unwrap_or_default();
        assert!(teacher.contains("Stable Diffusion XL"), "{teacher}");
        if *method != Method::Scratch {
            assert_eq!(out.report.rerank.as_ref().unwrap().scores.len(), 2);
        }
        let sds = out.report.sds.as_ref().map(|s| s.stats.steps_done);
        assert_eq!(sds, (*method != Method::SdLive).then_some(3), "{method:?}");
        let again = runs::run(&m, &req(*method)).unwrap();
        assert_eq!(
            again.svg, out.svg,
            "{method:?}: the same seed, the same SVG"
        );
    }
}

/// A 16:9 canvas samples and distils at 56x32 px: the size time ids say so.
#[test]
fn a_wide_canvas_reaches_the_size_conditioning() {
    let m = runs::executor(fixture("sdxl-tiny"), Some(fixture("clip-tiny")));
    let mut r = req(Method::SdLiveSds);
    r.canvas.aspect = Some(Aspect::Wide16x9);
    let plan = runs::plan(&m, &r);
    let text = plan.text.as_ref().unwrap();
    let models = m.load_models(text).unwrap();
    assert_eq!(models.teacher().image_dims(), (56, 32));
    let c = models.teacher().condition("a crown", "").unwrap();
    let ids = c.added.unwrap().time_ids;
    assert_eq!(ids, [32.0, 56.0, 0.0, 0.0, 32.0, 56.0]);
    let out = runs::run(&m, &r).unwrap();
    assert_eq!((out.scene.width, out.scene.height), (64, 36));
    assert_valid_svg(&out.svg);
}

/// The size conditioning asked for reaches sampling and every SDS noise prediction, and it
/// changes what the model draws; without it, the drawn size and no crop (diffusers' default).
#[test]
fn size_conditioning_reaches_sampling_and_sds() {
    let m = runs::executor(fixture("sdxl-tiny"), Some(fixture("clip-tiny")));
    let mut r = req(Method::SdLiveSds);
    r.size_conditioning = Some(SizeConditioningRequest {
        original_width: Some(1024),
        original_height: Some(768),
        crop_left: Some(16),
        crop_top: Some(8),
    });
    let plan = runs::plan(&m, &r);
    let text = plan.text.as_ref().unwrap();
    let asked = text.size_conditioning.unwrap();
    assert_eq!(text.sample_dims(), (32, 32));
    let (paths, seen) = run_recorded(SdTeacher::load(&fixture("sdxl-tiny"), 32).unwrap(), &plan);
    assert!(paths > 0);
    assert_eq!(
        seen,
        [
            "sample: ".to_string(),
            format!("sample size: {asked:?}"),
            "sds: ".to_string(),
            "noise: [768.0, 1024.0, 8.0, 16.0, 32.0, 32.0]".to_string(),
        ]
    );

    // It changes the picture; the default is the drawn size without a crop.
    let teacher = SdTeacher::load(&fixture("sdxl-tiny"), 32).unwrap();
    let draw = |size: Option<SizeConditioning>| {
        let cfg = SampleConfig {
            k: 1,
            steps: 3,
            guidance: 7.5,
            seed: 1,
            strength: 1.0,
            negative_prompt: String::new(),
            size_conditioning: size,
        };
        let images = teacher.sample("a crown", &[], &cfg, &NullSink, &CancelToken::new());
        images.unwrap().remove(0).data
    };
    assert_eq!(draw(None), draw(Some(SizeConditioning::drawn(32, 32))));
    assert_ne!(draw(None), draw(Some(asked)));
}

/// `generate --sdxl-original-size/--sdxl-crop` reach the plan of an SDXL model; a model without
/// size conditioning refuses them (exit 2, naming the flag's field).
#[test]
fn generate_takes_the_sdxl_size_flags() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("crown.svg");
    let run = |model: &str, extra: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
            .args(["generate", "a crown", "--preset", "draft", "--steps", "2"])
            .args(["--samples", "1", "--model"])
            .arg(fixture(model))
            .arg("-o")
            .arg(&out)
            .args(extra)
            .output()
            .unwrap()
    };
    let flags = ["--sdxl-original-size", "1024x768", "--sdxl-crop", "0,64"];
    let st = run("sdxl-tiny", &flags);
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(st.status.success(), "{err}");
    let summary: serde_json::Value = serde_json::from_slice(&st.stdout).unwrap();
    let size = &summary["plan"]["text"]["size_conditioning"];
    assert_eq!(
        *size,
        serde_json::json!({"original_width": 1024, "original_height": 768,
                           "crop_left": 0, "crop_top": 64}),
        "{summary}"
    );
    let st = run("sd-tiny", &flags);
    let err = String::from_utf8_lossy(&st.stderr);
    assert_eq!(st.status.code(), Some(2), "{err}");
    assert!(err.contains("--sdxl-original-size / --sdxl-crop"), "{err}");
    for bad in [
        ["--sdxl-original-size", "1024"],
        ["--sdxl-original-size", "0x64"],
    ] {
        let st = run("sdxl-tiny", &bad);
        let err = String::from_utf8_lossy(&st.stderr);
        assert_eq!(st.status.code(), Some(2), "{bad:?}: {err}");
        assert!(err.contains("--sdxl-original-size"), "{bad:?}: {err}");
    }
}

/// Through the service: the job's params echo the request, its plan holds the resolved numbers,
/// and the job runs; a bad number is refused naming its field.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_sdxl_job_with_size_conditioning_through_the_service() {
    let srv = TestServer::with_model(fixture("sdxl-tiny")).await;
    let a = srv.addr;
    let job = srv
        .submit(
            &json!({"kind": "text", "caption": "a crown", "method": "sd_live",
            "preset": "draft", "samples": 1, "seed": 5,
            "size_conditioning": {"original_width": 1024.0, "original_height": 1024}}),
        )
        .await;
    assert_eq!(
        job["params"]["plan"]["text"]["size_conditioning"],
        json!({"original_width": 1024, "original_height": 1024, "crop_left": 0, "crop_top": 0}),
        "{job}"
    );
    assert_eq!(job["params"]["size_conditioning"]["original_width"], 1024);
    let id = job["id"].as_str().unwrap().to_string();
    wait_status(a, &id, &["succeeded"], Duration::from_secs(120)).await;
    let bad = json!({"kind": "text", "caption": "x", "size_conditioning": {"crop_top": -1}});
    let r = post_json(a, "/jobs", &bad).await;
    assert_eq!(r.status, 400, "{}", r.text());
    assert_eq!(r.json()["error"]["field"], "size_conditioning");
    let big = json!({"kind": "text", "caption": "x", "size_conditioning": {"crop_top": 16385}});
    let r = post_json(a, "/jobs", &big).await;
    assert_eq!(r.status, 400, "{}", r.text());
    assert_eq!(r.json()["error"]["field"], "size_conditioning.crop_top");
    srv.stop().await;
}

#[test]
fn generate_writes_the_svg_of_an_sdxl_model() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("crown.svg");
    let (model, scorer) = (fixture("sdxl-tiny"), fixture("clip-tiny"));
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
        .args(["generate", "a crown", "--preset", "draft", "--steps", "3"])
        .args(["--negative-prompt", "blurry", "--model"])
        .args([
            &model,
            Path::new("--scorer"),
            &scorer,
            Path::new("-o"),
            &out,
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(st.status.success(), "{err}");
    assert_valid_svg(&std::fs::read_to_string(&out).unwrap());
    assert!(
        err.contains("rerank") && err.contains("Stable Diffusion XL"),
        "{err}"
    );
}
