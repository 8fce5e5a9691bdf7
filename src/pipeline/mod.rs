//! The job-execution seam: what the service's workers call to turn a validated [`JobSpec`] into
//! an SVG. The worker owns queueing, leases, storage and events; an [`Executor`] owns the
//! computation and talks back only through its [`JobContext`] (progress, cancellation,
//! checkpoints).
//!
//! [`DefaultExecutor`] is the production executor. Its `text` and `vectorize` entry points are
//! where the pipeline stages are wired in; until they land they return
//! [`PipelineError::NotImplemented`].

pub mod methods;

use crate::models::ComputeDevice;
use crate::progress::{CancelToken, NullSink, Progress, ProgressSink};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::Mutex;

/// What a job produces: caption → SVG, or image → SVG.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JobKind {
    Text,
    Vectorize,
}

impl JobKind {
    pub const ALL: &[JobKind] = &[JobKind::Text, JobKind::Vectorize];
}

/// Visual style of the output.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Style {
    #[default]
    Iconography,
    PixelArt,
    Sketch,
}

impl Style {
    pub const ALL: &[Style] = &[Style::Iconography, Style::PixelArt, Style::Sketch];
}

/// How a text job is produced (VectorFusion §4): sample+trace, sample+trace+SDS, or SDS alone.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    Scratch,
    SdLive,
    #[default]
    SdLiveSds,
}

impl Method {
    pub const ALL: &[Method] = &[Method::Scratch, Method::SdLive, Method::SdLiveSds];

    /// The method's name as in the API and on the command line (`sd_live_sds`).
    pub fn as_str(self) -> &'static str {
        match self {
            Method::Scratch => "scratch",
            Method::SdLive => "sd_live",
            Method::SdLiveSds => "sd_live_sds",
        }
    }
}

/// Named speed/quality trade-offs (resolution, steps, paths, samples, encoder; see
/// [`Preset::settings`]). `default` and `quality` are accepted as older names of `balanced` and
/// `paper`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Preset {
    Draft,
    Fast,
    #[default]
    #[serde(alias = "default")]
    Balanced,
    #[serde(alias = "quality")]
    Paper,
}

impl Preset {
    pub const ALL: &[Preset] = &[Preset::Draft, Preset::Fast, Preset::Balanced, Preset::Paper];
}

/// Hard limits on a job's parameters (set from the service configuration).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Limits {
    pub max_paths: u32,
    pub max_steps: u32,
    pub max_samples: u32,
    pub max_caption_chars: usize,
    pub max_svg_bytes: usize,
    pub max_image_side: u32,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_paths: 1024,
            max_steps: 20_000,
            max_samples: 64,
            max_caption_chars: 1000,
            max_svg_bytes: 2 * 1024 * 1024,
            max_image_side: 4096,
        }
    }
}

/// A validated job. Construct through the service's request validation (or fill it in directly
/// in code and call [`JobSpec::validate`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JobSpec {
    pub kind: JobKind,
    pub caption: Option<String>,
    /// PNG or JPEG bytes (base64 in JSON).
    #[serde(default, with = "base64_bytes")]
    pub image: Option<Vec<u8>>,
    /// An SVG to start from.
    pub svg: Option<String>,
    pub style: Style,
    pub method: Method,
    pub paths: u32,
    pub steps: u32,
    pub seed: u64,
    pub samples: u32,
    pub preset: Preset,
    pub priority: i32,
    /// Text jobs: start some samples from the training icons nearest to the caption
    /// (retrieval, when the model has an installed index); false samples from noise only.
    #[serde(default = "default_retrieval")]
    pub retrieval: bool,
}

fn default_retrieval() -> bool {
    true
}

/// Why a [`JobSpec`] is invalid: which field, and why.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{field}: {reason}")]
pub struct SpecError {
    pub field: &'static str,
    pub reason: String,
}

impl SpecError {
    pub fn new(field: &'static str, reason: impl Into<String>) -> Self {
        SpecError {
            field,
            reason: reason.into(),
        }
    }
}

/// Allowed priority range (higher runs first).
pub const PRIORITY_RANGE: std::ops::RangeInclusive<i32> = -100..=100;

