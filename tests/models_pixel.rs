//! Pixel-space models (`docs/EMBEDDED.md`: a diffusers directory without `vae/`) against
//! diffusers on `tests/fixtures/sd-tiny-pixel` (`scripts/make_pixel_fixtures.py`), the TAESD SDS
//! encoder against its diffusers reference, and the loader's pixel-space detection.

mod common;
use common::{assert_close, fixture, max_abs, tc};

use candle_core::{DType, Device, Tensor};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use vectorfusion::image::Image;
use vectorfusion::models::codec::CodecKind;
use vectorfusion::models::scheduler::{SamplerKind, SamplerRun};
use vectorfusion::models::stable_diffusion::ModelHints;
use vectorfusion::models::{LoadOptions, ModelError, StableDiffusion};
use vectorfusion::stages::sds::{Weighting, sds_image_grad};
use vectorfusion::teacher::{Conditioning, SdTeacher, Teacher};

fn refs(path: PathBuf) -> HashMap<String, Tensor> {
    candle_core::safetensors::load(path, &Device::Cpu).unwrap()
}

fn pixel_refs() -> HashMap<String, Tensor> {
    refs(fixture("sd-tiny-pixel").join("refs.safetensors"))
}

fn pixel() -> StableDiffusion {
    StableDiffusion::load(&fixture("sd-tiny-pixel"), &LoadOptions::default()).unwrap()
}

#[test]
fn directory_without_vae_loads_as_pixel_space() {
    let sd = pixel();
    assert!(sd.is_pixel_space());
    assert_eq!(sd.codec.kind(), CodecKind::Pixel);
    assert!(sd.vae().is_none());
    assert_eq!(sd.latent_side(128), Ok(16));
    assert_eq!(sd.latent_side(40), Ok(16));
    // A TAESD given in the options is ignored by pixel-space models.
    let opts = LoadOptions {
        taesd: Some(fixture("taesd-tiny")),
        ..LoadOptions::default()
    };
    let sd = StableDiffusion::load(&fixture("sd-tiny-pixel"), &opts).unwrap();
    assert!(sd.is_pixel_space());
}

#[test]
fn pixel_unet_and_guidance_match_diffusers() {
    let sd = pixel();
    let r = pixel_refs();
    let (z, cond, uncond) = (&r["unet.z"], &r["text.cond"], &r["text.uncond"]);
    let (c2, u2) = sd.text_embeddings("a red cat").unwrap();
    assert_close("cond emb", &c2, cond, 1e-4);
    assert_close("uncond emb", &u2, uncond, 1e-4);
    for t in [999usize, 500, 10] {
        let out = sd.unet.forward(z, t as f64, cond).unwrap();
        assert_close(
            &format!("cond t={t}"),
            &out,
            &r[&format!("unet.cond.t{t}")],
            1e-4,
        );
        let g = sd.predict_noise(z, t, &tc(cond), &tc(uncond), 7.5).unwrap();
        assert_close(
            &format!("guided t={t}"),
            &g,
            &r[&format!("unet.guided.t{t}")],
            1e-4,
        );
        // diffusers with the tanh GELU (candle-transformers' UNet) is measurably further off
        let tanh = max_abs(&g, &r[&format!("unet_tanh.guided.t{t}")]);
        assert!(
            tanh > 5.0 * max_abs(&g, &r[&format!("unet.guided.t{t}")]),
            "t={t}"
        );
    }
}

#[test]
fn squaredcos_schedule_and_four_step_ddim_sample_match_diffusers() {
    let sd = pixel();
    let r = pixel_refs();
    let want: Vec<f32> = r["sched.alphas_cumprod"].to_vec1().unwrap();
    assert_eq!(want.len(), sd.alphas_cumprod().len());
    for (a, b) in sd.alphas_cumprod().iter().zip(&want) {
        assert!((*a as f32 - b).abs() < 1e-6, "{a} vs {b}");
    }
    let traj = sd
        .sample(
            &r["ddim.init"],
            &tc(&r["text.cond"]),
            &tc(&r["text.uncond"]),
            7.5,
            SamplerRun::plain(SamplerKind::Ddim, 4),
        )
        .unwrap();
    assert_eq!(traj.len(), 4);
    for (i, x) in traj.iter().enumerate() {
        assert_close(
            &format!("ddim step {i}"),
            x,
            &r[&format!("ddim.step{i}")],
            1e-4,
        );
    }
    let img = sd.decode(&traj[3]).unwrap();
    assert_eq!(img.dims(), &[1, 3, 16, 16], "decoded at the sample size");
}

