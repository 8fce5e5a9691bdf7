//! The run plan: every number of a run, resolved once at the edge (HTTP submit, the command
//! line, `eval`, `bench stability`) from the request, the preset table and the model's hints,
//! checked against the limits, stored with the job and shown to the caller. Workers, stages and
//! checkpoints read the plan and nothing else, so a queued job runs the same whatever the preset
//! table says later, and the CLI and the service cannot disagree.

use super::canvas::{CanvasPlan, CanvasRequest, resolve_canvas};
use super::presets::PresetSettings;
use super::spec::{check_range, check_text};
use super::{EncoderChoice, JobKind, Limits, Method, Preset, SpecError, Style};
use crate::caption::CaptionPlan;
use crate::models::guided::SizeConditioning;
use crate::stages::live::{CANVAS_SIDES, LiveConfig, PathBudget};
use crate::stages::sds::{T_MAX, T_MIN};
use crate::vector::VectorOptions;
use crate::vector::fill::FillKind;
use crate::vector::palette::ColorPlan;
use serde::{Deserialize, Serialize};

/// Version of the plan format (stored with jobs; part of every checkpoint key).
pub const PLAN_VERSION: u32 = 1;

/// Paths below this area (px² at 512 px) are re-initialised in `sd_live_sds` and pruned at the
/// end (paper: 64 px²).
pub const MIN_AREA_512: f32 = 64.0;
/// Paths with fill opacity below this are faint (LIVE's threshold, shared by every stage).
pub use crate::stages::live::MIN_OPACITY;

/// [`MIN_AREA_512`] at a `size` px canvas.
pub fn min_area_at(size: u32) -> f32 {
    let k = size as f32 / 512.0;
    MIN_AREA_512 * k * k
}

/// Where a text run starts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StartKind {
    /// From the method: a random init (`scratch`) or the best sampled image (`sd_live*`).
    #[default]
    Method,
    /// A given image, traced with LIVE, then fine-tuned with SDS.
    Image,
    /// A given SVG, fine-tuned with SDS.
    Svg,
}

/// What a caller asks for, before the preset and the model's hints are applied. Omitted
/// numbers are the preset's.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanRequest {
    pub kind: JobKind,
    /// Text runs (and vectorize jobs fine-tuned to it).
    pub caption: Option<String>,
    pub start: StartKind,
    pub style: Style,
    pub method: Method,
    pub preset: Preset,
    pub paths: Option<u32>,
    pub steps: Option<u32>,
    pub samples: Option<u32>,
    pub seed: u64,
    pub retrieval: bool,
    /// Text runs: how many of the best distinct results to return (1..=[`MAX_VARIATIONS`]).
    pub variations: u32,
    /// Colours, background, grouping; for vectorize runs the stopping rules too.
    pub vector: VectorOptions,
    /// Text runs: the canvas asked for (nothing: the preset's square).
    pub canvas: CanvasRequest,
    /// Text runs: what classifier-free guidance steers away from.
    pub negative_prompt: Option<String>,
    /// Text runs on SDXL: the size and crop conditioning asked for (nothing: the drawn size).
    pub size_conditioning: Option<SizeConditioningRequest>,
    /// Settings only the command line exposes (none from HTTP).
    pub tuning: Tuning,
}

impl PlanRequest {
    /// A text request for `caption` with every other field at its default.
    pub fn text(caption: impl Into<String>) -> Self {
        PlanRequest {
            kind: JobKind::Text,
            caption: Some(caption.into()),
            start: StartKind::Method,
            style: Style::default(),
            method: Method::default(),
            preset: Preset::default(),
            paths: None,
            steps: None,
            samples: None,
            seed: 0,
            retrieval: true,
            variations: 1,
            vector: VectorOptions::default(),
            canvas: CanvasRequest::default(),
            negative_prompt: None,
            size_conditioning: None,
            tuning: Tuning::default(),
        }
    }
}

