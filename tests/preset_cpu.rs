//! The `cpu` preset: Stable Diffusion at 256 px through TAESD, sized for 2 CPU cores. Its plan on
//! the tiny fixtures (an ordinary sampler, an LCM scheduler, a turbo checkpoint), what it means
//! for the embedded small prior, and `generate --preset cpu` end to end on the tiny model.

use std::path::{Path, PathBuf};
use vectorfusion::pipeline::{
    DefaultExecutor, EncoderChoice, Executor, Limits, ModelDirs, PlanRequest, Preset, TextPlan,
};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// The text plan of "a crown" with `preset` on the model in `sd` (TAESD: the tiny fixture).
fn plan(sd: &Path, preset: Preset) -> TextPlan {
    let exec = DefaultExecutor::new(ModelDirs {
        sd_dir: Some(sd.to_path_buf()),
        taesd_dir: Some(fixture("taesd-tiny")),
        ..ModelDirs::default()
    });
    let req = PlanRequest {
        preset,
        ..PlanRequest::text("a crown")
    };
    exec.plan(&req, &Limits::default()).unwrap().text.unwrap()
}

/// `(size, paths, SDS steps, K, sampler steps, trace size, LIVE iterations)` of a plan.
fn numbers(t: &TextPlan) -> (u32, u32, u32, u32, u32, u32, u32) {
    let s = t.sample.as_ref().unwrap();
    (
        t.size,
        t.paths,
        t.sds.as_ref().unwrap().steps,
        s.samples,
        s.steps,
        t.trace.size,
        t.trace.iters,
    )
}

/// A copy of the tiny model with `scheduler_config.json`'s class and `model_index.json`'s
/// sample guidance replaced.
fn variant(dir: &Path, class: &str, sample_guidance: Option<f32>) -> PathBuf {
    let src = fixture("sd-tiny");
    for part in ["unet", "vae", "text_encoder", "tokenizer", "scheduler"] {
        let to = dir.join(part);
        std::fs::create_dir_all(&to).unwrap();
        for f in std::fs::read_dir(src.join(part)).unwrap() {
            let f = f.unwrap().path();
            std::fs::copy(&f, to.join(f.file_name().unwrap())).unwrap();
        }
    }
    let edit = |path: PathBuf, key: &str, value: serde_json::Value| {
        let mut v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        v[key] = value;
        std::fs::write(path, v.to_string()).unwrap();
    };
    std::fs::copy(src.join("model_index.json"), dir.join("model_index.json")).unwrap();
    edit(
        dir.join("scheduler/scheduler_config.json"),
        "_class_name",
        class.into(),
    );
    if let Some(g) = sample_guidance {
        edit(dir.join("model_index.json"), "_sample_guidance", g.into());
    }
    dir.to_path_buf()
}

#[test]
fn cpu_plan_on_an_ordinary_model_is_the_measured_budget() {
    let t = plan(&fixture("sd-tiny"), Preset::Cpu);
    // 256 px, 64 paths, 80 SDS steps, K = 4 images of 12 sampler steps, LIVE at 256 px, 100
    // iterations per stage; SDS through TAESD.
    assert_eq!(numbers(&t), (256, 64, 80, 4, 12, 256, 100));
    assert_eq!(t.model.encoder, EncoderChoice::Taesd);
    assert_eq!(t.snapshot_every, 20);
    // Cheaper than balanced in every UNet-bound number, the same picture size and LIVE.
    let b = plan(&fixture("sd-tiny"), Preset::Balanced);
    let (c, b) = (numbers(&t), numbers(&b));
    assert_eq!((c.0, c.1, c.5, c.6), (b.0, b.1, b.5, b.6));
    assert!(c.2 < b.2 && c.3 < b.3 && c.4 < b.4, "{c:?} vs {b:?}");
}

