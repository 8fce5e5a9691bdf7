//! Element-wise ops and multi-head attention without weights: each runs on our kernels when
//! they apply and on candle's ops otherwise.

use super::R;
use crate::models::kernels::{self, attention, pointwise};
use candle_core::{DType, Tensor};

/// `max(a + b, 0)`.
pub fn add_relu(a: &Tensor, b: &Tensor) -> R<Tensor> {
    if !kernels::applies(&[a, b]) || a.dims() != b.dims() {
        return (a + b)?.relu();
    }
    let y = kernels::with_f32(a, |av| {
        kernels::with_f32(b, |bv| pointwise::add_relu(av, bv).map_err(kernels::err))
    })?;
    kernels::tensor(y, a.dims())
}

/// Input gradient of a ReLU given its output `out`: `dy · [out > 0]`.
pub fn relu_backward(out: &Tensor, dy: &Tensor) -> R<Tensor> {
    if !kernels::applies(&[out, dy]) || out.dims() != dy.dims() {
        return dy * out.gt(0.0)?.to_dtype(dy.dtype())?;
    }
    let d = kernels::with_f32(out, |o| {
        kernels::with_f32(dy, |g| pointwise::relu_backward(o, g).map_err(kernels::err))
    })?;
    kernels::tensor(d, dy.dims())
}

/// Multi-head `softmax(Q Kᵀ / √d) V` for `q [b, n, c]`, `k, v [b, m, c]` (head `h` is columns
/// `h·d..(h+1)·d`). `causal`: query `i` sees keys `0..=i`. `upcast`: scores and softmax in f32
/// for half-precision inputs.
pub fn attention(
    q: &Tensor,
    k: &Tensor,
    v: &Tensor,
    heads: usize,
    causal: bool,
    upcast: bool,
) -> R<Tensor> {
    let (b, n, c) = q.dims3()?;
    let (_, m, _) = k.dims3()?;
    let g = attention::AttentionGeom::new(b, n, m, c, heads).map_err(kernels::err)?;
    let g = if causal { g.causal() } else { g };
    let scale = 1.0 / ((c / heads) as f64).sqrt();
    if kernels::applies(&[q, k, v]) && k.dims() == v.dims() && k.dim(0)? == b && k.dim(2)? == c {
        let o = kernels::with_f32(q, |qs| {
            kernels::with_f32(k, |ks| {
                kernels::with_f32(v, |vs| {
                    attention::attention(&g, qs, ks, vs, scale as f32).map_err(kernels::err)
                })
            })
        })?;
        return kernels::tensor(o, &[b, n, c]);
    }
    let dtype = q.dtype();
    let split = |t: &Tensor, len: usize| -> R<Tensor> {
        let t = t.reshape((b, len, heads, c / heads))?.transpose(1, 2)?;
        let t = if upcast { t.to_dtype(DType::F32)? } else { t };
        t.contiguous()
    };
    let (qh, kh, vh) = (split(q, n)?, split(k, m)?, split(v, m)?);
    let mut s = (qh.matmul(&kh.t()?)? * scale)?;
    if causal {
        let mask: Vec<f32> = (0..n)
            .flat_map(|i| (0..m).map(move |j| if j > i { f32::NEG_INFINITY } else { 0.0 }))
            .collect();
        let mask = Tensor::from_vec(mask, (1, 1, n, m), s.device())?.to_dtype(s.dtype())?;
        s = s.broadcast_add(&mask)?;
    }
    let p = candle_nn::ops::softmax_last_dim(&s)?;
    let p = if upcast { p.to_dtype(vh.dtype())? } else { p };
    p.matmul(&vh)?
        .to_dtype(dtype)?
        .transpose(1, 2)?
        .contiguous()?
        .reshape((b, n, c))
}

/// `(a + b) · scale` (`scale = 1` is a plain sum).
pub fn add_scaled(a: &Tensor, b: &Tensor, scale: f64) -> R<Tensor> {
    if !kernels::applies(&[a, b]) || a.dims() != b.dims() {
        let s = (a + b)?;
        return if scale == 1.0 { Ok(s) } else { s * scale };
    }
    let y = kernels::with_f32(a, |av| {
        kernels::with_f32(b, |bv| {
            pointwise::add_scaled(av, bv, scale as f32).map_err(kernels::err)
        })
    })?;
    kernels::tensor(y, a.dims())
}

/// `silu'(x) · dy`.
pub fn silu_backward(x: &Tensor, dy: &Tensor) -> R<Tensor> {
    let s = candle_nn::ops::sigmoid(x)?;
    // s * (1 + x * (1 - s))
    let d = (&s * ((x * (1.0 - &s)?)? + 1.0)?)?;
    dy * d
}