impl JobSpec {
    /// Checks every field against `limits` and the kind's requirements.
    pub fn validate(&self, limits: &Limits) -> Result<(), SpecError> {
        fn range(field: &'static str, v: u32, max: u32) -> Result<(), SpecError> {
            if v == 0 || v > max {
                return Err(SpecError::new(
                    field,
                    format!("must be between 1 and {max}, got {v}"),
                ));
            }
            Ok(())
        }
        range("paths", self.paths, limits.max_paths)?;
        range("steps", self.steps, limits.max_steps)?;
        range("samples", self.samples, limits.max_samples)?;
        if !PRIORITY_RANGE.contains(&self.priority) {
            return Err(SpecError::new(
                "priority",
                format!(
                    "must be between {} and {}, got {}",
                    PRIORITY_RANGE.start(),
                    PRIORITY_RANGE.end(),
                    self.priority
                ),
            ));
        }
        if let Some(c) = &self.caption {
            let n = c.chars().count();
            if c.trim().is_empty() {
                return Err(SpecError::new("caption", "must not be empty"));
            }
            if n > limits.max_caption_chars {
                return Err(SpecError::new(
                    "caption",
                    format!(
                        "is {n} characters, at most {} allowed",
                        limits.max_caption_chars
                    ),
                ));
            }
            if c.chars()
                .any(|ch| ch.is_control() && ch != '\n' && ch != '\t')
            {
                return Err(SpecError::new("caption", "contains control characters"));
            }
        }
        if let Some(svg) = &self.svg
            && svg.len() > limits.max_svg_bytes
        {
            return Err(SpecError::new(
                "svg",
                format!(
                    "is {} bytes, at most {} allowed",
                    svg.len(),
                    limits.max_svg_bytes
                ),
            ));
        }
        match self.kind {
            JobKind::Text => {
                if self.caption.is_none() {
                    return Err(SpecError::new("caption", "is required for kind \"text\""));
                }
                if self.image.is_some() {
                    return Err(SpecError::new(
                        "image",
                        "only applies to kind \"vectorize\" (use \"svg\" to start a text job from a drawing)",
                    ));
                }
            }
            JobKind::Vectorize => {
                if self.image.is_none() {
                    return Err(SpecError::new(
                        "image",
                        "is required for kind \"vectorize\" (base64 PNG or JPEG)",
                    ));
                }
            }
        }
        Ok(())
    }
}

/// Errors from running a job.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error("not implemented yet: {0}")]
    NotImplemented(&'static str),
    #[error("invalid input: {0}")]
    InvalidInput(String),
    #[error("models are not configured: {0}")]
    ModelsNotConfigured(String),
    #[error("cancelled")]
    Cancelled,
    /// A failure worth retrying (resource exhaustion, I/O hiccup).
    #[error("transient failure: {0}")]
    Transient(String),
    #[error("{0}")]
    Failed(String),
}

impl PipelineError {
    /// Stable machine-readable code stored with failed jobs.
    pub fn code(&self) -> &'static str {
        match self {
            PipelineError::NotImplemented(_) => "not_implemented",
            PipelineError::InvalidInput(_) => "invalid_input",
            PipelineError::ModelsNotConfigured(_) => "models_not_configured",
            PipelineError::Cancelled => "cancelled",
            PipelineError::Transient(_) => "transient",
            PipelineError::Failed(_) => "failed",
        }
    }

    /// Whether the worker should retry the job (with backoff).
    pub fn is_retryable(&self) -> bool {
        matches!(self, PipelineError::Transient(_))
    }
}

/// The result of a job.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JobOutput {
    pub svg: String,
    pub paths: usize,
    /// Stage-specific details (scores, timings, resume information).
    pub detail: serde_json::Value,
}

type Checkpointer = dyn Fn(serde_json::Value) -> Result<(), String> + Send + Sync;

/// What an executor gets besides the spec: where to report, when to stop, how to checkpoint.
pub struct JobContext {
    progress: Arc<dyn ProgressSink>,
    cancel: CancelToken,
    checkpoint_every: u32,
    checkpointer: Box<Checkpointer>,
    resume: Option<serde_json::Value>,
}

impl JobContext {
    /// A context that reports to `progress`, stops on `cancel`, saves checkpoints through
    /// `checkpointer` (advised every `checkpoint_every` steps) and resumes from `resume`.
    pub fn new(
        progress: Arc<dyn ProgressSink>,
        cancel: CancelToken,
        checkpoint_every: u32,
        checkpointer: Box<Checkpointer>,
        resume: Option<serde_json::Value>,
    ) -> Self {
        JobContext {
            progress,
            cancel,
            checkpoint_every: checkpoint_every.max(1),
            checkpointer,
            resume,
        }
    }

    /// A context for running outside the service: no progress, no checkpoints.
    pub fn detached(cancel: CancelToken) -> Self {
        JobContext::new(
            Arc::new(NullSink),
            cancel,
            u32::MAX,
            Box::new(|_| Ok(())),
            None,
        )
    }

