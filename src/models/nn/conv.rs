//! 2-D convolution ([`Conv2d`]) on our kernels or candle's, with its input gradient, and the
//! VAE's padded downsampler ([`Downsample`]).

use super::R;
use crate::models::kernels::{self, conv, conv::ConvGeom, pointwise, winograd};
use candle_core::Tensor;
use candle_nn::VarBuilder;
use std::sync::{Arc, OnceLock};

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
        if k == 3
            && self.stride == 1
            && let Some(w) = self.weight.take_if(|w| kernels::applies(&[w]))
        {
            let u = kernels::with_f32(&w, |w| Ok(winograd::transform_kernel(w, co, ci)))?;
            if self.cache.wino.set(u).is_err() {
                candle_core::bail!("conv2d: Winograd kernel computed twice");
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

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{DType, Device};
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
