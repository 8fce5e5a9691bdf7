//! The autoencoders with our CPU kernels switched off (candle's own ops: the path CUDA and f16
//! take) still match the diffusers fixtures, and agree with the kernel path. The switch is
//! process-wide, so this file holds a single test.

mod common;
use common::{abs_max, fixture, max_abs};

use candle_core::{Device, Tensor};
use std::collections::HashMap;
use vectorfusion::models::kernels;
use vectorfusion::models::stable_diffusion::load_unet;
use vectorfusion::models::taesd::Taesd;
use vectorfusion::models::{LoadOptions, Precision, StableDiffusion};

fn refs(name: &str) -> HashMap<String, Tensor> {
    candle_core::safetensors::load(fixture(name).join("refs.safetensors"), &Device::Cpu).unwrap()
}

/// Every autoencoder, text encoder and UNet output the fixtures check, in a fixed order.
fn outputs() -> Vec<(&'static str, Tensor, Tensor)> {
    let sd = StableDiffusion::load(&fixture("sd-tiny"), &LoadOptions::default()).unwrap();
    let r = refs("sd-tiny");
    let vae = sd.vae().unwrap();
    let d = vae.encode_dist(&r["vae.image"]).unwrap();
    let mut v = vec![
        ("vae mean", d.mean, r["vae.mean"].clone()),
        ("vae logvar", d.logvar, r["vae.logvar"].clone()),
        (
            "vae decode",
            vae.decode_raw(&r["vae.z"]).unwrap(),
            r["vae.decoded"].clone(),
        ),
        (
            "vae d_image",
            sd.encode_vjp(&r["vae.image"], &r["vjp.d_latents"]).unwrap(),
            r["vjp.d_image"].clone(),
        ),
    ];
    // the CLIP text encoder (causal attention)
    let (cond, _) = sd.text_embeddings("a red cat").unwrap();
    v.push(("text embeddings", cond, r["text.cond"].clone()));
    for t in [999usize, 10] {
        v.push((
            "unet",
            sd.unet
                .forward(&r["unet.z"], t as f64, &r["text.cond"])
                .unwrap(),
            r[&format!("unet.cond.t{t}")].clone(),
        ));
    }
    // SD 2.x style: linear projections, per-block head counts, v-prediction, fp16 file
    let unet = load_unet(
        &fixture("sd-tiny-v").join("unet"),
        Precision::F32,
        &Device::Cpu,
    )
    .unwrap();
    let rv = refs("sd-tiny-v");
    let (z, t) = (&rv["unet.z"], 500.0);
    let cond = unet.forward(z, t, &rv["text.cond"]).unwrap();
    let uncond = unet.forward(z, t, &rv["text.uncond"]).unwrap();
    let guided = (&uncond + ((cond - &uncond).unwrap() * 7.5).unwrap()).unwrap();
    v.push((
        "unet guided (linear projection)",
        guided,
        rv["unet.guided.t500"].clone(),
    ));
    let t = Taesd::load(&fixture("taesd-tiny"), Precision::F32, &Device::Cpu).unwrap();
    let r = refs("taesd-tiny");
    let (lat, d) = t.encode_vjp(&r["image"], &r["d_latents"]).unwrap();
    v.push(("taesd latents", lat, r["latents"].clone()));
    v.push(("taesd d_image", d, r["d_image"].clone()));
    v.push((
        "taesd decode",
        t.decode_raw(&r["z"]).unwrap(),
        r["decoded"].clone(),
    ));
    v
}

#[test]
fn candle_fallback_matches_diffusers_and_the_kernels() {
    kernels::set_enabled(true);
    let ours = outputs();
    kernels::set_enabled(false);
    let candle = outputs();
    kernels::set_enabled(true);
    for ((name, a, want), (_, b, _)) in ours.iter().zip(&candle) {
        assert!(abs_max(want) > 1e-3, "{name}: reference is trivially small");
        let e = max_abs(b, want);
        assert!(
            e <= 1e-4,
            "{name}: candle path differs from diffusers by {e}"
        );
        let e = max_abs(a, b);
        assert!(e <= 1e-4, "{name}: kernels and candle path differ by {e}");
    }
}

/// `bench models` runs full-size TAESD with either set of kernels and says which it used.
#[test]
fn bench_models_reports_both_kernel_sets() {
    for (flag, name) in [(None, "ours"), (Some("--candle-kernels"), "candle")] {
        let mut args = vec![
            "bench", "models", "--arch", "taesd", "--size", "64", "--reps", "1", "--warmup", "0",
            "--json",
        ];
        args.extend(flag);
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
            .args(&args)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(v["kernels"], name);
        assert_eq!(v["device"], "cpu");
        for k in [
            "encoder_fwd_ms",
            "encoder_vjp_ms",
            "encoder_bwd_ms",
            "decoder_ms",
        ] {
            assert!(v[k].as_f64().is_some_and(|ms| ms > 0.0), "{k}: {v}");
        }
    }
    // A device this build cannot open is a usage error, not a panic.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
        .args(["bench", "models", "--arch", "taesd", "--device", "tpu"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("tpu"));
}