    pub fn report(&self, event: Progress) {
        self.progress.report(event);
    }

    pub fn sink(&self) -> &dyn ProgressSink {
        self.progress.as_ref()
    }

    pub fn cancel_token(&self) -> &CancelToken {
        &self.cancel
    }

    pub fn is_cancelled(&self) -> bool {
        self.cancel.is_cancelled()
    }

    /// `Err(Cancelled)` once cancellation was requested; call between steps. Executors that
    /// checkpoint should save one when they see the cancellation, before returning
    /// [`PipelineError::Cancelled`]: on shutdown the job resumes from it.
    pub fn check_cancelled(&self) -> Result<(), PipelineError> {
        if self.is_cancelled() {
            Err(PipelineError::Cancelled)
        } else {
            Ok(())
        }
    }

    /// Whether `step` (1-based) is one at which a checkpoint is due.
    pub fn checkpoint_due(&self, step: u32) -> bool {
        step > 0 && step % self.checkpoint_every == 0
    }

    /// Saves resumable state (current SVG, step, optimiser state). A failure to save is
    /// reported as [`PipelineError::Transient`].
    pub fn checkpoint(&self, state: serde_json::Value) -> Result<(), PipelineError> {
        (self.checkpointer)(state).map_err(PipelineError::Transient)
    }

    /// State from the last checkpoint of an earlier, interrupted attempt.
    pub fn resume_state(&self) -> Option<serde_json::Value> {
        self.resume.clone()
    }
}

/// Runs jobs. Called on a dedicated worker thread, never on the async runtime.
pub trait Executor: Send + Sync {
    fn run(&self, spec: &JobSpec, ctx: &JobContext) -> Result<JobOutput, PipelineError>;

    /// `Ok` when `text` jobs can run (models configured and loadable); otherwise a message
    /// telling the operator how to configure them. Text jobs are refused at submit time while
    /// this is an error.
    fn text_ready(&self) -> Result<(), String>;

    /// Whether text jobs run on a small prior, whose presets differ
    /// ([`methods::PresetSettings`]); the service resolves omitted fields with it.
    fn small_prior(&self) -> bool {
        false
    }
}

/// Which encoder turns renders into latents for SDS with a latent (Stable Diffusion) model.
/// Pixel-space models have no encoder to choose and ignore it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EncoderChoice {
    /// TAESD when a TAESD directory is configured or found beside the model and the preset
    /// prefers it (every preset but `paper`), else the VAE.
    #[default]
    Auto,
    /// The model's VAE encoder (exact, slow on a CPU).
    Vae,
    /// TAESD (`madebyollin/taesd` layout): ~10× cheaper, approximate; needs its directory.
    Taesd,
}

impl std::str::FromStr for EncoderChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "auto" => Ok(EncoderChoice::Auto),
            "vae" => Ok(EncoderChoice::Vae),
            "taesd" => Ok(EncoderChoice::Taesd),
            other => Err(format!(
                "unknown encoder {other:?} (expected vae, taesd or auto)"
            )),
        }
    }
}

/// A TAESD directory (`config.json` + weights) for `model`: `configured` if given, else a
/// `taesd/` folder inside the model directory, else a `taesd/` folder beside it.
pub fn find_taesd(model: &Path, configured: Option<&Path>) -> Option<PathBuf> {
    if let Some(c) = configured {
        return Some(c.to_path_buf());
    }
    let inside = model.join("taesd");
    let beside = model.parent().map(|p| p.join("taesd"));
    [Some(inside), beside]
        .into_iter()
        .flatten()
        .find(|d| d.join("config.json").is_file())
}

/// The TAESD directory to use as the SDS encoder of `model` (`None` = the VAE), or why the
/// choice cannot be honoured. Pixel-space models never use one.
pub fn resolve_encoder(
    choice: EncoderChoice,
    prefer_taesd: bool,
    model: &Path,
    configured: Option<&Path>,
) -> Result<Option<PathBuf>, PipelineError> {
    if is_pixel_model(model) {
        return Ok(None);
    }
    match choice {
        EncoderChoice::Vae => Ok(None),
        EncoderChoice::Auto if !prefer_taesd => Ok(None),
        EncoderChoice::Auto => Ok(find_taesd(model, configured)),
        EncoderChoice::Taesd => find_taesd(model, configured).map(Some).ok_or_else(|| {
            PipelineError::InvalidInput(format!(
                "encoder taesd needs a TAESD directory: pass --taesd DIR (or set models.taesd_dir), \
                 or put one at {}/taesd",
                model.display()
            ))
        }),
    }
}

