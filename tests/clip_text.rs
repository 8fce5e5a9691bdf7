//! The CLIP tokenizer and text tower against `transformers` on the tiny fixture
//! (`scripts/make_clip_fixtures.py`).

mod common;
use common::max_abs as max_abs_diff;

use candle_core::{DType, Device, IndexOp, Tensor};
use std::path::PathBuf;
use vectorfusion::models::clip::text::ClipTextModelWithProjection;
use vectorfusion::models::clip::{ClipConfig, ClipTextConfig, ClipTextModel, ClipTokenizer};

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/clip-tiny")
}

struct Tokens {
    texts: Vec<String>,
    ids: Vec<Vec<u32>>,
    lengths: Vec<usize>,
}

fn tokens() -> Tokens {
    let v: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir().join("reference/tokens.json")).unwrap(),
    )
    .unwrap();
    Tokens {
        texts: serde_json::from_value(v["texts"].clone()).unwrap(),
        ids: serde_json::from_value(v["input_ids"].clone()).unwrap(),
        lengths: serde_json::from_value(v["unpadded_lengths"].clone()).unwrap(),
    }
}

fn reference() -> std::collections::HashMap<String, Tensor> {
    candle_core::safetensors::load(dir().join("reference/outputs.safetensors"), &Device::Cpu)
        .unwrap()
}

#[test]
fn tokenizer_matches_transformers_on_all_captions() {
    let t = tokens();
    assert_eq!(t.texts.len(), 132);
    assert!(t.texts.iter().any(|s| s == "自転車"));
    for tok in [
        ClipTokenizer::from_dir(&dir()).unwrap(),
        ClipTokenizer::from_tokenizer_json(&dir().join("tokenizer.json")).unwrap(),
    ] {
        assert_eq!(tok.max_length, 77);
        assert_eq!(tok.pad_id, tok.eos_id);
        for (i, text) in t.texts.iter().enumerate() {
            assert_eq!(tok.encode_padded(text), t.ids[i], "caption {i}: {text:?}");
            assert_eq!(
                tok.encode_with_special(text).len(),
                t.lengths[i].min(77),
                "{text:?}"
            );
        }
    }
    // The long caption really was truncated, keeping the end token.
    let long = t.lengths.iter().position(|&l| l > 77).unwrap();
    let tok = ClipTokenizer::from_dir(&dir()).unwrap();
    assert_eq!(t.ids[long][76], tok.eos_id);
}

fn input_ids(rows: &[Vec<u32>]) -> Tensor {
    let flat: Vec<u32> = rows.iter().flatten().copied().collect();
    Tensor::from_vec(flat, (rows.len(), rows[0].len()), &Device::Cpu).unwrap()
}

#[test]
fn text_model_matches_transformers_hidden_states_and_pooled() {
    let t = tokens();
    let r = reference();
    let dev = Device::Cpu;
    let sel: Vec<i64> = r["text_sel"].to_vec1().unwrap();
    let sel_rows: Vec<Vec<u32>> = sel.iter().map(|&i| t.ids[i as usize].clone()).collect();

    // Full CLIPModel checkpoint (`text_model.` prefix) and the standalone text encoder
    // (no prefix) must both load and agree with the reference.
    let cfg = ClipTextConfig::from_file(&dir().join("config.json")).unwrap();
    let vb = vectorfusion::models::clip::load_weights(&dir(), DType::F32, &dev).unwrap();
    let full = ClipTextModel::new(vb, &cfg).unwrap();
    let standalone = ClipTextModel::load(&dir().join("text_encoder"), &dev).unwrap();
    for m in [&full, &standalone] {
        let out = m
            .text_model
            .forward_with_hidden_states(&input_ids(&sel_rows))
            .unwrap();
        let d = max_abs_diff(&out.last_hidden_state, &r["text_last_hidden_state_sel"]);
        assert!(d < 1e-4, "last_hidden_state diff {d}");
        let pen = &out.hidden_states[out.hidden_states.len() - 2];
        let d = max_abs_diff(pen, &r["text_penultimate_sel"]);
        assert!(d < 1e-4, "penultimate diff {d}");
        let all = m.forward(&input_ids(&t.ids)).unwrap();
        let d = max_abs_diff(&all.pooled, &r["text_pooled"]);
        assert!(d < 1e-4, "pooled diff {d}");
        // Non-trivial outputs: rows differ between captions.
        let p0 = all.pooled.i(0).unwrap();
        let p1 = all.pooled.i(1).unwrap();
        assert!(max_abs_diff(&p0, &p1) > 1e-2);
    }
}

#[test]
fn text_projection_matches_transformers() {
    let t = tokens();
    let r = reference();
    let dev = Device::Cpu;
    let cfg = ClipConfig::from_file(&dir().join("config.json")).unwrap();
    let vb = vectorfusion::models::clip::load_weights(&dir(), DType::F32, &dev).unwrap();
    let m = ClipTextModelWithProjection::new(vb, &cfg.text_config, cfg.projection_dim).unwrap();
    let (embeds, _) = m.forward(&input_ids(&t.ids)).unwrap();
    let d = max_abs_diff(&embeds, &r["text_embeds"]);
    assert!(d < 1e-4, "text_embeds diff {d}");
}

#[test]
fn missing_files_give_clear_errors() {
    let tmp = std::env::temp_dir().join(format!("vf-clip-empty-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let e = ClipTokenizer::from_dir(&tmp).unwrap_err().to_string();
    assert!(e.contains("vocab.json"), "{e}");
    let e = ClipTextModel::load(&tmp, &Device::Cpu)
        .unwrap_err()
        .to_string();
    assert!(e.contains("config.json"), "{e}");
    std::fs::remove_dir_all(&tmp).unwrap();
}

#[test]
fn pad_token_and_context_come_from_tokenizer_config() {
    // SD 2.x tokenizers pad with "!" (id 0); the config's model_max_length is honoured.
    let tmp = std::env::temp_dir().join(format!("vf-clip-pad-{}", std::process::id()));
    std::fs::create_dir_all(tmp.join("tokenizer")).unwrap();
    for f in ["vocab.json", "merges.txt"] {
        std::fs::copy(dir().join(f), tmp.join("tokenizer").join(f)).unwrap();
    }
    std::fs::write(
        tmp.join("tokenizer/tokenizer_config.json"),
        r#"{"pad_token": {"content": "!", "lstrip": false}, "model_max_length": 16}"#,
    )
    .unwrap();
    let tok = ClipTokenizer::from_dir(&tmp).unwrap();
    assert_eq!(tok.pad_id, tok.token_to_id("!").unwrap());
    assert_eq!(tok.max_length, 16);
    let ids = tok.encode_padded("a cat");
    assert_eq!(ids.len(), 16);
    assert_eq!(ids[0], tok.bos_id);
    let eos_at = ids.iter().position(|&i| i == tok.eos_id).unwrap();
    assert!(ids[eos_at + 1..].iter().all(|&i| i == tok.pad_id));
    std::fs::write(
        tmp.join("tokenizer/tokenizer_config.json"),
        r#"{"pad_token": "<nope>"}"#,
    )
    .unwrap();
    assert!(ClipTokenizer::from_dir(&tmp).is_err());
    std::fs::remove_dir_all(&tmp).unwrap();
}
