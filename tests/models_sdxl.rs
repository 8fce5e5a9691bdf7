//! Equivalence of the SDXL components with diffusers/transformers on the tiny random-weight
//! SDXL-architecture fixture produced by `scripts/make_sdxl_fixtures.py` (fp32, max abs error
//! ≤ 1e-4).

mod common;
use common::{abs_max, assert_close, fixture, max_abs};

use candle_core::{Device, Tensor};
use std::collections::HashMap;
use vectorfusion::image::Image;
use vectorfusion::models::scheduler::{Sampler, SamplerKind, SamplerRun};
use vectorfusion::models::sdxl_text::SdxlTextEncoders;
use vectorfusion::models::stable_diffusion::load_unet;
use vectorfusion::models::unet::{AddedCond, Unet};
use vectorfusion::models::{LoadOptions, ModelError, Precision, StableDiffusion, TextCond};
use vectorfusion::stages::sds::{Weighting, sds_image_grad};
use vectorfusion::teacher::{SdTeacher, Teacher};

fn refs() -> HashMap<String, Tensor> {
    candle_core::safetensors::load(fixture("sdxl-tiny").join("refs.safetensors"), &Device::Cpu)
        .unwrap()
}

fn unet() -> Unet {
    load_unet(
        &fixture("sdxl-tiny").join("unet"),
        Precision::F32,
        &Device::Cpu,
    )
    .unwrap()
}

#[test]
fn sdxl_unet_config_resolves_the_real_architecture() {
    let u = unet();
    let a = &u.arch;
    let layers: Vec<_> = a
        .levels
        .iter()
        .map(|l| l.down_attn.map(|x| x.layers))
        .collect();
    assert_eq!(layers, [None, Some(2), Some(2)]);
    assert_eq!(a.mid.layers, 2);
    let tt = a.text_time.unwrap();
    assert_eq!((tt.time_dim, tt.pooled_dim()), (8, 32));
    // the full-size SDXL base config resolves too (2048-wide context, 10-deep transformers)
    let full = vectorfusion::models::unet::UnetConfig::sdxl()
        .arch()
        .unwrap();
    assert_eq!(full.cross_attention_dim, 2048);
    assert_eq!(full.mid.layers, 10);
    assert_eq!(full.text_time.unwrap().pooled_dim(), 1280);
}

#[test]
fn sdxl_unet_matches_diffusers() {
    let u = unet();
    let r = refs();
    let (z, ctx) = (&r["unet.z"], &r["text.context"]);
    for (ids, key) in [("unet.time_ids", "cond"), ("unet.time_ids2", "cond2")] {
        let added = AddedCond {
            text_embeds: r["text.pooled"].clone(),
            time_ids: r[ids].clone(),
        };
        for t in [999usize, 500, 10] {
            let out = u.forward_added(z, t as f64, ctx, Some(&added)).unwrap();
            assert_close(
                &format!("{key} t={t}"),
                &out,
                &r[&format!("unet.{key}.t{t}")],
                1e-4,
            );
        }
    }
    // the size/crop conditioning changes the output (each time id enters)
    let d = max_abs(&r["unet.cond.t500"], &r["unet.cond2.t500"]);
    assert!(d > 1e-3, "time ids had no effect on the reference: {d}");
}

#[test]
fn sdxl_unet_refuses_to_run_without_its_added_conditioning() {
    let u = unet();
    let r = refs();
    let (z, ctx) = (&r["unet.z"], &r["text.context"]);
    let e = u.forward(z, 500.0, ctx).unwrap_err();
    assert!(matches!(e, ModelError::InvalidInput(_)), "{e}");
    assert!(e.to_string().contains("added conditioning"), "{e}");
    // wrong widths: pooled embedding of the wrong size, 5 time ids
    for (te, ids) in [
        (
            Tensor::zeros((1, 31), candle_core::DType::F32, &Device::Cpu).unwrap(),
            r["unet.time_ids"].clone(),
        ),
        (
            r["text.pooled"].clone(),
            r["unet.time_ids"].narrow(1, 0, 5).unwrap(),
        ),
    ] {
        let added = AddedCond {
            text_embeds: te,
            time_ids: ids,
        };
        let e = u.forward_added(z, 500.0, ctx, Some(&added)).unwrap_err();
        assert!(matches!(e, ModelError::InvalidInput(_)), "{e}");
    }
}

