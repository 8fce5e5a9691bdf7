//! The CLIP vision tower, full model and image preprocessing against `transformers` on the
//! tiny fixture (`scripts/make_clip_fixtures.py`).

mod common;
use common::max_abs as max_abs_diff;

use candle_core::{Device, Tensor};
use std::path::PathBuf;
use vectorfusion::image::Image;
use vectorfusion::models::clip::preprocess::{PreprocessConfig, preprocess};
use vectorfusion::models::clip::{ClipModel, ClipTokenizer};

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/clip-tiny")
}

fn reference() -> std::collections::HashMap<String, Tensor> {
    candle_core::safetensors::load(dir().join("reference/outputs.safetensors"), &Device::Cpu)
        .unwrap()
}

fn image_names() -> Vec<String> {
    let v: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir().join("reference/images.json")).unwrap(),
    )
    .unwrap();
    serde_json::from_value(v["images"].clone()).unwrap()
}

#[test]
fn vision_tower_and_projection_match_transformers() {
    let r = reference();
    let m = ClipModel::load(&dir(), &Device::Cpu).unwrap();
    let out = m.vision_model.forward(&r["pixel_values"]).unwrap();
    let d = max_abs_diff(&out.pooled, &r["vision_pooled"]);
    assert!(d < 1e-4, "vision pooled diff {d}");
    let f = m.image_features(&r["pixel_values"]).unwrap();
    let d = max_abs_diff(&f, &r["image_embeds"]);
    assert!(d < 1e-4, "image_embeds diff {d}");
    // Wrong input size is an error, not a panic.
    let bad = Tensor::zeros((1, 3, 16, 16), candle_core::DType::F32, &Device::Cpu).unwrap();
    assert!(m.vision_model.forward(&bad).is_err());
}

#[test]
fn logits_match_transformers() {
    let r = reference();
    let m = ClipModel::load(&dir(), &Device::Cpu).unwrap();
    let tok = ClipTokenizer::from_dir(&dir()).unwrap();
    let v: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir().join("reference/tokens.json")).unwrap(),
    )
    .unwrap();
    let texts: Vec<String> = serde_json::from_value(v["texts"].clone()).unwrap();
    let ids: Vec<u32> = texts[..8]
        .iter()
        .flat_map(|t| tok.encode_padded(t))
        .collect();
    let ids = Tensor::from_vec(ids, (8, 77), &Device::Cpu).unwrap();
    let logits = m.logits_per_image(&r["pixel_values"], &ids).unwrap();
    let d = max_abs_diff(&logits, &r["logits_per_image"]);
    assert!(
        d < 1e-4 * 100.0_f32.max(m.logit_scale.exp()),
        "logits diff {d}"
    );
    assert!(d < 1e-3, "logits diff {d}");
}

/// Preprocessing from the PNG files reproduces `CLIPImageProcessor` (PIL bicubic): the 8-bit
/// pipeline is bit-exact, so the only differences are float rounding in rescale/normalise
/// (documented tolerance 1e-5 on normalised values; one 8-bit step would be ~0.015).
#[test]
fn preprocessing_matches_clip_image_processor() {
    let r = reference();
    let cfg = PreprocessConfig::from_file(&dir().join("preprocessor_config.json"), 32).unwrap();
    assert_eq!(cfg.output_size(), (32, 32));
    let names = image_names();
    let mut all = Vec::new();
    for n in &names {
        let img = Image::open(&dir().join("images").join(n)).unwrap();
        all.extend(preprocess(&img, &cfg).unwrap());
    }
    let got = Tensor::from_vec(all, (names.len(), 3, 32, 32), &Device::Cpu).unwrap();
    let d = max_abs_diff(&got, &r["pixel_values"]);
    assert!(d < 1e-5, "pixel diff {d}");
    // And the embeddings computed from our preprocessing match the reference ones.
    let m = ClipModel::load(&dir(), &Device::Cpu).unwrap();
    let d = max_abs_diff(&m.image_features(&got).unwrap(), &r["image_embeds"]);
    assert!(d < 1e-4, "image_embeds from PNG diff {d}");
}
