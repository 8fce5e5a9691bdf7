//! The paper's methods joined from the stages, shared by `vectorfusion generate` and the
//! service's [`super::DefaultExecutor`]:
//!
//! - `scratch`: SDS from a random init of the style ([`crate::stages::sds`]);
//! - `sd_live`: sample K images with the style suffix, keep the best by CLIP
//!   ([`ImageTextScorer::best_of`]), trace it with LIVE ([`crate::stages::live`]); pixel art is the
//!   L1 pixelation of the best sample instead, sketch the traced outlines as strokes;
//! - `sd_live_sds`: `sd_live`, then SDS without augmentation, re-initialising faint paths and
//!   paths with area below 64 px² (at 512 px, scaled to the working size);
//! - a user image (traced with LIVE first) or SVG (imported) as the start of SDS fine-tuning.
//!
//! At the end, iconography paths that stayed faint or tiny are pruned and the number of paths
//! the scene needed is reported in the output `detail`.

use super::{JobContext, PipelineError, Preset};
use crate::image::Image;
use crate::image::ops::resize;
use crate::models::ComputeDevice;
use crate::models::pipeline::ModelHints;
use crate::models::scorer::{ImageTextScorer, Scorer};
use crate::progress::{CancelToken, Progress, ProgressSink};
use crate::retrieval::install::CAPTION_TOKENS;
use crate::retrieval::{Hit, IconIndex, RetrievalLocations};
use crate::scene::{Rgba, Scene, Shape, ShapeKind, Stroke};
use crate::stages::live::prune::weak_paths;
use crate::stages::live::{self, LiveConfig, PathBudget};
use crate::stages::sample;
use crate::stages::sds::{
    RasterBackend, SdsCheckpoint, SdsConfig, SdsError, SdsState, run_sds_resumable,
};
use crate::stages::styles::{Style, pixelate_l1, random_circle, random_stroke};
use crate::teacher::{AnalyticTeacher, AnalyticTeacherConfig, SdTeacher, Teacher};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use serde_json::json;
use std::path::Path;

pub use super::Method;

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
        }
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
            Preset::Balanced => PresetSettings {
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

    /// Explicit `paths`/`steps`/`samples` win; omitted ones are the preset's (paths per style:
    /// iconography the preset's, pixel art its grid, sketch at most its stroke count). The one
    /// resolution shared by `generate`, `eval --method`, the service and [`run_text`].
    pub fn resolve(
        self,
        small_prior: bool,
        style: Style,
        paths: Option<usize>,
        steps: Option<u32>,
        samples: Option<u32>,
    ) -> Resolved {
        let ps = self.settings_for(small_prior);
        Resolved {
            paths: paths.unwrap_or(match style {
                Style::Iconography => ps.paths,
                Style::PixelArt => style.default_paths(),
                Style::Sketch => ps.paths.min(Style::Sketch.default_paths()),
            }),
            steps: steps.unwrap_or(ps.steps),
            samples: samples.unwrap_or(ps.samples),
        }
    }

    /// The path budget of a vectorize job when the request names none: the total of this
    /// preset's LIVE budget.
    pub fn vectorize_paths(self) -> usize {
        match LiveConfig::preset(self.live()).budget {
            PathBudget::Schedule { stages } => stages.iter().sum(),
            PathBudget::Auto { max_paths, .. } => max_paths,
        }
    }

    /// The LIVE preset used for vectorize jobs.
    pub fn live(self) -> live::Preset {
        match self {
            Preset::Draft | Preset::Fast => live::Preset::Fast,
            Preset::Balanced => live::Preset::Balanced,
            Preset::Paper => live::Preset::Quality,
        }
    }
}

/// Paths, steps and samples of a run after [`Preset::resolve`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Resolved {
    pub paths: usize,
    pub steps: u32,
    pub samples: u32,
}

impl std::str::FromStr for Preset {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "draft" => Ok(Preset::Draft),
            "fast" => Ok(Preset::Fast),
            "balanced" | "default" => Ok(Preset::Balanced),
            "paper" | "quality" => Ok(Preset::Paper),
            other => Err(format!(
                "unknown preset {other:?} (expected draft, fast, balanced or paper)"
            )),
        }
    }
}

impl std::str::FromStr for Method {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().replace('-', "_").as_str() {
            "scratch" => Ok(Method::Scratch),
            "sd_live" => Ok(Method::SdLive),
            "sd_live_sds" => Ok(Method::SdLiveSds),
            other => Err(format!(
                "unknown method {other:?} (expected scratch, sd_live or sd_live_sds)"
            )),
        }
    }
}

