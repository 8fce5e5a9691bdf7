//! `ClipScorer` on the tiny fixtures: transformers layout and OpenCLIP layout.

mod common;
use common::max_abs as max_abs_diff;

use candle_core::{Device, Tensor};
use std::path::PathBuf;
use vectorfusion::image::Image;
use vectorfusion::models::scorer::ClipScorer;
use vectorfusion::models::scorer::ImageTextScorer;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn reference(name: &str) -> std::collections::HashMap<String, Tensor> {
    candle_core::safetensors::load(
        fixture(name).join("reference/outputs.safetensors"),
        &Device::Cpu,
    )
    .unwrap()
}

fn texts(name: &str) -> Vec<String> {
    let v: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(fixture(name).join("reference/tokens.json")).unwrap(),
    )
    .unwrap();
    serde_json::from_value(v["texts"].clone()).unwrap()
}

fn images(name: &str) -> Vec<Image> {
    let v: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(fixture(name).join("reference/images.json")).unwrap(),
    )
    .unwrap();
    let names: Vec<String> = serde_json::from_value(v["images"].clone()).unwrap();
    names
        .iter()
        .map(|n| Image::open(&fixture(name).join("images").join(n)).unwrap())
        .collect()
}

fn normalize(t: &Tensor) -> Tensor {
    vectorfusion::models::clip::text::l2_normalize(t).unwrap()
}

#[test]
fn scorer_scores_match_reference_logits() {
    let s = ClipScorer::load(&fixture("clip-tiny")).unwrap();
    assert_eq!(s.image_size(), 32);
    assert_eq!(s.name(), "clip-tiny");
    let r = reference("clip-tiny");
    let imgs = images("clip-tiny");
    let caps = texts("clip-tiny");
    let scale = s.model.logit_scale.exp();
    for (j, cap) in caps[..8].iter().enumerate() {
        let scores = s.score_images(&imgs, cap).unwrap();
        for (i, sc) in scores.iter().enumerate() {
            let want: f32 = r["logits_per_image"]
                .get(i)
                .unwrap()
                .get(j)
                .unwrap()
                .to_scalar()
                .unwrap();
            assert!(
                (sc * scale - want).abs() < 1e-4,
                "image {i} caption {j}: {} vs {want}",
                sc * scale
            );
        }
    }
    let (best, scores) = s.best_of(&imgs, &caps[0]).unwrap();
    assert!(scores.iter().all(|&x| x <= scores[best]));
    assert!(s.best_of(&[], &caps[0]).is_err());
    assert!(s.score_images(&[], "x").unwrap().is_empty());
}

#[test]
fn scorer_embeds_every_caption_including_non_ascii_and_long() {
    let s = ClipScorer::load(&fixture("clip-tiny")).unwrap();
    let r = reference("clip-tiny");
    let caps = texts("clip-tiny");
    let refs: Vec<&str> = caps.iter().map(String::as_str).collect();
    let e = s.text_embeddings(&refs).unwrap();
    let got = Tensor::from_vec(e.concat(), (e.len(), e[0].len()), &Device::Cpu).unwrap();
    let d = max_abs_diff(&got, &normalize(&r["text_embeds"]));
    assert!(d < 1e-4, "text embedding diff {d}");
}

#[test]
fn openclip_layout_matches_open_clip() {
    let s = ClipScorer::load(&fixture("openclip-tiny")).unwrap();
    let r = reference("openclip-tiny");
    let caps = texts("clip-tiny");
    // Tokenization in the open_clip layout (zero padding).
    let ids: Vec<Vec<i64>> = r["input_ids"].to_vec2().unwrap();
    for (i, c) in caps.iter().enumerate() {
        let mine: Vec<i64> = s
            .tokenizer
            .encode_padded(c)
            .iter()
            .map(|&x| x as i64)
            .collect();
        assert_eq!(mine, ids[i], "{c:?}");
    }
    let refs: Vec<&str> = caps.iter().map(String::as_str).collect();
    let e = s.text_embeddings(&refs).unwrap();
    let got = Tensor::from_vec(e.concat(), (e.len(), e[0].len()), &Device::Cpu).unwrap();
    let d = max_abs_diff(&got, &normalize(&r["text_embeds"]));
    assert!(d < 1e-4, "open_clip text diff {d}");
    // Preprocessing (torchvision centre-crop rounding) and image tower.
    let imgs = images("openclip-tiny");
    let px = s.pixel_values(&imgs).unwrap();
    let d = max_abs_diff(&px, &r["pixel_values"]);
    assert!(d < 1e-5, "open_clip pixel diff {d}");
    let e = s.image_embeddings(&imgs).unwrap();
    let got = Tensor::from_vec(e.concat(), (e.len(), e[0].len()), &Device::Cpu).unwrap();
    let d = max_abs_diff(&got, &normalize(&r["image_embeds"]));
    assert!(d < 1e-4, "open_clip image diff {d}");
}

#[test]
fn missing_scorer_directories_are_clear_errors() {
    let e = ClipScorer::load(&PathBuf::from("openai/clip-vit-large-patch14")).unwrap_err();
    // (load() never touches the hub; load_source() does.)
    assert!(e.to_string().contains("huggingface-cli download"), "{e}");
    let tmp = std::env::temp_dir().join(format!("vf-scorer-empty-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let e = ClipScorer::load(&tmp).unwrap_err().to_string();
    assert!(
        e.contains("config.json") && e.contains("model.safetensors"),
        "{e}"
    );
    std::fs::remove_dir_all(&tmp).unwrap();
}
