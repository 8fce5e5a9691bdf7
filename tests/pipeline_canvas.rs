//! Canvases and negative prompts of text runs on the tiny Stable Diffusion and CLIP fixtures: a
//! 16:9 request samples, traces and distils at a 16:9-ish sample and writes a 16:9 SVG (the
//! library, `generate` and the service); pixel art draws its square centred on the canvas; a
//! negative prompt reaches the teacher's conditioning in sampling and in SDS.

mod common;

use common::http::{get, post_json};
use common::recording::run_recorded;
use common::runs;
use common::server::TestServer;
use common::wait_status;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::time::Duration;
use vectorfusion::pipeline::canvas::CanvasPlan;
use vectorfusion::pipeline::{Aspect, CanvasRequest, Method, PlanRequest, Preset, Style};
use vectorfusion::progress::{CancelToken, NullSink};
use vectorfusion::teacher::{SampleConfig, SdTeacher, Teacher};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// A draft request for a 16:9 canvas.
fn req(method: Method, style: Style) -> PlanRequest {
    let mut r = PlanRequest::text("a crown");
    (r.style, r.method, r.preset) = (style, method, Preset::Draft);
    (r.steps, r.samples, r.seed) = (Some(3), Some(2), 3);
    r.canvas.aspect = Some(Aspect::Wide16x9);
    r
}

/// The `viewBox` of `svg` as `[x, y, w, h]`.
fn view_box(svg: &str) -> [f64; 4] {
    let start = svg.find("viewBox=\"").expect("a viewBox") + "viewBox=\"".len();
    let end = start + svg[start..].find('"').unwrap();
    let v: Vec<f64> = svg[start..end]
        .split([' ', ','])
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().unwrap())
        .collect();
    [v[0], v[1], v[2], v[3]]
}

fn assert_16_9(svg: &str) {
    let [_, _, w, h] = view_box(svg);
    assert!((w / h - 16.0 / 9.0).abs() < 1e-9, "viewBox {w}x{h}: {svg}");
}

#[test]
fn a_16_9_canvas_is_sampled_traced_and_distilled_at_its_aspect() {
    let m = runs::executor(fixture("sd-tiny"), Some(fixture("clip-tiny")));
    for method in Method::ALL {
        let r = req(*method, Style::Iconography);
        let plan = runs::plan(&m, &r);
        let text = plan.text.as_ref().unwrap();
        // Draft is 32 px; the tiny model needs multiples of 4 (VAE 2 x UNet 2): 32 · 16/9 ≈ 57 → 56.
        let want = CanvasPlan {
            width: 64,
            height: 36,
            sample_width: 56,
            sample_height: 32,
        };
        assert_eq!(text.canvas, Some(want), "{method:?}");
        let models = m.load_models(text).unwrap();
        assert_eq!(models.teacher().image_dims(), (56, 32));
        assert_eq!(models.teacher().latent_shape()[1..], [16, 28]);
        let out = runs::run(&m, &r).unwrap_or_else(|e| panic!("{method:?}: {e}"));
        assert_eq!((out.scene.width, out.scene.height), (64, 36), "{method:?}");
        assert_16_9(&out.svg);
        assert!(out.paths > 0, "{method:?}");
        let sds = out.report.sds.as_ref().map(|s| s.stats.steps_done);
        assert_eq!(sds, (*method != Method::SdLive).then_some(3), "{method:?}");
        if *method != Method::Scratch {
            assert_eq!(out.report.rerank.as_ref().unwrap().scores.len(), 2);
        }
    }
}

#[test]
fn pixel_art_draws_its_square_centred_on_the_canvas() {
    let m = runs::executor(fixture("sd-tiny"), Some(fixture("clip-tiny")));
    let r = req(Method::SdLive, Style::PixelArt);
    let text = runs::plan(&m, &r).text.unwrap();
    let c = text.canvas.unwrap();
    assert_eq!((c.sample_width, c.sample_height), (32, 32));
    let out = runs::run(&m, &r).unwrap();
    assert_eq!((out.scene.width, out.scene.height), (64, 36));
    // The 32x32 grid scaled to 36 px, centred: x from 14 to 50.
    let xs = out
        .scene
        .shapes
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.x));
    let (lo, hi) = xs.fold((f32::MAX, f32::MIN), |(a, b), x| (a.min(x), b.max(x)));
    assert!(
        (lo - 14.0).abs() < 0.01 && (hi - 50.0).abs() < 0.01,
        "{lo}..{hi}"
    );
}

