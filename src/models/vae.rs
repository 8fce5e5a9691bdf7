//! diffusers `AutoencoderKL` (the Stable Diffusion VAE), built from `vae/config.json`.
//!
//! Encoder forward can record a tape; [`AutoencoderKl::encode_vjp`] then pulls a latent-space
//! cotangent back to pixels with the hand-written input-only backward passes of
//! [`super::nn`] (no weight gradients are ever formed).

use super::nn::{Conv2d, Downsample, GroupNorm, ResnetBlock, SpatialSelfAttention};
use super::{ConfigIssue, ModelError, Result};
use crate::models::serde_defaults::{num, silu, yes};
use candle_core::Tensor;
use candle_nn::VarBuilder;
use serde::Deserialize;

/// The fields of `vae/config.json` that decide the architecture.
#[derive(Debug, Clone, Deserialize)]
pub struct VaeConfig {
    #[serde(default = "num::<3>")]
    pub in_channels: usize,
    #[serde(default = "num::<3>")]
    pub out_channels: usize,
    pub block_out_channels: Vec<usize>,
    #[serde(default)]
    pub down_block_types: Vec<String>,
    #[serde(default)]
    pub up_block_types: Vec<String>,
    #[serde(default = "num::<1>")]
    pub layers_per_block: usize,
    #[serde(default = "num::<4>")]
    pub latent_channels: usize,
    #[serde(default = "num::<32>")]
    pub norm_num_groups: usize,
    #[serde(default = "default_scaling")]
    pub scaling_factor: f64,
    #[serde(default)]
    pub shift_factor: Option<f64>,
    #[serde(default = "yes")]
    pub use_quant_conv: bool,
    #[serde(default = "yes")]
    pub use_post_quant_conv: bool,
    #[serde(default = "yes")]
    pub mid_block_add_attention: bool,
    #[serde(default = "silu")]
    pub act_fn: String,
}

fn default_scaling() -> f64 {
    0.18215
}

/// `Unsupported`, naming the first block type in `types` that is not `allowed`.
fn only(
    setting: &'static str,
    types: &[String],
    allowed: &str,
) -> std::result::Result<(), ConfigIssue> {
    match types.iter().find(|t| t.as_str() != allowed) {
        Some(t) => Err(ConfigIssue::Unsupported {
            setting,
            value: Some(format!("{t:?}")),
        }),
        None => Ok(()),
    }
}

impl VaeConfig {
    /// Rejects configs this implementation cannot run, with the reason.
    pub fn validate(&self) -> std::result::Result<(), ConfigIssue> {
        if self.block_out_channels.is_empty() {
            return Err(ConfigIssue::Inconsistent(
                "block_out_channels is empty".into(),
            ));
        }
        if self.act_fn != "silu" {
            return Err(ConfigIssue::Unsupported {
                setting: "act_fn",
                value: Some(format!("{:?} (only \"silu\")", self.act_fn)),
            });
        }
        only(
            "down_block_types",
            &self.down_block_types,
            "DownEncoderBlock2D",
        )?;
        only("up_block_types", &self.up_block_types, "UpDecoderBlock2D")?;
        for &c in &self.block_out_channels {
            if self.norm_num_groups == 0 || c % self.norm_num_groups != 0 {
                return Err(ConfigIssue::Inconsistent(format!(
                    "{c} channels not divisible by norm_num_groups {}",
                    self.norm_num_groups
                )));
            }
        }
        Ok(())
    }

    /// Spatial downsampling factor between pixels and latents.
    pub fn downscale(&self) -> usize {
        1 << (self.block_out_channels.len() - 1)
    }

    /// SD 1.x/2.x VAE (used by the benchmark with random weights).
    pub fn sd() -> Self {
        Self {
            in_channels: 3,
            out_channels: 3,
            block_out_channels: vec![128, 256, 512, 512],
            down_block_types: vec!["DownEncoderBlock2D".into(); 4],
            up_block_types: vec!["UpDecoderBlock2D".into(); 4],
            layers_per_block: 2,
            latent_channels: 4,
            norm_num_groups: 32,
            scaling_factor: 0.18215,
            shift_factor: None,
            use_quant_conv: true,
            use_post_quant_conv: true,
            mid_block_add_attention: true,
            act_fn: "silu".into(),
        }
    }
}