/// Settings of a run beyond the request's, from the command line; `None` = the plan's default.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Tuning {
    /// Teacher input side (the SVG's width).
    pub size: Option<u32>,
    /// SDS classifier-free guidance.
    pub guidance: Option<f32>,
    pub t_min: Option<usize>,
    pub t_max: Option<usize>,
    pub t_max_end: Option<usize>,
    pub grad_clip: Option<f32>,
    /// Multiplies every SDS learning rate (the style's schedule).
    pub lr_scale: Option<f32>,
    pub reinit_min_area: Option<f32>,
    /// `Some(false)`: no augmentation even where the method uses it.
    pub augment: Option<bool>,
    pub snapshot_every: Option<u32>,
    /// Vectorize runs: this LIVE configuration as it is (the `vectorize` command's options).
    pub live: Option<LiveConfig>,
}

/// The model a text plan runs on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelPlan {
    pub name: String,
    /// Presets sized for a small prior were used.
    pub small_prior: bool,
    /// SDS encoder of a latent model: `vae` or `taesd` (pixel-space models have none).
    pub encoder: EncoderChoice,
}

/// Sampling and rerank (`sd_live*`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SamplePlan {
    /// K.
    pub samples: u32,
    /// Sampler (DDIM) steps for a sample from noise.
    pub steps: u32,
    pub guidance: f32,
    /// Start some of the samples from retrieved training icons.
    pub retrieval: bool,
    /// The share of the K samples that do, rounded up ([`crate::stages::sample::retrieved_count`]);
    /// plans stored before it existed started half.
    #[serde(default = "half")]
    pub retrieval_share: f64,
    /// At most this many retrieved icons per caption (the model's `_retrieval_per_caption`);
    /// plans stored before it existed took one.
    #[serde(default = "one")]
    pub retrieval_per_caption: u32,
    /// SDEdit strength of those.
    pub strength: f64,
}

fn half() -> f64 {
    0.5
}
fn one() -> u32 {
    1
}
fn unit_scale() -> f32 {
    1.0
}

/// LIVE tracing of the kept sample (or of a given image).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TracePlan {
    /// Canvas side LIVE traces a sample at (smaller samples are upscaled to it first).
    pub size: u32,
    /// Iterations per stage and for the final pass.
    pub iters: u32,
}

/// Score distillation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SdsPlan {
    pub steps: u32,
    pub guidance: f32,
    pub t_min: usize,
    pub t_max: usize,
    pub t_max_end: Option<usize>,
    pub grad_clip: Option<f32>,
    /// Every learning rate of the style's schedule is multiplied by this; plans stored before
    /// it existed ran at 1.
    #[serde(default = "unit_scale")]
    pub lr_scale: f32,
    /// Random perspective + crop of the render (from-scratch runs).
    pub augment: bool,
    /// Closed paths below this area (px²) are re-initialised too.
    pub reinit_min_area: Option<f32>,
}

/// The seed of each stage, derived from the request's seed in one place.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Seeds {
    pub sample: u64,
    pub trace: u64,
    /// The from-scratch scene.
    pub init: u64,
    /// Shapes added to a starting scene that traced to too few.
    pub top_up: u64,
    pub sds: u64,
}

impl Seeds {
    pub fn from_seed(seed: u64) -> Self {
        Seeds {
            sample: seed,
            trace: seed,
            init: seed ^ 0x5eed_1a17,
            top_up: seed ^ 0x7095_0f11,
            sds: seed,
        }
    }
}