#[test]
fn cpu_plan_on_a_few_step_model_draws_more_images_in_fewer_steps() {
    let root = tempfile::tempdir().unwrap();
    let ordinary = numbers(&plan(&fixture("sd-tiny"), Preset::Cpu));
    let lcm = variant(&root.path().join("lcm"), "LCMScheduler", None);
    let turbo = variant(
        &root.path().join("turbo"),
        "EulerAncestralDiscreteScheduler",
        Some(0.0),
    );
    let ancestral = variant(
        &root.path().join("ancestral"),
        "EulerAncestralDiscreteScheduler",
        None,
    );
    for few in [&lcm, &turbo] {
        let n = numbers(&plan(few, Preset::Cpu));
        assert_eq!((n.3, n.4), (8, 4), "{few:?}");
        // Everything but the sampling is the ordinary model's.
        assert_eq!((n.0, n.1, n.2, n.5, n.6), (256, 64, 80, 256, 100));
    }
    // Euler ancestral with guidance is an ordinary checkpoint's sampler.
    assert_eq!(numbers(&plan(&ancestral, Preset::Cpu)), ordinary);
    // The other presets keep their numbers whatever the sampler.
    for p in [Preset::Draft, Preset::Fast, Preset::Balanced, Preset::Paper] {
        let base = numbers(&plan(&fixture("sd-tiny"), p));
        assert_eq!(numbers(&plan(&lcm, p)), base, "{p:?}");
        assert_eq!(numbers(&plan(&turbo, p)), base, "{p:?}");
    }
}

#[test]
fn cpu_on_a_small_prior_is_its_balanced_preset() {
    for few_step in [false, true] {
        assert_eq!(
            Preset::Cpu.settings_for_model(true, few_step),
            Preset::Balanced.settings_for(true)
        );
    }
    let b = Preset::Balanced.settings_for(true);
    // The small prior's balanced run already takes seconds: 2 samples × 12 steps at 64 px.
    assert_eq!(
        (b.size, b.samples, b.sample_steps, b.steps),
        (64, 2, 12, 50)
    );
    // For vectorize runs too, cpu is balanced.
    assert_eq!(Preset::Cpu.live_config(), Preset::Balanced.live_config());
    assert_eq!("CPU".parse::<Preset>(), Ok(Preset::Cpu));
}

#[test]
fn generate_with_the_cpu_preset_runs_end_to_end_on_the_tiny_model() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("crown.svg");
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
        .args(["generate", "a crown", "--preset", "cpu", "--no-retrieval"])
        .arg("--model")
        .arg(fixture("sd-tiny"))
        .arg("--scorer")
        .arg(fixture("clip-tiny"))
        .arg("--taesd")
        .arg(fixture("taesd-tiny"))
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(st.status.success(), "{err}");
    let svg = std::fs::read_to_string(&out).unwrap();
    assert!(svg.contains("<svg") && !svg.contains("NaN"), "{svg}");
    let summary: serde_json::Value = serde_json::from_slice(&st.stdout).unwrap();
    let (plan, detail) = (&summary["plan"]["text"], &summary["detail"]);
    assert_eq!(plan["size"], 256);
    assert_eq!(plan["sample"]["samples"], 4);
    assert_eq!(plan["sample"]["steps"], 12);
    assert_eq!(plan["sds"]["steps"], 80);
    assert_eq!(detail["preset"], "cpu");
    assert_eq!(detail["encoder"], "taesd");
    assert_eq!(detail["rerank"]["scores"].as_array().unwrap().len(), 4);
    assert_eq!(detail["sds"]["steps_done"], 80);
    // Seconds per part: sampling with the rerank, the LIVE trace, SDS; within the run's.
    let part = |v: &serde_json::Value| v["seconds"].as_f64().unwrap();
    let parts = [&detail["rerank"], &detail["live"], &detail["sds"]].map(part);
    assert!(parts.iter().all(|&s| s > 0.0), "{parts:?}");
    assert!(parts.iter().sum::<f64>() <= part(detail) + 1e-6, "{detail}");
}
