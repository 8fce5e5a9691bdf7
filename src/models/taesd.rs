//! TAESD (diffusers `AutoencoderTiny`, `madebyollin/taesd` layout: `config.json` +
//! `diffusion_pytorch_model.safetensors`): a fast approximate SD VAE with encode (+ input-only
//! VJP) and decode. Latents are in the SD latent space (already scaled).

use super::loader::{self, Precision};
use super::nn::{Conv2d, add_relu, relu_backward};
use super::{ConfigIssue, ModelError, Result};
use crate::models::serde_defaults::num;
use candle_core::{Device, Tensor};
use candle_nn::VarBuilder;
use serde::Deserialize;
use std::path::Path;

/// `config.json` of an `AutoencoderTiny`.
#[derive(Debug, Clone, Deserialize)]
pub struct TaesdConfig {
    #[serde(default = "num::<3>")]
    pub in_channels: usize,
    #[serde(default = "num::<3>")]
    pub out_channels: usize,
    #[serde(default = "chans")]
    pub encoder_block_out_channels: Vec<usize>,
    #[serde(default = "chans")]
    pub decoder_block_out_channels: Vec<usize>,
    #[serde(default = "enc_blocks")]
    pub num_encoder_blocks: Vec<usize>,
    #[serde(default = "dec_blocks")]
    pub num_decoder_blocks: Vec<usize>,
    #[serde(default = "num::<4>")]
    pub latent_channels: usize,
    #[serde(default = "relu")]
    pub act_fn: String,
    #[serde(default = "nearest")]
    pub upsample_fn: String,
    #[serde(default = "num::<2>")]
    pub upsampling_scaling_factor: usize,
}

fn chans() -> Vec<usize> {
    vec![64; 4]
}
fn enc_blocks() -> Vec<usize> {
    vec![1, 3, 3, 3]
}
fn dec_blocks() -> Vec<usize> {
    vec![3, 3, 3, 1]
}
fn relu() -> String {
    "relu".into()
}
fn nearest() -> String {
    "nearest".into()
}

impl TaesdConfig {
    pub fn validate(&self) -> std::result::Result<(), ConfigIssue> {
        if self.act_fn != "relu" {
            return Err(ConfigIssue::Unsupported {
                setting: "act_fn",
                value: Some(format!("{:?} (only relu)", self.act_fn)),
            });
        }
        if self.upsample_fn != "nearest" || self.upsampling_scaling_factor != 2 {
            return Err(ConfigIssue::Inconsistent(
                "only nearest ×2 upsampling is supported".into(),
            ));
        }
        if self.encoder_block_out_channels.len() != self.num_encoder_blocks.len()
            || self.decoder_block_out_channels.len() != self.num_decoder_blocks.len()
            || self.encoder_block_out_channels.is_empty()
            || self.decoder_block_out_channels.is_empty()
        {
            return Err(ConfigIssue::Inconsistent(
                "block channel / block count lists differ in length or are empty".into(),
            ));
        }
        for w in self.encoder_block_out_channels.windows(2) {
            if w[0] != w[1] {
                return Err(ConfigIssue::Inconsistent(
                    "encoder blocks with different widths are not supported".into(),
                ));
            }
        }
        for w in self.decoder_block_out_channels.windows(2) {
            if w[0] != w[1] {
                return Err(ConfigIssue::Inconsistent(
                    "decoder blocks with different widths are not supported".into(),
                ));
            }
        }
        Ok(())
    }

    pub fn downscale(&self) -> usize {
        1 << (self.encoder_block_out_channels.len() - 1)
    }

    /// madebyollin/taesd's config (benchmarks with random weights).
    pub fn taesd() -> Self {
        serde_json::from_str("{}").unwrap_or_else(|_| unreachable!())
    }
}

/// `AutoencoderTinyBlock`: relu(conv(relu(conv(relu(conv(x))))) + x).
#[derive(Debug, Clone)]
struct Block {
    convs: [Conv2d; 3],
}

