//! The CLIP transformer encoder and text tower, as `transformers`' `CLIPTextModel` /
//! `CLIPTextModelWithProjection` (checkpoint key names kept: `text_model.embeddings…`,
//! `text_model.encoder.layers.N.self_attn.q_proj…`, `text_model.final_layer_norm`,
//! `text_projection`).

use super::config::{Activation, ClipTextConfig};
use super::{ClipError, load_weights};
use crate::models::kernels::{self, math, pointwise};
use crate::models::nn::{self, LayerNorm, Linear};
use candle_core::{D, DType, Device, IndexOp, Module, Result, Tensor};
use candle_nn::{Embedding, VarBuilder, embedding};

fn activate(act: Activation, xs: &Tensor) -> Result<Tensor> {
    if kernels::applies(&[xs]) && act != Activation::GeluTanh {
        let mut v = xs.flatten_all()?.to_vec1::<f32>()?;
        match act {
            Activation::QuickGelu => {
                pointwise::map_inplace(&mut v, |x| x / (1.0 + math::exp_fast(-1.702 * x)))
            }
            _ => pointwise::map_inplace(&mut v, math::gelu),
        }
        return kernels::tensor(v, xs.dims());
    }
    match act {
        Activation::QuickGelu => xs * candle_nn::ops::sigmoid(&(xs * 1.702)?)?,
        Activation::Gelu => xs.gelu_erf(),
        Activation::GeluTanh => xs.gelu(),
    }
}

/// Shape of one encoder stack (shared by the text and vision towers).
#[derive(Debug, Clone, Copy)]
pub struct EncoderShape {
    pub hidden_size: usize,
    pub intermediate_size: usize,
    pub num_layers: usize,
    pub num_heads: usize,
    pub act: Activation,
    pub eps: f64,
}

#[derive(Debug, Clone)]
struct Attention {
    q: Linear,
    k: Linear,
    v: Linear,
    out: Linear,
    heads: usize,
}

impl Attention {
    fn new(vb: VarBuilder, s: &EncoderShape) -> Result<Self> {
        let h = s.hidden_size;
        if s.num_heads == 0 || !h.is_multiple_of(s.num_heads) {
            candle_core::bail!("{h} hidden units not divisible by {} heads", s.num_heads);
        }
        Ok(Self {
            q: Linear::load(vb.pp("q_proj"), h, h, true)?,
            k: Linear::load(vb.pp("k_proj"), h, h, true)?,
            v: Linear::load(vb.pp("v_proj"), h, h, true)?,
            out: Linear::load(vb.pp("out_proj"), h, h, true)?,
            heads: s.num_heads,
        })
    }

    /// `residual + out_proj(attention(xs))`.
    fn forward(&self, xs: &Tensor, causal: bool, residual: &Tensor) -> Result<Tensor> {
        let q = self.q.forward(xs)?;
        let k = self.k.forward(xs)?;
        let v = self.v.forward(xs)?;
        let o = nn::attention(&q, &k, &v, self.heads, causal, false)?;
        self.out.forward_residual(&o, residual)
    }
}

#[derive(Debug, Clone)]
struct EncoderLayer {
    attn: Attention,
    ln1: LayerNorm,
    fc1: Linear,
    fc2: Linear,
    ln2: LayerNorm,
    act: Activation,
}

impl EncoderLayer {
    fn new(vb: VarBuilder, s: &EncoderShape) -> Result<Self> {
        Ok(Self {
            attn: Attention::new(vb.pp("self_attn"), s)?,
            ln1: LayerNorm::load(vb.pp("layer_norm1"), s.hidden_size, s.eps)?,
            fc1: Linear::load(
                vb.pp("mlp").pp("fc1"),
                s.hidden_size,
                s.intermediate_size,
                true,
            )?,
            fc2: Linear::load(
                vb.pp("mlp").pp("fc2"),
                s.intermediate_size,
                s.hidden_size,
                true,
            )?,
            ln2: LayerNorm::load(vb.pp("layer_norm2"), s.hidden_size, s.eps)?,
            act: s.act,
        })
    }

    fn forward(&self, xs: &Tensor, causal: bool) -> Result<Tensor> {
        let h = self.attn.forward(&self.ln1.forward(xs)?, causal, xs)?;
        let a = activate(self.act, &self.fc1.forward(&self.ln2.forward(&h)?)?)?;
        self.fc2.forward_residual(&a, &h)
    }
}

/// `CLIPEncoder`: a stack of pre-norm transformer layers (`encoder.layers.N`).
#[derive(Debug, Clone)]
pub struct ClipEncoder {
    layers: Vec<EncoderLayer>,
}

