//! What [`StableDiffusion`] predicts and samples with: the text conditioning of one branch of
//! classifier-free guidance ([`TextCond`]: the cross-attention context and, for SDXL, the added
//! pooled-text and size/crop conditioning), the guided noise prediction, the SDS gradient and the
//! samplers. SD 1.x/2.x conditionings carry no added part; SDXL's carry it on both branches, so
//! every caller passes one value per branch whatever the model.

use super::scheduler::{Sampler, SamplerKind, SamplerRun, split_prediction};
use super::stable_diffusion::TextEncoder;
use super::unet::AddedCond;
use super::{ModelError, Result, StableDiffusion};
use candle_core::{Device, Tensor};

/// One branch's text conditioning: `context [1, L, cross_attention_dim]` and, for a UNet with
/// `addition_embed_type = "text_time"` (SDXL), its [`AddedCond`] (pooled text embedding and the
/// six size/crop time ids).
#[derive(Debug, Clone)]
pub struct TextCond {
    pub context: Tensor,
    pub added: Option<AddedCond>,
}

impl From<Tensor> for TextCond {
    /// A context alone (SD 1.x/2.x and the embedded model).
    fn from(context: Tensor) -> Self {
        Self {
            context,
            added: None,
        }
    }
}

impl TextCond {
    /// The batch `[uncond; cond]` of classifier-free guidance (the added parts too).
    fn stack(uncond: &Self, cond: &Self) -> Result<Self> {
        let shape_err = |e: candle_core::Error| {
            ModelError::InvalidInput(format!(
                "prompt and negative-prompt conditionings differ in shape: {e}"
            ))
        };
        let context = Tensor::cat(&[&uncond.context, &cond.context], 0).map_err(shape_err)?;
        let added = match (&uncond.added, &cond.added) {
            (None, None) => None,
            (Some(u), Some(c)) => Some(AddedCond {
                text_embeds: Tensor::cat(&[&u.text_embeds, &c.text_embeds], 0)
                    .map_err(shape_err)?,
                time_ids: Tensor::cat(&[&u.time_ids, &c.time_ids], 0).map_err(shape_err)?,
            }),
            _ => {
                return Err(ModelError::InvalidInput(
                    "one guidance branch has SDXL's added conditioning and the other not".into(),
                ));
            }
        };
        Ok(Self { context, added })
    }
}

/// SDXL's size and crop conditioning ("micro-conditioning", SDXL paper §2.2): the size of the
/// original image the drawn one was cropped from, and where the crop's top-left corner lay.
/// The UNet's time ids are `[original (h, w), crop (top, left), target (h, w)]` (diffusers'
/// `_get_add_time_ids`), the target being the drawn image's size.
///
/// Invariant (what `pipeline::SizeConditioningRequest::resolve` checks): both original sides
/// within `1..=`[`MAX_ORIGINAL_SIDE`], both crop coordinates within `0..=`[`MAX_ORIGINAL_SIDE`]
/// (the UNet embeds each number on its own, so a crop past the original is allowed, as in
/// diffusers).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SizeConditioning {
    pub original_width: u32,
    pub original_height: u32,
    pub crop_left: u32,
    pub crop_top: u32,
}

/// The largest original side and crop coordinate [`SizeConditioning`] takes (px).
pub const MAX_ORIGINAL_SIDE: u32 = 16384;

impl SizeConditioning {
    /// A `width x height` px image drawn whole: what `StableDiffusionXLPipeline` sets by
    /// default (the original is the drawn size, no crop).
    pub fn drawn(width: u32, height: u32) -> Self {
        SizeConditioning {
            original_width: width,
            original_height: height,
            crop_left: 0,
            crop_top: 0,
        }
    }

    /// The six time ids for an image drawn at `width x height` px.
    pub fn time_ids(&self, (width, height): (u32, u32)) -> [f32; 6] {
        [
            self.original_height as f32,
            self.original_width as f32,
            self.crop_top as f32,
            self.crop_left as f32,
            height as f32,
            width as f32,
        ]
    }