/// Environment variable naming the default (embedded) model directory.
pub const DEFAULT_MODEL_ENV: &str = "VF_DEFAULT_MODEL";
/// The embedded model, relative to the working directory or the crate root.
pub const EMBEDDED_MODEL: &str = "models/vf-icon";

/// Whether `dir` looks like a diffusers model directory (has `unet/config.json`).
pub fn is_model_dir(dir: &Path) -> bool {
    dir.join("unet").join("config.json").is_file()
}

/// Whether `dir` is a pixel-space model directory (a model directory without `vae/`; see
/// [`crate::models::codec::is_pixel_space`]).
pub fn is_pixel_model(dir: &Path) -> bool {
    is_model_dir(dir) && crate::models::codec::is_pixel_space(dir).unwrap_or(false)
}

/// Whether `dir` is a small prior (a pixel-space model, or one whose `model_index.json` says
/// `"_small_prior": true`, as the embedded latent `vf-icon` does): its presets are
/// [`Preset::settings_for`]`(true)`, not Stable Diffusion's.
pub fn is_small_model(dir: &Path) -> bool {
    is_pixel_model(dir)
        || (is_model_dir(dir) && crate::models::ModelHints::read(dir).is_ok_and(|h| h.small_prior))
}

/// The default model directory: `env_value` (from [`DEFAULT_MODEL_ENV`]) when set — an error if
/// it is not a model directory — else [`EMBEDDED_MODEL`] under `cwd`, then under `crate_root`.
/// `Ok(None)` when none is present.
pub fn resolve_default_model(
    env_value: Option<&std::ffi::OsStr>,
    cwd: Option<&Path>,
    crate_root: &Path,
) -> Result<Option<PathBuf>, String> {
    if let Some(v) = env_value.filter(|v| !v.is_empty()) {
        let dir = PathBuf::from(v);
        return if is_model_dir(&dir) {
            Ok(Some(dir))
        } else {
            Err(format!(
                "{DEFAULT_MODEL_ENV}={} is not a model directory (no unet/config.json)",
                dir.display()
            ))
        };
    }
    Ok([
        cwd.map(|c| c.join(EMBEDDED_MODEL)),
        Some(crate_root.join(EMBEDDED_MODEL)),
    ]
    .into_iter()
    .flatten()
    .find(|d| is_model_dir(d)))
}

/// [`resolve_default_model`] for this process (environment, current directory, this crate's
/// source tree).
pub fn default_model_dir() -> Result<Option<PathBuf>, String> {
    resolve_default_model(
        std::env::var_os(DEFAULT_MODEL_ENV).as_deref(),
        std::env::current_dir().ok().as_deref(),
        Path::new(env!("CARGO_MANIFEST_DIR")),
    )
}

/// Model locations (diffusers-layout directories).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ModelDirs {
    pub sd_dir: Option<PathBuf>,
    /// CLIP scorer for reranking samples (optional: without it the first sample is kept).
    pub clip_dir: Option<PathBuf>,
    /// TAESD encoder (optional; used for SDS per `encoder`).
    #[serde(default)]
    pub taesd_dir: Option<PathBuf>,
    /// SDS encoder of latent models (`auto`: TAESD when available and the preset prefers it).
    #[serde(default)]
    pub encoder: EncoderChoice,
    /// Where the diffusion model runs (`cpu`, or `cuda:N` in builds with the `cuda` feature).
    #[serde(default)]
    pub device: ComputeDevice,
    /// Testing only: a directory of PNG targets for the analytic TEST teacher, used when no
    /// `sd_dir` is set.
    #[serde(default)]
    pub analytic_dir: Option<PathBuf>,
}

impl ModelDirs {
    /// With no model configured (neither `sd_dir` nor `analytic_dir`), `default` (the embedded
    /// model, see [`default_model_dir`]) becomes `sd_dir` and its `scorer/` folder, when present
    /// and no `clip_dir` is set, the scorer.
    pub fn or_default_model(mut self, default: Option<PathBuf>) -> Self {
        if self.sd_dir.is_some() || self.analytic_dir.is_some() {
            return self;
        }
        if let Some(dir) = default {
            let scorer = dir.join("scorer");
            if self.clip_dir.is_none() && scorer.join("config.json").is_file() {
                self.clip_dir = Some(scorer);
            }
            self.sd_dir = Some(dir);
        }
        self
    }

