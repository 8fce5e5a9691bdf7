//! IconClip (image tower, text tower on BERT, logits) against the PyTorch reference
//! (`scripts/embedded/vf_icon.py`, fixture by `scripts/embedded/make_fixtures.py`), and the
//! scorer abstraction that loads CLIP or IconClip wherever a scorer is accepted.

mod common;
use common::max_abs;

use candle_core::{Device, Tensor};
use std::path::{Path, PathBuf};
use vectorfusion::eval::clip::evaluate;
use vectorfusion::image::Image;
use vectorfusion::models::scorer::{IconClipConfig, IconClipScorer, ImageTextScorer, Scorer};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
}

fn refs() -> std::collections::HashMap<String, Tensor> {
    candle_core::safetensors::load(
        fixtures().join("iconclip-tiny/refs.safetensors"),
        &Device::Cpu,
    )
    .unwrap()
}

fn captions() -> Vec<String> {
    let s = std::fs::read_to_string(fixtures().join("iconclip-tiny/captions.json")).unwrap();
    serde_json::from_str(&s).unwrap()
}

fn scorer() -> IconClipScorer {
    IconClipScorer::load(
        &fixtures().join("iconclip-tiny/scorer"),
        &fixtures().join("bert-tiny"),
        &Device::Cpu,
        false,
    )
    .unwrap()
}

fn rows(v: Vec<Vec<f32>>) -> Tensor {
    let (n, d) = (v.len(), v[0].len());
    Tensor::from_vec(v.concat(), (n, d), &Device::Cpu).unwrap()
}

#[test]
fn image_text_embeddings_and_logits_match_torch() {
    let s = scorer();
    let r = refs();
    let img = s.model.encode_image(&r["pixels"]).unwrap();
    let d = max_abs(&img, &r["image_embeds"]);
    assert!(d < 1e-4, "image embeddings max abs diff {d}");
    let caps = captions();
    let caps: Vec<&str> = caps.iter().map(String::as_str).collect();
    let txt = rows(s.text_embeddings(&caps).unwrap());
    let d = max_abs(&txt, &r["text_embeds"]);
    assert!(d < 1e-4, "text embeddings max abs diff {d}");
    let logits = s.model.logits(&img, &txt).unwrap();
    let d = max_abs(&logits, &r["logits"]);
    assert!(
        d < 1e-4 * s.model.logit_scale.exp(),
        "logits max abs diff {d}"
    );
    assert!((s.model.logit_scale - 2.3).abs() < 1e-6);
}

#[test]
fn png_preprocessing_is_over_white_then_area_resize() {
    let s = scorer();
    let r = refs();
    let img = Image::open(&fixtures().join("iconclip-tiny/icon64.png")).unwrap();
    let px = s.pixel_values(std::slice::from_ref(&img)).unwrap();
    let want = r["pixels"].narrow(0, 3, 1).unwrap();
    let d = max_abs(&px, &want);
    assert!(d < 1e-5, "pixels max abs diff {d}");
    let e = rows(s.image_embeddings(&[img]).unwrap());
    let d = max_abs(&e, &r["image_embeds"].narrow(0, 3, 1).unwrap());
    assert!(d < 1e-4, "embedding of the PNG max abs diff {d}");
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
    }
}