    /// [`SizeConditioning::time_ids`] as a `[1, 6]` tensor.
    pub fn time_ids_tensor(&self, target: (u32, u32), device: &Device) -> Result<Tensor> {
        Ok(Tensor::from_vec(
            self.time_ids(target).to_vec(),
            (1, 6),
            device,
        )?)
    }
}

/// SDXL's time ids for a `width x height` px image drawn whole, as `StableDiffusionXLPipeline`
/// sets them by default ([`SizeConditioning::drawn`]), `[1, 6]`.
pub fn size_time_ids(width: u32, height: u32, device: &Device) -> Result<Tensor> {
    SizeConditioning::drawn(width, height).time_ids_tensor((width, height), device)
}

impl StableDiffusion {
    /// Whether the UNet takes SDXL's added conditioning.
    pub fn is_sdxl(&self) -> bool {
        self.unet.arch.text_time.is_some()
    }

    /// The `(prompt, negative prompt)` conditionings for `width x height` px images. SDXL:
    /// both text encoders, the pooled embedding and the size time ids ([`size_time_ids`]); an
    /// empty negative prompt gives zeros when `force_zeros_for_empty_prompt` (as diffusers).
    /// Others: the context of each (`""`: the unconditional embedding).
    pub fn text_cond(
        &self,
        prompt: &str,
        negative: &str,
        (width, height): (u32, u32),
    ) -> Result<(TextCond, TextCond)> {
        let drawn = SizeConditioning::drawn(width, height);
        self.text_cond_sized(prompt, negative, (width, height), &drawn)
    }

    /// [`StableDiffusion::text_cond`] with SDXL's size and crop conditioning `size` (both
    /// branches); models without it ignore `size`.
    pub fn text_cond_sized(
        &self,
        prompt: &str,
        negative: &str,
        target: (u32, u32),
        size: &SizeConditioning,
    ) -> Result<(TextCond, TextCond)> {
        let dev = self.device();
        match self.text.as_ref().ok_or(ModelError::NoTextEncoder)? {
            TextEncoder::Sdxl(te) => {
                let time_ids = size.time_ids_tensor(target, dev)?;
                let branch = |e: super::sdxl_text::SdxlEmbedding| TextCond {
                    context: e.context,
                    added: Some(AddedCond {
                        text_embeds: e.pooled,
                        time_ids: time_ids.clone(),
                    }),
                };
                Ok((
                    branch(te.embed(prompt, dev)?),
                    branch(te.embed_negative(negative, dev)?),
                ))
            }
            t => Ok((t.embed(prompt, dev)?.into(), t.embed(negative, dev)?.into())),
        }
    }

    /// The raw guided model output (ε or v); `guidance == 1` runs the conditional branch only.
    fn guided_raw(
        &self,
        z_t: &Tensor,
        t: f64,
        cond: &TextCond,
        uncond: &TextCond,
        guidance: f64,
    ) -> Result<Tensor> {
        if guidance == 1.0 {
            return self
                .unet
                .forward_added(z_t, t, &cond.context, cond.added.as_ref());
        }
        let b = z_t.dim(0)?;
        let both = TextCond::stack(uncond, cond)?;
        let out = self.unet.forward_added(
            &Tensor::cat(&[z_t, z_t], 0)?,
            t,
            &both.context,
            both.added.as_ref(),
        )?;
        let u = out.narrow(0, 0, b)?;
        let c = out.narrow(0, b, b)?;
        Ok((&u + ((c - &u)? * guidance)?)?)
    }

    /// `ᾱ_t`, or an error naming the range.
    fn alpha_at(&self, t: usize) -> Result<f64> {
        let a = self.alphas_cumprod();
        a.get(t).copied().ok_or_else(|| {
            ModelError::InvalidInput(format!("timestep {t} out of range 0..{}", a.len()))
        })
    }

    /// Classifier-free-guided noise prediction `ε̂(z_t, t)`; v-prediction models are converted
    /// to ε. `guidance == 1` runs the conditional branch only.
    pub fn predict_noise(
        &self,
        z_t: &Tensor,
        t: usize,
        cond: &TextCond,
        uncond: &TextCond,
        guidance: f64,
    ) -> Result<Tensor> {
        let a = self.alpha_at(t)?;
        let raw = self.guided_raw(z_t, t as f64, cond, uncond, guidance)?;
        Ok(split_prediction(self.prediction_type(), &raw, z_t, a)?.1)
    }