    /// Whether the configured model is a small prior (presets differ: [`is_small_model`]).
    pub fn is_small_prior(&self) -> bool {
        self.sd_dir.as_deref().is_some_and(is_small_model)
    }
}

/// Loaded models per (teacher input size, TAESD directory used as the encoder).
type ModelCache = HashMap<(u32, Option<PathBuf>), Arc<methods::Models>>;

/// The production executor: LIVE for vectorize jobs, the methods of [`methods`] for text jobs.
/// Models are loaded on first use and kept per teacher input size.
#[derive(Clone, Default)]
pub struct DefaultExecutor {
    pub models: ModelDirs,
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
    pub fn new(models: ModelDirs) -> Self {
        DefaultExecutor {
            models,
            cache: Arc::default(),
        }
    }

    /// The settings of `preset` for the configured model (small priors have their own).
    pub fn settings(&self, preset: Preset) -> methods::PresetSettings {
        preset.settings_for(self.models.is_small_prior())
    }

    /// The models for `size` px teacher inputs with the VAE (loaded once).
    pub fn load_models(&self, size: u32) -> Result<Arc<methods::Models>, PipelineError> {
        self.load_models_for(size, false)
    }

    /// The models for `size` px teacher inputs; `prefer_taesd` (the preset's) lets
    /// [`EncoderChoice::Auto`] pick TAESD. Loaded once per size and encoder.
    pub fn load_models_for(
        &self,
        size: u32,
        prefer_taesd: bool,
    ) -> Result<Arc<methods::Models>, PipelineError> {
        self.text_ready()
            .map_err(PipelineError::ModelsNotConfigured)?;
        let taesd = match &self.models.sd_dir {
            Some(sd) => resolve_encoder(
                self.models.encoder,
                prefer_taesd,
                sd,
                self.models.taesd_dir.as_deref(),
            )?,
            None => None,
        };
        let mut cache = self
            .cache
            .lock()
            .map_err(|_| PipelineError::Failed("model cache poisoned".into()))?;
        let key = (size, taesd.clone());
        if let Some(m) = cache.get(&key) {
            return Ok(m.clone());
        }
        let scorer = self.models.clip_dir.as_deref();
        let m = match (&self.models.sd_dir, &self.models.analytic_dir) {
            (Some(sd), _) => methods::Models::load_sd_with(
                sd,
                scorer,
                size,
                taesd.as_deref(),
                self.models.device,
            )?,
            (None, Some(dir)) => methods::Models::load_analytic(dir, scorer, size)?,
            (None, None) => {
                return Err(PipelineError::ModelsNotConfigured("no sd_dir".into()));
            }
        };
        let m = Arc::new(m);
        cache.insert(key, m.clone());
        Ok(m)
    }

    fn run_text(
        &self,
        spec: &JobSpec,
        start: methods::Start,
        ctx: &JobContext,
    ) -> Result<JobOutput, PipelineError> {
        let caption = spec
            .caption
            .clone()
            .ok_or_else(|| PipelineError::InvalidInput("caption is required".into()))?;
        let ps = self.settings(spec.preset);
        let models = self.load_models_for(ps.size, ps.prefer_taesd)?;
        let req = methods::TextRequest {
            caption,
            style: methods::stage_style(spec.style),
            method: spec.method,
            preset: spec.preset,
            paths: Some(spec.paths as usize),
            steps: Some(spec.steps),
            samples: Some(spec.samples),
            seed: spec.seed,
            guidance: None,
            retrieval: spec.retrieval,
            start,
        };
        let out =
            methods::run_text_resumable(&models, &req, ctx.sink(), ctx.cancel_token(), Some(ctx))?;
        Ok(JobOutput {
            svg: out.svg,
            paths: out.paths,
            detail: out.detail,
        })
    }

    /// Image → SVG by LIVE tracing; with a caption and text models configured, the trace is then
    /// fine-tuned to the caption with SDS.
    fn vectorize(&self, spec: &JobSpec, ctx: &JobContext) -> Result<JobOutput, PipelineError> {
        let bytes = spec
            .image
            .as_deref()
            .ok_or_else(|| PipelineError::InvalidInput("image is required".into()))?;
        let image = crate::image::Image::decode(bytes)
            .map_err(|e| PipelineError::InvalidInput(format!("image: {e}")))?;
        if spec.caption.is_some() && self.text_ready().is_ok() {
            return self.run_text(spec, methods::Start::Image(image), ctx);
        }
        let out = methods::run_vectorize(
            &image,
            spec.preset,
            spec.paths as usize,
            spec.seed,
            ctx.sink(),
            ctx.cancel_token(),
            Some(ctx),
        )?;
        Ok(JobOutput {
            svg: out.svg,
            paths: out.paths,
            detail: out.detail,
        })
    }

