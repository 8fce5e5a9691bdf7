//! The candle BertModel against transformers (tiny random model over the real vocabulary) and,
//! when its weights are installed (`vectorfusion setup`), the real all-MiniLM-L6-v2.

mod common;
use common::max_abs as max_abs_diff;

use candle_core::{DType, Device, Tensor};
use std::path::{Path, PathBuf};
use vectorfusion::models::bert::weights::{self, MiniLmLocations};
use vectorfusion::models::bert::{BertTextEncoder, model};

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/bert-tiny")
}

fn refs(name: &str) -> std::collections::HashMap<String, Tensor> {
    candle_core::safetensors::load(fixture().join(name), &Device::Cpu).unwrap()
}

fn captions(name: &str) -> Vec<String> {
    serde_json::from_str(&std::fs::read_to_string(fixture().join(name)).unwrap()).unwrap()
}

fn tiny() -> BertTextEncoder {
    BertTextEncoder::load(&fixture(), DType::F32, &Device::Cpu, false).unwrap()
}

#[test]
fn tiny_bert_last_hidden_state_matches_transformers() {
    let enc = tiny();
    let caps = captions("captions.json");
    let caps: Vec<&str> = caps.iter().map(String::as_str).collect();
    let got = enc.last_hidden_state(&caps, 32).unwrap();
    let want = &refs("refs.safetensors")["last_hidden_state"];
    assert_eq!(got.dims(), &[caps.len(), 32, 16]);
    let d = max_abs_diff(&got, want);
    assert!(d < 1e-4, "max abs diff {d}");
}

#[test]
fn tiny_bert_mean_pooled_embeddings_match() {
    let enc = tiny();
    let caps = captions("captions.json");
    let caps: Vec<&str> = caps.iter().map(String::as_str).collect();
    let got = enc.sentence_embeddings(&caps, 64).unwrap();
    let want = &refs("refs.safetensors")["pooled"];
    let d = max_abs_diff(&got, want);
    assert!(d < 1e-4, "max abs diff {d}");
    // unit norm rows
    let n = got.sqr().unwrap().sum(1).unwrap().to_vec1::<f32>().unwrap();
    assert!(n.iter().all(|x| (x - 1.0).abs() < 1e-5), "{n:?}");
}

#[test]
fn attention_mask_changes_the_output() {
    // padding positions must not leak into real tokens: with the mask all ones the result differs
    let enc = tiny();
    let (ids, mask) = enc.encode(&["a red bicycle"], 32).unwrap();
    let masked = enc.model.forward(&ids, &mask).unwrap();
    let ones = enc.model.forward(&ids, &mask.ones_like().unwrap()).unwrap();
    let a = masked.narrow(1, 0, 3).unwrap();
    let b = ones.narrow(1, 0, 3).unwrap();
    assert!(max_abs_diff(&a, &b) > 1e-3);
    let bad = Tensor::zeros((1, 5), DType::U32, &Device::Cpu).unwrap();
    assert!(enc.model.forward(&ids, &bad).is_err());
    let long = Tensor::zeros((1, 65), DType::U32, &Device::Cpu).unwrap();
    assert!(enc.model.forward(&long, &long).is_err());
}

#[test]
fn missing_weights_of_a_non_minilm_model_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = model::read_config(&fixture().join("text_encoder/config.json")).unwrap();
    let err =
        weights::resolve_text_encoder_weights(dir.path(), &cfg, &MiniLmLocations::default(), true)
            .unwrap_err();
    assert!(err.to_string().contains("model.safetensors"), "{err}");
    // a config of another model type is refused
    let p = dir.path().join("config.json");
    std::fs::write(&p, r#"{"model_type": "clip_text_model"}"#).unwrap();
    assert!(model::read_config(&p).is_err());
}

/// The real all-MiniLM-L6-v2 against sentence-transformers-style pooling in PyTorch. Runs when
/// the weights are available (`vectorfusion setup`, or `VF_MINILM_DIR`).
#[test]
fn real_minilm_matches_reference_sentence_embeddings_when_available() {
    let loc = MiniLmLocations::from_env();
    let dir = match loc.ensure(false) {
        Ok(d) => d,
        Err(e) => {
            common::skip(
                "real_minilm_matches_reference_sentence_embeddings_when_available",
                &format!("MiniLM weights not installed (run `vectorfusion setup`): {e}"),
            );
            return;
        }
    };
    eprintln!("real MiniLM weights: {}", dir.display());
    // the committed embedded-model root has no weights: they resolve to the installed copy
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/vf-icon");
    let cfg = model::read_config(&root.join("text_encoder/config.json")).unwrap();
    assert!(weights::is_minilm(&cfg));
    let enc = BertTextEncoder::load(&root, DType::F32, &Device::Cpu, false).unwrap();
    assert_eq!(enc.tokenizer.max_length, 32);
    let caps = captions("minilm_captions.json");
    let caps: Vec<&str> = caps.iter().map(String::as_str).collect();
    let r = refs("minilm_refs.safetensors");
    let got = enc.sentence_embeddings(&caps, 64).unwrap();
    let d = max_abs_diff(&got, &r["sentence"]);
    assert!(d < 1e-4, "sentence embeddings max abs diff {d}");
    let cond = enc.last_hidden_state(&caps[..1], 32).unwrap();
    assert_eq!(cond.dims(), &[1, 32, 384]);
    let d = max_abs_diff(&cond, &r["cond0"]);
    assert!(d < 1e-4, "UNet conditioning max abs diff {d}");
}

#[test]
fn config_reads_activations_and_refuses_what_is_not_implemented() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("config.json");
    let read = |json: &str| {
        std::fs::write(&p, json).unwrap();
        model::read_config(&p)
    };
    // transformers' defaults fill what a config leaves out
    let c = read(r#"{"model_type": "bert", "hidden_size": 16, "num_attention_heads": 4}"#).unwrap();
    assert_eq!((c.vocab_size, c.max_position_embeddings), (30522, 512));
    assert_eq!(c.hidden_act, model::HiddenAct::Gelu);
    let c = read(r#"{"hidden_act": "gelu_pytorch_tanh"}"#).unwrap();
    assert_eq!(c.hidden_act, model::HiddenAct::GeluTanh);
    let e = read(r#"{"position_embedding_type": "relative_key"}"#).unwrap_err();
    assert!(e.to_string().contains("relative_key"), "{e}");
    assert!(read(r#"{"hidden_act": "swish"}"#).is_err());
    assert!(read(r#"{"hidden_size": 10, "num_attention_heads": 4}"#).is_err());
}