/// The service's style enum as the stages' style.
pub fn stage_style(s: super::Style) -> Style {
    match s {
        super::Style::Iconography => Style::Iconography,
        super::Style::PixelArt => Style::PixelArt,
        super::Style::Sketch => Style::Sketch,
    }
}

/// The diffusion model behind a run.
pub enum TeacherModel {
    /// Stable Diffusion: samples images and is the SDS teacher.
    Sd(Box<SdTeacher>),
    /// The analytic TEST teacher: its exact distribution is uniform over its target images, so
    /// "sampling" draws targets; SDS distils towards them.
    Analytic(AnalyticTeacher),
}

/// Everything a text run needs, loaded once per teacher size.
pub struct Models {
    pub teacher: TeacherModel,
    pub scorer: Option<Scorer>,
    /// The caption index of the model's training icons, when the model pins icon sets and
    /// `vectorfusion setup` installed it; why not otherwise (reported in the run's detail).
    pub retrieval: Result<std::sync::Arc<IconIndex>, String>,
}

impl std::fmt::Debug for Models {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Models")
            .field("teacher", &self.teacher().name())
            .field(
                "scorer",
                &self.scorer.as_ref().map(|s| s.name().to_string()),
            )
            .finish()
    }
}

fn failed(what: &str, e: impl std::fmt::Display) -> PipelineError {
    PipelineError::Failed(format!("{what}: {e}"))
}

impl Models {
    /// Loads Stable Diffusion from `sd_dir` for `size` px inputs and, when given, the CLIP scorer.
    pub fn load_sd(sd_dir: &Path, scorer: Option<&Path>, size: u32) -> Result<Self, PipelineError> {
        Self::load_sd_with(sd_dir, scorer, size, None, ComputeDevice::Cpu)
    }

    /// [`Models::load_sd`] with TAESD (`taesd`) as the SDS encoder instead of the VAE (see
    /// [`super::EncoderChoice`]; pixel-space models ignore it), on `device`.
    pub fn load_sd_with(
        sd_dir: &Path,
        scorer: Option<&Path>,
        size: u32,
        taesd: Option<&Path>,
        device: ComputeDevice,
    ) -> Result<Self, PipelineError> {
        let teacher = SdTeacher::load_on(sd_dir, size, taesd, device).map_err(|e| {
            PipelineError::ModelsNotConfigured(format!(
                "cannot load Stable Diffusion from {}: {e}",
                sd_dir.display()
            ))
        })?;
        let retrieval = match RetrievalLocations::from_env().load(sd_dir) {
            Ok(Some(idx)) => Ok(std::sync::Arc::new(idx)),
            Ok(None) => Err("the model pins no icon sets".to_string()),
            Err(e) => {
                tracing::warn!(model = %sd_dir.display(), "sampling from noise only: {e}");
                Err(e.to_string())
            }
        };
        Ok(Models {
            teacher: TeacherModel::Sd(Box::new(teacher)),
            scorer: load_scorer(scorer)?,
            retrieval,
        })
    }

    /// The analytic test teacher over the PNG targets in `dir`.
    pub fn load_analytic(
        dir: &Path,
        scorer: Option<&Path>,
        size: u32,
    ) -> Result<Self, PipelineError> {
        let pool = if size >= 64 && size % 64 == 0 {
            size / 64
        } else {
            1
        };
        let teacher = AnalyticTeacher::from_dir(
            dir,
            AnalyticTeacherConfig {
                image_size: size,
                pool,
                num_train_timesteps: 1000,
            },
        )
        .map_err(|e| PipelineError::ModelsNotConfigured(e.to_string()))?;
        Ok(Models {
            teacher: TeacherModel::Analytic(teacher),
            scorer: load_scorer(scorer)?,
            retrieval: Err("the test teacher has no retrieval index".into()),
        })
    }

    /// Whether the teacher is a small prior (presets differ: [`Preset::settings_for`]).
    pub fn is_small_prior(&self) -> bool {
        match &self.teacher {
            TeacherModel::Sd(t) => t.model().is_pixel_space() || t.model().hints.small_prior,
            TeacherModel::Analytic(_) => false,
        }
    }

    pub fn teacher(&self) -> &dyn Teacher {
        match &self.teacher {
            TeacherModel::Sd(t) => t.as_ref(),
            TeacherModel::Analytic(t) => t,
        }
    }

