//! The SD pipeline's `TextEncoder` dispatches on `text_encoder/config.json` `model_type`: a BERT
//! model root gives the embedded model's conditioning (`last_hidden_state` over all L positions).

mod common;
use common::max_abs;

use candle_core::{DType, Device};
use std::path::{Path, PathBuf};
use vectorfusion::models::Precision;
use vectorfusion::models::stable_diffusion::TextEncoder;

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/bert-tiny")
}

#[test]
fn bert_model_type_gives_bert_conditioning_of_length_32() {
    let enc = TextEncoder::load(&fixture(), Precision::F32, &Device::Cpu).unwrap();
    assert!(matches!(enc, TextEncoder::Bert(_)));
    let r =
        candle_core::safetensors::load(fixture().join("refs.safetensors"), &Device::Cpu).unwrap();
    let want = &r["last_hidden_state"];
    // captions.json: ["a red bicycle", "", ...]
    let cond = enc.embed("a red bicycle", &Device::Cpu).unwrap();
    assert_eq!(cond.dims(), &[1, 32, 16]);
    assert_eq!(cond.dtype(), DType::F32);
    assert!(max_abs(&cond, &want.narrow(0, 0, 1).unwrap()) < 1e-4);
    let uncond = enc.embed("", &Device::Cpu).unwrap();
    assert!(max_abs(&uncond, &want.narrow(0, 1, 1).unwrap()) < 1e-4);
    let ids: Vec<u32> = enc
        .ids("", &Device::Cpu)
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1()
        .unwrap();
    assert_eq!(&ids[..3], &[101, 102, 0]);
    assert_eq!(ids.len(), 32);
}

#[test]
fn bert_runs_in_f32_even_when_f16_is_asked_for() {
    let enc = TextEncoder::load(&fixture(), Precision::F16, &Device::Cpu).unwrap();
    let r =
        candle_core::safetensors::load(fixture().join("refs.safetensors"), &Device::Cpu).unwrap();
    let cond = enc.embed("a red bicycle", &Device::Cpu).unwrap();
    let d = max_abs(&cond, &r["last_hidden_state"].narrow(0, 0, 1).unwrap());
    assert!(d < 1e-4, "{d}");
}

#[test]
fn clip_model_type_still_loads_clip() {
    let sd = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sd-tiny");
    let enc = TextEncoder::load(&sd, Precision::F32, &Device::Cpu).unwrap();
    assert!(matches!(enc, TextEncoder::Clip { .. }));
}
