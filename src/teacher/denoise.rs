//! The denoising loop behind [`super::Teacher::sample`]: K raster samples of a prompt from a
//! diffusion model. The first `starts.len()` samples begin from given images (SDEdit: encoded,
//! noised to `strength`, then denoised with the caption-conditioned prior; the retrieval sampler
//! passes the training icons nearest to the caption), the others from pure noise. Retrieval and
//! reranking are the sample stage's ([`crate::stages::sample`]).

use crate::image::Image;
use crate::models::guided::SizeConditioning;
use crate::models::scheduler::{SamplerKind, SamplerRun};
use crate::models::{StableDiffusion, TextCond};
use crate::progress::{CancelToken, Progress, ProgressSink};
use candle_core::{DType, Tensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// What to draw.
#[derive(Clone, Debug, PartialEq)]
pub struct SampleConfig {
    /// Number of samples K.
    pub k: u32,
    /// Sampler steps for a sample from noise (the model's own sampler, `scheduler_config.json`'s
    /// `_class_name`); an SDEdit sample runs `strength` of them with DDIM.
    pub steps: usize,
    pub guidance: f64,
    pub seed: u64,
    pub strength: f64,
    /// What classifier-free guidance steers away from: the unconditional branch embeds it
    /// (empty: the unconditional prompt "").
    pub negative_prompt: String,
    /// SDXL's size and crop conditioning (`None`: the drawn size, no crop); other models
    /// ignore it.
    pub size_conditioning: Option<SizeConditioning>,
}

/// Why sampling stopped.
#[derive(Debug, thiserror::Error)]
pub enum SampleError {
    #[error("cancelled")]
    Cancelled,
    #[error("{0}")]
    Failed(String),
}

impl SampleError {
    /// A failure of `what` (a step of sampling or reranking) because of `e`.
    pub fn failed(what: &str, e: impl std::fmt::Display) -> SampleError {
        SampleError::Failed(format!("{what}: {e}"))
    }
}

/// An opaque RGB image as `[1, 3, H, W]` in `[0, 1]` (alpha composited over white).
pub fn image_tensor(image: &Image, device: &candle_core::Device) -> Result<Tensor, SampleError> {
    let (w, h) = (image.width as usize, image.height as usize);
    Tensor::from_vec(image.planar_rgb_over_white(), (1, 3, h, w), device)
        .map_err(|e| SampleError::failed("image", e))
}

/// `[1, 3, H, W]` in `[0, 1]` → opaque [`Image`]; non-finite values are an error.
pub fn tensor_image(t: &Tensor) -> Result<Image, SampleError> {
    let dims = t.dims().to_vec();
    let (h, w) = match dims.as_slice() {
        [1, 3, h, w] => (*h, *w),
        _ => {
            return Err(SampleError::failed(
                "decode",
                format!("unexpected shape {dims:?}"),
            ));
        }
    };
    let v: Vec<f32> = t
        .to_dtype(DType::F32)
        .and_then(|x| x.flatten_all())
        .and_then(|x| x.to_vec1())
        .map_err(|e| SampleError::failed("decode", e))?;
    if v.iter().any(|x| !x.is_finite()) {
        return Err(SampleError::failed("decode", "non-finite pixels"));
    }
    let mut im = Image::new(w as u32, h as u32);
    for p in 0..h * w {
        for c in 0..3 {
            im.data[4 * p + c] = v[c * h * w + p].clamp(0.0, 1.0);
        }
        im.data[4 * p + 3] = 1.0;
    }
    Ok(im)
}

/// Draws `cfg.k` samples conditioned on `(cond, uncond)` (the prompt's and the negative prompt's,
/// [`StableDiffusion::text_cond`]) at the latent shape `[c, h, w]`; `starts` (at most K used)
/// are SDEdit starting images at the model's image side. Seeded: the same inputs give the same
/// samples, and the noise of the samples from noise does not depend on `starts`.
pub fn draw(
    sd: &StableDiffusion,
    latent_shape: [usize; 3],
    (cond, uncond): &(TextCond, TextCond),
    starts: &[Image],
    cfg: &SampleConfig,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<Vec<Image>, SampleError> {
    let [c, h, w] = latent_shape;
    // noise samples draw from the sampler's historical stream; SDEdit noise from its own
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x5a3b_1e00);
    let mut start_rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x5de0_17a1);
    let n_starts = starts.len().min(cfg.k as usize);
    // samples from noise run the model's own sampler
    let kind = SamplerKind::of(&sd.scheduler);
    let mut out = Vec::with_capacity(cfg.k as usize);
    for i in 0..cfg.k as usize {
        let start = starts.get(i).filter(|_| i < n_starts);
        if cancel.is_cancelled() {
            return Err(SampleError::Cancelled);
        }
        let r = if i < n_starts {
            &mut start_rng
        } else {
            &mut rng
        };
        let noise = latent_noise(r, latent_shape, sd)?;
        let traj = if let Some(start) = start {
            let x = image_tensor(start, sd.device())?;
            let z = sd
                .encode(&x)
                .map_err(|e| SampleError::failed("encode the start image", e))?;
            if z.dims() != [1, c, h, w] {
                return Err(SampleError::failed(
                    "encode the start image",
                    format!("latent {:?}, expected {:?}", z.dims(), [1, c, h, w]),
                ));
            }
            sd.sample_from(
                &z,
                &noise,
                cfg.strength,
                cond,
                uncond,
                cfg.guidance,
                cfg.steps,
            )
        } else {
            // a stochastic sampler's step noise follows the start noise
            let step_noise = (0..SamplerRun::noise_count(kind, cfg.steps))
                .map(|_| latent_noise(r, latent_shape, sd))
                .collect::<Result<Vec<_>, _>>()?;
            let run = SamplerRun {
                kind,
                steps: cfg.steps,
                step_noise: &step_noise,
            };
            sd.sample(&noise, cond, uncond, cfg.guidance, run)
        }
        .map_err(|e| SampleError::failed("sampling", e))?;
        let z = traj
            .last()
            .ok_or_else(|| SampleError::failed("sampling", "no sampler steps"))?;
        let img = sd.decode(z).map_err(|e| SampleError::failed("decode", e))?;
        out.push(tensor_image(&img)?);
        sink.report(Progress::new(
            crate::progress::Stage::Sample,
            i as u32 + 1,
            cfg.k,
        ));
    }
    Ok(out)
}