impl ClipEncoder {
    pub fn new(vb: VarBuilder, s: &EncoderShape) -> Result<Self> {
        let vb = vb.pp("layers");
        let layers = (0..s.num_layers)
            .map(|i| EncoderLayer::new(vb.pp(i), s))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self { layers })
    }

    /// The same stack with its weights stored for inputs of few rows (the text towers' 77
    /// tokens): every linear weight [`Linear::stored_for_few_rows`] (transposed where the
    /// kernels' short-product path reads it).
    pub fn for_few_rows(self) -> Result<Self> {
        let layers = self
            .layers
            .into_iter()
            .map(|l| {
                Ok(EncoderLayer {
                    attn: Attention {
                        q: l.attn.q.stored_for_few_rows()?,
                        k: l.attn.k.stored_for_few_rows()?,
                        v: l.attn.v.stored_for_few_rows()?,
                        out: l.attn.out.stored_for_few_rows()?,
                        heads: l.attn.heads,
                    },
                    fc1: l.fc1.stored_for_few_rows()?,
                    fc2: l.fc2.stored_for_few_rows()?,
                    ..l
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self { layers })
    }

    pub fn num_layers(&self) -> usize {
        self.layers.len()
    }

    /// Runs all layers (`causal`: the text tower's causal attention mask); returns the input
    /// followed by every layer's output (`output_hidden_states=True`), so the last entry is the
    /// final hidden state.
    pub fn forward_all(&self, xs: &Tensor, causal: bool) -> Result<Vec<Tensor>> {
        let mut states = Vec::with_capacity(self.layers.len() + 1);
        states.push(xs.clone());
        let mut h = xs.clone();
        for l in &self.layers {
            h = l.forward(&h, causal)?;
            states.push(h.clone());
        }
        Ok(states)
    }

    pub fn forward(&self, xs: &Tensor, causal: bool) -> Result<Tensor> {
        let mut h = xs.clone();
        for l in &self.layers {
            h = l.forward(&h, causal)?;
        }
        Ok(h)
    }
}

/// Outputs of the text tower.
#[derive(Debug, Clone)]
pub struct TextOutput {
    /// `(batch, seq, hidden)` after the final layer norm.
    pub last_hidden_state: Tensor,
    /// `(batch, hidden)`: `last_hidden_state` at the end-of-text token.
    pub pooled: Tensor,
    /// Embeddings then every layer output, before the final layer norm (`hidden_states`),
    /// filled only by [`ClipTextTransformer::forward_with_hidden_states`].
    pub hidden_states: Vec<Tensor>,
}

/// `CLIPTextTransformer` (the weights under `text_model.`).
#[derive(Debug, Clone)]
pub struct ClipTextTransformer {
    token_embedding: Embedding,
    position_embedding: Embedding,
    encoder: ClipEncoder,
    final_layer_norm: LayerNorm,
    config: ClipTextConfig,
}

impl ClipTextTransformer {
    /// `vb` points at the `text_model` prefix.
    pub fn new(vb: VarBuilder, config: &ClipTextConfig) -> Result<Self> {
        let c = config;
        let emb = vb.pp("embeddings");
        let shape = EncoderShape {
            hidden_size: c.hidden_size,
            intermediate_size: c.intermediate_size,
            num_layers: c.num_hidden_layers,
            num_heads: c.num_attention_heads,
            act: c.hidden_act,
            eps: c.layer_norm_eps,
        };
        Ok(Self {
            token_embedding: embedding(c.vocab_size, c.hidden_size, emb.pp("token_embedding"))?,
            position_embedding: embedding(
                c.max_position_embeddings,
                c.hidden_size,
                emb.pp("position_embedding"),
            )?,
            encoder: ClipEncoder::new(vb.pp("encoder"), &shape)?.for_few_rows()?,
            final_layer_norm: LayerNorm::load(
                vb.pp("final_layer_norm"),
                c.hidden_size,
                c.layer_norm_eps,
            )?,
            config: c.clone(),
        })
    }

    pub fn config(&self) -> &ClipTextConfig {
        &self.config
    }

    fn embed(&self, input_ids: &Tensor) -> Result<Tensor> {
        let (_, n) = input_ids.dims2()?;
        if n > self.config.max_position_embeddings {
            candle_core::bail!(
                "sequence length {n} exceeds max_position_embeddings {}",
                self.config.max_position_embeddings
            );
        }
        let dev = input_ids.device();
        let pos = Tensor::arange(0u32, n as u32, dev)?;
        self.token_embedding
            .forward(input_ids)?
            .broadcast_add(&self.position_embedding.forward(&pos)?)
    }

    /// Index of the pooled token per row: the first `eos_token_id`, or the largest id when the
    /// config carries the legacy `eos_token_id == 2` (as transformers does).
    pub fn eos_positions(&self, input_ids: &Tensor) -> Result<Vec<usize>> {
        let rows = input_ids.to_dtype(DType::U32)?.to_vec2::<u32>()?;
        let eos = self.config.eos_token_id;
        Ok(rows
            .iter()
            .map(|r| {
                if eos == 2 {
                    let mut best = 0;
                    for (i, &v) in r.iter().enumerate() {
                        if v > r[best] {
                            best = i;
                        }
                    }
                    best
                } else {
                    r.iter().position(|&v| v == eos).unwrap_or(0)
                }
            })
            .collect())
    }

    fn pool(&self, last: &Tensor, input_ids: &Tensor) -> Result<Tensor> {
        let pos = self.eos_positions(input_ids)?;
        let rows = pos
            .iter()
            .enumerate()
            .map(|(b, &p)| last.i((b, p)))
            .collect::<Result<Vec<_>>>()?;
        Tensor::stack(&rows, 0)
    }

    /// `input_ids`: `(batch, seq)` u32 ids. No attention mask: padding follows the end token
    /// and the causal mask keeps it out of every earlier position, as Stable Diffusion uses it.
    pub fn forward(&self, input_ids: &Tensor) -> Result<TextOutput> {
        let x = self.embed(input_ids)?;
        let h = self.encoder.forward(&x, true)?;
        let last = self.final_layer_norm.forward(&h)?;
        let pooled = self.pool(&last, input_ids)?;
        Ok(TextOutput {
            last_hidden_state: last,
            pooled,
            hidden_states: Vec::new(),
        })
    }

    /// As [`Self::forward`], also returning every hidden state (for `clip_skip` /
    /// penultimate-layer conditioning).
    pub fn forward_with_hidden_states(&self, input_ids: &Tensor) -> Result<TextOutput> {
        let x = self.embed(input_ids)?;
        let states = self.encoder.forward_all(&x, true)?;
        let h = states.last().cloned().unwrap_or(x);
        let last = self.final_layer_norm.forward(&h)?;
        let pooled = self.pool(&last, input_ids)?;
        Ok(TextOutput {
            last_hidden_state: last,
            pooled,
            hidden_states: states,
        })
    }

    /// Applies the final layer norm (to turn a `hidden_states` entry into an embedding).
    pub fn final_layer_norm(&self, xs: &Tensor) -> Result<Tensor> {
        self.final_layer_norm.forward(xs)
    }
}

/// The prefix of the text tower in a checkpoint: `text_model.` (CLIPModel and every released
/// Stable Diffusion `text_encoder`), or none (`CLIPTextModel` saved by transformers >= 5).
pub fn text_tower(vb: VarBuilder) -> VarBuilder {
    if vb.contains_tensor("text_model.embeddings.token_embedding.weight") {
        vb.pp("text_model")
    } else {
        vb
    }
}

/// `CLIPTextModel` (Stable Diffusion's `text_encoder`).
#[derive(Debug, Clone)]
pub struct ClipTextModel {
    pub text_model: ClipTextTransformer,
}

impl ClipTextModel {
    /// `vb` points at the checkpoint root; the weights may sit under `text_model.` or not.
    pub fn new(vb: VarBuilder, config: &ClipTextConfig) -> Result<Self> {
        Ok(Self {
            text_model: ClipTextTransformer::new(text_tower(vb), config)?,
        })
    }

    /// Loads `config.json` and the safetensors weights from a directory (e.g. a diffusers
    /// `text_encoder/` folder) in f32.
    pub fn load(dir: &std::path::Path, device: &Device) -> std::result::Result<Self, ClipError> {
        let config = ClipTextConfig::from_file(&dir.join("config.json"))?;
        let vb = load_weights(dir, DType::F32, device)?;
        Ok(Self::new(vb, &config)?)
    }

    pub fn forward(&self, input_ids: &Tensor) -> Result<TextOutput> {
        self.text_model.forward(input_ids)
    }
}

/// `CLIPTextModelWithProjection`: adds `text_projection` (no bias) on the pooled output.
#[derive(Debug, Clone)]
pub struct ClipTextModelWithProjection {
    pub text_model: ClipTextTransformer,
    pub text_projection: Linear,
}

impl ClipTextModelWithProjection {
    pub fn new(vb: VarBuilder, config: &ClipTextConfig, projection_dim: usize) -> Result<Self> {
        Ok(Self {
            text_model: ClipTextTransformer::new(text_tower(vb.clone()), config)?,
            text_projection: Linear::load(
                vb.pp("text_projection"),
                config.hidden_size,
                projection_dim,
                false,
            )?,
        })
    }

    /// Returns `(text_embeds, output)`: the projected (not normalised) pooled output.
    pub fn forward(&self, input_ids: &Tensor) -> Result<(Tensor, TextOutput)> {
        let out = self.text_model.forward(input_ids)?;
        let embeds = self.text_projection.forward(&out.pooled)?;
        Ok((embeds, out))
    }
}

/// Row-wise L2 normalisation over the last dimension.
pub fn l2_normalize(xs: &Tensor) -> Result<Tensor> {
    let n = xs.sqr()?.sum_keepdim(D::Minus1)?.sqrt()?;
    xs.broadcast_div(&n)
}
