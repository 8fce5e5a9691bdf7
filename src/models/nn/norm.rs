//! Group normalisation (with a fused SiLU and its tape) and layer normalisation.

use super::{R, silu_backward};
use crate::models::kernels::{self, norm};
use candle_core::{DType, Module, Tensor};
use candle_nn::VarBuilder;

/// Group normalisation over `[b, c, h, w]` (or `[b, c, n]`) inputs.
#[derive(Debug, Clone)]
pub struct GroupNorm {
    pub weight: Tensor,
    pub bias: Tensor,
    pub groups: usize,
    pub eps: f64,
}

/// What [`GroupNorm::backward`] needs: the normalised input, `1/σ` per group and whether a SiLU
/// followed the norm.
#[derive(Debug)]
pub struct GroupNormTape {
    xhat: Tensor,
    inv_std: Tensor,
    silu: bool,
}

impl GroupNorm {
    pub fn load(vb: VarBuilder, groups: usize, channels: usize, eps: f64) -> R<Self> {
        if groups == 0 || !channels.is_multiple_of(groups) {
            candle_core::bail!("group norm: {channels} channels not divisible by {groups} groups");
        }
        Ok(Self {
            weight: vb.get(channels, "weight")?,
            bias: vb.get(channels, "bias")?,
            groups,
            eps,
        })
    }

    fn affine(&self, xhat: &Tensor, shape: &[usize]) -> R<Tensor> {
        let c = shape[1];
        let mut bshape = vec![1usize; shape.len()];
        bshape[1] = c;
        xhat.reshape(shape)?
            .broadcast_mul(&self.weight.reshape(bshape.as_slice())?)?
            .broadcast_add(&self.bias.reshape(bshape.as_slice())?)
    }

    fn normalise(&self, x: &Tensor) -> R<(Tensor, Tensor)> {
        let b = x.dim(0)?;
        let xg = x.reshape((b, self.groups, ()))?;
        let in_dtype = xg.dtype();
        let xg = xg.to_dtype(DType::F32)?;
        let mean = xg.mean_keepdim(2)?;
        let xc = xg.broadcast_sub(&mean)?;
        let var = xc.sqr()?.mean_keepdim(2)?;
        let inv_std = (var + self.eps)?.sqrt()?.recip()?;
        let xhat = xc.broadcast_mul(&inv_std)?.to_dtype(in_dtype)?;
        Ok((xhat, inv_std))
    }

    /// Runs `f` with the kernel geometry of an input of shape `dims`.
    fn with_geom<T>(&self, dims: &[usize], f: impl FnOnce(&norm::GroupNormGeom) -> R<T>) -> R<T> {
        if dims.len() < 2 {
            candle_core::bail!("group norm: input of shape {dims:?} has no channel axis");
        }
        let (b, c, n) = (dims[0], dims[1], dims[2..].iter().product());
        let gamma = self.weight.to_vec1::<f32>()?;
        let beta = self.bias.to_vec1::<f32>()?;
        let g = norm::GroupNormGeom::new((b, c, n), self.groups, self.eps, &gamma, &beta)
            .map_err(kernels::err)?;
        f(&g)
    }

    /// The fused kernel: `(y, x̂, 1/σ)`.
    fn kernel(&self, x: &Tensor, silu: bool, keep: bool) -> R<(Tensor, Option<Tensor>, Tensor)> {
        let b = x.dim(0)?;
        let (y, xhat, inv) = self.with_geom(x.dims(), |g| {
            kernels::with_f32(x, |xs| {
                norm::group_norm(g, xs, silu, keep).map_err(kernels::err)
            })
        })?;
        let xhat = match xhat {
            Some(v) => Some(kernels::tensor(v, x.dims())?),
            None => None,
        };
        Ok((
            kernels::tensor(y, x.dims())?,
            xhat,
            kernels::tensor(inv, &[b, self.groups, 1])?,
        ))
    }

    fn forward_act(&self, x: &Tensor, silu: bool) -> R<Tensor> {
        if kernels::applies(&[x, &self.weight, &self.bias]) {
            return Ok(self.kernel(x, silu, false)?.0);
        }
        let (xhat, _) = self.normalise(x)?;
        let y = self.affine(&xhat, x.dims())?;
        if silu { y.silu() } else { Ok(y) }
    }

