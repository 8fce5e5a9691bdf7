//! CLIP (text and vision towers, tokenizer, preprocessing) on candle, for rejection sampling
//! and the paper's evaluation. Loads the `transformers` layout; see [`openclip`] for the
//! OpenCLIP layout.

pub mod config;
pub mod model;
pub mod openclip;
pub mod preprocess;
pub mod text;
pub mod tokenizer;
pub mod vision;

pub use config::{Activation, ClipConfig, ClipTextConfig, ClipVisionConfig};
pub use model::ClipModel;
pub use preprocess::PreprocessConfig;
pub use text::{ClipTextModel, ClipTextModelWithProjection, ClipTextTransformer, TextOutput};
pub use tokenizer::ClipTokenizer;

use std::path::{Path, PathBuf};

/// Errors of the CLIP layer.
#[derive(Debug, thiserror::Error)]
pub enum ClipError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("bad CLIP config: {0}")]
    Config(String),
    #[error("tokenizer: {0}")]
    Tokenizer(String),
    #[error("{}: missing {}{hint}", dir.display(), files.join(", "))]
    MissingFiles {
        dir: PathBuf,
        files: Vec<String>,
        hint: String,
    },
    #[error("bad input: {0}")]
    Input(String),
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
}

/// Appended to missing-file errors of local directories.
pub(crate) const DOWNLOAD_HINT: &str = " (download the model into this directory, e.g. with \
    `huggingface-cli download <repo> --local-dir <dir>`)";

impl ClipError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        ClipError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// Safetensors weight files of a model directory: `model.safetensors`, else
/// `model.fp16.safetensors`, else `open_clip_model.safetensors`, else every `*.safetensors`
/// (sorted; sharded checkpoints).
pub fn weight_files(dir: &Path) -> Result<Vec<PathBuf>, ClipError> {
    for name in [
        "model.safetensors",
        "model.fp16.safetensors",
        "open_clip_model.safetensors",
    ] {
        let p = dir.join(name);
        if p.is_file() {
            return Ok(vec![p]);
        }
    }
    let mut all: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| ClipError::io(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "safetensors"))
        .collect();
    all.sort();
    if all.is_empty() {
        return Err(ClipError::MissingFiles {
            dir: dir.to_path_buf(),
            files: vec!["model.safetensors".into()],
            hint: DOWNLOAD_HINT.into(),
        });
    }
    Ok(all)
}

/// Reads every weight file of `dir` into a [`VarBuilder`] (tensors converted to `dtype` on use).
pub fn load_weights(
    dir: &Path,
    dtype: candle_core::DType,
    device: &candle_core::Device,
) -> Result<candle_nn::VarBuilder<'static>, ClipError> {
    let mut tensors = std::collections::HashMap::new();
    for f in weight_files(dir)? {
        let t = candle_core::safetensors::load(&f, device)
            .map_err(|e| ClipError::Config(format!("{}: {e}", f.display())))?;
        tensors.extend(t);
    }
    Ok(candle_nn::VarBuilder::from_tensors(tensors, dtype, device))
}
