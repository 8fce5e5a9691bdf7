//! Equivalence of the SDXL components with diffusers/transformers on the tiny random-weight
//! SDXL-architecture fixture produced by `scripts/make_sdxl_fixtures.py` (fp32, max abs error
//! ≤ 1e-4).

mod common;
use common::{abs_max, assert_close, fixture, max_abs};

use candle_core::{Device, Tensor};
use std::collections::HashMap;
use vectorfusion::models::sdxl_text::SdxlTextEncoders;
use vectorfusion::models::stable_diffusion::load_unet;
use vectorfusion::models::unet::{AddedCond, Unet};
use vectorfusion::models::{ModelError, Precision};

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

#[test]
fn sdxl_pipeline_directory_is_refused_with_a_clear_error() {
    let e = vectorfusion::models::StableDiffusion::load(
        &fixture("sdxl-tiny"),
        &vectorfusion::models::LoadOptions::default(),
    )
    .unwrap_err();
    assert!(
        matches!(
            e,
            ModelError::Unsupported {
                component: "pipeline",
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("SDXL"), "{e}");
}