    /// Samples `k` images for `prompt` (seeded), reporting stage `"sample"` progress; the first
    /// `starts.len()` begin from those images (SDEdit at `strength`, [`sample::draw`]).
    #[allow(clippy::too_many_arguments)]
    pub fn sample(
        &self,
        prompt: &str,
        k: u32,
        sample_steps: usize,
        seed: u64,
        starts: &[Image],
        strength: f64,
        sink: &dyn ProgressSink,
        cancel: &CancelToken,
    ) -> Result<Vec<Image>, PipelineError> {
        match &self.teacher {
            TeacherModel::Sd(t) => {
                let cfg = sample::SampleConfig {
                    k,
                    steps: sample_steps,
                    guidance: f64::from(t.model().hints.sample_guidance),
                    seed,
                    strength,
                };
                sample::draw(
                    t.model(),
                    t.latent_shape(),
                    prompt,
                    starts,
                    &cfg,
                    sink,
                    cancel,
                )
                .map_err(|e| match e {
                    sample::SampleError::Cancelled => PipelineError::Cancelled,
                    sample::SampleError::Failed(m) => PipelineError::Failed(m),
                })
            }
            TeacherModel::Analytic(t) => {
                use rand::RngExt;
                let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5a3b_1e00);
                let targets = t.targets();
                if targets.is_empty() {
                    return Err(failed("sampling", "the test teacher has no targets"));
                }
                let mut out = Vec::with_capacity(k as usize);
                for i in 0..k {
                    let j = rng.random_range(0..targets.len());
                    out.push(targets[j].clone());
                    sink.report(Progress::new("sample", i + 1, k));
                }
                Ok(out)
            }
        }
    }

    /// The training icons nearest to `caption` to start `n` samples from, rendered at the
    /// teacher's image side; `Err` says why there are none (no index, a CLIP text encoder, ...).
    pub fn retrieve(
        &self,
        caption: &str,
        n: usize,
        seed: u64,
    ) -> Result<Vec<(Hit, Image)>, String> {
        let idx = self.retrieval.as_ref().map_err(Clone::clone)?;
        let TeacherModel::Sd(t) = &self.teacher else {
            return Err("the test teacher has no retrieval index".into());
        };
        let q = t
            .model()
            .sentence_embedding(caption, CAPTION_TOKENS)
            .map_err(|e| e.to_string())?
            .ok_or("the model's text encoder is not the index's MiniLM")?;
        let side = t.image_size();
        idx.nearest(&q, n, 1, seed)
            .map_err(|e| e.to_string())?
            .into_iter()
            .map(|h| {
                let img = idx.render(&h.icon, side).map_err(|e| e.to_string())?;
                Ok((h, img))
            })
            .collect()
    }
}

/// The K raster samples of one caption and the scorer's pick among them.
///
/// Invariant: `images` is not empty and `best < images.len()` (checked where it is built).
#[derive(Debug, Clone)]
pub struct Ranked {
    images: Vec<Image>,
    best: usize,
    scores: Vec<f32>,
    /// The retrieved icon each sample started from (`None`: from noise); as long as `images`.
    sources: Vec<Option<Hit>>,
}

impl Ranked {
    pub fn images(&self) -> &[Image] {
        &self.images
    }
    /// Index of the kept image (0 without a scorer).
    pub fn best(&self) -> usize {
        self.best
    }
    /// One score per image (empty without a scorer).
    pub fn scores(&self) -> &[f32] {
        &self.scores
    }
    pub fn best_image(&self) -> &Image {
        &self.images[self.best]
    }
    /// Per sample, the icon it started from (`None`: pure noise).
    pub fn sources(&self) -> &[Option<Hit>] {
        &self.sources
    }
    /// The icon the kept sample started from.
    pub fn best_source(&self) -> Option<&Hit> {
        self.sources.get(self.best).and_then(Option::as_ref)
    }
}

impl Models {
    /// The prompt the diffusion model is conditioned on: `caption` with the style suffix, unless
    /// the model was trained on bare captions ([`ModelHints::style_suffix`]).
    pub fn prompt(&self, style: Style, caption: &str) -> String {
        style.prompt_with(caption, self.hints().style_suffix)
    }

    /// The diffusion model's defaults (the paper's for the analytic test teacher).
    pub fn hints(&self) -> ModelHints {
        match &self.teacher {
            TeacherModel::Sd(t) => t.model().hints,
            TeacherModel::Analytic(_) => ModelHints::default(),
        }
    }

