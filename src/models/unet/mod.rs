//! diffusers `UNet2DConditionModel` (SD 1.x, 2.x, Turbo, SDXL and smaller variants), built from
//! `unet/config.json`. Module and field names are the checkpoint keys. SDXL's added
//! conditioning (`addition_embed_type = "text_time"`: pooled text embedding and size/crop time
//! ids) is [`AddedCond`], passed to [`Unet::forward_added`].
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

pub use config::{AttnArch, LevelArch, TextTimeArch, UnetArch, UnetConfig};

use super::nn::{Conv2d, GroupNorm, Linear};
use super::{ModelError, Result};
use blocks::{DownBlock, MidBlock, UpBlock};
use candle_core::{DType, Device, Tensor};
use candle_nn::VarBuilder;

type R<T> = candle_core::Result<T>;

/// SDXL's added conditioning for a batch of `b`: `text_embeds [b, pooled_dim]` (the projected
/// pooled output of `text_encoder_2`) and `time_ids [b, 6]` (original height and width, crop top
/// and left, target height and width, in pixels).
#[derive(Debug, Clone)]
pub struct AddedCond {
    pub text_embeds: Tensor,
    pub time_ids: Tensor,
}

/// `add_embedding` (a `TimestepEmbedding`): `linear_2(silu(linear_1(x)))`.
#[derive(Debug, Clone)]
struct AddEmbedding {
    linear_1: Linear,
    linear_2: Linear,
    arch: TextTimeArch,
}

