//! diffusers `Transformer2DModel` as the SD UNet uses it: group norm, `proj_in`, a stack of
//! `BasicTransformerBlock`s (self-attention, cross-attention, GEGLU feed-forward, each pre-norm
//! with a residual), `proj_out`, residual.
//!
//! On the CPU in f32 the layout changes (`[b, c, h, w]` ↔ tokens `[b, hw, c]`) are folded into
//! `proj_in`/`proj_out` and attention is the fused kernel; otherwise candle ops run the same
//! maths (f16/bf16, CUDA).

use crate::models::kernels::{self, linear, pointwise};
use crate::models::nn::{self, GroupNorm, LayerNorm, Linear};
use candle_core::Tensor;
use candle_nn::VarBuilder;

type R<T> = candle_core::Result<T>;

/// `Attention` with `heads` heads; keys and values from `context` (cross) or the input (self).
#[derive(Debug, Clone)]
pub struct Attention {
    pub to_q: Linear,
    pub to_k: Linear,
    pub to_v: Linear,
    /// `to_out.0` (`to_out.1` is dropout).
    pub to_out: Linear,
    pub heads: usize,
    /// Compute scores and softmax in f32 for half-precision models (`upcast_attention`).
    pub upcast: bool,
}

impl Attention {
    pub fn load(vb: VarBuilder, c: usize, context: usize, heads: usize, upcast: bool) -> R<Self> {
        Ok(Self {
            to_q: Linear::load(vb.pp("to_q"), c, c, false)?,
            to_k: Linear::load(vb.pp("to_k"), context, c, false)?,
            to_v: Linear::load(vb.pp("to_v"), context, c, false)?,
            to_out: Linear::load(vb.pp("to_out.0"), c, c, true)?,
            heads,
            upcast,
        })
    }

    /// `residual + to_out(attention(x, context))` for tokens `x [b, n, c]`.
    pub fn forward(&self, x: &Tensor, context: Option<&Tensor>, residual: &Tensor) -> R<Tensor> {
        let kv = context.unwrap_or(x);
        let q = self.to_q.forward(x)?;
        let k = self.to_k.forward(kv)?;
        let v = self.to_v.forward(kv)?;
        let o = nn::attention(&q, &k, &v, self.heads, false, self.upcast)?;
        self.to_out.forward_residual(&o, residual)
    }
}

/// `FeedForward` with GEGLU: `net.2(h · gelu(gate))`, `[h, gate] = net.0.proj(x)`.
#[derive(Debug, Clone)]
pub struct FeedForward {
    pub proj: Linear,
    pub out: Linear,
    pub inner: usize,
}

impl FeedForward {
    pub fn load(vb: VarBuilder, c: usize) -> R<Self> {
        let inner = 4 * c;
        Ok(Self {
            proj: Linear::load(vb.pp("net.0.proj"), c, 2 * inner, true)?,
            out: Linear::load(vb.pp("net.2"), inner, c, true)?,
            inner,
        })
    }

    pub fn forward(&self, x: &Tensor, residual: &Tensor) -> R<Tensor> {
        let h = self.proj.forward(x)?;
        let a = if kernels::applies(&[&h]) {
            let mut dims = h.dims().to_vec();
            if let Some(last) = dims.last_mut() {
                *last = self.inner;
            }
            let a = kernels::with_f32(&h, |hs| {
                pointwise::geglu(hs, self.inner).map_err(kernels::err)
            })?;
            kernels::tensor(a, &dims)?
        } else {
            let last = h.rank() - 1;
            let a = h.narrow(last, 0, self.inner)?;
            let gate = h.narrow(last, self.inner, self.inner)?;
            (a * gate.gelu_erf()?)?
        };
        self.out.forward_residual(&a, residual)
    }
}

#[derive(Debug, Clone)]
pub struct BasicTransformerBlock {
    pub norm1: LayerNorm,
    pub attn1: Attention,
    pub norm2: LayerNorm,
    pub attn2: Attention,
    pub norm3: LayerNorm,
    pub ff: FeedForward,
}

