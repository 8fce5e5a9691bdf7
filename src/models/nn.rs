//! Layers with a forward pass that can record a tape and a hand-written backward pass that
//! returns only the gradient with respect to the layer input (never the weights' gradients).
//!
//! Score distillation needs `J_encoder^T · g`; candle's autograd would also compute every
//! kernel gradient (one extra convolution per layer, plus memory), which is pure waste here.
//! Field names follow the checkpoint keys.

use super::kernels::{self, attention, conv, conv::ConvGeom, linear, norm, pointwise, winograd};
use candle_core::{D, DType, Module, Tensor};
use candle_nn::VarBuilder;
use std::sync::{Arc, OnceLock};

type R<T> = candle_core::Result<T>;

/// 2-D convolution (`weight [co, ci, k, k]`, optional `bias [co]`).
///
/// Invariant: `weight` is `None` only for a 3×3 stride-1 layer loaded by
/// [`Conv2d::forward_only`] on the kernel path; its Winograd transform is then in the
/// cache, and only the forward pass is available.
#[derive(Debug, Clone)]
pub struct Conv2d {
    weight: Option<Tensor>,
    /// `(co, ci, k)` of the weight.
    dims: (usize, usize, usize),
    pub bias: Option<Tensor>,
    pub stride: usize,
    pub padding: usize,
    /// Kernel-path caches, filled on first use: the bias as f32 values, the weights' Winograd
    /// transform, and the transform of the flipped, transposed kernel (for the input gradient).
    cache: Arc<ConvCache>,
}

#[derive(Debug, Default)]
struct ConvCache {
    bias: OnceLock<Option<Vec<f32>>>,
    wino: OnceLock<Vec<f32>>,
    wino_flipped: OnceLock<Vec<f32>>,
}

impl Conv2d {
    pub fn load(
        vb: VarBuilder,
        ci: usize,
        co: usize,
        k: usize,
        stride: usize,
        padding: usize,
        bias: bool,
    ) -> R<Self> {
        let weight = vb.get((co, ci, k, k), "weight")?;
        let bias = if bias {
            Some(vb.get(co, "bias")?)
        } else {
            None
        };
        Ok(Self {
            weight: Some(weight),
            dims: (co, ci, k),
            bias,
            stride,
            padding,
            cache: Arc::default(),
        })
    }

    /// This layer for a model that only ever runs forward (the UNet, the VAE decoder). On the
    /// kernel path a 3×3 stride-1 layer computes its Winograd transform now and drops its
    /// weights: 9/25 of the memory the two took together. [`Conv2d::backward`] then fails.
    pub fn forward_only(mut self) -> R<Self> {
        let (co, ci, k) = self.dims;
        if k == 3 && self.stride == 1 {
            if let Some(w) = self.weight.take_if(|w| kernels::applies(&[w])) {
                let u = kernels::with_f32(&w, |w| Ok(winograd::transform_kernel(w, co, ci)))?;
                if self.cache.wino.set(u).is_err() {
                    candle_core::bail!("conv2d: Winograd kernel computed twice");
                }
            }
        }
        Ok(self)
    }

    /// Whether only the forward pass is available ([`Conv2d::forward_only`]).
    pub fn is_forward_only(&self) -> bool {
        self.weight.is_none()
    }

    /// The weights, or an error for a forward-only layer.
    pub fn weight(&self) -> R<&Tensor> {
        match &self.weight {
            Some(w) => Ok(w),
            None => candle_core::bail!(
                "conv2d: this layer was loaded forward-only and keeps only its Winograd kernel"
            ),
        }
    }

    /// Whether our kernels run this layer on `ts` (a forward-only layer always takes them).
    fn on_kernels(&self, ts: &[&Tensor]) -> bool {
        match &self.weight {
            Some(w) => kernels::applies(ts) && kernels::applies(&[w]),
            None => true,
        }
    }

