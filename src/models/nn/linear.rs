//! The linear layer, with the residual folded into the kernel's accumulator.

use super::R;
use crate::models::kernels::{self, linear};
use candle_core::{Module, Tensor};
use candle_nn::VarBuilder;

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

    /// The same layer with its weight stored transposed (`[in, out]`, read through a view as
    /// `[out, in]`) where the kernels' short-product path reads it (`in` ≥
    /// [`linear::MIN_DEPTH`]): faster for inputs of few rows, such as a text encoder's tokens;
    /// the same values, no more memory.
    pub fn stored_for_few_rows(self) -> R<Self> {
        if self.weight.dim(1)? < linear::MIN_DEPTH {
            return Ok(self);
        }
        Ok(Self {
            weight: self.weight.t()?.contiguous()?.t()?,
            bias: self.bias,
        })
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
            // The weight as stored: `[out, in]`, or transposed (`stored_for_few_rows`).
            let transposed = !self.weight.is_contiguous() && self.weight.t()?.is_contiguous();
            let stored = if transposed {
                self.weight.t()?
            } else {
                self.weight.clone()
            };
            let y = kernels::with_f32(x, |xs| {
                kernels::with_f32(&stored, |w| {
                    let w = if transposed {
                        linear::Weight::InOut(w)
                    } else {
                        linear::Weight::OutIn(w)
                    };
                    let b = bias.as_deref();
                    match residual {
                        Some(r) => kernels::with_f32(r, |rs| {
                            linear::linear(xs, i, w, o, b, Some(rs)).map_err(kernels::err)
                        }),
                        None => linear::linear(xs, i, w, o, b, None).map_err(kernels::err),
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

/// Plain module helper so [`Linear`] can be used where candle expects a `Module`.
impl Module for Linear {
    fn forward(&self, xs: &Tensor) -> R<Tensor> {
        Linear::forward(self, xs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::kernels::test_values;
    use candle_core::Device;

    /// A layer stored for few rows computes what it computed before (77 and 300 rows, with and
    /// without a residual), keeps its `[out, in]` shape, and a narrow layer is left as it is.
    #[test]
    fn stored_for_few_rows_gives_the_same_outputs() {
        let (i, o) = (512, 200);
        let t = |v: Vec<f32>, s: &[usize]| Tensor::from_vec(v, s, &Device::Cpu).unwrap();
        let layer = Linear {
            weight: t(test_values(o * i, 1), &[o, i]),
            bias: Some(t(test_values(o, 2), &[o])),
        };
        let stored = layer.clone().stored_for_few_rows().unwrap();
        assert_eq!(stored.weight.dims(), &[o, i]);
        assert!(!stored.weight.is_contiguous());
        for rows in [77, 300] {
            let x = t(test_values(rows * i, 3), &[rows, i]);
            let r = t(test_values(rows * o, 4), &[rows, o]);
            for (a, b) in [
                (layer.forward(&x).unwrap(), stored.forward(&x).unwrap()),
                (
                    layer.forward_residual(&x, &r).unwrap(),
                    stored.forward_residual(&x, &r).unwrap(),
                ),
            ] {
                let d = (a - b).unwrap().abs().unwrap().max_all().unwrap();
                assert!(d.to_scalar::<f32>().unwrap() < 1e-4, "{rows} rows");
            }
        }
        let narrow = Linear {
            weight: t(test_values(8 * 4, 5), &[8, 4]),
            bias: None,
        };
        assert!(narrow.stored_for_few_rows().unwrap().weight.is_contiguous());
    }
}
