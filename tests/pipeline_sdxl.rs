//! The pipeline on the tiny random-weight SDXL fixture (`tests/fixtures/sdxl-tiny`, the real
//! SDXL architecture at tiny widths): every method samples, reranks, traces and distils with the
//! dual text encoders and the pooled/size conditioning, at the canvas's aspect; `generate`
//! writes the SVG.

mod common;

use common::fixture;
use common::runs::{self, assert_valid_svg};
use std::path::Path;
use vectorfusion::pipeline::{Aspect, Method, PlanRequest, Preset};

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