    /// Samples `k` images with `prompt` ([`Models::prompt`]) and keeps the one the
    /// scorer matches best to `caption` (rejection sampling, the first stage of `sd_live*`).
    /// With `retrieval`, half of them start from the training icons nearest to `caption`
    /// ([`Models::retrieve`]); the second value says why none did, when none did.
    #[allow(clippy::too_many_arguments)]
    pub fn sample_and_rerank(
        &self,
        prompt: &str,
        caption: &str,
        k: u32,
        sample_steps: usize,
        seed: u64,
        retrieval: bool,
        sink: &dyn ProgressSink,
        cancel: &CancelToken,
    ) -> Result<(Ranked, Option<String>), PipelineError> {
        let (hits, why_not) = if retrieval {
            match self.retrieve(caption, sample::retrieved_count(k), seed) {
                Ok(h) => (h, None),
                Err(e) => (Vec::new(), Some(e)),
            }
        } else {
            (Vec::new(), Some("turned off".to_string()))
        };
        let (hits, starts): (Vec<Hit>, Vec<Image>) = hits.into_iter().unzip();
        let images = self.sample(
            prompt,
            k,
            sample_steps,
            seed,
            &starts,
            sample::DEFAULT_STRENGTH,
            sink,
            cancel,
        )?;
        if images.is_empty() {
            return Err(failed("sampling", "no samples drawn (K = 0)"));
        }
        let (best, scores) = match &self.scorer {
            Some(scorer) => scorer
                .best_of(&images, caption)
                .map_err(|e| failed("CLIP rerank", e))?,
            None => (0, Vec::new()),
        };
        if best >= images.len() {
            return Err(failed("rerank", "best index out of range"));
        }
        let mut sources: Vec<Option<Hit>> = hits.into_iter().map(Some).collect();
        sources.resize(images.len(), None);
        Ok((
            Ranked {
                images,
                best,
                scores,
                sources,
            },
            why_not,
        ))
    }
}

fn load_scorer(dir: Option<&Path>) -> Result<Option<Scorer>, PipelineError> {
    dir.map(|d| {
        Scorer::load(d).map_err(|e| {
            PipelineError::ModelsNotConfigured(format!(
                "cannot load the scorer from {}: {e}",
                d.display()
            ))
        })
    })
    .transpose()
}

/// Where a text run starts.
#[derive(Clone, Debug, Default)]
pub enum Start {
    /// From the method (random init or sampled image).
    #[default]
    Method,
    /// Trace this image with LIVE, then fine-tune with SDS.
    Image(Image),
    /// Fine-tune this imported scene with SDS.
    Svg(Scene),
}

/// A caption → SVG request.
#[derive(Clone, Debug)]
pub struct TextRequest {
    pub caption: String,
    pub style: Style,
    pub method: Method,
    pub preset: Preset,
    pub paths: Option<usize>,
    pub steps: Option<u32>,
    pub samples: Option<u32>,
    pub seed: u64,
    /// SDS guidance scale [default: the model's, [`ModelHints::sds_guidance`]].
    pub guidance: Option<f32>,
    /// Start some of the K samples from retrieved icons (when the model has an index).
    pub retrieval: bool,
    pub start: Start,
}

/// The result of a run.
#[derive(Clone, Debug)]
pub struct MethodOutput {
    pub scene: Scene,
    pub svg: String,
    /// Paths in the final scene.
    pub paths: usize,
    pub detail: serde_json::Value,
}

/// Paths below this area (px² at 512 px) are re-initialised in `sd_live_sds` and pruned at the
/// end (paper: 64 px²).
pub const MIN_AREA_512: f32 = 64.0;
/// Paths with fill opacity below this are faint.
pub const MIN_OPACITY: f32 = 0.05;

fn min_area_at(size: u32) -> f32 {
    let k = size as f32 / 512.0;
    MIN_AREA_512 * k * k
}

fn live_cfg(size: u32, paths: usize, iters: u32, seed: u64, snapshot_every: u32) -> LiveConfig {
    LiveConfig {
        size,
        budget: PathBudget::fixed(paths.clamp(1, 1024)),
        iters_per_stage: iters,
        final_iters: iters,
        seed,
        snapshot_every,
        ..LiveConfig::preset(live::Preset::Fast)
    }
}