#[test]
fn sdxl_text_encoders_match_transformers() {
    let root = fixture("sdxl-tiny");
    let te = SdxlTextEncoders::load(&root, Precision::F32, &Device::Cpu).unwrap();
    let r = refs();
    // both tokenizers, the second padding with "!"
    for (tok, key) in [(&te.tokenizer, "text.ids1"), (&te.tokenizer_2, "text.ids2")] {
        let want: Vec<u32> = r[key]
            .flatten_all()
            .unwrap()
            .to_vec1::<i64>()
            .unwrap()
            .into_iter()
            .map(|v| v as u32)
            .collect();
        assert_eq!(tok.encode_padded("a red cat"), want, "{key}");
    }
    assert_ne!(te.tokenizer.pad_id, te.tokenizer_2.pad_id);
    assert_eq!((te.context_dim(), te.pooled_dim()), (48, 32));
    let e = te.embed("a red cat", &Device::Cpu).unwrap();
    assert_close("context", &e.context, &r["text.context"], 1e-4);
    assert_close("pooled", &e.pooled, &r["text.pooled"], 1e-4);
    let e = te.embed("", &Device::Cpu).unwrap();
    assert_close("empty context", &e.context, &r["text.context_empty"], 1e-4);
    assert_close("empty pooled", &e.pooled, &r["text.pooled_empty"], 1e-4);
    // force_zeros_for_empty_prompt: the empty negative prompt is zeros, a written one is not
    assert!(te.zeros_for_empty);
    let n = te.embed_negative("", &Device::Cpu).unwrap();
    assert_eq!(n.context.dims(), [1, 77, 48]);
    assert_eq!(abs_max(&n.context) + abs_max(&n.pooled), 0.0);
    let n = te.embed_negative("a red cat", &Device::Cpu).unwrap();
    assert_close("negative", &n.pooled, &r["text.pooled"], 1e-4);
}

#[test]
fn sdxl_text_embeddings_drive_the_unet() {
    let te = SdxlTextEncoders::load(&fixture("sdxl-tiny"), Precision::F32, &Device::Cpu).unwrap();
    let r = refs();
    let e = te.embed("a red cat", &Device::Cpu).unwrap();
    let added = AddedCond {
        text_embeds: e.pooled,
        time_ids: r["unet.time_ids"].clone(),
    };
    let out = unet()
        .forward_added(&r["unet.z"], 500.0, &e.context, Some(&added))
        .unwrap();
    assert_close("prompt → unet t=500", &out, &r["unet.cond.t500"], 1e-4);
}

fn pipeline() -> StableDiffusion {
    StableDiffusion::load(&fixture("sdxl-tiny"), &LoadOptions::default()).unwrap()
}

