//! Stable Diffusion as an SDS [`Teacher`]: the model's codec (the VAE encoder in fp32, TAESD in
//! its place, or pixel space for models without `vae/`) with its VJP, the UNet with
//! classifier-free guidance and the text encoder, from [`crate::models::StableDiffusion`].
//!
//! Pixel-space models take renders of any size (e.g. 128 px) and area-resize them to the UNet's
//! `sample_size` inside the encoder; latent models need a multiple of the VAE's downsampling.
//!
//! Images cross the boundary composited over white as `[1, 3, H, W]` tensors in `[0, 1]`; the
//! image gradient is mapped back to premultiplied RGBA (`d/dα = −Σ_c d/dc`).

use super::{
    AddedConditioning, Conditioning, Latent, Pullback, SampleConfig, SampleError, Teacher,
    TeacherError,
};
use crate::image::Image;
use crate::models::codec::CodecKind;
use crate::models::guided::SizeConditioning;
use crate::models::stable_diffusion::ModelHints;
use crate::models::unet::AddedCond;
use crate::models::{ComputeDevice, LoadOptions, StableDiffusion, TextCond};
use crate::progress::{CancelToken, ProgressSink};
use candle_core::{DType, Tensor};
use std::path::Path;

/// Stable Diffusion behind the [`Teacher`] interface.
pub struct SdTeacher {
    sd: StableDiffusion,
    /// Encoder input width and height (equal unless loaded for a non-square canvas).
    width: u32,
    height: u32,
    latent_shape: [usize; 3],
    alphas: Vec<f32>,
}

fn model_err(e: impl std::fmt::Display) -> TeacherError {
    TeacherError::Model(e.to_string())
}

impl SdTeacher {
    /// Loads a diffusers directory; `image_size` is the encoder input side (512 for SD 1.x).
    pub fn load(dir: &Path, image_size: u32) -> Result<Self, TeacherError> {
        Self::load_with(dir, image_size, None)
    }

    /// [`SdTeacher::load`] with TAESD (`taesd`, an `AutoencoderTiny` directory) as the encoder
    /// instead of the VAE; pixel-space models ignore it.
    pub fn load_with(
        dir: &Path,
        image_size: u32,
        taesd: Option<&Path>,
    ) -> Result<Self, TeacherError> {
        Self::load_on(dir, (image_size, image_size), taesd, ComputeDevice::Cpu)
    }

    /// [`SdTeacher::load_with`] on `device` (CUDA needs the `cuda` feature) for `(width,
    /// height)` px encoder inputs.
    pub fn load_on(
        dir: &Path,
        (width, height): (u32, u32),
        taesd: Option<&Path>,
        device: ComputeDevice,
    ) -> Result<Self, TeacherError> {
        let opts = LoadOptions {
            device: device.open().map_err(model_err)?,
            allow_download: false,
            taesd: taesd.map(Path::to_path_buf),
            ..LoadOptions::default()
        };
        let sd = StableDiffusion::load(dir, &opts).map_err(model_err)?;
        Self::new_shaped(sd, width, height)
    }

    /// Wraps an already built model (benchmarks use random weights).
    pub fn new(sd: StableDiffusion, image_size: u32) -> Result<Self, TeacherError> {
        Self::new_shaped(sd, image_size, image_size)
    }

    /// [`SdTeacher::new`] for `width x height` px encoder inputs (a non-square canvas: each
    /// side must suit the autoencoder; pixel-space models draw their square).
    pub fn new_shaped(sd: StableDiffusion, width: u32, height: u32) -> Result<Self, TeacherError> {
        let side = |v: u32| {
            sd.latent_side(v as usize)
                .map_err(|e| TeacherError::Setup(e.to_string()))
        };
        let (lw, lh) = (side(width)?, side(height)?);
        if sd.is_pixel_space() && width != height {
            return Err(TeacherError::Setup(format!(
                "a pixel-space model draws squares, not {width}x{height}"
            )));
        }
        let latent_shape = [sd.codec.latent_channels(), lh, lw];
        let alphas = sd.alphas_cumprod().iter().map(|&a| a as f32).collect();
        Ok(Self {
            sd,
            width,
            height,
            latent_shape,
            alphas,
        })
    }

    pub fn model(&self) -> &StableDiffusion {
        &self.sd
    }