    /// Caption → SVG (sampling, tracing, score distillation), or SDS fine-tuning of `svg`.
    fn text(&self, spec: &JobSpec, ctx: &JobContext) -> Result<JobOutput, PipelineError> {
        let start = match &spec.svg {
            Some(svg) => methods::Start::Svg(
                crate::svg::from_svg(svg)
                    .map_err(|e| PipelineError::InvalidInput(format!("svg: {e}")))?,
            ),
            None => methods::Start::Method,
        };
        self.run_text(spec, start, ctx)
    }
}

impl Executor for DefaultExecutor {
    fn run(&self, spec: &JobSpec, ctx: &JobContext) -> Result<JobOutput, PipelineError> {
        ctx.check_cancelled()?;
        match spec.kind {
            JobKind::Text => self.text(spec, ctx),
            JobKind::Vectorize => self.vectorize(spec, ctx),
        }
    }

    fn small_prior(&self) -> bool {
        self.models.is_small_prior()
    }

    fn text_ready(&self) -> Result<(), String> {
        if self.models.sd_dir.is_none()
            && let Some(dir) = &self.models.analytic_dir
        {
            return if dir.is_dir() {
                Ok(())
            } else {
                Err(format!(
                    "the analytic test teacher directory {} does not exist",
                    dir.display()
                ))
            };
        }
        let Some(dir) = &self.models.sd_dir else {
            return Err(format!(
                "text-to-SVG needs a diffusion model: the embedded {EMBEDDED_MODEL} was not found \
                 (set {DEFAULT_MODEL_ENV} to its directory), or set `sd_dir` in the [models] \
                 section of config.toml (or the VECTORFUSION_MODELS_SD_DIR environment variable) \
                 to a diffusers-layout model directory, then restart the server"
            ));
        };
        if !dir.join("unet").join("config.json").is_file() {
            return Err(format!(
                "the configured Stable Diffusion directory {} does not exist or is not a \
                 diffusers layout (no unet/config.json): fix `sd_dir` in the [models] section of \
                 config.toml (or VECTORFUSION_MODELS_SD_DIR)",
                dir.display()
            ));
        }
        let te = dir.join("text_encoder");
        // The embedded model's MiniLM weights are not committed: they resolve from
        // VF_MINILM_DIR or the cache (`vectorfusion setup`), or download on first use.
        let locations = crate::models::bert::weights::MiniLmLocations::from_env();
        if te.is_dir()
            && !crate::models::bert::weights::text_encoder_weights_available(&te, &locations)
        {
            return Err(format!(
                "the model {} has no text encoder weights ({} holds none; for the embedded \
                 model run `vectorfusion setup` or set VF_MINILM_DIR: see docs/EMBEDDED.md, \
                 \"MiniLM weights\")",
                dir.display(),
                te.display()
            ));
        }
        if let Some(c) = &self.models.clip_dir
            && !c.is_dir()
        {
            return Err(format!(
                "the configured CLIP scorer directory {} does not exist: fix `clip_dir` in the \
                 [models] section of config.toml",
                c.display()
            ));
        }
        Ok(())
    }
}