fn trace(
    image: &Image,
    size: u32,
    paths: usize,
    ps: &PresetSettings,
    seed: u64,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<(Scene, serde_json::Value), PipelineError> {
    let cfg = live_cfg(size, paths, ps.live_iters, seed, ps.snapshot_every);
    let img = if image.width.max(image.height) > size {
        let k = size as f32 / image.width.max(image.height) as f32;
        resize(
            image,
            ((image.width as f32 * k).round() as u32).max(1),
            ((image.height as f32 * k).round() as u32).max(1),
        )
    } else {
        image.clone()
    };
    let r = live::vectorize(&img, &cfg, sink, cancel).map_err(|e| match e {
        live::LiveError::Cancelled => PipelineError::Cancelled,
        other => failed("LIVE", other),
    })?;
    let detail = json!({"paths": r.paths, "psnr": r.psnr, "pruned": r.pruned, "steps": r.steps});
    Ok((r.scene, detail))
}

/// Sketch from a trace: every closed outline becomes an open black stroke.
fn outlines_as_strokes(scene: &Scene, size: u32) -> Result<Scene, PipelineError> {
    let mut out =
        Scene::new(scene.width, scene.height, Rgba::WHITE).map_err(|e| failed("scene", e))?;
    for s in &scene.shapes {
        if s.kind != ShapeKind::ClosedCubic || s.points.is_empty() {
            continue;
        }
        let mut pts = s.points.clone();
        pts.push(s.points[0]);
        let stroke = Stroke {
            color: Rgba::BLACK,
            width: Style::stroke_width(size),
        };
        out.shapes
            .push(Shape::open_cubic(pts, stroke).map_err(|e| failed("scene", e))?);
    }
    Ok(out)
}

fn scaled(scene: &Scene, width: u32) -> Result<Scene, PipelineError> {
    if scene.width == width {
        return Ok(scene.clone());
    }
    Ok(scene.scaled_to_width(width))
}

/// Runs `req` with `models`: progress (with SVG snapshots) goes to `sink`, `cancel` is polled
/// between steps.
pub fn run_text(
    models: &Models,
    req: &TextRequest,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<MethodOutput, PipelineError> {
    run_text_resumable(models, req, sink, cancel, None)
}

/// What a text run checkpoints (the service stores it with the job): the SDS loop's state and
/// what the stages before it produced, so a resumed run skips sampling, rerank and tracing.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TextCheckpoint {
    /// The request the state belongs to ([`checkpoint_key`]); another request ignores it.
    pub key: String,
    pub augment: bool,
    /// The run's `detail` when SDS started (rerank scores, LIVE statistics).
    pub detail: serde_json::Value,
    pub sds: SdsState,
}

/// Identifies the run a checkpoint belongs to: everything that shapes the SDS stage (with the
/// prompt the model is conditioned on and the SDS guidance, which the model's hints decide).
pub fn checkpoint_key(req: &TextRequest, models: &Models, size: u32) -> String {
    let teacher = models.teacher().name();
    let prompt = models.prompt(req.style, &req.caption);
    let guidance = req.guidance.unwrap_or(models.hints().sds_guidance);
    let start = match &req.start {
        Start::Method => "method",
        Start::Image(_) => "image",
        Start::Svg(_) => "svg",
    };
    format!(
        "v3|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}|{}|{start}|{teacher}|{size}|{prompt:?}|{guidance}|{}",
        req.method,
        req.style,
        req.preset,
        req.paths,
        req.steps,
        req.samples,
        req.caption,
        req.seed,
        req.retrieval
    )
}

struct JobCheckpoints<'a> {
    ctx: &'a JobContext,
    key: &'a str,
    augment: bool,
    detail: &'a serde_json::Value,
}

impl SdsCheckpoint for JobCheckpoints<'_> {
    fn due(&self, step: u32) -> bool {
        self.ctx.checkpoint_due(step)
    }

    fn save(&self, state: &SdsState) -> Result<(), String> {
        save_checkpoint(
            self.ctx,
            &TextCheckpoint {
                key: self.key.to_string(),
                augment: self.augment,
                detail: self.detail.clone(),
                sds: state.clone(),
            },
        )
    }
}

/// Stores `state` as the job's checkpoint (JSON through `ctx`).
fn save_checkpoint(ctx: &JobContext, state: &impl Serialize) -> Result<(), String> {
    let value = serde_json::to_value(state).map_err(|e| e.to_string())?;
    ctx.checkpoint(value).map_err(|e| e.to_string())
}