    pub fn forward(&self, x: &Tensor) -> R<Tensor> {
        if self.on_kernels(&[x]) {
            return self.forward_padded(x, [self.padding; 4]);
        }
        let y = x.conv2d(self.weight()?, self.padding, self.stride, 1, 1)?;
        match &self.bias {
            Some(b) => y.broadcast_add(&b.reshape((1, b.dim(0)?, 1, 1))?),
            None => Ok(y),
        }
    }

    fn geom(&self, x_dims: (usize, usize, usize, usize), pad: [usize; 4]) -> R<ConvGeom> {
        let (co, ci, k) = self.dims;
        let (b, xc, h, w) = x_dims;
        if xc != ci {
            candle_core::bail!("conv2d: input has {xc} channels, kernel expects {ci}");
        }
        ConvGeom::new(b, ci, h, w, co, k, self.stride, pad).map_err(kernels::err)
    }

    /// Forward with explicit zero padding `[top, bottom, left, right]` (the kernel path; the
    /// candle fallback pads first).
    pub fn forward_padded(&self, x: &Tensor, pad: [usize; 4]) -> R<Tensor> {
        if !self.on_kernels(&[x]) {
            let x = x
                .pad_with_zeros(2, pad[0], pad[1])?
                .pad_with_zeros(3, pad[2], pad[3])?;
            let c = Conv2d {
                padding: 0,
                ..self.clone()
            };
            return c.forward(&x);
        }
        let (y, shape) = self.kernel_forward(x, pad)?;
        kernels::tensor(y, &shape)
    }

    /// `relu(conv(x))`, the ReLU applied to the kernel's output before it becomes a tensor.
    pub fn forward_relu(&self, x: &Tensor) -> R<Tensor> {
        if !self.on_kernels(&[x]) {
            return self.forward(x)?.relu();
        }
        let (mut y, shape) = self.kernel_forward(x, [self.padding; 4])?;
        pointwise::relu_inplace(&mut y);
        kernels::tensor(y, &shape)
    }

    /// `conv(x) + v[b, co]` broadcast over the image (how the UNet adds its time embedding),
    /// added to the kernel's output in place.
    pub fn forward_channel_add(&self, x: &Tensor, v: &Tensor) -> R<Tensor> {
        let (b, c) = v.dims2()?;
        if !self.on_kernels(&[x, v]) {
            return self.forward(x)?.broadcast_add(&v.reshape((b, c, 1, 1))?);
        }
        let (mut y, shape) = self.kernel_forward(x, [self.padding; 4])?;
        if (b, c) != (shape[0], shape[1]) {
            candle_core::bail!("conv2d: offsets {:?} for an output {shape:?}", v.dims());
        }
        kernels::with_f32(v, |vs| {
            pointwise::add_per_channel(&mut y, vs, shape[2] * shape[3]).map_err(kernels::err)
        })?;
        kernels::tensor(y, &shape)
    }

    fn kernel_forward(&self, x: &Tensor, pad: [usize; 4]) -> R<(Vec<f32>, [usize; 4])> {
        let g = self.geom(x.dims4()?, pad)?;
        let (ho, wo) = g.out_hw();
        let bias = self.cached_bias()?;
        if !kernels::cpu_f32(&[x]) {
            candle_core::bail!(
                "conv2d: our kernels need an f32 CPU input, got {:?} on {:?}",
                x.dtype(),
                x.device()
            );
        }
        let Some(weight) = &self.weight else {
            let u = match self.cache.wino.get() {
                Some(u) if winograd::applies(&g) => u,
                _ => candle_core::bail!("conv2d: forward-only layer without its Winograd kernel"),
            };
            let y = kernels::with_f32(x, |xs| {
                winograd::conv2d(&g, xs, u, bias).map_err(kernels::err)
            })?;
            return Ok((y, [g.b, g.co, ho, wo]));
        };
        // the weights are read in place (no copy); only their Winograd transform is cached
        let y = kernels::with_f32(weight, |weight| {
            let wino = if winograd::applies(&g) {
                Some(
                    self.cache
                        .wino
                        .get_or_init(|| winograd::transform_kernel(weight, g.co, g.ci)),
                )
            } else {
                None
            };
            kernels::with_f32(x, |xs| {
                conv::conv2d_prepared(&g, xs, weight, wino.map(|v| v.as_slice()), bias)
                    .map_err(kernels::err)
            })
        })?;
        Ok((y, [g.b, g.co, ho, wo]))
    }

