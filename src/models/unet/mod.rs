//! diffusers `UNet2DConditionModel` (SD 1.x, 2.x, Turbo and smaller variants), built from
//! `unet/config.json`. Module and field names are the checkpoint keys.
//!
//! - [`config`]: the config file, resolved and validated into [`UnetArch`];
//! - [`resnet`]: `ResnetBlock2D` with the time embedding;
//! - [`transformer`]: `Transformer2DModel` (attention, GEGLU feed-forward);
//! - [`blocks`]: down / mid / up blocks and the resamplers.
//!
//! f32 on the CPU runs on [`crate::models::kernels`] (Winograd/GEMM convolutions, fused group
//! norm + SiLU, fused attention, linear layers with fused bias and residual); other dtypes and
//! devices run the same graph on candle ops.

pub mod blocks;
pub mod config;
pub mod resnet;
pub mod transformer;

pub use config::{AttnArch, LevelArch, UnetArch, UnetConfig};

use super::nn::{Conv2d, GroupNorm, Linear};
use super::{ModelError, Result};
use blocks::{DownBlock, MidBlock, UpBlock};
use candle_core::{DType, Device, Tensor};
use candle_nn::VarBuilder;

type R<T> = candle_core::Result<T>;

/// The UNet plus its parsed config.
pub struct Unet {
    pub config: UnetConfig,
    pub arch: UnetArch,
    conv_in: Conv2d,
    linear_1: Linear,
    linear_2: Linear,
    down_blocks: Vec<DownBlock>,
    mid_block: MidBlock,
    up_blocks: Vec<UpBlock>,
    conv_norm_out: GroupNorm,
    conv_out: Conv2d,
    dtype: DType,
}

impl std::fmt::Debug for Unet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Unet")
            .field("config", &self.config)
            .finish()
    }
}

impl Unet {
    /// Builds the UNet (`path` is only used in error messages).
    pub fn new(vb: VarBuilder, config: UnetConfig, path: &std::path::Path) -> Result<Self> {
        let arch = config.arch().map_err(|e| ModelError::Unsupported {
            component: "unet",
            path: path.display().to_string(),
            reason: e.to_string(),
        })?;
        Self::build(vb, config, arch).map_err(super::loader::mismatch("unet", path))
    }

    fn build(vb: VarBuilder, config: UnetConfig, arch: UnetArch) -> R<Unet> {
        let arch = &arch;
        let c0 = arch.levels[0].channels;
        let n = arch.levels.len();
        let temb = arch.time_embed_dim();
        let down_blocks = (0..n)
            .map(|i| DownBlock::load(vb.pp(format!("down_blocks.{i}")), arch, i))
            .collect::<R<Vec<_>>>()?;
        let up_blocks = (0..n)
            .map(|i| UpBlock::load(vb.pp(format!("up_blocks.{i}")), arch, i))
            .collect::<R<Vec<_>>>()?;
        Ok(Unet {
            config,
            arch: arch.clone(),
            conv_in: Conv2d::load(vb.pp("conv_in"), arch.in_channels, c0, 3, 1, 1, true)?
                .forward_only()?,
            linear_1: Linear::load(vb.pp("time_embedding.linear_1"), c0, temb, true)?,
            linear_2: Linear::load(vb.pp("time_embedding.linear_2"), temb, temb, true)?,
            down_blocks,
            mid_block: MidBlock::load(vb.pp("mid_block"), arch)?,
            up_blocks,
            conv_norm_out: GroupNorm::load(vb.pp("conv_norm_out"), arch.groups, c0, arch.eps)?,
            conv_out: Conv2d::load(vb.pp("conv_out"), c0, arch.out_channels, 3, 1, 1, true)?
                .forward_only()?,
            dtype: vb.dtype(),
        })
    }

    /// Raw model output (ε or v, as the scheduler's `prediction_type` says) for latents
    /// `[b, c, h, w]` at timestep `t`, conditioned on `context [b, seq, cross_attention_dim]`.
    pub fn forward(&self, latents: &Tensor, t: f64, context: &Tensor) -> Result<Tensor> {
        let (b, _, h, w) = super::latent_dims(latents, self.arch.in_channels, "UNet")?;
        if h == 0 || w == 0 {
            return Err(ModelError::InvalidInput(format!("latents of size {h}x{w}")));
        }
        let (cb, _, cd) = context.dims3().map_err(|_| {
            ModelError::InvalidInput(format!(
                "context must be [b, seq, dim], got {:?}",
                context.dims()
            ))
        })?;
        let want = self.arch.cross_attention_dim;
        if cb != b || cd != want {
            return Err(ModelError::InvalidInput(format!(
                "context shape {:?} does not match batch {b} and cross_attention_dim {want}",
                context.dims()
            )));
        }
        if !t.is_finite() {
            return Err(ModelError::InvalidInput(format!("timestep {t}")));
        }
        let out = self.run(
            &latents.to_dtype(self.dtype)?,
            t,
            &context.to_dtype(self.dtype)?,
        )?;
        Ok(out.to_dtype(latents.dtype())?)
    }

    /// diffusers' `get_timestep_embedding`, in f32 as PyTorch computes it.
    fn time_proj(&self, t: f64, b: usize, device: &Device) -> R<Tensor> {
        let dim = self.arch.levels[0].channels;
        let half = dim / 2;
        let ln = -(10000f64.ln()) as f32;
        let denom = half as f32 - self.arch.freq_shift as f32;
        let args: Vec<f32> = (0..half)
            .map(|i| t as f32 * (ln * i as f32 / denom).exp())
            .collect();
        let (sin, cos): (Vec<f32>, Vec<f32>) = args.iter().map(|a| (a.sin(), a.cos())).unzip();
        let mut emb = if self.arch.flip_sin_to_cos {
            [cos, sin].concat()
        } else {
            [sin, cos].concat()
        };
        emb.resize(dim, 0.0);
        Tensor::from_vec(emb, (1, dim), device)?
            .repeat((b, 1))?
            .to_dtype(self.dtype)
    }

    fn run(&self, x: &Tensor, t: f64, ctx: &Tensor) -> R<Tensor> {
        let (b, _, h, w) = x.dims4()?;
        let temb = self.time_proj(t, b, x.device())?;
        let temb = self
            .linear_2
            .forward(&self.linear_1.forward(&temb)?.silu()?)?;
        // every resnet applies SiLU to the same embedding first
        let temb = temb.silu()?;
        let x = if self.arch.center_input_sample {
            ((x * 2.0)? - 1.0)?
        } else {
            x.clone()
        };
        let mut hs = self.conv_in.forward(&x)?;
        let mut skips = vec![hs.clone()];
        for d in &self.down_blocks {
            hs = d.forward(hs, &temb, ctx, &mut skips)?;
        }
        hs = self.mid_block.forward(&hs, &temb, ctx)?;
        let factor = 1usize << (self.up_blocks.len() - 1);
        let odd = h % factor != 0 || w % factor != 0;
        for u in &self.up_blocks {
            hs = u.forward(hs, &temb, ctx, &mut skips, odd)?;
        }
        self.conv_out
            .forward(&self.conv_norm_out.forward_silu(&hs)?)
    }
}
