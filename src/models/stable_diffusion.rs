//! [`StableDiffusion`]: the components SDS and sampling need, behind one small API.

use super::bert::BertTextEncoder;
use super::clip::{ClipTextModel, ClipTokenizer};
use super::codec::{self, Codec, CodecKind, EncodeTape};
use super::loader::{self, LoadOptions, ModelSource, Precision, UNET_WEIGHTS};
use super::scheduler::{PredictionType, SchedulerConfig};
use super::sdxl_text::{ClipParts, SdxlTextEncoders};
use super::taesd::Taesd;
use super::unet::{Unet, UnetConfig};
use super::vae::{AutoencoderKl, VaeConfig};
use super::{ConfigIssue, ModelError, Result};
use crate::caption::ColourSteer;
use crate::models::serde_defaults::yes;
use candle_core::{DType, Device, Tensor};
use std::path::Path;

/// candle has no bf16 matmul on CPU: refuse it up front instead of failing mid-forward.
pub fn check_precision(
    component: &'static str,
    precision: Precision,
    device: &Device,
) -> Result<()> {
    if precision == Precision::Bf16 && device.is_cpu() {
        return Err(ModelError::Unsupported {
            component,
            path: "<load options>".into(),
            reason: "bf16 on CPU (candle has no CPU bf16 matmul); use f32 or f16, or bf16 with the `cuda` feature".into(),
        });
    }
    Ok(())
}

/// Loads `dir/config.json` + weights as a UNet.
pub fn load_unet(dir: &Path, precision: Precision, device: &Device) -> Result<Unet> {
    check_precision("unet", precision, device)?;
    let cfg: UnetConfig = loader::read_config(&dir.join("config.json"))?;
    let w = loader::find_weights(dir, UNET_WEIGHTS)?;
    let vb = loader::var_builder(&w, precision.dtype(), device)?;
    Unet::new(vb, cfg, &w)
}

/// Loads `dir/config.json` + weights as an `AutoencoderKL`.
pub fn load_vae(dir: &Path, precision: Precision, device: &Device) -> Result<AutoencoderKl> {
    check_precision("vae", precision, device)?;
    loader::load_autoencoder(
        dir,
        "vae",
        VaeConfig::validate,
        (precision, device),
        AutoencoderKl::new,
    )
}

/// Loads `dir/scheduler_config.json`.
pub fn load_scheduler(dir: &Path) -> Result<SchedulerConfig> {
    let p = dir.join("scheduler_config.json");
    let cfg: SchedulerConfig = loader::read_config(&p)?;
    cfg.alphas_cumprod().map_err(|e| ModelError::Config {
        path: p.display().to_string(),
        reason: e.to_string(),
    })?;
    Ok(cfg)
}

/// The text conditioning, chosen by `text_encoder/config.json` `model_type`: CLIP
/// (`clip_text_model`, SD 1.x/2.x: `[1, 77, d]` `last_hidden_state`) or BERT (`bert`, the
/// embedded model's MiniLM: `[1, L, 384]` `last_hidden_state` over all `L =
/// tokenizer.model_max_length` positions, padding included, see `docs/EMBEDDED.md`); SDXL
/// directories (a UNet with `addition_embed_type = "text_time"`) load both of theirs
/// ([`SdxlTextEncoders`], by [`StableDiffusion::load_source`]).
#[derive(Debug)]
#[allow(clippy::large_enum_variant)] // one per loaded model
pub enum TextEncoder {
    Clip {
        tokenizer: ClipTokenizer,
        model: ClipTextModel,
    },
    Bert(BertTextEncoder),
    /// SDXL's two CLIP text encoders (context and pooled embedding).
    Sdxl(Box<SdxlTextEncoders>),
}

impl TextEncoder {
    /// Loads `root/tokenizer/` and `root/text_encoder/` (config + safetensors). The MiniLM
    /// weights of a BERT encoder may be fetched (see [`crate::models::bert::weights`]; not when
    /// `VF_OFFLINE` is set).
    pub fn load(root: &Path, precision: Precision, device: &Device) -> Result<Self> {
        Self::load_with(root, precision, device, true)
    }