    /// The bias as f32 values, read once.
    fn cached_bias(&self) -> R<Option<&[f32]>> {
        if self.cache.bias.get().is_none() {
            let b = match &self.bias {
                Some(b) => Some(b.to_vec1::<f32>()?),
                None => None,
            };
            let _ = self.cache.bias.set(b);
        }
        match self.cache.bias.get() {
            Some(b) => Ok(b.as_deref()),
            None => candle_core::bail!("conv2d: bias cache not filled"),
        }
    }

    /// Input gradient of [`Conv2d::forward_padded`] for an input of spatial size `(h, w)`.
    pub fn backward_padded(&self, dy: &Tensor, h: usize, w: usize, pad: [usize; 4]) -> R<Tensor> {
        let weight = self.weight()?;
        if !kernels::applies(&[dy, weight]) {
            let c = Conv2d {
                padding: 0,
                ..self.clone()
            };
            let d = c.backward(dy, h + pad[0] + pad[1], w + pad[2] + pad[3])?;
            return d.narrow(2, pad[0], h)?.narrow(3, pad[2], w);
        }
        let (b, co, oh, ow) = dy.dims4()?;
        let (_, ci, _) = self.dims;
        let g = self.geom((b, ci, h, w), pad)?;
        if g.co != co || g.out_hw() != (oh, ow) {
            candle_core::bail!(
                "conv2d backward: gradient {:?} does not match the output {:?} of a {h}x{w} input",
                dy.dims(),
                (b, g.co, g.out_hw())
            );
        }
        let dx = kernels::with_f32(weight, |weight| {
            let wino = if winograd::applies(&g) {
                Some(self.cache.wino_flipped.get_or_init(|| {
                    winograd::transform_kernel(&conv::flip_transpose(weight, g.co, ci, 3), ci, g.co)
                }))
            } else {
                None
            };
            kernels::with_f32(dy, |ds| {
                conv::conv2d_input_grad_prepared(&g, ds, weight, wino.map(|v| v.as_slice()))
                    .map_err(kernels::err)
            })
        })?;
        kernels::tensor(dx, &[b, ci, h, w])
    }

    /// Gradient w.r.t. the input of spatial size `(h, w)` given the output gradient `dy`: the
    /// kernels' adjoint ([`Conv2d::backward_padded`]), or, off the kernel path, a stride-1
    /// candle convolution of the (dilated, padded) `dy` with the flipped, transposed kernel.
    pub fn backward(&self, dy: &Tensor, h: usize, w: usize) -> R<Tensor> {
        let weight = self.weight()?;
        if kernels::applies(&[dy, weight]) {
            return self.backward_padded(dy, h, w, [self.padding; 4]);
        }
        let (_, _, k) = self.dims;
        let (b, c, oh, ow) = dy.dims4()?;
        let s = self.stride;
        let dy = if s > 1 {
            dy.reshape((b, c, oh, 1, ow, 1))?
                .pad_with_zeros(3, 0, s - 1)?
                .pad_with_zeros(5, 0, s - 1)?
                .reshape((b, c, oh * s, ow * s))?
                .narrow(2, 0, (oh - 1) * s + 1)?
                .narrow(3, 0, (ow - 1) * s + 1)?
        } else {
            dy.clone()
        };
        let wt = flip_transpose(weight)?;
        // full correlation: pad by k-1, then remove the forward padding
        let full = dy
            .pad_with_zeros(2, k - 1, k - 1)?
            .pad_with_zeros(3, k - 1, k - 1)?
            .conv2d(&wt, 0, 1, 1, 1)?;
        let (_, _, fh, fw) = full.dims4()?;
        // full covers padded-input rows [0, fh); input row i sits at padded row i + padding
        let p = self.padding;
        let take_h = h.min(fh.saturating_sub(p));
        let take_w = w.min(fw.saturating_sub(p));
        let g = full.narrow(2, p, take_h)?.narrow(3, p, take_w)?;
        let g = if take_h < h {
            g.pad_with_zeros(2, 0, h - take_h)?
        } else {
            g
        };
        if take_w < w {
            g.pad_with_zeros(3, 0, w - take_w)
        } else {
            Ok(g)
        }
    }
}