impl BasicTransformerBlock {
    pub fn load(vb: VarBuilder, c: usize, context: usize, heads: usize, upcast: bool) -> R<Self> {
        Ok(Self {
            norm1: LayerNorm::load(vb.pp("norm1"), c, 1e-5)?,
            attn1: Attention::load(vb.pp("attn1"), c, c, heads, upcast)?,
            norm2: LayerNorm::load(vb.pp("norm2"), c, 1e-5)?,
            attn2: Attention::load(vb.pp("attn2"), c, context, heads, upcast)?,
            norm3: LayerNorm::load(vb.pp("norm3"), c, 1e-5)?,
            ff: FeedForward::load(vb.pp("ff"), c)?,
        })
    }

    pub fn forward(&self, x: &Tensor, context: &Tensor) -> R<Tensor> {
        let x = self.attn1.forward(&self.norm1.forward(x)?, None, x)?;
        let x = self
            .attn2
            .forward(&self.norm2.forward(&x)?, Some(context), &x)?;
        self.ff.forward(&self.norm3.forward(&x)?, &x)
    }
}

/// `Transformer2DModel` (continuous input). `proj_in`/`proj_out` are 1×1 convolutions in SD 1.x
/// checkpoints and linear layers in SD 2.x (`use_linear_projection`); both are the same product
/// on tokens, and [`Linear::load`] reads either weight shape.
#[derive(Debug, Clone)]
pub struct Transformer2DModel {
    pub norm: GroupNorm,
    pub proj_in: Linear,
    pub transformer_blocks: Vec<BasicTransformerBlock>,
    pub proj_out: Linear,
}

impl Transformer2DModel {
    pub fn load(
        vb: VarBuilder,
        c: usize,
        (heads, layers): (usize, usize),
        context: usize,
        groups: usize,
        upcast: bool,
    ) -> R<Self> {
        let blocks = (0..layers)
            .map(|i| {
                BasicTransformerBlock::load(
                    vb.pp(format!("transformer_blocks.{i}")),
                    c,
                    context,
                    heads,
                    upcast,
                )
            })
            .collect::<R<Vec<_>>>()?;
        Ok(Self {
            norm: GroupNorm::load(vb.pp("norm"), groups, c, 1e-6)?,
            proj_in: Linear::load(vb.pp("proj_in"), c, c, true)?,
            transformer_blocks: blocks,
            proj_out: Linear::load(vb.pp("proj_out"), c, c, true)?,
        })
    }

    /// `x [b, c, h, w]`, `context [b, seq, cross_attention_dim]`.
    pub fn forward(&self, x: &Tensor, context: &Tensor) -> R<Tensor> {
        let (b, c, h, w) = x.dims4()?;
        let hn = self.norm.forward(x)?;
        let mut t = self.tokens_in(&hn, (b, c, h * w))?;
        for blk in &self.transformer_blocks {
            t = blk.forward(&t, context)?;
        }
        self.tokens_out(&t, x)
    }

    /// `proj_in` on `[b, c, n]` read channels-first, giving tokens `[b, n, c]`.
    fn tokens_in(&self, x: &Tensor, (b, c, n): (usize, usize, usize)) -> R<Tensor> {
        let p = &self.proj_in;
        if p.kernels_apply(&[x]) {
            let o = p.weight.dim(0)?;
            let bias = p.bias_f32()?;
            let y = kernels::with_f32(x, |xs| {
                kernels::with_f32(&p.weight, |ws| {
                    linear::linear_from_channels(xs, (b, c, n), ws, o, bias.as_deref())
                        .map_err(kernels::err)
                })
            })?;
            return kernels::tensor(y, &[b, n, o]);
        }
        let t = x.reshape((b, c, n))?.transpose(1, 2)?.contiguous()?;
        p.forward(&t)
    }

    /// `residual + proj_out(t)` back in `[b, c, h, w]`.
    fn tokens_out(&self, t: &Tensor, residual: &Tensor) -> R<Tensor> {
        let p = &self.proj_out;
        let (b, n, i) = t.dims3()?;
        if p.kernels_apply(&[t, residual]) {
            let o = p.weight.dim(0)?;
            let bias = p.bias_f32()?;
            let y = kernels::with_f32(t, |tsv| {
                kernels::with_f32(&p.weight, |ws| {
                    kernels::with_f32(residual, |rs| {
                        linear::linear_to_channels(tsv, (b, n, i), ws, o, bias.as_deref(), rs)
                            .map_err(kernels::err)
                    })
                })
            })?;
            return kernels::tensor(y, residual.dims());
        }
        let y = p.forward(t)?.transpose(1, 2)?.contiguous()?;
        residual + y.reshape(residual.dims())?
    }
}