const EPS: f64 = 1e-6;

#[derive(Debug, Clone)]
enum Layer {
    Conv(Conv2d),
    Res(ResnetBlock),
    Attn(SpatialSelfAttention),
    Down(Downsample),
    NormSilu(GroupNorm),
}

#[derive(Debug)]
enum Tape {
    Conv(usize, usize),
    Res(super::nn::ResnetTape),
    Attn(super::nn::AttentionTape),
    Down(usize, usize),
    NormSilu(super::nn::GroupNormTape),
}

/// What the encoder's forward pass keeps for its VJP ([`AutoencoderKl::encode_t`]): one
/// entry per encoder layer, the moments' spatial size and the latents' shape.
#[derive(Debug)]
pub struct EncodeTape {
    layers: Vec<Tape>,
    moments_hw: (usize, usize),
    latent_dims: Vec<usize>,
    dtype: candle_core::DType,
}

/// The encoder as a flat sequence of layers (diffusers order).
#[derive(Debug, Clone)]
pub struct Encoder {
    layers: Vec<Layer>,
}

fn mid_block(vb: VarBuilder, c: usize, cfg: &VaeConfig) -> candle_core::Result<Vec<Layer>> {
    let g = cfg.norm_num_groups;
    let mut v = vec![Layer::Res(ResnetBlock::load(
        vb.pp("resnets.0"),
        c,
        c,
        g,
        EPS,
    )?)];
    if cfg.mid_block_add_attention {
        v.push(Layer::Attn(SpatialSelfAttention::load(
            vb.pp("attentions.0"),
            c,
            g,
            EPS,
            1,
        )?));
    }
    v.push(Layer::Res(ResnetBlock::load(
        vb.pp("resnets.1"),
        c,
        c,
        g,
        EPS,
    )?));
    Ok(v)
}

