//! The score-distillation teacher interface: what SDS needs from a diffusion model.
//!
//! A [`Teacher`] encodes an image into a latent (with an exact vector-Jacobian product back to the
//! image), exposes its noise schedule (`alphas_cumprod`), and predicts the noise in a noised latent
//! with classifier-free guidance. [`sd::SdTeacher`] wraps Stable Diffusion (VAE encoder); [`analytic::AnalyticTeacher`] is an exact **test teacher** (the optimal denoiser of a
//! small fixed set of target images) used to prove that distillation converges end to end without
//! pretrained weights.

pub mod analytic;
pub mod denoise;
pub mod sd;

pub use analytic::{AnalyticTeacher, AnalyticTeacherConfig};
pub use denoise::{SampleConfig, SampleError};
pub use sd::SdTeacher;

use crate::image::Image;
use crate::models::guided::SizeConditioning;
use crate::models::stable_diffusion::ModelHints;
use crate::progress::{CancelToken, ProgressSink};
use rand::{Rng, RngExt};

/// A standard normal draw (Box–Muller over two uniforms): the noise of SDS and of sampling.
pub fn gaussian<R: Rng + ?Sized>(rng: &mut R) -> f32 {
    let u1: f64 = rng.random::<f64>().max(1e-12);
    let u2: f64 = rng.random::<f64>();
    ((-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()) as f32
}

/// Why a teacher call failed.
#[derive(Debug, thiserror::Error)]
pub enum TeacherError {
    #[error("image is {got_w}x{got_h}, the teacher expects {want_w}x{want_h}")]
    ImageSize {
        got_w: u32,
        got_h: u32,
        want_w: u32,
        want_h: u32,
    },
    #[error("latent has shape {got:?}, the teacher expects {want:?}")]
    LatentShape { got: [usize; 3], want: [usize; 3] },
    #[error("timestep {t} is out of range 0..{max}")]
    Timestep { t: usize, max: usize },
    #[error("invalid teacher setup: {0}")]
    Setup(String),
    #[error("teacher I/O: {0}")]
    Io(String),
    #[error("model error: {0}")]
    Model(String),
}

/// A `C x H x W` latent tensor (row-major, channel planes).
#[derive(Clone, Debug, PartialEq)]
pub struct Latent {
    pub shape: [usize; 3],
    pub data: Vec<f32>,
}

impl Latent {
    pub fn zeros(shape: [usize; 3]) -> Self {
        Self {
            shape,
            data: vec![0.0; shape[0] * shape[1] * shape[2]],
        }
    }

    pub fn len(&self) -> usize {
        self.data.len()
    }

    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    pub fn all_finite(&self) -> bool {
        self.data.iter().all(|v| v.is_finite())
    }
}

/// Text conditioning prepared once per job by [`Teacher::condition`].
///
/// Model teachers keep their text embeddings here (`cond` and `uncond`, flattened, with
/// `embed_shape`; SDXL's pooled embeddings and time ids in `added`); the analytic test teacher
/// keeps only the prompt (and may select a target by it).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Conditioning {
    pub prompt: String,
    pub negative_prompt: String,
    pub embed_shape: Vec<usize>,
    pub cond: Vec<f32>,
    pub uncond: Vec<f32>,
    /// SDXL's added conditioning; `None` for models without it.
    pub added: Option<AddedConditioning>,
}

impl Conditioning {
    /// The conditioning with SDXL's time ids set from `size` for an image drawn at `target`
    /// px (`None`, or a model without added conditioning: unchanged).
    pub fn sized(mut self, size: Option<&SizeConditioning>, target: (u32, u32)) -> Self {
        if let (Some(s), Some(a)) = (size, self.added.as_mut()) {
            a.time_ids = s.time_ids(target).to_vec();
        }
        self
    }
}

/// SDXL's added conditioning, flattened: the pooled text embedding of each branch (`[1, d]`)
/// and the size/crop time ids (`[1, 6]`) both branches share.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AddedConditioning {
    pub pooled: Vec<f32>,
    pub pooled_uncond: Vec<f32>,
    pub time_ids: Vec<f32>,
}

/// Pulls dL/d(latent) back to dL/d(image data), at the image an encoder pass was linearised at
/// ([`Teacher::encode_linearised`]). Called at most once: it may consume the encoder's tape.
pub type Pullback<'a> = Box<dyn FnOnce(&Latent) -> Result<Vec<f32>, TeacherError> + 'a>;

/// A diffusion model seen through the needs of score distillation.
pub trait Teacher: Send + Sync {
    /// The model's defaults: prompt suffix, sampling and SDS guidance, whether presets for a
    /// small prior apply (the paper's for teachers without a model directory).
    fn hints(&self) -> ModelHints {
        ModelHints::default()
    }

    /// Draws `cfg.k` raster samples of `prompt` at [`Teacher::image_size`]; the first
    /// `starts.len()` start from those images (SDEdit). Seeded by `cfg.seed`. A teacher that
    /// only distils says so.
    fn sample(
        &self,
        _prompt: &str,
        _starts: &[Image],
        _cfg: &SampleConfig,
        _sink: &dyn ProgressSink,
        _cancel: &CancelToken,
    ) -> Result<Vec<Image>, SampleError> {
        Err(SampleError::Failed(format!(
            "sampling: {} cannot draw samples",
            self.name()
        )))
    }