#[test]
fn scorer_loads_a_model_root_or_its_scorer_folder_or_clip() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("vf-tiny");
    copy_dir(
        &fixtures().join("iconclip-tiny/scorer"),
        &root.join("scorer"),
    );
    copy_dir(
        &fixtures().join("bert-tiny/text_encoder"),
        &root.join("text_encoder"),
    );
    copy_dir(
        &fixtures().join("bert-tiny/tokenizer"),
        &root.join("tokenizer"),
    );

    let direct = scorer();
    let caps = captions();
    let img = Image::open(&fixtures().join("iconclip-tiny/icon64.png")).unwrap();
    let want = direct
        .score_images(std::slice::from_ref(&img), &caps[0])
        .unwrap();
    for dir in [root.clone(), root.join("scorer")] {
        let s = Scorer::load_on(&dir, &Device::Cpu, false).unwrap();
        assert!(matches!(s, Scorer::IconClip(_)), "{}", dir.display());
        assert_eq!(s.name(), "vf-tiny");
        assert_eq!(s.image_size(), 32);
        let got = s
            .score_images(std::slice::from_ref(&img), &caps[0])
            .unwrap();
        assert!((got[0] - want[0]).abs() < 1e-6);
    }
    let src = Scorer::load_source(root.to_str().unwrap(), false).unwrap();
    assert!(matches!(src, Scorer::IconClip(_)));

    // CLIP directories still load as CLIP
    let clip = Scorer::load(&fixtures().join("clip-tiny")).unwrap();
    assert!(matches!(clip, Scorer::Clip(_)));

    // best_of picks the highest cosine similarity
    let black = Image::filled(40, 40, [0.0, 0.0, 0.0, 1.0]);
    let imgs = vec![black, img.clone()];
    let s = Scorer::load_on(&root, &Device::Cpu, false).unwrap();
    let (best, scores) = s.best_of(&imgs, &caps[1]).unwrap();
    assert_eq!(scores.len(), 2);
    let arg = if scores[0] >= scores[1] { 0 } else { 1 };
    assert_eq!(best, arg);
    assert!(s.best_of(&[], &caps[1]).is_err());

    // evaluation takes any scorer
    let res = evaluate(&s, &caps[..2], &imgs).unwrap();
    assert_eq!(res.per_svg.len(), 2);
    assert!((0.0..=1.0).contains(&res.r_precision));
}

#[test]
fn bad_configs_and_missing_text_encoder_are_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("config.json");
    std::fs::write(
        &p,
        r#"{"model_type": "vf_iconclip", "image_size": 32, "channels": [8, 18], "groups": 4, "embed_dim": 32, "text_max_length": 64}"#,
    )
    .unwrap();
    let e = IconClipConfig::from_file(&p).unwrap_err().to_string();
    assert!(e.contains("groups"), "{e}");
    // a scorer folder whose parent has no tokenizer/text encoder
    let root = tmp.path().join("m");
    copy_dir(
        &fixtures().join("iconclip-tiny/scorer"),
        &root.join("scorer"),
    );
    let e = Scorer::load_on(&root, &Device::Cpu, false)
        .unwrap_err()
        .to_string();
    assert!(e.contains("vocab.txt"), "{e}");
}

#[test]
fn eval_cli_accepts_an_iconclip_model_directory_as_scorer() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("vf-tiny");
    copy_dir(
        &fixtures().join("iconclip-tiny/scorer"),
        &root.join("scorer"),
    );
    copy_dir(
        &fixtures().join("bert-tiny/text_encoder"),
        &root.join("text_encoder"),
    );
    copy_dir(
        &fixtures().join("bert-tiny/tokenizer"),
        &root.join("tokenizer"),
    );
    let svgs = tmp.path().join("svgs");
    std::fs::create_dir_all(&svgs).unwrap();
    let svg = |fill: &str| {
        format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64"><circle cx="32" cy="32" r="20" fill="{fill}"/></svg>"#
        )
    };
    std::fs::write(svgs.join("0001.svg"), svg("red")).unwrap();
    std::fs::write(svgs.join("0002.svg"), svg("blue")).unwrap();
    let prompts = tmp.path().join("prompts.txt");
    std::fs::write(&prompts, "a red circle\na blue circle\n").unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
        .args(["eval", "--json", "--prompts"])
        .arg(&prompts)
        .arg("--svgs")
        .arg(&svgs)
        .arg("--scorer")
        .arg(&root)
        .env("VF_OFFLINE", "1")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["scorers"][0]["scorer"], "vf-tiny");
    assert_eq!(v["scorers"][0]["per_svg"].as_array().unwrap().len(), 2);
}