#[test]
fn sdedit_keeps_its_start_at_strength_zero_and_runs_the_tail_of_the_schedule() {
    let sd = pixel();
    let r = pixel_refs();
    let (cond, uncond) = (&tc(&r["text.cond"]), &tc(&r["text.uncond"]));
    let init = &r["ddim.init"];
    let noise = (init * 0.5).unwrap();
    let same = sd
        .sample_from(init, &noise, 0.0, cond, uncond, 7.5, 4)
        .unwrap();
    assert_eq!(same.len(), 1);
    assert_close("strength 0", &same[0], init, 0.0);
    // strength 0.5 of 4 steps: the last two DDIM steps, from the schedule's third timestep
    let half = sd
        .sample_from(init, &noise, 0.5, cond, uncond, 7.5, 4)
        .unwrap();
    assert_eq!(half.len(), 2);
    let full = sd
        .sample_from(init, &noise, 1.0, cond, uncond, 7.5, 4)
        .unwrap();
    assert_eq!(full.len(), 4);
    let d = (&half[1] - &full[3]).unwrap().abs().unwrap();
    let d: f32 = d.max_all().unwrap().to_scalar().unwrap();
    assert!(d > 1e-4, "a later start gives another sample");
    for s in [-0.1, 1.5, f64::NAN] {
        assert!(
            sd.sample_from(init, &noise, s, cond, uncond, 7.5, 4)
                .is_err(),
            "{s}"
        );
    }
    // strength 1 from a zero start, with the noise scaled by 1/sqrt(1 - ᾱ) of the first
    // timestep, is sampling from that noise
    let t0 = vectorfusion::models::scheduler::Sampler::new(&sd.scheduler, SamplerKind::Ddim, 4)
        .unwrap()
        .timesteps[0];
    let abar = sd.alphas_cumprod()[t0 as usize];
    let zero = init.zeros_like().unwrap();
    let scaled = (init / (1.0 - abar).sqrt()).unwrap();
    let a = sd
        .sample_from(&zero, &scaled, 1.0, cond, uncond, 7.5, 4)
        .unwrap();
    let b = sd
        .sample(
            init,
            cond,
            uncond,
            7.5,
            SamplerRun::plain(SamplerKind::Ddim, 4),
        )
        .unwrap();
    assert_close("strength 1 = sample", &a[3], &b[3], 1e-3);
}

#[test]
fn pixel_encode_and_its_vjp_match_torch_area_interpolation() {
    let sd = pixel();
    let r = pixel_refs();
    for side in [64, 40] {
        let img = &r[&format!("encode.image{side}")];
        let lat = sd.encode(img).unwrap();
        assert_close(
            &format!("latents {side}"),
            &lat,
            &r[&format!("encode.latents{side}")],
            1e-5,
        );
        let d = sd.encode_vjp(img, &r["encode.d_latents"]).unwrap();
        assert_close(
            &format!("d_image {side}"),
            &d,
            &r[&format!("encode.d_image{side}")],
            1e-5,
        );
    }
    let bad = Tensor::zeros((1, 4, 8, 8), DType::F32, &Device::Cpu).unwrap();
    assert!(matches!(sd.encode(&bad), Err(ModelError::InvalidInput(_))));
}

fn opaque(t: &Tensor) -> Image {
    let dims = t.dims().to_vec();
    let (h, w) = (dims[2], dims[3]);
    let v: Vec<f32> = t.flatten_all().unwrap().to_vec1().unwrap();
    let n = h * w;
    let mut im = Image::new(w as u32, h as u32);
    for i in 0..n {
        for c in 0..3 {
            im.data[4 * i + c] = v[c * n + i];
        }
        im.data[4 * i + 3] = 1.0;
    }
    im
}

fn flat(t: &Tensor) -> Vec<f32> {
    t.flatten_all().unwrap().to_vec1().unwrap()
}

/// The teacher's premultiplied-RGBA gradient against a `[1, 3, H, W]` reference (alpha gets
/// `−Σ_c`), within the GELU tolerance.
fn assert_image_grad(name: &str, g: &[f32], want: &Tensor) {
    let n = want.elem_count() / 3;
    let want = flat(want);
    let s = want.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(s > 1e-4, "{name}: reference is trivially small ({s})");
    let tol = 2e-4 * s.max(1.0);
    let mut err = 0.0f32;
    for i in 0..n {
        let mut sum = 0.0;
        for c in 0..3 {
            err = err.max((g[4 * i + c] - want[c * n + i]).abs());
            sum += want[c * n + i];
        }
        err = err.max((g[4 * i + 3] + sum).abs());
    }
    assert!(err <= tol, "{name}: max abs err {err} > {tol} (scale {s})");
}