    /// Latent-space SDS gradient `w(t) (ε̂(z_t, t) − ε)` with `w(t) = 1 − ᾱ_t` and
    /// `z_t = √ᾱ_t z + √(1−ᾱ_t) ε`.
    pub fn sds_latent_grad(
        &self,
        latents: &Tensor,
        t: usize,
        noise: &Tensor,
        cond: &TextCond,
        uncond: &TextCond,
        guidance: f64,
    ) -> Result<Tensor> {
        let a = self.alpha_at(t)?;
        let z_t = ((latents * a.sqrt())? + (noise * (1.0 - a).sqrt())?)?;
        let eps = self.predict_noise(&z_t, t, cond, uncond, guidance)?;
        Ok(((eps - noise)? * (1.0 - a))?)
    }

    /// SDEdit (Meng et al., ICLR 2022) with DDIM: the clean latents `init` noised with `noise`
    /// (standard normal, same shape) to the step `strength` of the way up a `steps`-step schedule
    /// (0 returns `init`; 1 starts at the first step, like [`StableDiffusion::sample`]), then
    /// denoised with CFG to the end. Returns the latents after each step run.
    #[allow(clippy::too_many_arguments)]
    pub fn sample_from(
        &self,
        init: &Tensor,
        noise: &Tensor,
        strength: f64,
        cond: &TextCond,
        uncond: &TextCond,
        guidance: f64,
        steps: usize,
    ) -> Result<Vec<Tensor>> {
        if !(0.0..=1.0).contains(&strength) {
            return Err(ModelError::InvalidInput(format!(
                "SDEdit strength must be in 0..=1, got {strength}"
            )));
        }
        let s = Sampler::new(&self.scheduler, SamplerKind::Ddim, steps)?;
        let run = ((steps as f64 * strength).round() as usize).min(steps);
        if run == 0 {
            return Ok(vec![init.clone()]);
        }
        let start = steps - run;
        let a = self.alpha_at(s.timesteps[start] as usize)?;
        let mut x = ((init * a.sqrt())? + (noise * (1.0 - a).sqrt())?)?;
        let mut traj = Vec::with_capacity(run);
        for i in start..steps {
            let out = self.guided_raw(&x, s.timesteps[i], cond, uncond, guidance)?;
            x = s.step(&out, i, &x, None)?;
            traj.push(x.clone());
        }
        Ok(traj)
    }

    /// Samples latents from `init_noise` (standard normal, `[b, 4, h, w]`) with CFG as `run`
    /// says; returns the latents after every step (the last one is the result). As diffusers,
    /// `guidance ≤ 1` runs the conditional branch alone (SD-Turbo samples with 0).
    pub fn sample(
        &self,
        init_noise: &Tensor,
        cond: &TextCond,
        uncond: &TextCond,
        guidance: f64,
        run: SamplerRun<'_>,
    ) -> Result<Vec<Tensor>> {
        let s = Sampler::new(&self.scheduler, run.kind, run.steps)?;
        let spacing = matches!(
            self.scheduler.timestep_spacing.as_str(),
            "trailing" | "linspace"
        );
        let guidance = if guidance <= 1.0 { 1.0 } else { guidance };
        let mut x = (init_noise * s.init_noise_sigma(spacing))?;
        let mut traj = Vec::with_capacity(run.steps);
        let mut noise = run.step_noise.iter();
        for (i, &t) in s.timesteps.iter().enumerate() {
            let inp = s.scale_model_input(&x, i)?;
            let out = self.guided_raw(&inp, t, cond, uncond, guidance)?;
            // a missing noise is refused by the step
            let z = run
                .kind
                .adds_noise(i, run.steps)
                .then(|| noise.next())
                .flatten();
            x = s.step(&out, i, &x, z)?;
            traj.push(x.clone());
        }
        Ok(traj)
    }
}