    /// [`TextEncoder::load`] with explicit control over the MiniLM download.
    pub fn load_with(
        root: &Path,
        precision: Precision,
        device: &Device,
        allow_download: bool,
    ) -> Result<Self> {
        check_precision("text_encoder", precision, device)?;
        let dir = root.join("text_encoder");
        let cfg: serde_json::Value = loader::read_config(&dir.join("config.json"))?;
        if cfg.get("model_type").and_then(|t| t.as_str()) == Some("bert") {
            // BERT runs in f32 whatever the precision: candle's BERT builds its attention mask
            // from f32::MIN, which overflows to -inf (and 0·-inf = NaN) in f16; MiniLM is small.
            let enc = BertTextEncoder::load(root, DType::F32, device, allow_download)?;
            return Ok(Self::Bert(enc));
        }
        let p = ClipParts::load(root, ("tokenizer", "text_encoder"), precision, device)?;
        let model = ClipTextModel::new(p.vb, &p.config)
            .map_err(loader::mismatch("text_encoder", &p.weights))?;
        Ok(Self::Clip {
            tokenizer: p.tokenizer,
            model,
        })
    }

    /// Token ids padded to the context length (`[1, L]`, u32).
    pub fn ids(&self, prompt: &str, device: &Device) -> Result<Tensor> {
        let ids = match self {
            Self::Clip { tokenizer, .. } => tokenizer.encode_padded(prompt),
            Self::Bert(b) => b.tokenizer.encode(prompt, b.tokenizer.max_length)?.ids,
            Self::Sdxl(s) => s.tokenizer.encode_padded(prompt),
        };
        Ok(Tensor::from_vec(ids.clone(), (1, ids.len()), device)?)
    }

    /// `[1, L, hidden]` f32 embeddings of a prompt (`""` gives the unconditional ones); SDXL:
    /// the context alone (both encoders' penultimate states), without the pooled embedding.
    pub fn embed(&self, prompt: &str, device: &Device) -> Result<Tensor> {
        let out = match self {
            Self::Clip { model, .. } => {
                model.forward(&self.ids(prompt, device)?)?.last_hidden_state
            }
            Self::Bert(b) => b.last_hidden_state(&[prompt], b.tokenizer.max_length)?,
            Self::Sdxl(s) => s.embed(prompt, device)?.context,
        };
        Ok(out.to_dtype(candle_core::DType::F32)?)
    }
}

/// Text encoder + UNet + image codec (VAE, TAESD or pixel space) + noise schedule of a
/// diffusion checkpoint.
#[derive(Debug)]
pub struct StableDiffusion {
    pub text: Option<TextEncoder>,
    pub unet: Unet,
    /// The image ↔ latent map: the VAE, TAESD in its place ([`LoadOptions::taesd`]), or pixel
    /// space for models without `vae/`.
    pub codec: Codec,
    pub scheduler: SchedulerConfig,
    /// Per-model defaults from `model_index.json` (style suffix, guidance scales).
    pub hints: ModelHints,
    alphas_cumprod: Vec<f64>,
    device: Device,
}

/// vectorfusion's defaults for one model, from underscore keys of its `model_index.json` (keys
/// diffusers ignores). Stable Diffusion directories have none and get the paper's values.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
pub struct ModelHints {
    /// `_style_suffix`: whether prompts get the paper's style suffix ("… minimal flat 2d vector
    /// icon …"). The embedded `vf-icon`, trained on bare icon names, sets false.
    #[serde(rename = "_style_suffix", default = "yes")]
    pub style_suffix: bool,
    /// `_sample_guidance`: classifier-free guidance when sampling the K raster images.
    #[serde(rename = "_sample_guidance", default = "sample_guidance")]
    pub sample_guidance: f32,
    /// `_sds_guidance`: classifier-free guidance of the SDS teacher (the paper uses 100).
    #[serde(rename = "_sds_guidance", default = "sds_guidance")]
    pub sds_guidance: f32,
    /// `_small_prior`: a small prior (the embedded `vf-icon`) rather than Stable Diffusion: the
    /// pipeline plans with the presets sized for it ([`crate::pipeline::Preset::settings_for`]).
    /// Pixel-space models are small priors whatever this says.
    #[serde(rename = "_small_prior", default)]
    pub small_prior: bool,
    /// `_sdedit_strength`: the SDEdit strength of samples started from retrieved icons, the
    /// fraction of the sampler's schedule run from the icon (0 keeps it, 1 forgets it). 0.4
    /// keeps an icon's layout and lets the prior redraw it for the caption; a model tuned on
    /// held-out captions says its own (`docs/embedded/TRAINING.md`).
    #[serde(rename = "_sdedit_strength", default = "sdedit_strength")]
    pub sdedit_strength: f64,
    /// `_retrieval_share`: the share of the K samples started from retrieved icons, rounded up
    /// (0.5: one of two, two of four); the others start from noise. 1 starts every sample from
    /// an icon (a model whose samples from noise rarely win the rerank).
    #[serde(rename = "_retrieval_share", default = "retrieval_share")]
    pub retrieval_share: f64,
    /// `_retrieval_per_caption`: at most this many of the retrieved icons share a caption (1:
    /// one drawing each of the nearest captions; 2: two artists' drawings of the nearest one,
    /// then the next caption's). At least 1.
    #[serde(rename = "_retrieval_per_caption", default = "one")]
    pub retrieval_per_caption: u32,
    /// `_colour_steer`: how far the sampler steers toward the colour and the objects a caption
    /// names (`off`, `start`, `rerank`, `sample`, `svg`; [`ColourSteer`]). A prior that does not
    /// bind colour words (the embedded `vf-icon`) sets it; Stable Diffusion is `off`.
    #[serde(rename = "_colour_steer", default)]
    pub colour_steer: ColourSteer,
}

