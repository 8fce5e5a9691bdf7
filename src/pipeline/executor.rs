//! The production executor that every entry point shares: the service's workers, `generate`,
//! `vectorize`, `eval --method` and `bench stability`. It resolves requests into plans
//! ([`DefaultExecutor::plan`]) and runs plans ([`DefaultExecutor::run_plan`]); models are
//! loaded on first use and kept per teacher size and encoder.

use super::context::{Executor, JobContext};
use super::models::Models;
use super::plan::{self, PlanRequest, RunPlan, StartKind, Tuning};
use super::text::{Start, run_text};
use super::vectorize::run_vectorize;
use super::{
    EncoderChoice, JobKind, JobSpec, Limits, ModelDirs, NotReady, PipelineError, RunOutput,
    SpecError,
};
use crate::image::Image;
use crate::scene::{MAX_PATHS, Scene};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// Loaded models per (teacher input size, SDS encoder).
type ModelCache = HashMap<((u32, u32), EncoderChoice), Arc<Models>>;

/// The inputs of a run besides its plan.
#[derive(Clone, Debug, Default)]
pub struct RunInput {
    pub caption: Option<String>,
    pub image: Option<Image>,
    pub svg: Option<Scene>,
}

/// The production executor: LIVE for vectorize plans, [`run_text`] for text plans.
#[derive(Clone, Default)]
pub struct DefaultExecutor {
    pub models: ModelDirs,
    /// Whether loading may download (the embedded model's MiniLM weights: the command line
    /// does, the service never does and refuses text jobs until `vectorfusion setup` ran).
    downloads: bool,
    cache: Arc<Mutex<ModelCache>>,
}

impl std::fmt::Debug for DefaultExecutor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DefaultExecutor")
            .field("models", &self.models)
            .finish_non_exhaustive()
    }
}

impl DefaultExecutor {
    /// The service's executor: text jobs need every model file in place.
    pub fn new(models: ModelDirs) -> Self {
        DefaultExecutor {
            models,
            downloads: false,
            cache: Arc::default(),
        }
    }

    /// The command line's: loading fetches the embedded model's MiniLM weights on first use.
    pub fn with_downloads(models: ModelDirs) -> Self {
        DefaultExecutor {
            downloads: true,
            ..DefaultExecutor::new(models)
        }
    }

    /// Whether the configured model is a small prior (its presets differ).
    pub fn small_prior(&self) -> bool {
        self.models.is_small_prior()
    }

    /// The models for a text plan (loaded once per size and encoder).
    pub fn load_models(&self, plan: &plan::TextPlan) -> Result<Arc<Models>, PipelineError> {
        if !self.downloads {
            self.models.text_ready()?;
        }
        // A plan that chose TAESD when none is configured any more fails in `Models::load`.
        let encoder = plan.model.encoder;
        let mut cache = self
            .cache
            .lock()
            .map_err(|_| PipelineError::Failed("model cache poisoned".into()))?;
        let key = (plan.sample_dims(), encoder);
        if let Some(m) = cache.get(&key) {
            return Ok(m.clone());
        }
        let m = Arc::new(Models::load(&self.models, key.0, encoder)?);
        cache.insert(key, m.clone());
        Ok(m)
    }

