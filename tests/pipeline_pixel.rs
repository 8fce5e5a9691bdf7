//! The shared pipeline on the tiny pixel-space fixture (`tests/fixtures/sd-tiny-pixel`, no vae/,
//! 16 px prior): every method produces a valid SVG; TAESD as the SDS encoder of the tiny SD
//! model; the default-model resolution of `generate` and the service executor.

mod common;

use common::runs::{self, assert_valid_svg};
use std::path::PathBuf;
use vectorfusion::pipeline::{
    DefaultExecutor, EncoderChoice, Executor, JobContext, JobKind, JobSpec, Method, ModelDirs,
    PlanRequest, Preset, Style,
};
use vectorfusion::progress::CancelToken;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn req(method: Method, style: Style) -> PlanRequest {
    PlanRequest {
        style,
        method,
        preset: Preset::Draft,
        steps: Some(3),
        samples: Some(2),
        seed: 3,
        ..PlanRequest::text("a crown")
    }
}

#[test]
fn every_method_runs_on_the_pixel_space_model() {
    // 64 px renders for a 16 px prior; samples (16 px) are upscaled to the 64 px trace canvas.
    let m = runs::executor(fixture("sd-tiny-pixel"), Some(fixture("clip-tiny")));
    assert!(m.small_prior());
    for method in Method::ALL {
        for style in [Style::Iconography, Style::PixelArt] {
            let out = runs::run(&m, &req(*method, style))
                .unwrap_or_else(|e| panic!("{method:?} {style:?}: {e}"));
            assert_valid_svg(&out.svg);
            assert!(out.paths > 0, "{method:?} {style:?}: empty scene");
            assert_eq!(out.scene.width, 64);
            let d = &serde_json::to_value(&out.report).unwrap();
            assert_eq!(d["encoder"], "pixel", "{d}");
            match method {
                Method::Scratch => assert_eq!(d["sds"]["steps_done"], 3),
                Method::SdLive => {
                    assert_eq!(d["rerank"]["scores"].as_array().unwrap().len(), 2);
                    assert!(d["sds"].is_null());
                }
                Method::SdLiveSds => {
                    assert_eq!(d["sds"]["steps_done"], 3);
                    assert_eq!(d["sds"]["augment"], false);
                }
            }
            if style == Style::Iconography && *method != Method::Scratch {
                // traced at the pixel preset's canvas, not at the 16 px sample size
                assert!(d["live"]["paths"].as_u64().unwrap() > 0, "{d}");
            }
        }
    }
}

#[test]
fn sd_live_sds_with_taesd_as_the_encoder() {
    let m = DefaultExecutor::with_downloads(ModelDirs {
        sd_dir: Some(fixture("sd-tiny")),
        clip_dir: Some(fixture("clip-tiny")),
        taesd_dir: Some(fixture("taesd-tiny")),
        encoder: EncoderChoice::Taesd,
        ..ModelDirs::default()
    });
    assert!(!m.small_prior());
    let r = req(Method::SdLiveSds, Style::Iconography);
    let plan = runs::plan(&m, &r);
    assert_eq!(
        plan.text.as_ref().unwrap().model.encoder,
        EncoderChoice::Taesd
    );
    let out = runs::run(&m, &r).unwrap();
    assert_valid_svg(&out.svg);
    let d = serde_json::to_value(&out.report).unwrap();
    assert_eq!(d["encoder"], "taesd");
    assert_eq!(d["sds"]["steps_done"], 3);
    assert!(d["teacher"].as_str().unwrap().contains("TAESD"), "{d}");
}

#[test]
fn service_executor_runs_a_text_job_on_the_default_pixel_model() {
    let dirs = ModelDirs::default().or_default_model(Some(fixture("sd-tiny-pixel")));
    let exec = DefaultExecutor::new(dirs);
    exec.text_ready().unwrap();
    let spec = JobSpec {
        kind: JobKind::Text,
        caption: Some("a crown".into()),
        image: None,
        svg: None,
        style: Style::Iconography,
        method: Method::SdLiveSds,
        paths: Some(4),
        steps: Some(2),
        seed: 1,
        samples: Some(1),
        preset: Preset::Draft,
        priority: 0,
        retrieval: true,
        vector: Default::default(),
        canvas: Default::default(),
        negative_prompt: None,
        size_conditioning: None,
        plan: None,
        variations: None,
    };
    let out = exec
        .run(&spec, &JobContext::detached(CancelToken::new()))
        .unwrap();
    assert_valid_svg(&out.svg);
    // the pixel draft preset's size, not the SD draft's 32 px
    let d = serde_json::to_value(&out.report).unwrap();
    assert_eq!(d["size"], Preset::Draft.settings_for(true).size);
    assert_eq!(d["encoder"], "pixel");
}

fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vf-pixel-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn generate_without_model_uses_the_default_model() {
    let dir = tmpdir("default");
    let out = dir.join("crown.svg");
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
        .args(["generate", "a crown", "--preset", "draft", "--steps", "2"])
        .args(["--samples", "1", "--method", "sd_live_sds", "-o"])
        .arg(&out)
        .env("VF_DEFAULT_MODEL", fixture("sd-tiny-pixel"))
        .env_remove("VECTORFUSION_MODELS_SD_DIR")
        .current_dir(&dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(st.status.success(), "{err}");
    assert!(err.contains("pixel-space"), "{err}");
    assert_valid_svg(&std::fs::read_to_string(&out).unwrap());
    // plain `generate CAPTION -o` (scratch, no preset) on a pixel model runs the pipeline with
    // the small-prior presets: the SVG is written at the default (balanced) preset's 64 px
    let out2 = dir.join("scratch.svg");
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
        .args(["generate", "a crown", "--steps", "2", "-o"])
        .arg(&out2)
        .env("VF_DEFAULT_MODEL", fixture("sd-tiny-pixel"))
        .current_dir(&dir)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let svg = std::fs::read_to_string(&out2).unwrap();
    assert!(svg.contains("width=\"64\""), "{svg}");
    // a bad VF_DEFAULT_MODEL is a usage error naming the variable
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
        .args(["generate", "a crown", "-o"])
        .arg(dir.join("x.svg"))
        .env("VF_DEFAULT_MODEL", dir.join("nope"))
        .output()
        .unwrap();
    assert_eq!(st.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&st.stderr).contains("VF_DEFAULT_MODEL"));
    // --encoder taesd without a TAESD directory is a usage error; with one it runs
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
        .args(["generate", "a crown", "--encoder", "taesd", "--model"])
        .arg(fixture("sd-tiny"))
        .args(["--size", "32", "--steps", "1", "-o"])
        .arg(dir.join("t.svg"))
        .output()
        .unwrap();
    assert_eq!(st.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&st.stderr).contains("--taesd"));
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
        .args(["generate", "a crown", "--encoder", "taesd", "--taesd"])
        .arg(fixture("taesd-tiny"))
        .arg("--model")
        .arg(fixture("sd-tiny"))
        .args(["--size", "32", "--steps", "2", "-o"])
        .arg(dir.join("t.svg"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(st.status.success(), "{err}");
    assert!(err.contains("TAESD encoder"), "{err}");
    assert_valid_svg(&std::fs::read_to_string(dir.join("t.svg")).unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}
