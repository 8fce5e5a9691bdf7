//! The VAE mid-block's spatial self-attention, with its tape.

use super::{GroupNorm, GroupNormTape, Linear, R};
use candle_core::{D, Tensor};
use candle_nn::VarBuilder;

/// diffusers VAE mid-block `Attention` (group norm, single or multi head, residual).
#[derive(Debug, Clone)]
pub struct SpatialSelfAttention {
    pub group_norm: GroupNorm,
    pub to_q: Linear,
    pub to_k: Linear,
    pub to_v: Linear,
    pub to_out: Linear,
    pub heads: usize,
}

#[derive(Debug)]
pub struct AttentionTape {
    n: GroupNormTape,
    q: Tensor,
    k: Tensor,
    v: Tensor,
    p: Tensor,
}

impl SpatialSelfAttention {
    pub fn load(vb: VarBuilder, c: usize, groups: usize, eps: f64, heads: usize) -> R<Self> {
        if heads == 0 || !c.is_multiple_of(heads) {
            candle_core::bail!("attention: {c} channels not divisible by {heads} heads");
        }
        // current diffusers names; older checkpoints use query/key/value/proj_attn
        let (q, k, v, o) = if vb.contains_tensor("to_q.weight") {
            ("to_q", "to_k", "to_v", "to_out.0")
        } else {
            ("query", "key", "value", "proj_attn")
        };
        Ok(Self {
            group_norm: GroupNorm::load(vb.pp("group_norm"), groups, c, eps)?,
            to_q: Linear::load(vb.pp(q), c, c, true)?,
            to_k: Linear::load(vb.pp(k), c, c, true)?,
            to_v: Linear::load(vb.pp(v), c, c, true)?,
            to_out: Linear::load(vb.pp(o), c, c, true)?,
            heads,
        })
    }

    /// `[b, n, c] -> [b, heads, n, c/heads]`
    fn split(&self, x: &Tensor) -> R<Tensor> {
        let (b, n, c) = x.dims3()?;
        x.reshape((b, n, self.heads, c / self.heads))?
            .transpose(1, 2)?
            .contiguous()
    }

    fn merge(&self, x: &Tensor) -> R<Tensor> {
        let (b, hds, n, d) = x.dims4()?;
        x.transpose(1, 2)?.contiguous()?.reshape((b, n, hds * d))
    }

    fn to_tokens(x: &Tensor) -> R<Tensor> {
        let (b, c, h, w) = x.dims4()?;
        x.reshape((b, c, h * w))?.transpose(1, 2)?.contiguous()
    }

    fn from_tokens(x: &Tensor, h: usize, w: usize) -> R<Tensor> {
        let (b, _, c) = x.dims3()?;
        x.transpose(1, 2)?.contiguous()?.reshape((b, c, h, w))
    }

    fn core(&self, x: &Tensor) -> R<(Tensor, Option<GroupNormTape>, [Tensor; 4])> {
        let (_, c, _, _) = x.dims4()?;
        let (hn, tape) = self.group_norm.forward_t(x)?;
        let tokens = Self::to_tokens(&hn)?;
        let q = self.split(&self.to_q.forward(&tokens)?)?;
        let k = self.split(&self.to_k.forward(&tokens)?)?;
        let v = self.split(&self.to_v.forward(&tokens)?)?;
        let scale = 1.0 / ((c / self.heads) as f64).sqrt();
        let s = (q.matmul(&k.t()?)? * scale)?;
        let p = candle_nn::ops::softmax_last_dim(&s)?;
        let o = self.merge(&p.matmul(&v)?)?;
        Ok((o, Some(tape), [q, k, v, p]))
    }

    pub fn forward(&self, x: &Tensor) -> R<Tensor> {
        let (_, _, h, w) = x.dims4()?;
        let (o, _, _) = self.core(x)?;
        let y = Self::from_tokens(&self.to_out.forward(&o)?, h, w)?;
        x + y
    }

    pub fn forward_t(&self, x: &Tensor) -> R<(Tensor, AttentionTape)> {
        let (_, _, h, w) = x.dims4()?;
        let (o, tape, [q, k, v, p]) = self.core(x)?;
        let n = tape.ok_or_else(|| candle_core::Error::Msg("attention tape missing".into()))?;
        let y = (x + Self::from_tokens(&self.to_out.forward(&o)?, h, w)?)?;
        Ok((y, AttentionTape { n, q, k, v, p }))
    }

    pub fn backward(&self, t: &AttentionTape, dy: &Tensor) -> R<Tensor> {
        let (_, c, h, w) = dy.dims4()?;
        let scale = 1.0 / ((c / self.heads) as f64).sqrt();
        let d_out = Self::to_tokens(dy)?;
        let d_o = self.split(&self.to_out.backward(&d_out)?)?;
        let d_p = d_o.matmul(&t.v.t()?)?;
        let d_v = t.p.t()?.matmul(&d_o)?;
        let row = (&d_p * &t.p)?.sum_keepdim(D::Minus1)?;
        let d_s = (t.p.clone() * d_p.broadcast_sub(&row)?)?;
        let d_q = (d_s.matmul(&t.k)? * scale)?;
        let d_k = (d_s.t()?.matmul(&t.q)? * scale)?;
        let d_tok = ((self.to_q.backward(&self.merge(&d_q)?)?
            + self.to_k.backward(&self.merge(&d_k)?)?)?
            + self.to_v.backward(&self.merge(&d_v)?)?)?;
        let d_hn = Self::from_tokens(&d_tok, h, w)?;
        let d_x = self.group_norm.backward(&t.n, &d_hn)?;
        d_x + dy
    }
}
