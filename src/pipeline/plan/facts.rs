//! What the executor knows about its model before loading it ([`ModelFacts`]).

use super::EncoderChoice;
use crate::models::scheduler::SamplerKind;
use crate::models::stable_diffusion::ModelHints;
use crate::pipeline::canvas::SampleShape;

/// What the executor knows about its model before loading it.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelFacts {
    /// What the model is: the model directory's name, or the test teacher (never a path).
    pub name: String,
    pub hints: ModelHints,
    /// The configured SDS encoder.
    pub encoder_choice: EncoderChoice,
    /// A TAESD encoder was found for this model.
    pub taesd_found: bool,
    /// The shapes it samples at (a non-square canvas is sampled at its aspect only by a
    /// model that takes [`SampleShape::Multiple`]).
    pub sample_shape: SampleShape,
    /// Its guidance has an unconditional branch that can embed a negative prompt.
    pub negative_prompt: bool,
    /// Its UNet takes SDXL's size and crop conditioning (`addition_embed_type` `text_time`).
    pub size_conditioning: bool,
    /// It samples in a few steps ([`few_step`]); the `cpu` preset reads it
    /// ([`crate::pipeline::Preset::settings_for_model`]).
    pub few_step: bool,
}

/// Whether a model samples in a few steps: its `scheduler_config.json` names `LCMScheduler`
/// (a latent consistency model), or its `_sample_guidance` is at most 1 (a guidance-distilled
/// turbo checkpoint, which samples without the unconditional branch). Euler ancestral alone
/// says nothing: ordinary checkpoints ship it too.
pub fn few_step(sampler: SamplerKind, hints: &ModelHints) -> bool {
    sampler == SamplerKind::Lcm || hints.sample_guidance <= 1.0
}

impl ModelFacts {
    /// A model without a directory of its own (the test teacher, a custom executor): the
    /// paper's hints, the VAE, no TAESD.
    pub fn paper(name: impl Into<String>) -> Self {
        ModelFacts {
            name: name.into(),
            hints: ModelHints::default(),
            encoder_choice: EncoderChoice::Vae,
            taesd_found: false,
            sample_shape: SampleShape::Square,
            negative_prompt: false,
            size_conditioning: false,
            few_step: false,
        }
    }

    /// [`ModelFacts::paper`] for a model that samples like Stable Diffusion 1.x/2.x: any
    /// multiple of 64 px, a negative prompt in its guidance (a custom executor's default).
    pub fn stable_diffusion(name: impl Into<String>) -> Self {
        ModelFacts {
            sample_shape: SampleShape::Multiple(64),
            negative_prompt: true,
            ..ModelFacts::paper(name)
        }
    }

    /// The SDS encoder a run uses, `prefer_taesd` being its preset's wish.
    pub fn encoder(&self, prefer_taesd: bool) -> EncoderChoice {
        match self.encoder_choice {
            EncoderChoice::Auto if prefer_taesd && self.taesd_found => EncoderChoice::Taesd,
            EncoderChoice::Auto => EncoderChoice::Vae,
            fixed => fixed,
        }
    }
}