/// A caption → SVG run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TextPlan {
    pub method: Method,
    pub style: Style,
    pub start: StartKind,
    /// What the diffusion model is conditioned on (the caption, with the style suffix unless
    /// the model was trained on bare captions).
    pub prompt: String,
    /// Teacher input side in pixels (the shorter side of a non-square sample); without a
    /// [`TextPlan::canvas`] the SVG is written at this width.
    pub size: u32,
    /// The SVG's canvas and the sample's shape, when the request asked for a canvas; `None`:
    /// the square `size` canvas.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub canvas: Option<CanvasPlan>,
    /// What classifier-free guidance steers away from: the unconditional branch of sampling
    /// and of SDS embeds it instead of the empty prompt.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub negative_prompt: Option<String>,
    /// SDXL's size and crop conditioning of sampling and SDS, resolved for every run of a
    /// model that takes it ([`ModelFacts::size_conditioning`]); `None` for other models (and
    /// SDXL plans stored before it existed: the drawn size, no crop, the same numbers).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub size_conditioning: Option<SizeConditioning>,
    /// Paths (iconography, low-poly), strokes (sketch, painting) or cells (pixel art).
    pub paths: u32,
    /// `None`: the start needs no samples.
    pub sample: Option<SamplePlan>,
    pub trace: TracePlan,
    /// `None`: no distillation (`sd_live`).
    pub sds: Option<SdsPlan>,
    /// SVG snapshot period of the LIVE and SDS stages (steps).
    pub snapshot_every: u32,
    pub seeds: Seeds,
    pub model: ModelPlan,
    /// Fill colours, background and grouping of the trace and the finish; plans stored
    /// before it existed take the default (near-equal fills merged).
    #[serde(default)]
    pub colors: ColorPlan,
    /// What the trace and SDS paint fills with; `flat` (and plans stored before it existed)
    /// is left out of the JSON, so the plan's key is unchanged.
    #[serde(default, skip_serializing_if = "FillKind::is_flat")]
    pub fill: FillKind,
    /// How many results the run returns: the best `variations` distinct samples of the rerank
    /// (K is at least this), each traced and distilled with its own seeds
    /// ([`Seeds::variation`]); from-scratch runs start each from its own init. 1 (the plans
    /// stored before it existed) is left out of the JSON, so the plan's key is unchanged.
    #[serde(
        default = "variations::one",
        skip_serializing_if = "variations::is_one"
    )]
    pub variations: u32,
    /// The colour and objects the caption names and how far the model steers toward them;
    /// absent for a caption of one uncoloured thing (and in plans stored before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub caption: Option<CaptionPlan>,
}

/// The fully numeric plan of a run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunPlan {
    pub version: u32,
    pub kind: JobKind,
    /// The preset the omitted numbers came from (the numbers below are what runs).
    pub preset: Preset,
    pub seed: u64,
    /// Set for text runs, including vectorize jobs fine-tuned to a caption.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub text: Option<TextPlan>,
    /// Set for plain vectorize runs: LIVE's configuration.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vectorize: Option<LiveConfig>,
}

impl RunPlan {
    /// The most paths the run makes: a text run's paths, a vectorize run's LIVE budget.
    pub fn paths(&self) -> Option<u32> {
        match (&self.text, &self.vectorize) {
            (Some(t), _) => Some(t.paths),
            (None, Some(v)) => Some(u32::try_from(v.budget.max_paths()).unwrap_or(u32::MAX)),
            (None, None) => None,
        }
    }

    /// SDS steps of a text run that distils.
    pub fn sds_steps(&self) -> Option<u32> {
        Some(self.text.as_ref()?.sds.as_ref()?.steps)
    }

    /// K, the samples of a text run that samples.
    pub fn samples(&self) -> Option<u32> {
        Some(self.text.as_ref()?.sample.as_ref()?.samples)
    }

    /// How many results the run returns (1 but for text runs asked for more).
    pub fn variations(&self) -> u32 {
        self.text.as_ref().map_or(1, |t| t.variations)
    }

    /// Identifies the run for its checkpoints: a state saved under another plan is ignored.
    pub fn key(&self) -> String {
        format!(
            "plan-v{}|{}",
            self.version,
            serde_json::to_string(self).unwrap_or_default()
        )
    }
}

/// Largest SDS learning-rate multiplier a plan accepts.
pub const MAX_LR_SCALE: f32 = 100.0;

/// Resolves `req`: the preset's numbers for everything it omits (sized for `model`, whose
/// hints also give the prompt form and the guidance), checked against `limits`. `model` is
/// `None` when no text model is configured: text requests are then refused, and a vectorize
/// request with a caption is only traced.
pub fn resolve(
    req: &PlanRequest,
    model: Option<&ModelFacts>,
    limits: &Limits,
) -> Result<RunPlan, SpecError> {
    let base = RunPlan {
        version: PLAN_VERSION,
        kind: req.kind,
        preset: req.preset,
        seed: req.seed,
        text: None,
        vectorize: None,
    };
    let text_model = match (req.kind, &req.caption, model) {
        (JobKind::Text, _, None) => {
            return Err(SpecError::new(
                "kind",
                "text jobs need a diffusion model, and none is configured",
            ));
        }
        (_, Some(_), Some(m)) => Some(m),
        _ => None,
    };
    let Some(model) = text_model else {
        return Ok(RunPlan {
            vectorize: Some(vectorize_plan(req, limits)?),
            ..base
        });
    };
    Ok(RunPlan {
        text: Some(text_plan(req, model, limits)?),
        ..base
    })
}