    /// "Stable Diffusion XL" for SDXL checkpoints, else "Stable Diffusion".
    fn family(&self) -> &'static str {
        if self.sd.is_sdxl() {
            "Stable Diffusion XL"
        } else {
            "Stable Diffusion"
        }
    }

    /// The encoder VJP's `[1, 3, s, s]` gradient as dL/d(premultiplied RGBA data): the alpha
    /// gradient is minus the sum of the colour gradients.
    fn image_grad(&self, dx: &Tensor) -> Result<Vec<f32>, TeacherError> {
        let (dx, _) = flat(dx)?;
        let n = (self.width * self.height) as usize;
        if dx.len() != 3 * n {
            return Err(TeacherError::Model(format!(
                "encoder VJP returned {} values, expected {}",
                dx.len(),
                3 * n
            )));
        }
        let mut out = vec![0.0f32; 4 * n];
        for i in 0..n {
            let mut da = 0.0;
            for c in 0..3 {
                let g = dx[c * n + i];
                out[4 * i + c] = g;
                da -= g;
            }
            out[4 * i + 3] = da;
        }
        Ok(out)
    }

    fn image_tensor(&self, image: &Image) -> Result<Tensor, TeacherError> {
        let (w, h) = (self.width, self.height);
        if image.width != w || image.height != h || image.data.len() != 4 * (w * h) as usize {
            return Err(TeacherError::ImageSize {
                got_w: image.width,
                got_h: image.height,
                want_w: w,
                want_h: h,
            });
        }
        Tensor::from_vec(
            image.planar_rgb_over_white(),
            (1, 3, h as usize, w as usize),
            self.sd.device(),
        )
        .map_err(model_err)
    }

    fn latent_tensor(&self, z: &Latent) -> Result<Tensor, TeacherError> {
        if z.shape != self.latent_shape || z.data.len() != z.shape.iter().product::<usize>() {
            return Err(TeacherError::LatentShape {
                got: z.shape,
                want: self.latent_shape,
            });
        }
        let [c, h, w] = z.shape;
        Tensor::from_vec(z.data.clone(), (1, c, h, w), self.sd.device()).map_err(model_err)
    }

    fn to_latent(&self, t: &Tensor) -> Result<Latent, TeacherError> {
        let data = t
            .to_dtype(DType::F32)
            .and_then(|t| t.flatten_all())
            .and_then(|t| t.to_vec1::<f32>())
            .map_err(model_err)?;
        if data.len() != self.latent_shape.iter().product::<usize>() {
            return Err(TeacherError::Model(format!(
                "model returned {} latent values, expected shape {:?}",
                data.len(),
                self.latent_shape
            )));
        }
        Ok(Latent {
            shape: self.latent_shape,
            data,
        })
    }

    fn embedding(&self, data: &[f32], shape: &[usize]) -> Result<Tensor, TeacherError> {
        if shape.is_empty() || shape.iter().product::<usize>() != data.len() {
            return Err(TeacherError::Setup(
                "conditioning has no text embeddings for this model (use Teacher::condition)"
                    .into(),
            ));
        }
        Tensor::from_vec(data.to_vec(), shape, self.sd.device()).map_err(model_err)
    }

    /// The `(prompt, negative prompt)` model conditionings of a [`Conditioning`].
    fn branches(&self, cond: &Conditioning) -> Result<(TextCond, TextCond), TeacherError> {
        let mut c = TextCond::from(self.embedding(&cond.cond, &cond.embed_shape)?);
        let mut u = TextCond::from(self.embedding(&cond.uncond, &cond.embed_shape)?);
        if let Some(a) = &cond.added {
            let row = |d: &[f32]| self.embedding(d, &[1, d.len()]);
            let time_ids = row(&a.time_ids)?;
            u.added = Some(AddedCond {
                text_embeds: row(&a.pooled_uncond)?,
                time_ids: time_ids.clone(),
            });
            c.added = Some(AddedCond {
                text_embeds: row(&a.pooled)?,
                time_ids,
            });
        }
        Ok((c, u))
    }
}

fn flat(t: &Tensor) -> Result<(Vec<f32>, Vec<usize>), TeacherError> {
    let dims = t.dims().to_vec();
    let v = t
        .to_dtype(DType::F32)
        .and_then(|t| t.flatten_all())
        .and_then(|t| t.to_vec1::<f32>())
        .map_err(model_err)?;
    Ok((v, dims))
}

impl Teacher for SdTeacher {
    /// The model's `model_index.json` hints; a pixel-space model is always a small prior.
    fn hints(&self) -> ModelHints {
        let mut h = self.sd.hints;
        h.small_prior |= self.sd.is_pixel_space();
        h
    }