/// The UNet plus its parsed config.
pub struct Unet {
    pub config: UnetConfig,
    pub arch: UnetArch,
    conv_in: Conv2d,
    linear_1: Linear,
    linear_2: Linear,
    add_embedding: Option<AddEmbedding>,
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
        let add_embedding = match arch.text_time {
            Some(a) => Some(AddEmbedding {
                linear_1: Linear::load(vb.pp("add_embedding.linear_1"), a.input_dim, temb, true)?,
                linear_2: Linear::load(vb.pp("add_embedding.linear_2"), temb, temb, true)?,
                arch: a,
            }),
            None => None,
        };
        Ok(Unet {
            config,
            arch: arch.clone(),
            conv_in: Conv2d::load(vb.pp("conv_in"), arch.in_channels, c0, 3, 1, 1, true)?
                .forward_only()?,
            linear_1: Linear::load(vb.pp("time_embedding.linear_1"), c0, temb, true)?,
            linear_2: Linear::load(vb.pp("time_embedding.linear_2"), temb, temb, true)?,
            add_embedding,
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
    /// A UNet with added conditioning (SDXL) refuses this: use [`Self::forward_added`].
    pub fn forward(&self, latents: &Tensor, t: f64, context: &Tensor) -> Result<Tensor> {
        self.forward_added(latents, t, context, None)
    }

    /// As [`Self::forward`], with SDXL's added conditioning, which must be given exactly when
    /// the config has `addition_embed_type = "text_time"`.
    pub fn forward_added(
        &self,
        latents: &Tensor,
        t: f64,
        context: &Tensor,
        added: Option<&AddedCond>,
    ) -> Result<Tensor> {
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
        let added = self.check_added(added, b)?;
        let out = self.run(
            &latents.to_dtype(self.dtype)?,
            t,
            &context.to_dtype(self.dtype)?,
            added.as_ref(),
        )?;
        Ok(out.to_dtype(latents.dtype())?)
    }

    /// The added conditioning checked against the config and batch, in f32 (the time ids are
    /// embedded on the host): `(text_embeds, time_ids)` rows.
    fn check_added(
        &self,
        added: Option<&AddedCond>,
        b: usize,
    ) -> Result<Option<(Tensor, Vec<Vec<f32>>)>> {
        let (emb, added) = match (&self.add_embedding, added) {
            (None, None) => return Ok(None),
            (Some(e), Some(a)) => (e, a),
            (None, Some(_)) => {
                return Err(ModelError::InvalidInput(
                    "added conditioning given to a UNet without addition_embed_type".into(),
                ));
            }
            (Some(_), None) => {
                return Err(ModelError::InvalidInput(
                    "this UNet (addition_embed_type \"text_time\", SDXL) needs the added \
                     conditioning: pooled text embeds and size/crop time ids"
                        .into(),
                ));
            }
        };
        let pooled = emb.arch.pooled_dim();
        let n_ids = TextTimeArch::TIME_IDS;
        if added.text_embeds.dims() != [b, pooled] || added.time_ids.dims() != [b, n_ids] {
            return Err(ModelError::InvalidInput(format!(
                "added conditioning text_embeds {:?} / time_ids {:?}: want [{b}, {pooled}] / \
                 [{b}, {n_ids}]",
                added.text_embeds.dims(),
                added.time_ids.dims()
            )));
        }
        let ids = added.time_ids.to_dtype(DType::F32)?.to_vec2::<f32>()?;
        if ids.iter().flatten().any(|v| !v.is_finite()) {
            return Err(ModelError::InvalidInput("time_ids must be finite".into()));
        }
        Ok(Some((added.text_embeds.clone(), ids)))
    }

    /// diffusers' `get_timestep_embedding` of `t` (the same for the whole batch).
    fn time_proj(&self, t: f64, b: usize, device: &Device) -> R<Tensor> {
        let dim = self.arch.levels[0].channels;
        let emb = self.sinusoidal(t as f32, dim);
        Tensor::from_vec(emb, (1, dim), device)?
            .repeat((b, 1))?
            .to_dtype(self.dtype)
    }

    /// diffusers' `get_timestep_embedding` of one value in `dim` channels, in f32 as PyTorch
    /// computes it (`flip_sin_to_cos` and `freq_shift` from the config).
    fn sinusoidal(&self, t: f32, dim: usize) -> Vec<f32> {
        let half = dim / 2;
        let ln = -(10000f64.ln()) as f32;
        let denom = half as f32 - self.arch.freq_shift as f32;
        let args: Vec<f32> = (0..half)
            .map(|i| t * (ln * i as f32 / denom).exp())
            .collect();
        let (sin, cos): (Vec<f32>, Vec<f32>) = args.iter().map(|a| (a.sin(), a.cos())).unzip();
        let mut emb = if self.arch.flip_sin_to_cos {
            [cos, sin].concat()
        } else {
            [sin, cos].concat()
        };
        emb.resize(dim, 0.0);
        emb
    }

    /// `add_embedding(cat(text_embeds, add_time_proj(time_ids)))` `[b, time_embed_dim]`.
    fn added_embedding(&self, (text_embeds, ids): &(Tensor, Vec<Vec<f32>>)) -> R<Option<Tensor>> {
        let Some(e) = &self.add_embedding else {
            return Ok(None);
        };
        let d = e.arch.time_dim;
        let rows: Vec<f32> = ids
            .iter()
            .flat_map(|row| row.iter().flat_map(|&v| self.sinusoidal(v, d)))
            .collect();
        let times = Tensor::from_vec(
            rows,
            (ids.len(), TextTimeArch::TIME_IDS * d),
            text_embeds.device(),
        )?
        .to_dtype(self.dtype)?;
        let x = Tensor::cat(&[&text_embeds.to_dtype(self.dtype)?, &times], 1)?;
        let h = e.linear_1.forward(&x)?.silu()?;
        Ok(Some(e.linear_2.forward(&h)?))
    }

    fn run(
        &self,
        x: &Tensor,
        t: f64,
        ctx: &Tensor,
        added: Option<&(Tensor, Vec<Vec<f32>>)>,
    ) -> R<Tensor> {
        let (b, _, h, w) = x.dims4()?;
        let temb = self.time_proj(t, b, x.device())?;
        let mut temb = self
            .linear_2
            .forward(&self.linear_1.forward(&temb)?.silu()?)?;
        if let Some(aug) = added
            .map(|a| self.added_embedding(a))
            .transpose()?
            .flatten()
        {
            temb = (temb + aug)?;
        }
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