    /// The sentence embedding (of at most `tokens` tokens) the model's retrieval index is keyed
    /// by (MiniLM), when the model's text encoder makes one; `Ok(None)` otherwise.
    fn caption_embedding(
        &self,
        _text: &str,
        _tokens: usize,
    ) -> Result<Option<Vec<f32>>, TeacherError> {
        Ok(None)
    }

    /// Short human-readable name (the analytic teacher says it is a test teacher).
    fn name(&self) -> String;

    /// Whether this is a test teacher (not a generative model).
    fn is_test_teacher(&self) -> bool {
        false
    }

    /// The encoder in front of the model (`"vae"`, `"taesd"`, `"pixel"`; test teachers say
    /// what they use).
    fn encoder(&self) -> &'static str {
        "builtin"
    }

    /// Side of the square image the encoder expects, in pixels.
    fn image_size(&self) -> u32;

    /// `(width, height)` of the image the encoder expects: the square of
    /// [`Teacher::image_size`] unless the teacher was loaded for a non-square canvas.
    fn image_dims(&self) -> (u32, u32) {
        let s = self.image_size();
        (s, s)
    }

    /// Latent shape `[C, H, W]` produced by [`Teacher::encode`].
    fn latent_shape(&self) -> [usize; 3];

    /// `ᾱ_t` for `t = 0..T` (DDPM training schedule).
    fn alphas_cumprod(&self) -> &[f32];

    /// Prepares text conditioning for a caption (and negative prompt).
    fn condition(&self, prompt: &str, negative_prompt: &str) -> Result<Conditioning, TeacherError>;

    /// Encodes a premultiplied RGBA image of [`Teacher::image_dims`] into a latent.
    fn encode(&self, image: &Image) -> Result<Latent, TeacherError>;

    /// Vector-Jacobian product of [`Teacher::encode`] at `image`: returns dL/d(image data)
    /// (length `4 * w * h`, premultiplied RGBA layout) given dL/d(latent).
    fn encode_vjp(&self, image: &Image, d_latent: &Latent) -> Result<Vec<f32>, TeacherError>;

    /// [`Teacher::encode`] linearised at `image`: the latent, and the [`Pullback`] that applies
    /// [`Teacher::encode_vjp`] at the same image. Teachers whose encoder keeps a tape override
    /// this so that the pair costs one encoder forward pass instead of two; the default encodes,
    /// then runs `encode_vjp` from scratch when the pullback is called.
    fn encode_linearised<'a>(
        &'a self,
        image: &Image,
    ) -> Result<(Latent, Pullback<'a>), TeacherError> {
        linearise_by_recomputing(self, image)
    }

    /// Predicts the noise in `z_t` at timestep `t` with classifier-free guidance
    /// `ε̂ = ε_u + guidance · (ε_c − ε_u)`.
    fn predict_noise(
        &self,
        z_t: &Latent,
        t: usize,
        cond: &Conditioning,
        guidance: f32,
    ) -> Result<Latent, TeacherError>;
}

/// `Ok` when `t` indexes a schedule of `len` timesteps, else [`TeacherError::Timestep`].
pub fn check_timestep(t: usize, len: usize) -> Result<(), TeacherError> {
    if t < len {
        Ok(())
    } else {
        Err(TeacherError::Timestep { t, max: len })
    }
}

/// [`Teacher::encode_linearised`] without a tape: encodes now, and runs
/// [`Teacher::encode_vjp`] from scratch (a second encoder forward) when the pullback is called.
/// The trait's default; also for wrappers that want this behaviour from a taped teacher.
pub fn linearise_by_recomputing<'a, T: Teacher + ?Sized>(
    teacher: &'a T,
    image: &Image,
) -> Result<(Latent, Pullback<'a>), TeacherError> {
    let z = teacher.encode(image)?;
    let image = image.clone();
    Ok((z, Box::new(move |d: &Latent| teacher.encode_vjp(&image, d))))
}

/// The scaled-linear `ᾱ` schedule of Stable Diffusion (β from 0.00085 to 0.012, linear in √β),
/// as `models::scheduler` computes it for SD's default scheduler config.
pub fn sd_alphas_cumprod(num_train_timesteps: usize) -> Result<Vec<f32>, TeacherError> {
    let cfg = crate::models::scheduler::SchedulerConfig {
        num_train_timesteps,
        ..crate::models::scheduler::SchedulerConfig::sd()
    };
    let a = cfg
        .alphas_cumprod()
        .map_err(|e| TeacherError::Setup(e.to_string()))?;
    Ok(a.into_iter().map(|v| v as f32).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sd_schedule_endpoints() {
        let a = sd_alphas_cumprod(1000).unwrap();
        assert_eq!(a.len(), 1000);
        assert!((a[0] - (1.0 - 0.00085)).abs() < 1e-6);
        // diffusers' final ᾱ for SD 1.x is ≈ 0.0047.
        assert!((a[999] - 0.00466).abs() < 2e-4, "{}", a[999]);
        assert!(a.windows(2).all(|w| w[1] < w[0]));
    }
}