    /// Runs `plan` on `input`: progress, cancellation and checkpoints through `ctx`.
    pub fn run_plan(
        &self,
        plan: &RunPlan,
        input: &RunInput,
        ctx: &JobContext,
    ) -> Result<RunOutput, PipelineError> {
        ctx.check_cancelled()?;
        let key = plan.key();
        if let Some(text) = &plan.text {
            let caption = input
                .caption
                .as_deref()
                .ok_or_else(|| PipelineError::InvalidInput("caption is required".into()))?;
            let start = match (text.start, &input.image, &input.svg) {
                (StartKind::Method, _, _) => Start::Method,
                (StartKind::Image, Some(im), _) => Start::Image(im.clone()),
                (StartKind::Svg, _, Some(svg)) => Start::Svg(svg.clone()),
                (k, _, _) => {
                    return Err(PipelineError::InvalidInput(format!(
                        "the plan starts from {k:?}, and the job has no such input"
                    )));
                }
            };
            let models = self.load_models(text)?;
            let mut out = run_text(
                &models,
                text,
                &key,
                caption,
                &start,
                ctx.sink(),
                ctx.cancel_token(),
                Some(ctx),
            )?;
            out.report.preset = Some(plan.preset);
            return Ok(out);
        }
        let cfg = plan
            .vectorize
            .as_ref()
            .ok_or_else(|| PipelineError::InvalidInput("the plan has no stage to run".into()))?;
        let image = input
            .image
            .as_ref()
            .ok_or_else(|| PipelineError::InvalidInput("image is required".into()))?;
        let mut out = run_vectorize(image, cfg, &key, ctx.sink(), ctx.cancel_token(), Some(ctx))?;
        out.report.preset = Some(plan.preset);
        Ok(out)
    }
}

/// The request a stored job made (for jobs stored before plans: resolved when they run).
pub fn request_of(spec: &JobSpec) -> PlanRequest {
    PlanRequest {
        kind: spec.kind,
        caption: spec.caption.clone(),
        start: if spec.svg.is_some() {
            StartKind::Svg
        } else {
            StartKind::Method
        },
        style: spec.style,
        method: spec.method,
        preset: spec.preset,
        paths: spec.paths,
        steps: spec.steps,
        samples: spec.samples,
        seed: spec.seed,
        retrieval: spec.retrieval,
        variations: spec.variations.unwrap_or(1),
        vector: spec.vector.clone(),
        canvas: spec.canvas,
        negative_prompt: spec.negative_prompt.clone(),
        size_conditioning: spec.size_conditioning,
        tuning: Tuning::default(),
    }
}

impl Executor for DefaultExecutor {
    fn run(&self, spec: &JobSpec, ctx: &JobContext) -> Result<RunOutput, PipelineError> {
        ctx.check_cancelled()?;
        let plan = match &spec.plan {
            Some(p) => p.clone(),
            None => {
                // Validated when it was accepted; any size its limits allowed runs.
                let limits = Limits {
                    max_paths: MAX_PATHS as u32,
                    max_steps: u32::MAX,
                    max_samples: u32::MAX,
                    ..Limits::default()
                };
                self.plan(&request_of(spec), &limits)
                    .map_err(|e| PipelineError::InvalidInput(e.to_string()))?
            }
        };
        let image = match (&spec.image, spec.kind) {
            (Some(bytes), JobKind::Vectorize) => Some(Image::decode(bytes)?),
            _ => None,
        };
        let (svg, warnings) = match &spec.svg {
            Some(svg) => {
                let import = crate::svg::import_svg(svg)?;
                (Some(import.scene), import.warnings)
            }
            None => (None, Vec::new()),
        };
        let input = RunInput {
            caption: spec.caption.clone(),
            image,
            svg,
        };
        let mut out = self.run_plan(&plan, &input, ctx)?;
        out.report.import_warnings = warnings;
        Ok(out)
    }

    fn plan(&self, request: &PlanRequest, limits: &Limits) -> Result<RunPlan, SpecError> {
        let wants_text = request.kind == JobKind::Text || request.caption.is_some();
        let facts = if wants_text && self.text_ready().is_ok() {
            self.models.facts()
        } else {
            None
        };
        if let Some(f) = &facts
            && f.encoder_choice == EncoderChoice::Taesd
            && !f.taesd_found
        {
            return Err(SpecError::new(
                "encoder",
                "taesd needs a TAESD directory: pass --taesd DIR (or set models.taesd_dir), or \
                 put a taesd/ folder in or beside the model directory",
            ));
        }
        plan::resolve(request, facts.as_ref(), limits)
    }

    fn text_ready(&self) -> Result<(), NotReady> {
        if self.downloads {
            // The command line: only what loading cannot fix is an error here.
            return match (&self.models.sd_dir, &self.models.analytic_dir) {
                (None, None) => Err(NotReady::NoModelGiven),
                _ => Ok(()),
            };
        }
        self.models.text_ready()
    }
}
