//! The preset tables: what `draft`, `fast`, `balanced`, `paper` and `cpu` mean for Stable
//! Diffusion, for a small prior and for LIVE (vectorize runs). Read only by [`super::plan`] when a request
//! is resolved (and by the benchmarks, which name a preset); a stored plan keeps the numbers, so
//! editing these tables changes new jobs only.

use super::Preset;
use crate::stages::live::LiveConfig;
use serde::Serialize;

/// What a preset sets. Explicit `paths`/`steps`/`samples` in a request override it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct PresetSettings {
    /// Teacher input side in pixels (the SVG is written at this width).
    pub size: u32,
    /// SDS steps.
    pub steps: u32,
    /// Paths (iconography) or strokes (sketch); pixel art is always a 32x32 grid.
    pub paths: usize,
    /// Images sampled for `sd_live*` (K).
    pub samples: u32,
    /// Sampler steps per image.
    pub sample_steps: usize,
    /// LIVE iterations per stage (and for the final pass).
    pub live_iters: u32,
    /// SVG snapshot period of the SDS and LIVE stages.
    pub snapshot_every: u32,
    /// Encoder for SDS: `"taesd"` when a TAESD directory is configured and the preset allows it,
    /// otherwise `"vae"`.
    pub prefer_taesd: bool,
    /// Canvas side LIVE traces the best sample at (pixel-space samples, 32 px, are upscaled to
    /// it first); the traced scene is then scaled to `size`.
    pub trace_size: u32,
}

/// Sampler steps per image of the `cpu` preset with a few-step (turbo or LCM) model: the top
/// of the 1–4 such checkpoints are made for.
pub const FEW_STEP_SAMPLE_STEPS: usize = 4;

impl Preset {
    /// The settings of this preset.
    pub fn settings(self) -> PresetSettings {
        match self {
            Preset::Draft => PresetSettings {
                size: 32,
                steps: 8,
                paths: 8,
                samples: 2,
                sample_steps: 3,
                live_iters: 8,
                snapshot_every: 4,
                prefer_taesd: true,
                trace_size: 32,
            },
            Preset::Fast => PresetSettings {
                size: 64,
                steps: 100,
                paths: 16,
                samples: 4,
                sample_steps: 10,
                live_iters: 40,
                snapshot_every: 20,
                prefer_taesd: true,
                trace_size: 64,
            },
            Preset::Balanced => PresetSettings {
                size: 256,
                steps: 500,
                paths: 64,
                samples: 8,
                sample_steps: 25,
                live_iters: 100,
                snapshot_every: 50,
                prefer_taesd: true,
                trace_size: 256,
            },
            Preset::Paper => PresetSettings {
                size: 512,
                steps: 1000,
                paths: 128,
                samples: 64,
                sample_steps: 50,
                live_iters: 200,
                snapshot_every: 100,
                prefer_taesd: false,
                trace_size: 512,
            },
            // Sized by measured parts (docs/BENCHMARKS.md, 2-core AMD EPYC, 256 px): a guided
            // UNet call 3.3 s, an SDS step through TAESD 3.4 s, the LIVE trace seconds; so 4 × 12
            // sampler calls + 80 SDS steps + loading ≈ 8 min computed, 5.6 min measured end to
            // end (quiet), leaving room for a slower machine. LIVE keeps `balanced`'s paths and
            // iterations (they cost seconds). A few-step model samples differently
            // ([`Preset::settings_for_model`]).
            Preset::Cpu => PresetSettings {
                size: 256,
                steps: 80,
                paths: 64,
                samples: 4,
                sample_steps: 12,
                live_iters: 100,
                snapshot_every: 20,
                prefer_taesd: true,
                trace_size: 256,
            },
        }
    }