#[test]
fn sds_image_gradient_through_the_pixel_teacher_matches_diffusers() {
    let r = pixel_refs();
    // 64 px renders, area-resized to the 16 px prior inside the encoder.
    let te = SdTeacher::load(&fixture("sd-tiny-pixel"), 64).unwrap();
    assert_eq!(te.latent_shape(), [3, 16, 16]);
    assert_eq!(te.encoder(), "pixel");
    assert!(te.name().contains("pixel"), "{}", te.name());
    let c = Conditioning {
        prompt: "a red cat".into(),
        negative_prompt: String::new(),
        embed_shape: r["text.cond"].dims().to_vec(),
        cond: flat(&r["text.cond"]),
        uncond: flat(&r["text.uncond"]),
        added: None,
    };
    let im = opaque(&r["encode.image64"]);
    let (g, _) = sds_image_grad(
        &te,
        &im,
        600,
        &flat(&r["sds.noise"]),
        &c,
        7.5,
        Weighting::OneMinusAlpha,
    )
    .unwrap();
    assert_image_grad("pixel sds", &g, &r["sds.d_image"]);
}

#[test]
fn sds_image_gradient_with_taesd_as_the_encoder_matches_diffusers() {
    let r = refs(fixture("taesd-tiny").join("sds_refs.safetensors"));
    let sd_refs = refs(fixture("sd-tiny").join("refs.safetensors"));
    let te = SdTeacher::load_with(&fixture("sd-tiny"), 64, Some(&fixture("taesd-tiny"))).unwrap();
    assert_eq!(te.encoder(), "taesd");
    assert_eq!(te.latent_shape(), [4, 8, 8]);
    let im = opaque(&r["image"]);
    let z = te.encode(&im).unwrap();
    let zr = Tensor::from_vec(z.data.clone(), (1, 4, 8, 8), &Device::Cpu).unwrap();
    assert_close("taesd latents", &zr, &r["latents"], 1e-4);
    let c = Conditioning {
        prompt: "a red cat".into(),
        negative_prompt: String::new(),
        embed_shape: sd_refs["text.cond"].dims().to_vec(),
        cond: flat(&sd_refs["text.cond"]),
        uncond: flat(&sd_refs["text.uncond"]),
        added: None,
    };
    let (g, _) = sds_image_grad(
        &te,
        &im,
        600,
        &flat(&r["noise"]),
        &c,
        7.5,
        Weighting::OneMinusAlpha,
    )
    .unwrap();
    assert_image_grad("taesd sds", &g, &r["d_image"]);
    // and the VAE teacher on the same model differs (the choice is real)
    let vae = SdTeacher::load(&fixture("sd-tiny"), 64).unwrap();
    assert_eq!(vae.encoder(), "vae");
    assert_ne!(vae.encode(&im).unwrap().data, z.data);
}

fn copy_dir(src: &Path, dst: &Path) {
    std::fs::create_dir_all(dst).unwrap();
    for e in std::fs::read_dir(src).unwrap() {
        let e = e.unwrap();
        let p = e.path();
        if p.is_dir() {
            copy_dir(&p, &dst.join(e.file_name()));
        } else {
            std::fs::copy(&p, dst.join(e.file_name())).unwrap();
        }
    }
}