/// The state an interrupted attempt saved, when it is a `T`; none, garbage or a checkpoint of
/// another kind of run give `None` (the run starts over).
fn resume_as<T: serde::de::DeserializeOwned>(ctx: Option<&JobContext>) -> Option<T> {
    ctx.and_then(JobContext::resume_state)
        .and_then(|v| serde_json::from_value(v).ok())
}

/// [`run_text`] for a service job: checkpoints the SDS stage through `ctx` every
/// `ctx.checkpoint_due` steps (and when cancelled), and resumes from `ctx.resume_state()` when
/// it holds a [`TextCheckpoint`] of the same request, skipping the stages before SDS. A resumed
/// run ends with the same SVG as an uninterrupted one; `detail.resumed_from` is the step.
pub fn run_text_resumable(
    models: &Models,
    req: &TextRequest,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
    ctx: Option<&JobContext>,
) -> Result<MethodOutput, PipelineError> {
    let ps = req.preset.settings_for(models.is_small_prior());
    let teacher = models.teacher();
    let size = teacher.image_size();
    let Resolved {
        paths,
        steps,
        samples: k,
    } = req.preset.resolve(
        models.is_small_prior(),
        req.style,
        req.paths,
        req.steps,
        req.samples,
    );
    let (steps, k) = (steps.max(1), k.max(1));
    if paths == 0 || paths > 1024 {
        return Err(PipelineError::InvalidInput(format!(
            "paths must be in 1..=1024, got {paths}"
        )));
    }
    let prompt = models.prompt(req.style, &req.caption);
    let mut detail = json!({
        "method": req.method,
        "style": req.style,
        "preset": req.preset,
        "teacher": teacher.name(),
        "encoder": teacher.encoder(),
        "size": size,
        "prompt": prompt,
    });
    let t0 = std::time::Instant::now();
    let key = checkpoint_key(req, models, size);
    let mut resumed = resume_as::<TextCheckpoint>(ctx).filter(|c| c.key == key);

    // 1. The starting scene, and whether SDS (with augmentation) follows.
    let mut sds_after = req.method != Method::SdLive;
    let mut augment = true;
    let mut resume_sds = None;
    let start_scene: Scene = match &req.start {
        // A restarted job: the SDS state and the detail of the stages before it.
        _ if resumed.is_some() => {
            let r = resumed
                .take()
                .ok_or_else(|| failed("resume", "no saved state"))?;
            sds_after = true;
            augment = r.augment;
            detail = r.detail;
            detail["resumed_from"] = json!(r.sds.step);
            let scene = r.sds.scene.clone();
            resume_sds = Some(r.sds);
            scene
        }
        Start::Svg(scene) => {
            sds_after = true;
            augment = false;
            scaled(scene, size)?
        }
        Start::Image(image) => {
            sds_after = true;
            augment = false;
            let (scene, d) = trace(image, size, paths, &ps, req.seed, sink, cancel)?;
            detail["live"] = d;
            scaled(&scene, size)?
        }
        Start::Method if req.method == Method::Scratch => {
            let cfg = SdsConfig::for_style(req.style, &req.caption, steps, size);
            let mut rng = ChaCha8Rng::seed_from_u64(req.seed ^ 0x5eed_1a17);
            req.style
                .init_scene(cfg.render_size(size), paths, &mut rng)
                .map_err(|e| failed("initial scene", e))?
        }
        Start::Method => {
            augment = false;
            let (ranked, why_not) = models.sample_and_rerank(
                &prompt,
                &req.caption,
                k,
                ps.sample_steps,
                req.seed,
                req.retrieval,
                sink,
                cancel,
            )?;
            let rerank = json!({
                "scorer": models.scorer.as_ref().map(|s| s.name().to_string()),
                "scores": ranked.scores(),
                "best": ranked.best(),
                "samples": k,
                "sources": ranked.sources(),
            });
            detail["retrieval"] = json!({
                "strength": sample::DEFAULT_STRENGTH,
                "starts": ranked.sources().iter().flatten().collect::<Vec<_>>(),
                "chosen": ranked.best_source(),
                "unavailable": why_not,
            });
            let mut ev = Progress::new("rerank", 1, 1);
            ev.detail = Some(rerank.clone());
            sink.report(ev);
            detail["rerank"] = rerank;
            let best_img = ranked.best_image();
            match req.style {
                Style::PixelArt => {
                    pixelate_l1(best_img, size).map_err(|e| failed("pixelation", e))?
                }
                Style::Iconography | Style::Sketch => {
                    // Small samples (a 32 px pixel-space prior) are upscaled to the trace canvas.
                    let side = best_img.width.max(best_img.height);
                    let upscaled;
                    let best_img = if side < ps.trace_size {
                        let k = ps.trace_size as f32 / side as f32;
                        upscaled = resize(
                            best_img,
                            ((best_img.width as f32 * k).round() as u32).max(1),
                            ((best_img.height as f32 * k).round() as u32).max(1),
                        );
                        &upscaled
                    } else {
                        best_img
                    };
                    let (scene, d) =
                        trace(best_img, ps.trace_size, paths, &ps, req.seed, sink, cancel)?;
                    detail["live"] = d;
                    let scene = scaled(&scene, size)?;
                    let mut scene = if req.style == Style::Sketch {
                        outlines_as_strokes(&scene, size)?
                    } else {
                        scene
                    };
                    // A flat sample can trace to (almost) nothing: top the scene up with the
                    // style's random shapes so SDS has something to move (sketches always get
                    // their stroke count).
                    let want = if req.style == Style::Sketch { paths } else { 1 };
                    let mut rng = ChaCha8Rng::seed_from_u64(req.seed ^ 0x7095_0f11);
                    let mut added = 0usize;
                    while scene.shapes.len() < want {
                        let shape = if req.style == Style::Sketch {
                            random_stroke(size, &mut rng)
                        } else {
                            random_circle(size, &mut rng)
                        }
                        .map_err(|e| failed("initial scene", e))?;
                        scene.shapes.push(shape);
                        added += 1;
                    }
                    detail["topped_up"] = json!(added);
                    scene
                }
            }
        }
    };
    if cancel.is_cancelled() {
        return Err(PipelineError::Cancelled);
    }

    // 2. Score distillation.
    let mut scene = start_scene;
    if sds_after {
        let mut cfg = SdsConfig::for_style(req.style, &req.caption, steps, size);
        cfg.prompt = prompt.clone();
        cfg.guidance = req.guidance.unwrap_or(models.hints().sds_guidance);
        cfg.seed = req.seed;
        cfg.snapshot_every = ps.snapshot_every;
        if !augment {
            cfg.augment = None;
            if let Some(r) = cfg.reinit.as_mut() {
                r.min_area = Some(min_area_at(size));
            }
        }
        let render = cfg.render_size(size);
        let state = match resume_sds {
            Some(s) => s,
            None => SdsState::start(scaled(&scene, render)?, &cfg),
        };
        let checkpoints = ctx.map(|ctx| JobCheckpoints {
            ctx,
            key: &key,
            augment,
            detail: &detail,
        });
        let out = run_sds_resumable(
            &RasterBackend,
            teacher,
            state,
            &cfg,
            sink,
            cancel,
            checkpoints.as_ref().map(|c| c as &dyn SdsCheckpoint),
        )
        .map_err(|e| match e {
            SdsError::Config(m) => PipelineError::InvalidInput(m),
            SdsError::Checkpoint(m) => PipelineError::Transient(m),
            other => failed("score distillation", other),
        })?;
        if out.stats.cancelled {
            return Err(PipelineError::Cancelled);
        }
        detail["sds"] = serde_json::to_value(&out.stats).unwrap_or_default();
        detail["sds"]["augment"] = json!(augment);
        scene = scaled(&out.scene, size)?;
    }

    // 3. Prune faint/tiny paths (filled free-form paths only).
    let before = scene.shapes.len();
    let mut pruned = 0usize;
    if req.style == Style::Iconography {
        let weak = weak_paths(&scene, MIN_OPACITY, min_area_at(size));
        if weak.len() < scene.shapes.len() {
            for &i in weak.iter().rev() {
                scene.shapes.remove(i);
            }
            pruned = weak.len();
        }
    }
    detail["paths_initial"] = json!(before);
    detail["paths_pruned"] = json!(pruned);
    detail["paths_needed"] = json!(scene.shapes.len());
    detail["seconds"] = json!(t0.elapsed().as_secs_f64());
    scene.validate().map_err(|e| failed("final scene", e))?;
    let svg = RasterBackend::svg_text(&scene);
    // A drawing that started from a retrieved icon names it and its licence.
    let svg = match serde_json::from_value::<Hit>(detail["retrieval"]["chosen"].clone()) {
        Ok(h) => crate::svg::with_metadata(
            &svg,
            &format!(
                "Started from the icon \"{}\" of the {} {} icon set ({}, licence {}), redrawn by \
                 vectorfusion for the caption \"{}\".",
                h.icon.name,
                h.icon.set,
                h.icon.version,
                h.icon.caption,
                h.icon.license,
                req.caption
            ),
        ),
        Err(_) => svg,
    };
    let mut done = Progress::new("done", 1, 1);
    done.svg = Some(svg.clone());
    sink.report(done);
    Ok(MethodOutput {
        paths: scene.shapes.len(),
        scene,
        svg,
        detail,
    })
}