impl Encoder {
    fn load(vb: VarBuilder, cfg: &VaeConfig) -> candle_core::Result<Self> {
        let ch = &cfg.block_out_channels;
        let g = cfg.norm_num_groups;
        let mut layers = vec![Layer::Conv(Conv2d::load(
            vb.pp("conv_in"),
            cfg.in_channels,
            ch[0],
            3,
            1,
            1,
            true,
        )?)];
        let mut cin = ch[0];
        for (i, &cout) in ch.iter().enumerate() {
            let vbb = vb.pp("down_blocks").pp(i);
            for j in 0..cfg.layers_per_block {
                let c_in = if j == 0 { cin } else { cout };
                layers.push(Layer::Res(ResnetBlock::load(
                    vbb.pp("resnets").pp(j),
                    c_in,
                    cout,
                    g,
                    EPS,
                )?));
            }
            if i + 1 < ch.len() {
                layers.push(Layer::Down(Downsample::load(
                    vbb.pp("downsamplers.0"),
                    cout,
                )?));
            }
            cin = cout;
        }
        let last = cin;
        layers.extend(mid_block(vb.pp("mid_block"), last, cfg)?);
        layers.push(Layer::NormSilu(GroupNorm::load(
            vb.pp("conv_norm_out"),
            g,
            last,
            EPS,
        )?));
        layers.push(Layer::Conv(Conv2d::load(
            vb.pp("conv_out"),
            last,
            2 * cfg.latent_channels,
            3,
            1,
            1,
            true,
        )?));
        Ok(Self { layers })
    }

    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        let mut x = x.clone();
        for l in &self.layers {
            x = match l {
                Layer::Conv(c) => c.forward(&x)?,
                Layer::Res(r) => r.forward(&x)?,
                Layer::Attn(a) => a.forward(&x)?,
                Layer::Down(d) => d.forward(&x)?,
                Layer::NormSilu(n) => n.forward_silu(&x)?,
            };
        }
        Ok(x)
    }

    fn forward_t(&self, x: &Tensor) -> candle_core::Result<(Tensor, Vec<Tape>)> {
        let mut x = x.clone();
        let mut tapes = Vec::with_capacity(self.layers.len());
        for l in &self.layers {
            let (_, _, h, w) = x.dims4()?;
            let (y, t) = match l {
                Layer::Conv(c) => (c.forward(&x)?, Tape::Conv(h, w)),
                Layer::Res(r) => {
                    let (y, t) = r.forward_t(&x)?;
                    (y, Tape::Res(t))
                }
                Layer::Attn(a) => {
                    let (y, t) = a.forward_t(&x)?;
                    (y, Tape::Attn(t))
                }
                Layer::Down(d) => (d.forward(&x)?, Tape::Down(h, w)),
                Layer::NormSilu(n) => {
                    let (a, t) = n.forward_silu_t(&x)?;
                    (a, Tape::NormSilu(t))
                }
            };
            tapes.push(t);
            x = y;
        }
        Ok((x, tapes))
    }

    fn backward(&self, tapes: Vec<Tape>, dy: &Tensor) -> candle_core::Result<Tensor> {
        let mut d = dy.clone();
        // consume the tape from the end so its memory is released as we go
        let mut tapes = tapes;
        for l in self.layers.iter().rev() {
            let t = tapes
                .pop()
                .ok_or_else(|| candle_core::Error::Msg("encoder tape too short".into()))?;
            d = match (l, t) {
                (Layer::Conv(c), Tape::Conv(h, w)) => c.backward(&d, h, w)?,
                (Layer::Res(r), Tape::Res(t)) => r.backward(&t, &d)?,
                (Layer::Attn(a), Tape::Attn(t)) => a.backward(&t, &d)?,
                (Layer::Down(dn), Tape::Down(h, w)) => dn.backward(&d, h, w)?,
                (Layer::NormSilu(n), Tape::NormSilu(t)) => n.backward(&t, &d)?,
                _ => candle_core::bail!("encoder tape out of order"),
            };
        }
        Ok(d)
    }
}

/// The decoder (forward only).
#[derive(Debug, Clone)]
pub struct Decoder {
    conv_in: Conv2d,
    mid: Vec<Layer>,
    /// per up block: resnets, optional upsample conv
    up: Vec<(Vec<ResnetBlock>, Option<Conv2d>)>,
    conv_norm_out: GroupNorm,
    conv_out: Conv2d,
}

impl Decoder {
    fn load(vb: VarBuilder, cfg: &VaeConfig) -> candle_core::Result<Self> {
        let rev: Vec<usize> = cfg.block_out_channels.iter().rev().copied().collect();
        let g = cfg.norm_num_groups;
        let top = rev[0];
        // the decoder only runs forward (see `Conv2d::forward_only`)
        let conv_in = Conv2d::load(vb.pp("conv_in"), cfg.latent_channels, top, 3, 1, 1, true)?
            .forward_only()?;
        let mid = mid_block(vb.pp("mid_block"), top, cfg)?
            .into_iter()
            .map(|l| match l {
                Layer::Res(r) => r.forward_only().map(Layer::Res),
                l => Ok(l),
            })
            .collect::<candle_core::Result<Vec<_>>>()?;
        let mut up = Vec::new();
        let mut cin = top;
        for (i, &cout) in rev.iter().enumerate() {
            let vbb = vb.pp("up_blocks").pp(i);
            let mut resnets = Vec::new();
            for j in 0..=cfg.layers_per_block {
                let c_in = if j == 0 { cin } else { cout };
                resnets.push(
                    ResnetBlock::load(vbb.pp("resnets").pp(j), c_in, cout, g, EPS)?
                        .forward_only()?,
                );
            }
            let upsample = if i + 1 < rev.len() {
                Some(
                    Conv2d::load(vbb.pp("upsamplers.0.conv"), cout, cout, 3, 1, 1, true)?
                        .forward_only()?,
                )
            } else {
                None
            };
            up.push((resnets, upsample));
            cin = cout;
        }
        Ok(Self {
            conv_in,
            mid,
            up,
            conv_norm_out: GroupNorm::load(vb.pp("conv_norm_out"), g, cin, EPS)?,
            conv_out: Conv2d::load(vb.pp("conv_out"), cin, cfg.out_channels, 3, 1, 1, true)?
                .forward_only()?,
        })
    }