impl Block {
    fn load(vb: VarBuilder, c: usize) -> candle_core::Result<Self> {
        let l = |i: usize| Conv2d::load(vb.pp("conv").pp(i), c, c, 3, 1, 1, true);
        Ok(Self {
            convs: [l(0)?, l(2)?, l(4)?],
        })
    }

    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        let h = self.convs[0].forward_relu(x)?;
        let h = self.convs[1].forward_relu(&h)?;
        add_relu(&self.convs[2].forward(&h)?, x)
    }

    /// Forward keeping the three ReLU outputs.
    fn forward_t(&self, x: &Tensor) -> candle_core::Result<[Tensor; 3]> {
        let a = self.convs[0].forward_relu(x)?;
        let b = self.convs[1].forward_relu(&a)?;
        let y = add_relu(&self.convs[2].forward(&b)?, x)?;
        Ok([a, b, y])
    }

    fn backward(&self, t: &[Tensor; 3], dy: &Tensor) -> candle_core::Result<Tensor> {
        let (_, _, h, w) = dy.dims4()?;
        let d = relu_backward(&t[2], dy)?;
        let skip = d.clone();
        let d = self.convs[2].backward(&d, h, w)?;
        let d = relu_backward(&t[1], &d)?;
        let d = self.convs[1].backward(&d, h, w)?;
        let d = relu_backward(&t[0], &d)?;
        let d = self.convs[0].backward(&d, h, w)?;
        d + skip
    }
}

#[derive(Debug, Clone)]
enum Layer {
    Conv(Conv2d),
    Block(Block),
}

#[derive(Debug)]
enum Tape {
    Conv(usize, usize),
    Block([Tensor; 3]),
}

/// What the TAESD encoder's forward pass keeps for its VJP ([`Taesd::encode_t`]).
#[derive(Debug)]
pub struct EncodeTape {
    layers: Vec<Tape>,
    latent_dims: Vec<usize>,
    dtype: candle_core::DType,
}

/// TAESD encoder + decoder.
#[derive(Debug, Clone)]
pub struct Taesd {
    pub config: TaesdConfig,
    encoder: Vec<Layer>,
    /// decoder: conv_in, then per block (blocks, upsample?, conv)
    dec_in: Conv2d,
    decoder: Vec<(Vec<Block>, bool, Conv2d)>,
}

impl Taesd {
    pub fn new(vb: VarBuilder, config: TaesdConfig) -> candle_core::Result<Self> {
        let ve = vb.pp("encoder").pp("layers");
        let mut idx = 0;
        let mut encoder = Vec::new();
        for (i, (&c, &n)) in config
            .encoder_block_out_channels
            .iter()
            .zip(&config.num_encoder_blocks)
            .enumerate()
        {
            let conv = if i == 0 {
                Conv2d::load(ve.pp(idx), config.in_channels, c, 3, 1, 1, true)?
            } else {
                Conv2d::load(ve.pp(idx), c, c, 3, 2, 1, false)?
            };
            encoder.push(Layer::Conv(conv));
            idx += 1;
            for _ in 0..n {
                encoder.push(Layer::Block(Block::load(ve.pp(idx), c)?));
                idx += 1;
            }
        }
        let last = *config
            .encoder_block_out_channels
            .last()
            .ok_or_else(|| candle_core::Error::Msg("empty encoder".into()))?;
        encoder.push(Layer::Conv(Conv2d::load(
            ve.pp(idx),
            last,
            config.latent_channels,
            3,
            1,
            1,
            true,
        )?));

        let vd = vb.pp("decoder").pp("layers");
        let c0 = config.decoder_block_out_channels[0];
        let dec_in = Conv2d::load(vd.pp(0), config.latent_channels, c0, 3, 1, 1, true)?;
        let mut idx = 2; // conv, relu
        let mut decoder = Vec::new();
        let nb = config.num_decoder_blocks.len();
        for (i, (&c, &n)) in config
            .decoder_block_out_channels
            .iter()
            .zip(&config.num_decoder_blocks)
            .enumerate()
        {
            let last = i + 1 == nb;
            let mut blocks = Vec::new();
            for _ in 0..n {
                blocks.push(Block::load(vd.pp(idx), c)?);
                idx += 1;
            }
            if !last {
                idx += 1; // Upsample has no weights
            }
            let co = if last { config.out_channels } else { c };
            let conv = Conv2d::load(vd.pp(idx), c, co, 3, 1, 1, last)?;
            idx += 1;
            decoder.push((blocks, !last, conv));
        }
        Ok(Self {
            config,
            encoder,
            dec_in,
            decoder,
        })
    }

    /// Loads `dir/config.json` + `dir/diffusion_pytorch_model.safetensors`.
    pub fn load(dir: &Path, precision: Precision, device: &Device) -> Result<Self> {
        loader::load_autoencoder(
            dir,
            "taesd",
            TaesdConfig::validate,
            (precision, device),
            Self::new,
        )
    }