/// A vectorize job's saved LIVE state, tagged with the request it belongs to.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct VectorizeCheckpoint {
    /// [`vectorize_checkpoint_key`]; a state saved for another request is ignored.
    pub key: String,
    pub live: live::LiveState,
}

/// Identifies a vectorize run: preset, path budget, seed and the image itself (size and a
/// checksum of its pixels).
pub fn vectorize_checkpoint_key(
    image: &Image,
    preset: Preset,
    max_paths: usize,
    seed: u64,
) -> String {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for v in &image.data {
        v.to_bits().hash(&mut h);
    }
    format!(
        "live-v1|{preset:?}|{max_paths}|{seed}|{}x{}|{:016x}",
        image.width,
        image.height,
        h.finish()
    )
}

struct VectorizeCheckpoints<'a> {
    ctx: &'a JobContext,
    key: &'a str,
}

impl live::LiveCheckpoint for VectorizeCheckpoints<'_> {
    fn save(&self, state: &live::LiveState) -> Result<(), String> {
        save_checkpoint(
            self.ctx,
            &VectorizeCheckpoint {
                key: self.key.to_string(),
                live: state.clone(),
            },
        )
    }
}

/// Image → SVG with LIVE (vectorize jobs), with an `auto` path budget capped at `max_paths`.
/// With a job context, the LIVE state is checkpointed after every stage
/// and a restarted job continues from the last one (`detail.resumed_from_stage`), ending with
/// the SVG an uninterrupted run gives.
pub fn run_vectorize(
    image: &Image,
    preset: Preset,
    max_paths: usize,
    seed: u64,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
    ctx: Option<&JobContext>,
) -> Result<MethodOutput, PipelineError> {
    let mut cfg = LiveConfig::preset(preset.live());
    cfg.seed = seed;
    if let PathBudget::Auto { max_paths: m, .. } = &mut cfg.budget {
        *m = max_paths.clamp(1, 1024);
    } else {
        cfg.budget = PathBudget::Auto {
            stage: 8.min(max_paths.max(1)),
            max_paths: max_paths.clamp(1, 1024),
            min_gain_db_per_path: 0.05,
            prune_tolerance: 2e-5,
        };
    }
    if preset == Preset::Draft {
        cfg.iters_per_stage = 20;
        cfg.final_iters = 10;
        cfg.size = 64;
    }
    let key = vectorize_checkpoint_key(image, preset, max_paths, seed);
    let resume = resume_as::<VectorizeCheckpoint>(ctx)
        .filter(|c| c.key == key)
        .map(|c| c.live);
    let resumed_from = resume.as_ref().map(|s| s.reports.len());
    let hook = ctx.map(|ctx| VectorizeCheckpoints { ctx, key: &key });
    let r = live::vectorize_resumable(
        image,
        &cfg,
        sink,
        cancel,
        resume,
        hook.as_ref().map(|h| h as &dyn live::LiveCheckpoint),
    )
    .map_err(|e| match e {
        live::LiveError::Cancelled => PipelineError::Cancelled,
        live::LiveError::Target(m) => PipelineError::InvalidInput(m),
        live::LiveError::Checkpoint(m) => PipelineError::Transient(m),
        other => failed("LIVE", other),
    })?;
    let svg = RasterBackend::svg_text(&r.scene);
    let mut detail = json!({
        "method": "live",
        "preset": preset,
        "psnr": r.psnr,
        "paths_needed": r.paths,
        "paths_pruned": r.pruned,
        "steps": r.steps,
        "stages": r.stages,
    });
    if let Some(n) = resumed_from {
        detail["resumed_from_stage"] = json!(n);
    }
    Ok(MethodOutput {
        paths: r.scene.shapes.len(),
        scene: r.scene,
        svg,
        detail,
    })
}