#[test]
fn loader_tells_pixel_space_from_a_latent_model_with_missing_files() {
    let base = std::env::temp_dir().join(format!("vf-pixel-detect-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&base);
    // An SD directory whose vae/ is gone but whose model_index.json names a VAE: missing files.
    let sd = base.join("sd");
    copy_dir(&fixture("sd-tiny"), &sd);
    std::fs::remove_dir_all(sd.join("vae")).unwrap();
    let e = StableDiffusion::load(&sd, &LoadOptions::default()).unwrap_err();
    assert!(matches!(e, ModelError::MissingFiles { .. }), "{e}");
    assert!(e.to_string().contains("vae"), "{e}");
    // Without the "vae" entry it is a pixel-space model, and a 4-channel UNet is refused.
    std::fs::write(
        sd.join("model_index.json"),
        r#"{"unet": ["diffusers", "UNet2DConditionModel"]}"#,
    )
    .unwrap();
    let e = StableDiffusion::load(&sd, &LoadOptions::default()).unwrap_err();
    assert!(matches!(e, ModelError::Unsupported { .. }), "{e}");
    assert!(e.to_string().contains("pixel"), "{e}");
    let _ = std::fs::remove_dir_all(&base);
}

/// `"_style_suffix": false` in `model_index.json` (a model trained on bare captions) turns the
/// paper's style suffix off for prompts; `_sample_guidance` / `_sds_guidance` set the model's
/// guidance defaults; `_sdedit_strength` the strength of retrieved starts, `_retrieval_share` how
/// many start from icons and `_retrieval_per_caption` how many drawings of one caption; absent
/// keys keep the paper's values; bad values are refused.
#[test]
fn model_index_style_suffix_switch() {
    assert_eq!(pixel().hints, ModelHints::default(), "SD defaults");
    assert!(ModelHints::default().style_suffix);
    let base = std::env::temp_dir().join(format!("vf-style-suffix-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&base);
    let dir = base.join("m");
    copy_dir(&fixture("sd-tiny-pixel"), &dir);
    let index = dir.join("model_index.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&index).unwrap()).unwrap();
    v["_style_suffix"] = serde_json::json!(false);
    v["_sample_guidance"] = serde_json::json!(3.0);
    v["_sdedit_strength"] = serde_json::json!(0.25);
    v["_retrieval_share"] = serde_json::json!(1.0);
    v["_retrieval_per_caption"] = serde_json::json!(2);
    std::fs::write(&index, v.to_string()).unwrap();
    let sd = StableDiffusion::load(&dir, &LoadOptions::default()).unwrap();
    assert!(!sd.hints.style_suffix);
    assert_eq!(sd.hints.sample_guidance, 3.0);
    assert_eq!(sd.hints.sds_guidance, 100.0, "absent: the default");

    // The hints reach the plan: the bare caption and the sampling guidance.
    use vectorfusion::pipeline::{DefaultExecutor, Executor, Limits, ModelDirs, PlanRequest};
    use vectorfusion::stages::styles::Style as S;
    use vectorfusion::teacher::Teacher;
    let plan_of = |d: &Path| {
        DefaultExecutor::with_downloads(ModelDirs {
            sd_dir: Some(d.to_path_buf()),
            ..ModelDirs::default()
        })
        .plan(&PlanRequest::text(" a crown "), &Limits::default())
        .unwrap()
        .text
        .unwrap()
    };
    let bare = plan_of(&dir);
    assert_eq!(bare.prompt, "a crown");
    assert_eq!(bare.sample.as_ref().unwrap().guidance, 3.0);
    assert_eq!(bare.sample.as_ref().unwrap().strength, 0.25);
    assert_eq!(bare.sample.as_ref().unwrap().retrieval_share, 1.0);
    assert_eq!(bare.sample.as_ref().unwrap().retrieval_per_caption, 2);
    let with = plan_of(&fixture("sd-tiny-pixel"));
    assert_eq!(with.prompt, S::Iconography.prompt("a crown"));
    assert_eq!(with.sample.as_ref().unwrap().guidance, 7.5);
    assert_eq!(
        with.sample.as_ref().unwrap().strength,
        0.4,
        "absent: the default"
    );
    assert_eq!(with.sample.as_ref().unwrap().retrieval_share, 0.5);
    assert_eq!(with.sample.as_ref().unwrap().retrieval_per_caption, 1);
    // `_sample_guidance` reaches the sampler: the same prompt, seed and noise, another image.
    let draw = |d: &Path| {
        let t = vectorfusion::teacher::SdTeacher::load(d, 64).unwrap();
        let cfg = vectorfusion::teacher::SampleConfig {
            k: 1,
            steps: 3,
            guidance: f64::from(t.hints().sample_guidance),
            seed: 7,
            strength: 0.6,
            negative_prompt: String::new(),
            size_conditioning: None,
        };
        let sink = vectorfusion::progress::NullSink;
        let cancel = vectorfusion::progress::CancelToken::new();
        t.sample("a crown", &[], &cfg, &sink, &cancel).unwrap()[0]
            .data
            .clone()
    };
    assert_ne!(draw(&dir), draw(&fixture("sd-tiny-pixel")));

    v["_style_suffix"] = serde_json::json!("no");
    std::fs::write(&index, v.to_string()).unwrap();
    let e = StableDiffusion::load(&dir, &LoadOptions::default()).unwrap_err();
    assert!(e.to_string().contains("model_index.json"), "{e}");
    v["_style_suffix"] = serde_json::json!(false);
    // Each out-of-range hint is refused, naming its key; then it is set back to a good value.
    use serde_json::json;
    for (key, bad, good) in [
        ("_sds_guidance", json!(-1.0), json!(100.0)),
        ("_sdedit_strength", json!(1.5), json!(0.3)),
        ("_retrieval_share", json!(-0.5), json!(0.5)),
        ("_retrieval_per_caption", json!(0), json!(1)),
    ] {
        v[key] = bad;
        std::fs::write(&index, v.to_string()).unwrap();
        let e = StableDiffusion::load(&dir, &LoadOptions::default()).unwrap_err();
        assert!(e.to_string().contains(key), "{e}");
        v[key] = good;
    }
    let _ = std::fs::remove_dir_all(&base);
}
