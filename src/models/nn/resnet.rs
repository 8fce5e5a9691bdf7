//! diffusers `ResnetBlock2D` without time embedding (the VAE's), with its tape.

use super::{Conv2d, GroupNorm, GroupNormTape, R};
use candle_core::Tensor;
use candle_nn::VarBuilder;

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