/// The whole SDXL directory: `text_cond` gives diffusers' conditioning (both encoders, the
/// pooled embedding, zeros for the empty negative prompt, the size time ids of the image), and
/// the guided sampler driven as `StableDiffusionXLPipeline.__call__` does it (the scheduler's
/// Euler, leading spacing, 3 steps, guidance 5, 32 px) follows the reference trajectory.
#[test]
fn sdxl_pipeline_samples_the_reference_euler_trajectory() {
    let sd = pipeline();
    let r = refs();
    assert!(sd.is_sdxl());
    let (cond, uncond) = sd.text_cond("a red cat", "", (32, 32)).unwrap();
    assert_close("context", &cond.context, &r["text.context"], 1e-4);
    let (ca, ua) = (cond.added.as_ref().unwrap(), uncond.added.as_ref().unwrap());
    assert_close("pooled", &ca.text_embeds, &r["text.pooled"], 1e-4);
    assert_close("time ids", &ca.time_ids, &r["unet.time_ids"], 0.0);
    assert_close("negative time ids", &ua.time_ids, &r["unet.time_ids"], 0.0);
    assert_eq!(abs_max(&uncond.context) + abs_max(&ua.text_embeds), 0.0);
    let kind = SamplerKind::of(&sd.scheduler);
    assert_eq!(kind, SamplerKind::Euler);
    let ts = Sampler::new(&sd.scheduler, kind, 3).unwrap().timesteps;
    let want: Vec<f32> = r["traj.timesteps"].to_vec1().unwrap();
    assert_eq!(ts, want.iter().map(|&t| t as f64).collect::<Vec<_>>());
    let traj = sd
        .sample(
            &r["traj.init"],
            &cond,
            &uncond,
            5.0,
            SamplerRun::plain(kind, 3),
        )
        .unwrap();
    assert_eq!(traj.len(), 3);
    for (i, x) in traj.iter().enumerate() {
        // latents of scale ~12 (σ_max ≈ 14.6 at the start); measured: ≤ 3.6e-5
        assert_close(&format!("step {i}"), x, &r[&format!("traj.step{i}")], 1e-4);
    }
}

/// A written negative prompt is embedded (no zeros), and the time ids follow a non-square
/// image: `[h, w, 0, 0, h, w]`.
#[test]
fn sdxl_negative_prompt_and_canvas_reach_the_conditioning() {
    let sd = pipeline();
    let (cond, uncond) = sd.text_cond("a red cat", "blurry", (64, 32)).unwrap();
    assert!(abs_max(&uncond.added.unwrap().text_embeds) > 0.0);
    let ids: Vec<f32> = cond
        .added
        .unwrap()
        .time_ids
        .flatten_all()
        .unwrap()
        .to_vec1()
        .unwrap();
    assert_eq!(ids, [32.0, 64.0, 0.0, 0.0, 32.0, 64.0]);
    // a conditioning without its added part is refused by the UNet, not run
    let r = refs();
    let bare = TextCond::from(r["text.context"].clone());
    let e = sd
        .predict_noise(&r["unet.z"], 500, &bare, &bare, 5.0)
        .unwrap_err();
    assert!(e.to_string().contains("added conditioning"), "{e}");
}

/// An SDS step through the SDXL teacher: finite, non-zero image gradients, the same twice.
#[test]
fn sdxl_teacher_sds_step_is_finite_and_deterministic() {
    let te = SdTeacher::load(&fixture("sdxl-tiny"), 32).unwrap();
    assert!(te.name().contains("Stable Diffusion XL"), "{}", te.name());
    let c = te.condition("a red cat", "").unwrap();
    let added = c.added.as_ref().unwrap();
    assert_eq!(added.time_ids, [32.0, 32.0, 0.0, 0.0, 32.0, 32.0]);
    assert_eq!(added.pooled.len(), 32);
    let mut im = Image::filled(32, 32, [0.9, 0.5, 0.2, 1.0]);
    for (i, v) in im.data.iter_mut().enumerate() {
        *v *= 0.5 + 0.5 * ((i % 7) as f32 / 7.0);
    }
    let [ch, h, w] = te.latent_shape();
    let noise: Vec<f32> = (0..ch * h * w)
        .map(|i| ((i * 37 % 101) as f32 / 50.0) - 1.0)
        .collect();
    let step = || sds_image_grad(&te, &im, 600, &noise, &c, 7.5, Weighting::OneMinusAlpha).unwrap();
    let (g, _) = step();
    assert_eq!(g.len(), 4 * 32 * 32);
    assert!(g.iter().all(|v| v.is_finite()));
    assert!(g.iter().any(|v| *v != 0.0));
    assert_eq!(step().0, g, "the same step twice");
    // the pooled embedding enters: another prompt moves the gradient
    let c2 = te.condition("a blue dog", "").unwrap();
    let (g2, _) =
        sds_image_grad(&te, &im, 600, &noise, &c2, 7.5, Weighting::OneMinusAlpha).unwrap();
    assert_ne!(g, g2);
}