fn sample_guidance() -> f32 {
    7.5
}
fn sds_guidance() -> f32 {
    100.0
}
fn sdedit_strength() -> f64 {
    0.4
}
fn retrieval_share() -> f64 {
    0.5
}
fn one() -> u32 {
    1
}

impl Default for ModelHints {
    fn default() -> Self {
        Self {
            style_suffix: true,
            sample_guidance: sample_guidance(),
            sds_guidance: sds_guidance(),
            small_prior: false,
            sdedit_strength: sdedit_strength(),
            retrieval_share: retrieval_share(),
            retrieval_per_caption: one(),
            colour_steer: ColourSteer::Off,
        }
    }
}

impl ModelHints {
    /// The hints of the model directory `root`; defaults when it has no `model_index.json`.
    pub fn read(root: &Path) -> Result<Self> {
        let index = root.join("model_index.json");
        if !index.is_file() {
            return Ok(Self::default());
        }
        let h: Self = loader::read_config(&index)?;
        // Each number's range, checked in one place (printed as written: f32 or f64).
        fn within<T: Into<f64> + Copy + std::fmt::Display>(
            index: &Path,
            name: &str,
            v: T,
            max: f64,
        ) -> Result<()> {
            let x: f64 = v.into();
            if x.is_finite() && (0.0..=max).contains(&x) {
                return Ok(());
            }
            Err(ModelError::Config {
                path: index.display().to_string(),
                reason: format!("{name} must be in 0..={max}, got {v}"),
            })
        }
        within(&index, "_sample_guidance", h.sample_guidance, 1000.0)?;
        within(&index, "_sds_guidance", h.sds_guidance, 1000.0)?;
        within(&index, "_sdedit_strength", h.sdedit_strength, 1.0)?;
        within(&index, "_retrieval_share", h.retrieval_share, 1.0)?;
        if h.retrieval_per_caption == 0 {
            return Err(ModelError::Config {
                path: index.display().to_string(),
                reason: "_retrieval_per_caption must be at least 1, got 0".into(),
            });
        }
        Ok(h)
    }
}

impl StableDiffusion {
    /// Loads from a diffusers directory.
    pub fn load(dir: &Path, opts: &LoadOptions) -> Result<Self> {
        Self::load_source(&ModelSource::Dir(dir.to_path_buf()), opts)
    }

    /// Loads from a directory or a hub repo (fetched into the HF cache when online). A
    /// directory without `vae/` (and no `"vae"` in `model_index.json`) is a pixel-space model;
    /// otherwise `opts.taesd`, when set, replaces the VAE as the codec.
    pub fn load_source(source: &ModelSource, opts: &LoadOptions) -> Result<Self> {
        let root = loader::resolve(source, opts.allow_download)?;
        let unet = load_unet(&root.join("unet"), opts.unet, &opts.device)?;
        let codec: Codec = if codec::is_pixel_space(&root)? {
            codec::pixel_space_for(&unet.config, &root)?.into()
        } else if let Some(dir) = &opts.taesd {
            check_precision("taesd", opts.vae, &opts.device)?;
            Taesd::load(dir, opts.vae, &opts.device)?.into()
        } else {
            load_vae(&root.join("vae"), opts.vae, &opts.device)?.into()
        };
        let scheduler = load_scheduler(&root.join("scheduler"))?;
        let text = if unet.arch.text_time.is_some() {
            let te = SdxlTextEncoders::load(&root, opts.text, &opts.device)?;
            TextEncoder::Sdxl(Box::new(te))
        } else {
            TextEncoder::load(&root, opts.text, &opts.device)?
        };
        let mut sd = Self::from_parts(unet, codec, scheduler, opts.device.clone())?;
        sd.text = Some(text);
        sd.hints = ModelHints::read(&root)?;
        Ok(sd)
    }