    fn forward(&self, z: &Tensor) -> candle_core::Result<Tensor> {
        let mut x = self.conv_in.forward(z)?;
        for l in &self.mid {
            x = match l {
                Layer::Res(r) => r.forward(&x)?,
                Layer::Attn(a) => a.forward(&x)?,
                _ => candle_core::bail!("unexpected layer in decoder mid block"),
            };
        }
        for (resnets, upsample) in &self.up {
            for r in resnets {
                x = r.forward(&x)?;
            }
            if let Some(c) = upsample {
                let (_, _, h, w) = x.dims4()?;
                x = c.forward(&x.upsample_nearest2d(2 * h, 2 * w)?)?;
            }
        }
        let x = self.conv_norm_out.forward_silu(&x)?;
        self.conv_out.forward(&x)
    }
}

/// `AutoencoderKL` with SD's conventions: pixels in `[0, 1]` at the API, `[-1, 1]` inside,
/// latents multiplied by `scaling_factor`.
#[derive(Debug, Clone)]
pub struct AutoencoderKl {
    pub config: VaeConfig,
    encoder: Encoder,
    decoder: Decoder,
    quant_conv: Option<Conv2d>,
    post_quant_conv: Option<Conv2d>,
}

/// Mean and log-variance of the latent distribution (unscaled, diffusers' `latent_dist`).
#[derive(Debug, Clone)]
pub struct LatentDist {
    pub mean: Tensor,
    pub logvar: Tensor,
}

impl AutoencoderKl {
    /// Builds the model from a config and a var builder rooted at the VAE's weights.
    pub fn new(vb: VarBuilder, config: VaeConfig) -> candle_core::Result<Self> {
        let lc = config.latent_channels;
        let encoder = Encoder::load(vb.pp("encoder"), &config)?;
        let decoder = Decoder::load(vb.pp("decoder"), &config)?;
        let quant_conv = if config.use_quant_conv {
            Some(Conv2d::load(
                vb.pp("quant_conv"),
                2 * lc,
                2 * lc,
                1,
                1,
                0,
                true,
            )?)
        } else {
            None
        };
        let post_quant_conv = if config.use_post_quant_conv {
            Some(Conv2d::load(
                vb.pp("post_quant_conv"),
                lc,
                lc,
                1,
                1,
                0,
                true,
            )?)
        } else {
            None
        };
        Ok(Self {
            config,
            encoder,
            decoder,
            quant_conv,
            post_quant_conv,
        })
    }

    fn check_image(&self, image: &Tensor) -> Result<()> {
        let (_, c, h, w) = image.dims4().map_err(|_| {
            ModelError::InvalidInput(format!(
                "image must be [b, 3, h, w], got {:?}",
                image.dims()
            ))
        })?;
        let f = self.config.downscale();
        if c != self.config.in_channels || h % f != 0 || w % f != 0 || h == 0 || w == 0 {
            return Err(ModelError::InvalidInput(format!(
                "image must be [b, {}, h, w] with h, w multiples of {f}, got {:?}",
                self.config.in_channels,
                image.dims()
            )));
        }
        Ok(())
    }

    fn moments(&self, h: &Tensor) -> candle_core::Result<Tensor> {
        match &self.quant_conv {
            Some(q) => q.forward(h),
            None => Ok(h.clone()),
        }
    }