fn vectorize_plan(req: &PlanRequest, limits: &Limits) -> Result<LiveConfig, SpecError> {
    req.vector
        .validate()
        .map_err(|(field, reason)| SpecError::new(field, reason))?;
    check_fill_style(req.vector.fill, req.style)?;
    check_variations(req, None, limits)?;
    if let Some(cfg) = &req.tuning.live {
        cfg.validate()
            .map_err(|e| SpecError::new("paths", e.to_string()))?;
        return Ok(cfg.clone());
    }
    let paths = check_range(
        "paths",
        req.paths
            .unwrap_or(u32::try_from(req.preset.vectorize_paths()).unwrap_or(u32::MAX)),
        limits.max_paths,
    )? as usize;
    Ok(LiveConfig {
        // The preset's LIVE settings, with a budget that stops adding paths once they stop
        // paying off.
        budget: PathBudget::auto_up_to(paths),
        seed: req.seed,
        colors: req.vector.colors.clone(),
        fill: req.vector.fill,
        target_psnr: req.vector.target_psnr,
        max_bytes: req.vector.max_bytes,
        ..req.preset.live_config()
    })
}

/// The counts a text run resolves from the request and the preset.
struct TextNumbers {
    size: u32,
    paths: u32,
    steps: u32,
    samples: u32,
}

/// `req`'s size, paths, steps and samples, the preset's `ps` where it omits them, within
/// `limits`.
fn text_numbers(
    req: &PlanRequest,
    ps: &PresetSettings,
    limits: &Limits,
) -> Result<TextNumbers, SpecError> {
    let size = req.tuning.size.unwrap_or(ps.size);
    if !CANVAS_SIDES.contains(&size) {
        return Err(SpecError::new(
            "size",
            format!(
                "must be between {} and {}, got {size}",
                CANVAS_SIDES.start(),
                CANVAS_SIDES.end()
            ),
        ));
    }
    // A vectorize job fine-tuned to its caption keeps a vectorize job's path budget.
    let preset_paths = match req.kind {
        JobKind::Vectorize => req.preset.vectorize_paths(),
        JobKind::Text => req.style.spec().preset_paths(ps.paths),
    };
    let preset_paths = u32::try_from(preset_paths).unwrap_or(u32::MAX);
    Ok(TextNumbers {
        size,
        paths: check_range("paths", req.paths.unwrap_or(preset_paths), limits.max_paths)?,
        steps: check_range("steps", req.steps.unwrap_or(ps.steps), limits.max_steps)?,
        samples: check_range(
            "samples",
            req.samples.unwrap_or(ps.samples),
            limits.max_samples,
        )?,
    })
}

/// The score distillation of a text run that distils (`augment`: from-scratch runs), checked.
fn sds_plan(
    req: &PlanRequest,
    model: &ModelFacts,
    n: &TextNumbers,
    augment: bool,
) -> Result<SdsPlan, SpecError> {
    let t = &req.tuning;
    let s = SdsPlan {
        steps: n.steps,
        guidance: t.guidance.unwrap_or(model.hints.sds_guidance),
        t_min: t.t_min.unwrap_or(T_MIN),
        t_max: t.t_max.unwrap_or(T_MAX),
        t_max_end: t.t_max_end,
        grad_clip: t.grad_clip,
        lr_scale: t.lr_scale.unwrap_or(1.0),
        augment,
        reinit_min_area: if augment {
            t.reinit_min_area
        } else {
            Some(t.reinit_min_area.unwrap_or(min_area_at(n.size)))
        },
    };
    if s.t_min > s.t_max || s.t_max_end.is_some_and(|e| e < s.t_min) {
        return Err(SpecError::new(
            "t_min",
            format!(
                "the timestep range [{}, {}] must be ordered",
                s.t_min, s.t_max
            ),
        ));
    }
    if !s.guidance.is_finite() || s.grad_clip.is_some_and(|c| c.is_nan() || c <= 0.0) {
        return Err(SpecError::new(
            "guidance",
            "guidance must be finite and grad_clip positive",
        ));
    }
    if !(s.lr_scale > 0.0 && s.lr_scale <= MAX_LR_SCALE) {
        return Err(SpecError::new(
            "lr_scale",
            format!(
                "must be above 0 and at most {MAX_LR_SCALE}, got {}",
                s.lr_scale
            ),
        ));
    }
    Ok(s)
}

