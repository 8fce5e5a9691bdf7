//! diffusers `ResnetBlock2D` with a time embedding (`resnet_time_scale_shift = "default"`).

use crate::models::nn::{self, Conv2d, GroupNorm, Linear};
use candle_core::Tensor;
use candle_nn::VarBuilder;

type R<T> = candle_core::Result<T>;

#[derive(Debug, Clone)]
pub struct ResnetBlock2D {
    pub norm1: GroupNorm,
    pub conv1: Conv2d,
    pub time_emb_proj: Linear,
    pub norm2: GroupNorm,
    pub conv2: Conv2d,
    pub conv_shortcut: Option<Conv2d>,
    /// The output is `(x + h) / output_scale_factor`.
    pub output_scale_factor: f64,
}

impl ResnetBlock2D {
    pub fn load(
        vb: VarBuilder,
        (ci, co, temb): (usize, usize, usize),
        groups: usize,
        eps: f64,
        output_scale_factor: f64,
    ) -> R<Self> {
        let conv_shortcut = if ci != co {
            Some(Conv2d::load(vb.pp("conv_shortcut"), ci, co, 1, 1, 0, true)?.forward_only()?)
        } else {
            None
        };
        Ok(Self {
            norm1: GroupNorm::load(vb.pp("norm1"), groups, ci, eps)?,
            conv1: Conv2d::load(vb.pp("conv1"), ci, co, 3, 1, 1, true)?.forward_only()?,
            time_emb_proj: Linear::load(vb.pp("time_emb_proj"), temb, co, true)?,
            norm2: GroupNorm::load(vb.pp("norm2"), groups, co, eps)?,
            conv2: Conv2d::load(vb.pp("conv2"), co, co, 3, 1, 1, true)?.forward_only()?,
            conv_shortcut,
            output_scale_factor,
        })
    }

    /// `x [b, ci, h, w]`, `temb_act = silu(temb) [b, temb]` (shared by every block).
    pub fn forward(&self, x: &Tensor, temb_act: &Tensor) -> R<Tensor> {
        let t = self.time_emb_proj.forward(temb_act)?;
        let h = self
            .conv1
            .forward_channel_add(&self.norm1.forward_silu(x)?, &t)?;
        // dropout is the identity at inference
        let h = self.conv2.forward(&self.norm2.forward_silu(&h)?)?;
        let skip = match &self.conv_shortcut {
            Some(c) => c.forward(x)?,
            None => x.clone(),
        };
        nn::add_scaled(&skip, &h, 1.0 / self.output_scale_factor)
    }
}