    /// Latent distribution of images in `[0, 1]`.
    pub fn encode_dist(&self, image: &Tensor) -> Result<LatentDist> {
        self.check_image(image)?;
        let x = ((image * 2.0)? - 1.0)?;
        let m = self.moments(&self.encoder.forward(&x)?)?;
        let lc = self.config.latent_channels;
        Ok(LatentDist {
            mean: m.narrow(1, 0, lc)?,
            logvar: m.narrow(1, lc, lc)?.clamp(-30.0, 20.0)?,
        })
    }

    fn scale_latents(&self, mean: &Tensor) -> candle_core::Result<Tensor> {
        let shift = self.config.shift_factor.unwrap_or(0.0);
        (mean - shift)? * self.config.scaling_factor
    }

    /// Scaled latents (distribution mean × `scaling_factor`) of images in `[0, 1]`.
    pub fn encode(&self, image: &Tensor) -> Result<Tensor> {
        let d = self.encode_dist(image)?;
        Ok(self.scale_latents(&d.mean)?)
    }

    /// [`Self::encode`] that also keeps what the encoder's VJP needs: the latents and an
    /// [`EncodeTape`] for [`Self::encode_pullback`]. Encoding and pulling back at the same image
    /// then cost one forward pass.
    pub fn encode_t(&self, image: &Tensor) -> Result<(Tensor, EncodeTape)> {
        self.check_image(image)?;
        let x = ((image * 2.0)? - 1.0)?;
        let (h, layers) = self.encoder.forward_t(&x)?;
        let m = self.moments(&h)?;
        let lc = self.config.latent_channels;
        let latents = self.scale_latents(&m.narrow(1, 0, lc)?)?;
        let (_, _, hh, ww) = h.dims4()?;
        let tape = EncodeTape {
            layers,
            moments_hw: (hh, ww),
            latent_dims: latents.dims().to_vec(),
            dtype: m.dtype(),
        };
        Ok((latents, tape))
    }

    /// `J^T · d_latents` at the image `tape` was recorded for, with respect to the `[0, 1]`
    /// image, without any weight gradient. Consumes the tape, releasing it layer by layer.
    pub fn encode_pullback(&self, tape: EncodeTape, d_latents: &Tensor) -> Result<Tensor> {
        super::check_latent_grad(d_latents, &tape.latent_dims)?;
        let lc = self.config.latent_channels;
        let d_mean = (d_latents.to_dtype(tape.dtype)? * self.config.scaling_factor)?;
        // moments gradient: mean half gets d_mean, logvar half zero
        let d_m = d_mean.pad_with_zeros(1, 0, lc)?;
        let (hh, ww) = tape.moments_hw;
        let d_h = match &self.quant_conv {
            Some(q) => q.backward(&d_m, hh, ww)?,
            None => d_m,
        };
        let d_x = self.encoder.backward(tape.layers, &d_h)?;
        // x = 2 * image - 1
        Ok((d_x * 2.0)?)
    }

    /// Returns `(latents, J^T · d_latents)` for [`Self::encode`]: the gradient with respect to
    /// the `[0, 1]` image, without any weight gradient.
    pub fn encode_vjp(&self, image: &Tensor, d_latents: &Tensor) -> Result<(Tensor, Tensor)> {
        let (latents, tape) = self.encode_t(image)?;
        let d = self.encode_pullback(tape, d_latents)?;
        Ok((latents, d))
    }

    /// Decodes scaled latents to raw decoder output (≈ `[-1, 1]`).
    pub fn decode_raw(&self, latents: &Tensor) -> Result<Tensor> {
        super::latent_dims(latents, self.config.latent_channels, "VAE")?;
        let shift = self.config.shift_factor.unwrap_or(0.0);
        let z = ((latents / self.config.scaling_factor)? + shift)?;
        let z = match &self.post_quant_conv {
            Some(p) => p.forward(&z)?,
            None => z,
        };
        Ok(self.decoder.forward(&z)?)
    }

    /// Decodes scaled latents to images in `[0, 1]` (clamped).
    pub fn decode(&self, latents: &Tensor) -> Result<Tensor> {
        let x = self.decode_raw(latents)?;
        Ok(((x + 1.0)? * 0.5)?.clamp(0.0, 1.0)?)
    }
}