    /// [`Preset::settings_for`] for a model that does or does not sample in a few steps
    /// (`few_step`: an LCM scheduler or a guidance-distilled turbo checkpoint,
    /// [`super::plan::ModelFacts::few_step`]). Only `cpu` reads it: from such a Stable
    /// Diffusion model it draws K = 8 images in [`FEW_STEP_SAMPLE_STEPS`] steps each instead of
    /// 4 in 12 (32 UNet calls against 48, each half the cost for a turbo model, which runs no
    /// unconditional branch): a wider rerank for less time. The other presets keep their
    /// numbers for every model.
    pub fn settings_for_model(self, small_prior: bool, few_step: bool) -> PresetSettings {
        let ps = self.settings_for(small_prior);
        if self == Preset::Cpu && few_step && !small_prior {
            return PresetSettings {
                samples: 8,
                sample_steps: FEW_STEP_SAMPLE_STEPS,
                ..ps
            };
        }
        ps
    }

    /// The settings of this preset for a model of the given kind: Stable Diffusion
    /// ([`Preset::settings`]) or a small prior (`small_prior`: the embedded `models/vf-icon`,
    /// 64 px through a 16x16x4 latent, or a 32 px pixel-space prior): SDS renders at the
    /// prior's 64 px image side (a pixel-space encoder area-resizes it to its size), samples are
    /// traced at 64–256 px, and step counts are sized so that the default (`balanced`) run of
    /// `generate` stays within about 30 s on 2 CPU cores.
    pub fn settings_for(self, small_prior: bool) -> PresetSettings {
        if !small_prior {
            return self.settings();
        }
        match self {
            // One SDS step or one sampler step is one classifier-free-guided UNet call (batch
            // 2); for a ~3.4M-parameter UNet at 32 px that costs 1.2-1.7 CPU-seconds here
            // (docs/BENCHMARKS.md), so the balanced preset budgets ~75 calls in all.
            Preset::Draft => PresetSettings {
                size: 64,
                steps: 10,
                paths: 8,
                samples: 1,
                sample_steps: 5,
                live_iters: 10,
                snapshot_every: 5,
                prefer_taesd: false,
                trace_size: 64,
            },
            Preset::Fast => PresetSettings {
                size: 64,
                steps: 25,
                paths: 16,
                samples: 2,
                sample_steps: 8,
                live_iters: 20,
                snapshot_every: 5,
                prefer_taesd: false,
                trace_size: 128,
            },
            // `cpu` is `balanced` for a small prior: that already runs in seconds on 2 cores.
            Preset::Balanced | Preset::Cpu => PresetSettings {
                size: 64,
                steps: 50,
                paths: 24,
                samples: 2,
                sample_steps: 12,
                live_iters: 30,
                snapshot_every: 10,
                prefer_taesd: false,
                trace_size: 128,
            },
            Preset::Paper => PresetSettings {
                size: 64,
                steps: 300,
                paths: 64,
                samples: 8,
                sample_steps: 25,
                live_iters: 100,
                snapshot_every: 50,
                prefer_taesd: false,
                trace_size: 256,
            },
        }
    }

    /// The path budget of a vectorize job when the request names none: the total of this
    /// preset's LIVE budget.
    pub fn vectorize_paths(self) -> usize {
        self.live_config().budget.max_paths()
    }

    /// The LIVE configuration of a vectorize run of this preset (its budget, seed and colours
    /// are the request's): LIVE's own settings ([`LiveConfig::default`]) for `fast`, cut to
    /// 64 px and 20/10 iterations for `draft`, at a larger canvas, larger new circles and a
    /// wider UDF band for `balanced` and `paper`; `balanced` runs all stages but the last at
    /// 80 px (coarse-to-fine), `paper` at 256 px throughout with more iterations; `cpu` is
    /// `balanced` (a vectorize run takes seconds on 2 cores).
    pub fn live_config(self) -> LiveConfig {
        let base = LiveConfig::default();
        match self {
            Preset::Draft => LiveConfig {
                size: 64,
                iters_per_stage: 20,
                final_iters: 10,
                ..base
            },
            Preset::Fast => base,
            Preset::Balanced | Preset::Cpu => LiveConfig {
                size: 160,
                coarse_size: 80,
                iters_per_stage: 100,
                final_iters: 100,
                init_radius: 4.0,
                udf_tau: 6.0,
                reinit_min_area: 36.0,
                ..base
            },
            Preset::Paper => LiveConfig {
                size: 256,
                iters_per_stage: 300,
                final_iters: 150,
                init_radius: 5.0,
                udf_tau: 8.0,
                reinit_min_area: 64.0,
                ..base
            },
        }
    }
}
