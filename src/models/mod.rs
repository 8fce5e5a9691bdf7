//! Latent diffusion components on candle, loaded from the standard diffusers layout.
//!
//! The architecture always comes from the `config.json` files next to the weights (SD 1.x, 2.x
//! including `v_prediction`, SD-Turbo and tiny test models load through the same code path):
//!
//! | file | component |
//! |---|---|
//! | [`loader`] | diffusers directory / Hugging Face hub resolution, safetensors, precision |
//! | [`unet`] | `UNet2DConditionModel` built from its config on our layers and kernels |
//! | [`vae`] | `AutoencoderKL`: encode, decode and the encoder VJP without weight gradients |
//! | [`codec`] | the image ↔ latent map: VAE, TAESD or pixel space (models without `vae/`) |
//! | [`taesd`] | `AutoencoderTiny` (madebyollin/taesd layout): encode (+VJP) and decode |
//! | [`scheduler`] | noise schedules (`alphas_cumprod`), DDIM and Euler samplers |
//! | [`guided`] | [`TextCond`] (a guidance branch's text conditioning, SDXL's added part too), guided noise prediction, SDS gradient, sampling |
//! | [`sdxl_text`] | SDXL's two CLIP text encoders (context and pooled embedding) |
//! | [`bert`] | BERT/MiniLM text encoder (WordPiece tokenizer, `BertModel`, MiniLM weight fetch) |
//! | [`clip`] | CLIP text/vision towers and BPE tokenizer (text encoder of SD 1.x/2.x) |
//! | [`scorer`] | one scorer abstraction over CLIP and the embedded IconClip (rerank, eval) |
//! | [`nn`] | small layers with hand-written input-only backward passes |
//! | [`kernels`] | CPU f32 kernels behind those layers: conv as shifted GEMMs, fused group norm |
//!
//! [`StableDiffusion`] ties them together behind the small API the SDS and sampling stages use.

pub mod bert;
pub mod clip;
pub mod codec;
pub mod guided;
pub mod kernels;
pub mod loader;
pub mod nn;
pub mod scheduler;
pub mod scorer;
pub mod sdxl_text;
mod serde_defaults;
pub mod stable_diffusion;
pub mod taesd;
pub mod unet;
pub mod vae;

pub use guided::TextCond;
pub use loader::{
    ComputeDevice, DeviceError, LoadOptions, ModelSource, Precision, UnknownPrecision,
};
pub use stable_diffusion::{ModelHints, StableDiffusion};

/// Errors of the models layer.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// Files the layout needs are absent (locally and, when offline, from the hub cache).
    #[error("missing model files for {what}: {missing:?}\n{hint}")]
    MissingFiles {
        what: String,
        missing: Vec<String>,
        hint: String,
    },
    /// A config file could not be read or parsed.
    #[error("bad config {path}: {reason}")]
    Config { path: String, reason: String },
    /// The config asks for an architecture feature this implementation does not have.
    #[error("unsupported {component} config ({path}): {reason}")]
    Unsupported {
        component: &'static str,
        path: String,
        reason: String,
    },
    /// A weights file is unreadable or not valid safetensors.
    #[error("corrupt weights file {path}: {reason}")]
    CorruptWeights { path: String, reason: String },
    /// Weights do not match the architecture the config describes (missing tensor, wrong shape).
    #[error("weights in {path} do not match {component}/config.json: {reason}")]
    WeightMismatch {
        component: &'static str,
        path: String,
        reason: String,
    },
    /// Bad arguments (shapes, ranges) passed to a model call.
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// Fetching from the Hugging Face hub failed.
    #[error("hub download of {repo}/{file} failed: {reason}\n{hint}")]
    Hub {
        repo: String,
        file: String,
        reason: String,
        hint: String,
    },
    /// A tensor operation failed.
    #[error("tensor op failed: {0}")]
    Candle(#[from] candle_core::Error),
    /// The text encoder or tokenizer failed to load or run.
    #[error("text encoder: {0}")]
    Clip(#[from] clip::ClipError),
    /// The BERT text encoder or its tokenizer failed to load or run.
    #[error("text encoder: {0}")]
    Bert(#[from] bert::BertError),
    /// Text embeddings asked of a model assembled without a text encoder (benchmarks build the
    /// UNet and VAE alone).
    #[error("this StableDiffusion was assembled without a text encoder")]
    NoTextEncoder,
}

pub type Result<T> = std::result::Result<T, ModelError>;

/// Why a model config cannot run here (what [`ModelError::Unsupported`] and
/// [`ModelError::Config`] report as their reason).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfigIssue {
    /// A setting this implementation does not run, with the value the config gives it.
    #[error("{setting}{} is not supported", value.as_deref().map(|v| format!(" {v}")).unwrap_or_default())]
    Unsupported {
        setting: &'static str,
        value: Option<String>,
    },
    /// Settings that cannot hold together: an empty list, lengths or divisibility that do not
    /// agree, a number outside its range.
    #[error("{0}")]
    Inconsistent(String),
}

/// The dims of `latents`, or an error unless it is `[b, channels, h, w]` (`model` names the
/// model that expects it).
pub(crate) fn latent_dims(
    latents: &candle_core::Tensor,
    channels: usize,
    model: &str,
) -> Result<(usize, usize, usize, usize)> {
    let (b, c, h, w) = latents.dims4().map_err(|_| {
        ModelError::InvalidInput(format!(
            "latents must be [b, c, h, w], got {:?}",
            latents.dims()
        ))
    })?;
    if c != channels {
        return Err(ModelError::InvalidInput(format!(
            "latents have {c} channels, the {model} expects {channels}"
        )));
    }
    Ok((b, c, h, w))
}

/// The check every encoder VJP makes first: the latents' gradient has the latents' shape.
pub(crate) fn check_latent_grad(
    d_latents: &candle_core::Tensor,
    latent_dims: &[usize],
) -> Result<()> {
    if d_latents.dims() != latent_dims {
        return Err(ModelError::InvalidInput(format!(
            "d_latents shape {:?} != latents shape {:?}",
            d_latents.dims(),
            latent_dims
        )));
    }
    Ok(())
}