/// `W[co, ci, kh, kw] -> W'[ci, co, k-1-kh, k-1-kw]`.
fn flip_transpose(w: &Tensor) -> R<Tensor> {
    let (_, _, kh, kw) = w.dims4()?;
    let dev = w.device();
    let rh: Vec<u32> = (0..kh as u32).rev().collect();
    let rw: Vec<u32> = (0..kw as u32).rev().collect();
    let w = if kh > 1 {
        w.index_select(&Tensor::new(rh.as_slice(), dev)?, 2)?
    } else {
        w.clone()
    };
    let w = if kw > 1 {
        w.index_select(&Tensor::new(rw.as_slice(), dev)?, 3)?
    } else {
        w
    };
    w.transpose(0, 1)?.contiguous()
}

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
        if groups == 0 || channels % groups != 0 {
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

/// Linear layer, `weight [out, in]` (a 1×1 conv weight `[out, in, 1, 1]` is accepted too).
#[derive(Debug, Clone)]
pub struct Linear {
    pub weight: Tensor,
    pub bias: Option<Tensor>,
}

impl Linear {
    pub fn load(vb: VarBuilder, i: usize, o: usize, bias: bool) -> R<Self> {
        let weight = match vb.get((o, i), "weight") {
            Ok(w) => w,
            Err(e) => match vb.get((o, i, 1, 1), "weight") {
                Ok(w) => w.reshape((o, i))?,
                Err(_) => return Err(e),
            },
        };
        let bias = if bias { Some(vb.get(o, "bias")?) } else { None };
        Ok(Self { weight, bias })
    }

    /// `x [..., in] -> [..., out]`.
    pub fn forward(&self, x: &Tensor) -> R<Tensor> {
        self.forward_impl(x, None)
    }

    /// The bias as f32 values (for the kernels).
    pub fn bias_f32(&self) -> R<Option<Vec<f32>>> {
        self.bias.as_ref().map(|b| b.to_vec1::<f32>()).transpose()
    }

    /// Whether the kernels apply to this layer's weights together with `activations`.
    pub fn kernels_apply(&self, activations: &[&Tensor]) -> bool {
        let mut ts = vec![&self.weight];
        ts.extend(self.bias.as_ref());
        ts.extend_from_slice(activations);
        kernels::applies(&ts)
    }

    /// `residual + linear(x)`, the residual folded into the product's accumulator.
    pub fn forward_residual(&self, x: &Tensor, residual: &Tensor) -> R<Tensor> {
        self.forward_impl(x, Some(residual))
    }

    fn out_dims(&self, x: &Tensor) -> R<Vec<usize>> {
        let mut dims = x.dims().to_vec();
        match dims.last_mut() {
            Some(last) => *last = self.weight.dim(0)?,
            None => candle_core::bail!("linear: scalar input"),
        }
        Ok(dims)
    }

    fn forward_impl(&self, x: &Tensor, residual: Option<&Tensor>) -> R<Tensor> {
        let mut acts = vec![x];
        acts.extend(residual);
        let dims = self.out_dims(x)?;
        if self.kernels_apply(&acts) && residual.is_none_or(|r| r.dims() == dims.as_slice()) {
            let (o, i) = self.weight.dims2()?;
            let bias = self.bias_f32()?;
            let y = kernels::with_f32(x, |xs| {
                kernels::with_f32(&self.weight, |w| match residual {
                    Some(r) => kernels::with_f32(r, |rs| {
                        linear::linear(xs, i, w, o, bias.as_deref(), Some(rs)).map_err(kernels::err)
                    }),
                    None => {
                        linear::linear(xs, i, w, o, bias.as_deref(), None).map_err(kernels::err)
                    }
                })
            })?;
            return kernels::tensor(y, &dims);
        }
        let y = x.broadcast_matmul(&self.weight.t()?)?;
        let y = match &self.bias {
            Some(b) => y.broadcast_add(b)?,
            None => y,
        };
        match residual {
            Some(r) => y + r,
            None => Ok(y),
        }
    }

    pub fn backward(&self, dy: &Tensor) -> R<Tensor> {
        dy.broadcast_matmul(&self.weight)
    }
}

/// diffusers `ResnetBlock2D` without time embedding (the VAE's).
#[derive(Debug, Clone)]
pub struct ResnetBlock {
    pub norm1: GroupNorm,
    pub conv1: Conv2d,
    pub norm2: GroupNorm,
    pub conv2: Conv2d,
    pub conv_shortcut: Option<Conv2d>,
}

#[derive(Debug)]
pub struct ResnetTape {
    n1: GroupNormTape,
    n2: GroupNormTape,
    hw: (usize, usize),
}

impl ResnetBlock {
    /// This block for a model that only runs forward ([`Conv2d::forward_only`]).
    pub fn forward_only(self) -> R<Self> {
        Ok(Self {
            conv1: self.conv1.forward_only()?,
            conv2: self.conv2.forward_only()?,
            ..self
        })
    }

    pub fn load(vb: VarBuilder, ci: usize, co: usize, groups: usize, eps: f64) -> R<Self> {
        let conv_shortcut = if ci != co {
            Some(Conv2d::load(vb.pp("conv_shortcut"), ci, co, 1, 1, 0, true)?)
        } else {
            None
        };
        Ok(Self {
            norm1: GroupNorm::load(vb.pp("norm1"), groups, ci, eps)?,
            conv1: Conv2d::load(vb.pp("conv1"), ci, co, 3, 1, 1, true)?,
            norm2: GroupNorm::load(vb.pp("norm2"), groups, co, eps)?,
            conv2: Conv2d::load(vb.pp("conv2"), co, co, 3, 1, 1, true)?,
            conv_shortcut,
        })
    }

    pub fn forward(&self, x: &Tensor) -> R<Tensor> {
        let h = self.conv1.forward(&self.norm1.forward_silu(x)?)?;
        let h = self.conv2.forward(&self.norm2.forward_silu(&h)?)?;
        let skip = match &self.conv_shortcut {
            Some(c) => c.forward(x)?,
            None => x.clone(),
        };
        skip + h
    }

    pub fn forward_t(&self, x: &Tensor) -> R<(Tensor, ResnetTape)> {
        let (_, _, hh, ww) = x.dims4()?;
        let (a1, n1) = self.norm1.forward_silu_t(x)?;
        let h = self.conv1.forward(&a1)?;
        let (a2, n2) = self.norm2.forward_silu_t(&h)?;
        let h = self.conv2.forward(&a2)?;
        let skip = match &self.conv_shortcut {
            Some(c) => c.forward(x)?,
            None => x.clone(),
        };
        let y = (skip + h)?;
        Ok((
            y,
            ResnetTape {
                n1,
                n2,
                hw: (hh, ww),
            },
        ))
    }

    pub fn backward(&self, t: &ResnetTape, dy: &Tensor) -> R<Tensor> {
        let (h, w) = t.hw;
        let d = self.conv2.backward(dy, h, w)?;
        let d = self.norm2.backward(&t.n2, &d)?;
        let d = self.conv1.backward(&d, h, w)?;
        let d = self.norm1.backward(&t.n1, &d)?;
        let skip = match &self.conv_shortcut {
            Some(c) => c.backward(dy, h, w)?,
            None => dy.clone(),
        };
        d + skip
    }
}

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
        if heads == 0 || c % heads != 0 {
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

/// A convolution preceded by the asymmetric `(0, 1, 0, 1)` zero padding the VAE downsampler
/// uses.
#[derive(Debug, Clone)]
pub struct Downsample {
    pub conv: Conv2d,
}

impl Downsample {
    pub fn load(vb: VarBuilder, c: usize) -> R<Self> {
        Ok(Self {
            conv: Conv2d::load(vb.pp("conv"), c, c, 3, 2, 0, true)?,
        })
    }

    pub fn forward(&self, x: &Tensor) -> R<Tensor> {
        self.conv.forward_padded(x, [0, 1, 0, 1])
    }

    pub fn backward(&self, dy: &Tensor, h: usize, w: usize) -> R<Tensor> {
        self.conv.backward_padded(dy, h, w, [0, 1, 0, 1])
    }
}

/// Plain module helper so [`Linear`] can be used where candle expects a `Module`.
impl Module for Linear {
    fn forward(&self, xs: &Tensor) -> R<Tensor> {
        Linear::forward(self, xs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;
    use std::collections::HashMap;

    fn vb(co: usize, ci: usize, k: usize, dtype: DType) -> VarBuilder<'static> {
        let n = co * ci * k * k;
        let w = Tensor::from_vec(kernels::test_values(n, 7), (co, ci, k, k), &Device::Cpu).unwrap();
        let b = Tensor::from_vec(kernels::test_values(co, 8), co, &Device::Cpu).unwrap();
        let ts = HashMap::from([("weight".to_string(), w), ("bias".to_string(), b)]);
        VarBuilder::from_tensors(ts, dtype, &Device::Cpu)
    }

    fn input(c: usize) -> Tensor {
        let v = kernels::test_values(2 * c * 9 * 7, 9);
        Tensor::from_vec(v, (2, c, 9, 7), &Device::Cpu).unwrap()
    }

    #[test]
    fn forward_only_conv_keeps_the_winograd_kernel_and_matches_the_full_layer() {
        let (ci, co) = (5, 6);
        let full = Conv2d::load(vb(co, ci, 3, DType::F32), ci, co, 3, 1, 1, true).unwrap();
        let fwd = Conv2d::load(vb(co, ci, 3, DType::F32), ci, co, 3, 1, 1, true)
            .and_then(Conv2d::forward_only)
            .unwrap();
        assert!(fwd.is_forward_only() && !full.is_forward_only());
        let x = input(ci);
        let same = |a: Tensor, b: Tensor| {
            let d = (a - b).unwrap().abs().unwrap().max_all().unwrap();
            assert_eq!(d.to_scalar::<f32>().unwrap(), 0.0);
        };
        same(full.forward(&x).unwrap(), fwd.forward(&x).unwrap());
        let v = Tensor::from_vec(kernels::test_values(2 * co, 3), (2, co), &Device::Cpu).unwrap();
        same(
            full.forward_channel_add(&x, &v).unwrap(),
            fwd.forward_channel_add(&x, &v).unwrap(),
        );
        let dy = full.forward(&x).unwrap();
        assert!(full.backward(&dy, 9, 7).is_ok());
        let e = fwd.backward(&dy, 9, 7).unwrap_err().to_string();
        assert!(e.contains("forward-only"), "{e}");
        // a wrong input is an error, never a panic
        let e = fwd.forward(&x.to_dtype(DType::F16).unwrap()).unwrap_err();
        assert!(e.to_string().contains("f32 CPU input"), "{e}");
        let e = fwd.forward(&input(ci + 1)).unwrap_err();
        assert!(e.to_string().contains("channels"), "{e}");
    }

    #[test]
    fn forward_only_keeps_weights_where_winograd_does_not_apply() {
        let (ci, co) = (4, 3);
        for (k, stride, pad, dtype) in [
            (1, 1, 0, DType::F32),
            (3, 2, 1, DType::F32),
            (3, 1, 1, DType::F16),
        ] {
            let c = Conv2d::load(vb(co, ci, k, dtype), ci, co, k, stride, pad, true)
                .and_then(Conv2d::forward_only)
                .unwrap();
            assert!(!c.is_forward_only(), "k {k} stride {stride} {dtype:?}");
            assert!(c.weight().is_ok());
        }
    }
}