fn text_plan(
    req: &PlanRequest,
    model: &ModelFacts,
    limits: &Limits,
) -> Result<TextPlan, SpecError> {
    let caption = req
        .caption
        .as_deref()
        .ok_or_else(|| SpecError::new("caption", "is required for a text run"))?;
    let ps: PresetSettings = req
        .preset
        .settings_for_model(model.hints.small_prior, model.few_step);
    req.vector
        .validate()
        .map_err(|(field, reason)| SpecError::new(field, reason))?;
    check_fill_style(req.vector.fill, req.style)?;
    let n = text_numbers(req, &ps, limits)?;
    let start = match req.kind {
        JobKind::Vectorize => StartKind::Image,
        JobKind::Text => req.start,
    };
    let from_method = start == StartKind::Method;
    let samples = from_method && req.method != Method::Scratch;
    let variations = check_variations(req, samples.then_some(n.samples), limits)?;
    let sample = samples.then_some(SamplePlan {
        // K: enough samples for the variations' distinct picks.
        samples: n.samples.max(variations),
        steps: ps.sample_steps as u32,
        guidance: model.hints.sample_guidance,
        retrieval: req.retrieval,
        retrieval_share: model.hints.retrieval_share,
        retrieval_per_caption: model.hints.retrieval_per_caption,
        strength: model.hints.sdedit_strength,
    });
    let canvas = req
        .canvas
        .check(limits.max_canvas_side)?
        .map(|c| resolve_canvas(c, n.size, sample_shape(req, model)));
    let distil = !from_method || req.method != Method::SdLive;
    let augment = from_method && req.method == Method::Scratch && req.tuning.augment != Some(false);
    let sds = distil
        .then(|| sds_plan(req, model, &n, augment))
        .transpose()?;
    let mut plan = TextPlan {
        method: req.method,
        style: req.style,
        start,
        prompt: req.style.prompt_with(caption, model.hints.style_suffix),
        size: n.size,
        canvas,
        negative_prompt: negative_prompt(req, model, limits)?,
        size_conditioning: None,
        paths: n.paths,
        // Only a run that samples is steered toward the caption's colour and objects.
        caption: sample
            .as_ref()
            .and_then(|_| crate::caption::parse(caption, model.hints.colour_steer)),
        sample,
        trace: TracePlan {
            size: if from_method { ps.trace_size } else { n.size },
            iters: ps.live_iters,
        },
        sds,
        snapshot_every: req.tuning.snapshot_every.unwrap_or(ps.snapshot_every),
        seeds: Seeds::from_seed(req.seed),
        model: ModelPlan {
            name: model.name.clone(),
            small_prior: model.hints.small_prior,
            encoder: model.encoder(ps.prefer_taesd),
        },
        colors: req.vector.colors.clone(),
        fill: req.vector.fill,
        variations,
    };
    plan.size_conditioning = size_conditioning(req, model, plan.sample_dims())?;
    Ok(plan)
}

mod text_plan;
pub use text_plan::SizeConditioningRequest;
use text_plan::{check_fill_style, negative_prompt, sample_shape, size_conditioning};

mod facts;
mod variations;
pub use facts::{ModelFacts, few_step};
pub use variations::MAX_VARIATIONS;
use variations::check_variations;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_fill;
#[cfg(test)]
mod tests_size;
