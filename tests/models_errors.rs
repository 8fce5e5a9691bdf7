//! Missing, corrupt and mismatched model files give clear errors.

use std::path::{Path, PathBuf};
use vectorfusion::models::{LoadOptions, ModelError, ModelSource, StableDiffusion};

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sd-tiny")
}

fn copy_dir(src: &Path, dst: &Path) {
    std::fs::create_dir_all(dst).unwrap();
    for e in std::fs::read_dir(src).unwrap() {
        let e = e.unwrap();
        let to = dst.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &to);
        } else {
            std::fs::copy(e.path(), &to).unwrap();
        }
    }
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vf-models-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    copy_dir(&fixture(), &d);
    d
}

fn load(dir: &Path) -> Result<StableDiffusion, ModelError> {
    StableDiffusion::load(dir, &LoadOptions::default())
}

#[test]
fn missing_directory_and_weights_are_named() {
    let e = load(Path::new("/nonexistent/sd")).unwrap_err();
    assert!(matches!(e, ModelError::MissingFiles { .. }), "{e}");
    let d = scratch("missing");
    std::fs::remove_file(d.join("unet/diffusion_pytorch_model.safetensors")).unwrap();
    let e = load(&d).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, ModelError::MissingFiles { .. }), "{msg}");
    assert!(msg.contains("diffusion_pytorch_model.safetensors"), "{msg}");
    std::fs::write(d.join("unet/diffusion_pytorch_model.bin"), b"x").unwrap();
    let msg = load(&d).unwrap_err().to_string();
    assert!(msg.contains(".bin") && msg.contains("safetensors"), "{msg}");
    std::fs::remove_file(d.join("vae/config.json")).unwrap();
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn corrupt_weights_are_reported() {
    let d = scratch("corrupt");
    let w = d.join("vae/diffusion_pytorch_model.safetensors");
    let bytes = std::fs::read(&w).unwrap();
    std::fs::write(&w, &bytes[..bytes.len() / 2]).unwrap();
    let e = load(&d).unwrap_err();
    assert!(matches!(e, ModelError::CorruptWeights { .. }), "{e}");
    assert!(e.to_string().contains("truncated"), "{e}");
    std::fs::write(&w, b"not a safetensors file at all").unwrap();
    let e = load(&d).unwrap_err();
    assert!(matches!(e, ModelError::CorruptWeights { .. }), "{e}");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn config_weight_mismatch_and_unsupported_configs() {
    let d = scratch("mismatch");
    let cfg_path = d.join("unet/config.json");
    let orig = std::fs::read_to_string(&cfg_path).unwrap();
    let mut cfg: serde_json::Value = serde_json::from_str(&orig).unwrap();
    cfg["cross_attention_dim"] = 24.into();
    std::fs::write(&cfg_path, cfg.to_string()).unwrap();
    let e = load(&d).unwrap_err();
    assert!(
        matches!(
            e,
            ModelError::WeightMismatch {
                component: "unet",
                ..
            }
        ),
        "{e}"
    );

    // an added-conditioning kind that is not implemented, and SDXL's without its widths
    for (kind, says) in [
        ("text_image", "addition_embed_type"),
        ("text_time", "addition_time_embed_dim"),
    ] {
        let mut cfg: serde_json::Value = serde_json::from_str(&orig).unwrap();
        cfg["addition_embed_type"] = kind.into();
        std::fs::write(&cfg_path, cfg.to_string()).unwrap();
        let e = load(&d).unwrap_err();
        assert!(
            matches!(
                e,
                ModelError::Unsupported {
                    component: "unet",
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains(says), "{e}");
    }

    std::fs::write(&cfg_path, "{ not json").unwrap();
    assert!(matches!(load(&d).unwrap_err(), ModelError::Config { .. }));
    std::fs::write(&cfg_path, &orig).unwrap();

    let vcfg = d.join("vae/config.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&vcfg).unwrap()).unwrap();
    v["block_out_channels"] = serde_json::json!([16, 48]);
    std::fs::write(&vcfg, v.to_string()).unwrap();
    let e = load(&d).unwrap_err();
    assert!(
        matches!(
            e,
            ModelError::WeightMismatch {
                component: "vae",
                ..
            }
        ),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn offline_hub_source_lists_missing_files() {
    let src = ModelSource::parse("vectorfusion-test/no-such-model");
    assert!(matches!(src, ModelSource::Hub { .. }));
    let opts = LoadOptions {
        allow_download: false,
        ..LoadOptions::default()
    };
    let e = StableDiffusion::load_source(&src, &opts).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, ModelError::MissingFiles { .. }), "{msg}");
    assert!(
        msg.contains("unet/config.json") && msg.contains("snapshots"),
        "{msg}"
    );
    assert_eq!(
        ModelSource::parse("./local/dir"),
        ModelSource::Dir("./local/dir".into())
    );
}