/// Standard-normal noise of `[1, c, h, w]` from `r`.
fn latent_noise(
    r: &mut ChaCha8Rng,
    [c, h, w]: [usize; 3],
    sd: &StableDiffusion,
) -> Result<Tensor, SampleError> {
    let z: Vec<f32> = (0..c * h * w).map(|_| super::gaussian(r)).collect();
    Tensor::from_vec(z, (1, c, h, w), sd.device()).map_err(|e| SampleError::failed("noise", e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_tensor_round_trips_and_composites_over_white() {
        let mut im = Image::filled(2, 1, [0.25, 0.5, 0.75, 1.0]);
        im.data[4..8].copy_from_slice(&[0.0, 0.0, 0.0, 0.0]);
        let t = image_tensor(&im, &candle_core::Device::Cpu).unwrap();
        let back = tensor_image(&t).unwrap();
        assert_eq!(back.pixel(0, 0), [0.25, 0.5, 0.75, 1.0]);
        assert_eq!(back.pixel(1, 0), [1.0, 1.0, 1.0, 1.0]);
        let bad = Tensor::new(&[f32::NAN; 3], &candle_core::Device::Cpu)
            .unwrap()
            .reshape((1, 3, 1, 1))
            .unwrap();
        assert!(tensor_image(&bad).is_err());
    }
}