mod base64_bytes {
    use base64::Engine;
    use base64::engine::general_purpose::STANDARD;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &Option<Vec<u8>>, s: S) -> Result<S::Ok, S::Error> {
        match v {
            Some(bytes) => s.serialize_some(&STANDARD.encode(bytes)),
            None => s.serialize_none(),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Vec<u8>>, D::Error> {
        let v: Option<String> = Option::deserialize(d)?;
        v.map(|s| STANDARD.decode(s).map_err(serde::de::Error::custom))
            .transpose()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> JobSpec {
        JobSpec {
            kind: JobKind::Vectorize,
            caption: None,
            image: Some(vec![1, 2, 3]),
            svg: None,
            style: Style::Iconography,
            method: Method::SdLiveSds,
            paths: 16,
            steps: 100,
            seed: u64::MAX,
            samples: 4,
            preset: Preset::Balanced,
            priority: 0,
            retrieval: true,
        }
    }

    #[test]
    fn spec_roundtrips_through_json_with_base64_image() {
        let s = spec();
        let json = serde_json::to_string(&s).unwrap();
        assert!(json.contains("\"image\":\"AQID\""));
        let back: JobSpec = serde_json::from_str(&json).unwrap();
        assert_eq!(back, s);
    }

    #[test]
    fn validation_names_the_field() {
        let l = Limits::default();
        assert!(spec().validate(&l).is_ok());
        let mut s = spec();
        s.paths = 0;
        assert_eq!(s.validate(&l).unwrap_err().field, "paths");
        let mut s = spec();
        s.image = None;
        assert_eq!(s.validate(&l).unwrap_err().field, "image");
        let mut s = spec();
        s.kind = JobKind::Text;
        s.image = None;
        assert_eq!(s.validate(&l).unwrap_err().field, "caption");
        s.caption = Some("自転車".into());
        assert!(s.validate(&l).is_ok());
        s.priority = 1000;
        assert_eq!(s.validate(&l).unwrap_err().field, "priority");
    }

    /// A fresh temp directory for one test.
    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("vf-pipeline-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// A stand-in model directory (only what the resolution looks at).
    fn fake_model(dir: &Path, pixel: bool, scorer: bool) {
        std::fs::create_dir_all(dir.join("unet")).unwrap();
        std::fs::write(dir.join("unet/config.json"), "{}").unwrap();
        if !pixel {
            std::fs::create_dir_all(dir.join("vae")).unwrap();
        }
        if scorer {
            std::fs::create_dir_all(dir.join("scorer")).unwrap();
            std::fs::write(dir.join("scorer/config.json"), "{}").unwrap();
        }
    }

    #[test]
    fn default_model_resolution_order() {
        let root = tmp("default-model");
        let (cwd, crate_root, env) = (root.join("cwd"), root.join("crate"), root.join("env"));
        for d in [&cwd, &crate_root] {
            std::fs::create_dir_all(d).unwrap();
        }
        // nothing anywhere
        assert_eq!(
            resolve_default_model(None, Some(&cwd), &crate_root),
            Ok(None)
        );
        // the crate root's copy is found from any working directory
        fake_model(&crate_root.join(EMBEDDED_MODEL), true, true);
        assert_eq!(
            resolve_default_model(None, Some(&cwd), &crate_root),
            Ok(Some(crate_root.join(EMBEDDED_MODEL)))
        );
        assert_eq!(
            resolve_default_model(None, None, &crate_root),
            Ok(Some(crate_root.join(EMBEDDED_MODEL)))
        );
        // the working directory's copy wins over the crate root's
        fake_model(&cwd.join(EMBEDDED_MODEL), true, false);
        assert_eq!(
            resolve_default_model(None, Some(&cwd), &crate_root),
            Ok(Some(cwd.join(EMBEDDED_MODEL)))
        );
        // the environment variable wins over both; a bad value is an error, an empty one unset
        fake_model(&env, false, false);
        assert_eq!(
            resolve_default_model(Some(env.as_os_str()), Some(&cwd), &crate_root),
            Ok(Some(env.clone()))
        );
        let missing = root.join("missing");
        let e =
            resolve_default_model(Some(missing.as_os_str()), Some(&cwd), &crate_root).unwrap_err();
        assert!(
            e.contains(DEFAULT_MODEL_ENV) && e.contains("missing"),
            "{e}"
        );
        assert_eq!(
            resolve_default_model(Some(std::ffi::OsStr::new("")), Some(&cwd), &crate_root),
            Ok(Some(cwd.join(EMBEDDED_MODEL)))
        );
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn default_model_fills_unconfigured_dirs_and_passes_the_submit_check() {
        let root = tmp("default-dirs");
        let model = root.join("vf-icon");
        fake_model(&model, true, true);
        let dirs = ModelDirs::default().or_default_model(Some(model.clone()));
        assert_eq!(dirs.sd_dir.as_deref(), Some(model.as_path()));
        assert_eq!(dirs.clip_dir, Some(model.join("scorer")));
        assert!(dirs.is_small_prior());
        assert!(DefaultExecutor::new(dirs.clone()).text_ready().is_ok());
        // the pixel-space presets apply
        let e = DefaultExecutor::new(dirs);
        assert_eq!(
            e.settings(Preset::Balanced),
            Preset::Balanced.settings_for(true)
        );
        assert_ne!(e.settings(Preset::Balanced), Preset::Balanced.settings());
        // configured models are kept; a configured scorer is not replaced
        let sd = root.join("sd");
        fake_model(&sd, false, false);
        let configured = ModelDirs {
            sd_dir: Some(sd.clone()),
            ..ModelDirs::default()
        };
        assert_eq!(
            configured.clone().or_default_model(Some(model.clone())),
            configured
        );
        let with_clip = ModelDirs {
            clip_dir: Some(root.join("clip")),
            ..ModelDirs::default()
        }
        .or_default_model(Some(model.clone()));
        assert_eq!(with_clip.clip_dir, Some(root.join("clip")));
        assert_eq!(with_clip.sd_dir, Some(model.clone()));
        // a text_encoder/ folder without weights (the embedded model before its MiniLM weights
        // are fetched) is refused at submit time with a pointer to the docs
        std::fs::create_dir_all(model.join("text_encoder")).unwrap();
        let dirs = ModelDirs::default().or_default_model(Some(model.clone()));
        let msg = DefaultExecutor::new(dirs.clone()).text_ready().unwrap_err();
        assert!(
            msg.contains("MiniLM") && msg.contains("EMBEDDED.md"),
            "{msg}"
        );
        std::fs::write(model.join("text_encoder/model.safetensors"), b"x").unwrap();
        assert!(DefaultExecutor::new(dirs).text_ready().is_ok());
        // absent default: still the configuration hint
        let none = ModelDirs::default().or_default_model(None);
        let msg = DefaultExecutor::new(none).text_ready().unwrap_err();
        assert!(
            msg.contains("sd_dir") && msg.contains(EMBEDDED_MODEL),
            "{msg}"
        );
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn encoder_choice_resolution() {
        let root = tmp("encoder");
        let sd = root.join("sd");
        fake_model(&sd, false, false);
        let taesd = root.join("my-taesd");
        let r = |c, prefer, conf: Option<&Path>| resolve_encoder(c, prefer, &sd, conf);
        assert_eq!(r(EncoderChoice::Vae, true, Some(&taesd)).unwrap(), None);
        assert_eq!(r(EncoderChoice::Auto, true, None).unwrap(), None);
        let e = r(EncoderChoice::Taesd, true, None).unwrap_err();
        assert!(matches!(e, PipelineError::InvalidInput(_)) && e.to_string().contains("--taesd"));
        assert_eq!(
            r(EncoderChoice::Taesd, false, Some(&taesd)).unwrap(),
            Some(taesd.clone())
        );
        assert_eq!(
            r(EncoderChoice::Auto, true, Some(&taesd)).unwrap(),
            Some(taesd)
        );
        assert_eq!(r(EncoderChoice::Auto, false, None).unwrap(), None);
        // a taesd/ folder beside the model is found; one inside wins
        std::fs::create_dir_all(root.join("taesd")).unwrap();
        std::fs::write(root.join("taesd/config.json"), "{}").unwrap();
        assert_eq!(
            r(EncoderChoice::Auto, true, None).unwrap(),
            Some(root.join("taesd"))
        );
        std::fs::create_dir_all(sd.join("taesd")).unwrap();
        std::fs::write(sd.join("taesd/config.json"), "{}").unwrap();
        assert_eq!(
            r(EncoderChoice::Taesd, true, None).unwrap(),
            Some(sd.join("taesd"))
        );
        assert_eq!(
            r(EncoderChoice::Auto, false, None).unwrap(),
            None,
            "paper keeps the VAE"
        );
        // pixel-space models have no encoder to choose
        let px = root.join("px");
        fake_model(&px, true, false);
        assert_eq!(
            resolve_encoder(EncoderChoice::Taesd, true, &px, None).unwrap(),
            None
        );
        assert_eq!("TAESD".parse::<EncoderChoice>(), Ok(EncoderChoice::Taesd));
        assert!("fast".parse::<EncoderChoice>().is_err());
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn pixel_presets_suit_a_small_prior() {
        for p in Preset::ALL {
            let (sd, px) = (p.settings(), p.settings_for(true));
            assert_eq!(
                sd.trace_size, sd.size,
                "{p:?}: SD traces at the teacher size"
            );
            assert_eq!(px.size, 64, "{p:?}: the small prior's image side");
            assert!((64..=256).contains(&px.trace_size), "{p:?}");
            assert!(px.steps <= sd.steps.max(20), "{p:?}");
            assert!(!px.prefer_taesd);
        }
        let b = Preset::default().settings_for(true);
        assert_eq!((b.size, b.trace_size), (64, 128));
    }

    #[test]
    fn default_executor_refuses_text_with_configuration_hint() {
        let e = DefaultExecutor::default();
        let msg = e.text_ready().unwrap_err();
        assert!(msg.contains("sd_dir"), "{msg}");
        let ctx = JobContext::detached(CancelToken::new());
        // The spec's image bytes are not an image: a clear input error, not a panic.
        assert!(matches!(
            e.run(&spec(), &ctx),
            Err(PipelineError::InvalidInput(_))
        ));
    }
}