    /// Assembles already built components (benchmarks use random-weight ones).
    pub fn from_parts(
        unet: Unet,
        codec: impl Into<Codec>,
        scheduler: SchedulerConfig,
        device: Device,
    ) -> Result<Self> {
        let codec = codec.into();
        if codec.latent_channels() != unet.config.in_channels {
            return Err(ModelError::InvalidInput(format!(
                "the {} gives {}-channel latents but the UNet takes {} channels",
                codec.kind().as_str(),
                codec.latent_channels(),
                unet.config.in_channels
            )));
        }
        let alphas_cumprod = scheduler.alphas_cumprod().map_err(|e| ModelError::Config {
            path: "scheduler_config.json".into(),
            reason: e.to_string(),
        })?;
        Ok(Self {
            text: None,
            unet,
            codec,
            scheduler,
            hints: ModelHints::default(),
            alphas_cumprod,
            device,
        })
    }

    /// Embeddings of a prompt, `[1, 77, cross_attention_dim]`.
    pub fn embed_text(&self, prompt: &str) -> Result<Tensor> {
        let t = self.text.as_ref().ok_or(ModelError::NoTextEncoder)?;
        t.embed(prompt, &self.device)
    }

    /// `(prompt embeddings, empty-prompt embeddings)` for classifier-free guidance (contexts
    /// only: [`Self::text_cond`] gives SDXL's whole conditioning).
    pub fn text_embeddings(&self, prompt: &str) -> Result<(Tensor, Tensor)> {
        Ok((self.embed_text(prompt)?, self.embed_text("")?))
    }

    /// The mean-pooled, L2-normalised sentence embedding of `text` over `len` positions when the
    /// text encoder is BERT (the embedded model's MiniLM, as its retrieval index is built);
    /// `None` for CLIP text encoders.
    pub fn sentence_embedding(&self, text: &str, len: usize) -> Result<Option<Vec<f32>>> {
        match &self.text {
            Some(TextEncoder::Bert(b)) => {
                let e = b.sentence_embeddings(&[text], len)?;
                Ok(Some(e.flatten_all()?.to_vec1::<f32>()?))
            }
            _ => Ok(None),
        }
    }

    pub fn device(&self) -> &Device {
        &self.device
    }

    /// `ᾱ_t` for every training timestep.
    pub fn alphas_cumprod(&self) -> &[f64] {
        &self.alphas_cumprod
    }

    pub fn prediction_type(&self) -> PredictionType {
        self.scheduler.prediction_type
    }

    /// The VAE, when the codec is one.
    pub fn vae(&self) -> Option<&AutoencoderKl> {
        match &self.codec {
            Codec::Vae(v) => Some(v),
            _ => None,
        }
    }

    /// Whether the UNet works on RGB pixels (no VAE).
    pub fn is_pixel_space(&self) -> bool {
        self.codec.kind() == CodecKind::Pixel
    }

    /// Side of the latent for a square image of side `image_side` (SD: `image_side / 8`; pixel
    /// space: the UNet's `sample_size`).
    pub fn latent_side(&self, image_side: usize) -> std::result::Result<usize, ConfigIssue> {
        self.codec.latent_side(image_side)
    }

    /// Images `[b, 3, H, W]` in `[0, 1]` → latents (VAE/TAESD: scaled latents `[b, 4, H/8,
    /// W/8]`; pixel space: `[b, 3, s, s]` in `[-1, 1]`).
    pub fn encode(&self, image: &Tensor) -> Result<Tensor> {
        self.codec.encode(image)
    }

    /// `J_encode^T · d_latents` with respect to the `[0, 1]` image (no weight gradients).
    pub fn encode_vjp(&self, image: &Tensor, d_latents: &Tensor) -> Result<Tensor> {
        self.codec.encode_vjp(image, d_latents)
    }

    /// [`Self::encode`] that keeps the encoder's tape for [`Self::encode_pullback`]: one forward
    /// pass serves both the latents and the VJP.
    pub fn encode_t(&self, image: &Tensor) -> Result<(Tensor, EncodeTape)> {
        self.codec.encode_t(image)
    }

    /// `J_encode^T · d_latents` at the image `tape` was recorded for (no weight gradients).
    pub fn encode_pullback(&self, tape: EncodeTape, d_latents: &Tensor) -> Result<Tensor> {
        self.codec.encode_pullback(tape, d_latents)
    }

    /// Latents → images in `[0, 1]` (pixel space: at the latent size; callers upscale).
    pub fn decode(&self, latents: &Tensor) -> Result<Tensor> {
        self.codec.decode(latents)
    }
}