    fn check_image(&self, image: &Tensor) -> Result<()> {
        let f = self.config.downscale();
        match image.dims4() {
            Ok((_, c, h, w)) if c == self.config.in_channels && h % f == 0 && w % f == 0 => Ok(()),
            _ => Err(ModelError::InvalidInput(format!(
                "image must be [b, {}, h, w] with h, w multiples of {f}, got {:?}",
                self.config.in_channels,
                image.dims()
            ))),
        }
    }

    /// Images in `[0, 1]` → latents.
    pub fn encode(&self, image: &Tensor) -> Result<Tensor> {
        self.check_image(image)?;
        let mut x = image.clone();
        for l in &self.encoder {
            x = match l {
                Layer::Conv(c) => c.forward(&x)?,
                Layer::Block(b) => b.forward(&x)?,
            };
        }
        Ok(x)
    }

    /// [`Self::encode`] that also keeps what the encoder's VJP needs ([`Self::encode_pullback`]).
    pub fn encode_t(&self, image: &Tensor) -> Result<(Tensor, EncodeTape)> {
        self.check_image(image)?;
        let mut x = image.clone();
        let mut layers = Vec::with_capacity(self.encoder.len());
        for l in &self.encoder {
            let (_, _, h, w) = x.dims4()?;
            match l {
                Layer::Conv(c) => {
                    layers.push(Tape::Conv(h, w));
                    x = c.forward(&x)?;
                }
                Layer::Block(b) => {
                    let t = b.forward_t(&x)?;
                    x = t[2].clone();
                    layers.push(Tape::Block(t));
                }
            }
        }
        let tape = EncodeTape {
            layers,
            latent_dims: x.dims().to_vec(),
            dtype: x.dtype(),
        };
        Ok((x, tape))
    }

    /// `J^T · d_latents` at the image `tape` was recorded for, with respect to the `[0, 1]`
    /// image (no weight gradients). Consumes the tape, releasing it layer by layer.
    pub fn encode_pullback(&self, tape: EncodeTape, d_latents: &Tensor) -> Result<Tensor> {
        super::check_latent_grad(d_latents, &tape.latent_dims)?;
        let mut d = d_latents.to_dtype(tape.dtype)?;
        for (l, t) in self.encoder.iter().zip(tape.layers).rev() {
            d = match (l, t) {
                (Layer::Conv(c), Tape::Conv(h, w)) => c.backward(&d, h, w)?,
                (Layer::Block(b), Tape::Block(t)) => b.backward(&t, &d)?,
                _ => return Err(ModelError::InvalidInput("taesd tape out of order".into())),
            };
        }
        Ok(d)
    }

    /// `(latents, J^T · d_latents)` with respect to the `[0, 1]` image.
    pub fn encode_vjp(&self, image: &Tensor, d_latents: &Tensor) -> Result<(Tensor, Tensor)> {
        let (latents, tape) = self.encode_t(image)?;
        let d = self.encode_pullback(tape, d_latents)?;
        Ok((latents, d))
    }

    /// Latents → raw decoder output in the diffusers `[-1, 1]` convention.
    pub fn decode_raw(&self, latents: &Tensor) -> Result<Tensor> {
        match latents.dims4() {
            Ok((_, c, _, _)) if c == self.config.latent_channels => {}
            _ => {
                return Err(ModelError::InvalidInput(format!(
                    "latents must be [b, {}, h, w], got {:?}",
                    self.config.latent_channels,
                    latents.dims()
                )));
            }
        }
        let z = ((latents / 3.0)?.tanh()? * 3.0)?;
        let mut x = self.dec_in.forward_relu(&z)?;
        for (blocks, upsample, conv) in &self.decoder {
            for b in blocks {
                x = b.forward(&x)?;
            }
            if *upsample {
                let (_, _, h, w) = x.dims4()?;
                x = x.upsample_nearest2d(2 * h, 2 * w)?;
            }
            x = conv.forward(&x)?;
        }
        Ok(((x * 2.0)? - 1.0)?)
    }

    /// Latents → images in `[0, 1]` (clamped).
    pub fn decode(&self, latents: &Tensor) -> Result<Tensor> {
        let x = self.decode_raw(latents)?;
        Ok(((x + 1.0)? * 0.5)?.clamp(0.0, 1.0)?)
    }
}