#[test]
fn generate_writes_a_16_9_svg_and_refuses_bad_canvas_flags() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("wide.svg");
    let run = |extra: &[&str], model: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
            .args(["generate", "a crown", "--preset", "draft", "--steps", "2"])
            .args(["--samples", "2"])
            .args(model)
            .args(extra)
            .arg("-o")
            .arg(&out)
            .output()
            .unwrap()
    };
    let sd = fixture("sd-tiny").display().to_string();
    let model = ["--model", sd.as_str()];
    let st = run(&["--aspect", "16:9", "--negative-prompt", "blurry"], &model);
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    assert_16_9(&std::fs::read_to_string(&out).unwrap());
    let summary: Value = serde_json::from_slice(&st.stdout).unwrap();
    let text = &summary["plan"]["text"];
    assert_eq!(text["canvas"]["width"], 64, "{summary}");
    assert_eq!(text["canvas"]["sample_width"], 56, "{summary}");
    assert_eq!(text["negative_prompt"], "blurry", "{summary}");
    let st = run(&["--width", "320", "--height", "180"], &model);
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    // The canvas in pixels; the viewBox on the writer's coordinate grid (k user units per px).
    let svg = std::fs::read_to_string(&out).unwrap();
    assert!(svg.contains(r#"width="320" height="180""#), "{svg}");
    let [x, y, w, h] = view_box(&svg);
    let k = w / 320.0;
    assert!(
        x == 0.0 && y == 0.0 && k >= 1.0 && k == k.round() && h == 180.0 * k,
        "{svg}"
    );
    for (flags, field) in [
        (
            &["--aspect", "16:9", "--width", "320", "--height", "180"][..],
            "width",
        ),
        (&["--width", "320"][..], "height"),
        (&["--width", "32", "--height", "32"][..], "width"),
        (&["--aspect", "5:4"][..], "aspect"),
    ] {
        let st = run(flags, &model);
        let err = String::from_utf8_lossy(&st.stderr);
        assert_eq!(st.status.code(), Some(2), "{flags:?}: {err}");
        assert!(err.contains(field), "{flags:?}: {err}");
    }
    // The analytic test teacher has no guidance branch to put a negative prompt in.
    let targets = common::red_square_targets(dir.path());
    let teacher = format!("analytic:{}", targets.display());
    let st = run(
        &["--negative-prompt", "blurry", "--method", "scratch"],
        &["--teacher", teacher.as_str()],
    );
    let err = String::from_utf8_lossy(&st.stderr);
    assert_eq!(st.status.code(), Some(2), "{err}");
    assert!(err.contains("--negative-prompt"), "{err}");
}

fn sd_tiny(dir: &Path) -> SdTeacher {
    SdTeacher::load(dir, 32).unwrap()
}

#[test]
fn a_negative_prompt_reaches_sampling_and_sds() {
    let m = runs::executor(fixture("sd-tiny"), None);
    let r = PlanRequest {
        negative_prompt: Some("blurry, text".into()),
        canvas: CanvasRequest::default(),
        ..req(Method::SdLiveSds, Style::Iconography)
    };
    let plan = runs::plan(&m, &r);
    let text = plan.text.as_ref().unwrap();
    assert_eq!(text.negative_prompt.as_deref(), Some("blurry, text"));
    assert_eq!(text.sds_config().unwrap().negative_prompt, "blurry, text");
    let (paths, seen) = run_recorded(sd_tiny(&fixture("sd-tiny")), &plan);
    assert!(paths > 0);
    assert_eq!(seen, ["sample: blurry, text", "sds: blurry, text"]);

    // And it changes what the model draws: the unconditional branch embeds it.
    let teacher = sd_tiny(&fixture("sd-tiny"));
    let draw = |negative: &str| {
        let cfg = SampleConfig {
            k: 1,
            steps: 3,
            guidance: 7.5,
            seed: 1,
            strength: 1.0,
            negative_prompt: negative.into(),
            size_conditioning: None,
        };
        teacher
            .sample("a crown", &[], &cfg, &NullSink, &CancelToken::new())
            .unwrap()
    };
    assert_eq!(draw("").len(), 1);
    assert_ne!(draw("")[0].data, draw("blurry, text")[0].data);
    assert_eq!(draw("blurry")[0].data, draw("blurry")[0].data);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_16_9_text_job_through_the_service() {
    let srv = TestServer::with_model(fixture("sd-tiny")).await;
    let a = srv.addr;
    let job = srv
        .submit(
            &json!({"kind": "text", "caption": "a crown", "method": "sd_live",
            "preset": "draft", "samples": 2, "seed": 5, "aspect": "16:9",
            "negative_prompt": "blurry"}),
        )
        .await;
    let id = job["id"].as_str().unwrap().to_string();
    assert_eq!(job["params"]["aspect"], "16:9", "{job}");
    assert_eq!(job["params"]["negative_prompt"], "blurry", "{job}");
    assert_eq!(
        job["params"]["plan"]["text"]["canvas"]["height"], 36,
        "{job}"
    );
    wait_status(a, &id, &["succeeded"], Duration::from_secs(120)).await;
    let r = get(a, &format!("/jobs/{id}/result.svg")).await;
    assert_eq!(r.status, 200);
    assert_16_9(&r.text());
    // A width without a height is refused, naming the missing field.
    let r = post_json(
        a,
        "/jobs",
        &json!({"kind": "text", "caption": "x", "width": 640}),
    )
    .await;
    assert_eq!(r.status, 400, "{}", r.text());
    assert_eq!(r.json()["error"]["field"], "height");
    // Stable Diffusion 1.x has no size conditioning (SDXL's): refused, naming the field.
    let body = json!({"kind": "text", "caption": "x", "size_conditioning": {"crop_top": 0}});
    let r = post_json(a, "/jobs", &body).await;
    assert_eq!(r.status, 400, "{}", r.text());
    assert_eq!(r.json()["error"]["field"], "size_conditioning");
    srv.stop().await;
}