    fn forward_act_t(&self, x: &Tensor, silu: bool) -> R<(Tensor, GroupNormTape)> {
        if kernels::applies(&[x, &self.weight, &self.bias]) {
            let (y, xhat, inv_std) = self.kernel(x, silu, true)?;
            let xhat =
                xhat.ok_or_else(|| candle_core::Error::Msg("group norm: x̂ not kept".into()))?;
            return Ok((
                y,
                GroupNormTape {
                    xhat,
                    inv_std,
                    silu,
                },
            ));
        }
        let (xhat, inv_std) = self.normalise(x)?;
        let y = self.affine(&xhat, x.dims())?;
        let y = if silu { y.silu()? } else { y };
        Ok((
            y,
            GroupNormTape {
                xhat,
                inv_std,
                silu,
            },
        ))
    }

    pub fn forward(&self, x: &Tensor) -> R<Tensor> {
        self.forward_act(x, false)
    }

    /// `silu(group_norm(x))`, fused.
    pub fn forward_silu(&self, x: &Tensor) -> R<Tensor> {
        self.forward_act(x, true)
    }

    pub fn forward_t(&self, x: &Tensor) -> R<(Tensor, GroupNormTape)> {
        self.forward_act_t(x, false)
    }

    /// [`GroupNorm::forward_silu`] with a tape for [`GroupNorm::backward`].
    pub fn forward_silu_t(&self, x: &Tensor) -> R<(Tensor, GroupNormTape)> {
        self.forward_act_t(x, true)
    }

    /// Input gradient given the gradient of the output (of the SiLU, if the tape has one).
    pub fn backward(&self, t: &GroupNormTape, dy: &Tensor) -> R<Tensor> {
        let shape = dy.dims().to_vec();
        if kernels::applies(&[dy, &t.xhat, &t.inv_std, &self.weight, &self.bias]) {
            let dx = self.with_geom(&shape, |g| {
                kernels::with_f32(dy, |ds| {
                    kernels::with_f32(&t.xhat, |xh| {
                        kernels::with_f32(&t.inv_std, |iv| {
                            norm::group_norm_input_grad(g, ds, xh, iv, t.silu).map_err(kernels::err)
                        })
                    })
                })
            })?;
            return kernels::tensor(dx, &shape);
        }
        let dy = if t.silu {
            let a = self.affine(&t.xhat, &shape)?;
            silu_backward(&a, dy)?
        } else {
            dy.clone()
        };
        let b = shape[0];
        let mut bshape = vec![1usize; shape.len()];
        bshape[1] = shape[1];
        let dxhat = dy
            .broadcast_mul(&self.weight.reshape(bshape.as_slice())?)?
            .reshape((b, self.groups, ()))?;
        let xhat = t.xhat.reshape((b, self.groups, ()))?;
        let m1 = dxhat.mean_keepdim(2)?;
        let m2 = (&dxhat * &xhat)?.mean_keepdim(2)?;
        let dx = dxhat
            .broadcast_sub(&m1)?
            .sub(&xhat.broadcast_mul(&m2)?)?
            .broadcast_mul(&t.inv_std)?;
        dx.reshape(shape)
    }
}

/// Layer normalisation over the last axis.
#[derive(Debug, Clone)]
pub struct LayerNorm {
    pub weight: Tensor,
    pub bias: Tensor,
    pub eps: f64,
}

impl LayerNorm {
    pub fn load(vb: VarBuilder, c: usize, eps: f64) -> R<Self> {
        Ok(Self {
            weight: vb.get(c, "weight")?,
            bias: vb.get(c, "bias")?,
            eps,
        })
    }

    pub fn forward(&self, x: &Tensor) -> R<Tensor> {
        if kernels::applies(&[x, &self.weight, &self.bias]) {
            let c = self.weight.dim(0)?;
            let (g, b) = (self.weight.to_vec1::<f32>()?, self.bias.to_vec1::<f32>()?);
            let y = kernels::with_f32(x, |xs| {
                norm::layer_norm(xs, c, &g, &b, self.eps).map_err(kernels::err)
            })?;
            return kernels::tensor(y, x.dims());
        }
        candle_nn::LayerNorm::new(self.weight.clone(), self.bias.clone(), self.eps).forward(x)
    }
}