    fn sample(
        &self,
        prompt: &str,
        starts: &[Image],
        cfg: &SampleConfig,
        sink: &dyn ProgressSink,
        cancel: &CancelToken,
    ) -> Result<Vec<Image>, SampleError> {
        let target = (self.width, self.height);
        let size = cfg
            .size_conditioning
            .unwrap_or(SizeConditioning::drawn(self.width, self.height));
        let conds = self
            .sd
            .text_cond_sized(prompt, &cfg.negative_prompt, target, &size)
            .map_err(|e| SampleError::failed("text encoder", e))?;
        super::denoise::draw(
            &self.sd,
            self.latent_shape,
            &conds,
            starts,
            cfg,
            sink,
            cancel,
        )
    }

    fn caption_embedding(
        &self,
        text: &str,
        tokens: usize,
    ) -> Result<Option<Vec<f32>>, TeacherError> {
        self.sd.sentence_embedding(text, tokens).map_err(model_err)
    }

    fn name(&self) -> String {
        let s = if self.width == self.height {
            self.width.to_string()
        } else {
            format!("{}x{}", self.width, self.height)
        };
        match self.sd.codec.kind() {
            CodecKind::Pixel => format!(
                "pixel-space diffusion ({0}x{0} prior, {s} px renders)",
                self.latent_shape[1]
            ),
            CodecKind::Vae => format!("{} (VAE encoder, {s} px)", self.family()),
            CodecKind::Taesd => format!("{} (TAESD encoder, {s} px)", self.family()),
        }
    }

    fn encoder(&self) -> &'static str {
        self.sd.codec.kind().as_str()
    }

    /// The width (a square teacher's side).
    fn image_size(&self) -> u32 {
        self.width
    }

    fn image_dims(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    fn latent_shape(&self) -> [usize; 3] {
        self.latent_shape
    }

    fn alphas_cumprod(&self) -> &[f32] {
        &self.alphas
    }

    fn condition(&self, prompt: &str, negative_prompt: &str) -> Result<Conditioning, TeacherError> {
        let (c, u) = self
            .sd
            .text_cond(prompt, negative_prompt, (self.width, self.height))
            .map_err(model_err)?;
        let (cond, shape) = flat(&c.context)?;
        let (uncond, ushape) = flat(&u.context)?;
        if shape != ushape {
            return Err(TeacherError::Model(
                "prompt and negative-prompt embeddings differ in shape".into(),
            ));
        }
        let added = match (&c.added, &u.added) {
            (Some(a), Some(b)) => Some(AddedConditioning {
                pooled: flat(&a.text_embeds)?.0,
                pooled_uncond: flat(&b.text_embeds)?.0,
                time_ids: flat(&a.time_ids)?.0,
            }),
            _ => None,
        };
        Ok(Conditioning {
            prompt: prompt.to_string(),
            negative_prompt: negative_prompt.to_string(),
            embed_shape: shape,
            cond,
            uncond,
            added,
        })
    }

    fn encode(&self, image: &Image) -> Result<Latent, TeacherError> {
        let x = self.image_tensor(image)?;
        let z = self.sd.encode(&x).map_err(model_err)?;
        self.to_latent(&z)
    }

    fn encode_vjp(&self, image: &Image, d_latent: &Latent) -> Result<Vec<f32>, TeacherError> {
        let (_, pullback) = self.encode_linearised(image)?;
        pullback(d_latent)
    }

    fn encode_linearised<'a>(
        &'a self,
        image: &Image,
    ) -> Result<(Latent, Pullback<'a>), TeacherError> {
        let x = self.image_tensor(image)?;
        let (z, tape) = self.sd.encode_t(&x).map_err(model_err)?;
        let z = self.to_latent(&z)?;
        let pullback = move |d_latent: &Latent| {
            let dz = self.latent_tensor(d_latent)?;
            let dx = self.sd.encode_pullback(tape, &dz).map_err(model_err)?;
            self.image_grad(&dx)
        };
        Ok((z, Box::new(pullback)))
    }

    fn predict_noise(
        &self,
        z_t: &Latent,
        t: usize,
        cond: &Conditioning,
        guidance: f32,
    ) -> Result<Latent, TeacherError> {
        super::check_timestep(t, self.alphas.len())?;
        let z = self.latent_tensor(z_t)?;
        let (c, u) = self.branches(cond)?;
        let eps = self
            .sd
            .predict_noise(&z, t, &c, &u, guidance as f64)
            .map_err(model_err)?;
        self.to_latent(&eps)
    }
}
