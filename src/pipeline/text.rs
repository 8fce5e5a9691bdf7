//! Caption → SVG, as a [`TextPlan`] says (VectorFusion §4):
//!
//! - `scratch`: SDS from the style's random init ([`crate::stages::sds`]);
//! - `sd_live`: K samples, the scorer's pick ([`crate::stages::sample`]), turned into the
//!   style's starting scene (LIVE trace, or pixelation: [`crate::stages::styles`]);
//! - `sd_live_sds`: `sd_live`, then SDS without augmentation, re-initialising faint and tiny
//!   paths;
//! - a given image (traced with LIVE first) or SVG as the start of SDS fine-tuning.
//!
//! At the end the style's weak shapes are pruned and the number of paths the scene needed is
//! reported in the output `detail`. The SDS stage checkpoints through the job context and a
//! restarted job resumes from it to the identical SVG.

use super::context::{resume_as, save_checkpoint};
use super::plan::{MIN_OPACITY, TextPlan, min_area_at, render_size};
use super::{JobContext, Models, PipelineError};
use crate::image::Image;
use crate::image::ops::resize;
use crate::models::scorer::ImageTextScorer;
use crate::progress::{CancelToken, Progress, ProgressSink};
use crate::retrieval::Hit;
use crate::scene::Scene;
use crate::stages::live::prune::weak_paths;
use crate::stages::live::{self, LiveConfig, PathBudget};
use crate::stages::sample::{Ranked, RetrievalPick, retrieved_count, sample_and_rerank};
use crate::stages::sds::{
    RasterBackend, SdsCheckpoint, SdsConfig, SdsError, SdsState, run_sds_resumable,
};
use crate::stages::styles::SampleStart;
use crate::teacher::{SampleConfig, SampleError};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use serde_json::json;

/// The input a text run starts from (what [`TextPlan::start`] names).
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

/// The result of a run.
#[derive(Clone, Debug)]
pub struct MethodOutput {
    pub scene: Scene,
    pub svg: String,
    /// Paths in the final scene.
    pub paths: usize,
    pub detail: serde_json::Value,
}

pub(super) fn failed(what: &str, e: impl std::fmt::Display) -> PipelineError {
    PipelineError::Failed(format!("{what}: {e}"))
}

fn sample_err(e: SampleError) -> PipelineError {
    match e {
        SampleError::Cancelled => PipelineError::Cancelled,
        SampleError::Failed(m) => PipelineError::Failed(m),
    }
}

/// What a text run checkpoints (the service stores it with the job): the SDS loop's state and
/// what the stages before it produced, so a resumed run skips sampling, rerank and tracing.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TextCheckpoint {
    /// The plan the state belongs to ([`super::RunPlan::key`]); another plan ignores it.
    pub key: String,
    /// The run's `detail` when SDS started (rerank scores, LIVE statistics).
    pub detail: serde_json::Value,
    pub sds: SdsState,
}

struct JobCheckpoints<'a> {
    ctx: &'a JobContext,
    key: &'a str,
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
                detail: self.detail.clone(),
                sds: state.clone(),
            },
        )
    }
}

fn trace(
    image: &Image,
    size: u32,
    plan: &TextPlan,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<(Scene, serde_json::Value), PipelineError> {
    let cfg = LiveConfig {
        size,
        budget: PathBudget::fixed(plan.paths as usize),
        iters_per_stage: plan.trace.iters,
        final_iters: plan.trace.iters,
        seed: plan.seeds.trace,
        snapshot_every: plan.snapshot_every,
        colors: plan.colors.clone(),
        ..LiveConfig::preset(live::Preset::Fast)
    };
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

fn scaled(scene: &Scene, width: u32) -> Scene {
    if scene.width == width {
        scene.clone()
    } else {
        scene.scaled_to_width(width)
    }
}

/// The K samples of `plan` for `caption` and the scorer's pick (the first stage of
/// `sd_live*`; `eval --method samples` scores the pick as an image).
pub fn sample_ranked(
    models: &Models,
    plan: &TextPlan,
    caption: &str,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<(Ranked, Option<String>), PipelineError> {
    let sp = plan
        .sample
        .as_ref()
        .ok_or_else(|| failed("plan", "a sampled start needs a sample plan"))?;
    let n = retrieved_count(sp.samples, sp.retrieval_share);
    let retrieval = if !sp.retrieval {
        Err("turned off".to_string())
    } else if n == 0 {
        Err("the model's _retrieval_share is 0".to_string())
    } else {
        models
            .retrieval
            .as_deref()
            .map(|i| {
                let pick = RetrievalPick {
                    n,
                    per_caption: sp.retrieval_per_caption as usize,
                    seed: plan.seeds.sample,
                };
                (i, pick)
            })
            .map_err(Clone::clone)
    };
    let cfg = SampleConfig {
        k: sp.samples,
        steps: sp.steps as usize,
        guidance: f64::from(sp.guidance),
        seed: plan.seeds.sample,
        strength: sp.strength,
    };
    sample_and_rerank(
        models.teacher(),
        models.scorer.as_ref(),
        retrieval,
        &plan.prompt,
        caption,
        &cfg,
        sink,
        cancel,
    )
    .map_err(sample_err)
}

/// The starting scene from the best of K samples (`sd_live*`), with the rerank and retrieval
/// in `detail`.
fn from_samples(
    models: &Models,
    plan: &TextPlan,
    caption: &str,
    detail: &mut serde_json::Value,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<Scene, PipelineError> {
    let size = plan.size;
    let (ranked, why_not) = sample_ranked(models, plan, caption, sink, cancel)?;
    let sp = plan
        .sample
        .as_ref()
        .ok_or_else(|| failed("plan", "a sampled start needs a sample plan"))?;
    let rerank = json!({
        "scorer": models.scorer.as_ref().map(|s| s.name().to_string()),
        "scores": ranked.scores(),
        "best": ranked.best(),
        "samples": sp.samples,
        "sources": ranked.sources(),
    });
    detail["retrieval"] = json!({
        "strength": sp.strength,
        "share": sp.retrieval_share,
        "per_caption": sp.retrieval_per_caption,
        "starts": ranked.sources().iter().flatten().collect::<Vec<_>>(),
        "chosen": ranked.best_source(),
        "unavailable": why_not,
    });
    let mut ev = Progress::new("rerank", 1, 1);
    ev.detail = Some(rerank.clone());
    sink.report(ev);
    detail["rerank"] = rerank;
    let best_img = ranked.best_image();
    let spec = plan.style.spec();
    if spec.sample_start() == SampleStart::Image {
        return spec
            .scene_from_image(best_img, size)
            .map_err(|e| failed("initial scene", e));
    }
    // Small samples (a 32 px pixel-space prior) are upscaled to the trace canvas.
    let side = best_img.width.max(best_img.height);
    let trace_size = plan.trace.size;
    let upscaled;
    let best_img = if side < trace_size {
        let k = trace_size as f32 / side as f32;
        upscaled = resize(
            best_img,
            ((best_img.width as f32 * k).round() as u32).max(1),
            ((best_img.height as f32 * k).round() as u32).max(1),
        );
        &upscaled
    } else {
        best_img
    };
    let (scene, d) = trace(best_img, trace_size, plan, sink, cancel)?;
    detail["live"] = d;
    let mut scene = spec
        .restyle_trace(scaled(&scene, size), size)
        .map_err(|e| failed("initial scene", e))?;
    // A flat sample can trace to (almost) nothing: top the scene up with the style's random
    // shapes so SDS has something to move.
    let want = spec.min_shapes(plan.paths as usize);
    let mut rng = ChaCha8Rng::seed_from_u64(plan.seeds.top_up);
    let mut added = 0usize;
    while scene.shapes.len() < want {
        let shape = spec
            .extra_shape(size, &mut rng)
            .map_err(|e| failed("initial scene", e))?;
        scene.shapes.push(shape);
        added += 1;
    }
    detail["topped_up"] = json!(added);
    Ok(scene)
}

/// Runs `plan` (key `key`, [`super::RunPlan::key`]) for `caption` from `start` with `models`:
/// progress (with SVG snapshots) goes to `sink`, `cancel` is polled between steps. With a job
/// context the SDS stage is checkpointed every `ctx.checkpoint_due` steps (and when cancelled),
/// and a [`TextCheckpoint`] of the same plan in `ctx.resume_state()` skips the stages before
/// SDS; a resumed run ends with the same SVG as an uninterrupted one (`detail.resumed_from`).
#[allow(clippy::too_many_arguments)]
pub fn run_text(
    models: &Models,
    plan: &TextPlan,
    key: &str,
    caption: &str,
    start: &Start,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
    ctx: Option<&JobContext>,
) -> Result<MethodOutput, PipelineError> {
    let teacher = models.teacher();
    let size = teacher.image_size();
    if size != plan.size {
        return Err(failed(
            "models",
            format!("loaded for {size} px, the plan says {} px", plan.size),
        ));
    }
    let mut detail = json!({
        "method": plan.method,
        "style": plan.style,
        "teacher": teacher.name(),
        "encoder": teacher.encoder(),
        "size": size,
        "prompt": plan.prompt,
    });
    let t0 = std::time::Instant::now();
    let resumed = resume_as::<TextCheckpoint>(ctx).filter(|c| c.key == key);

    // 1. The starting scene (or the saved SDS state of an interrupted attempt).
    let mut resume_sds = None;
    let start_scene: Scene = match (resumed, start) {
        (Some(r), _) => {
            detail = r.detail;
            detail["resumed_from"] = json!(r.sds.step);
            let scene = r.sds.scene.clone();
            resume_sds = Some(r.sds);
            scene
        }
        (None, Start::Svg(scene)) => scaled(scene, size),
        (None, Start::Image(image)) => {
            let (scene, d) = trace(image, size, plan, sink, cancel)?;
            detail["live"] = d;
            scaled(&scene, size)
        }
        (None, Start::Method) if plan.sample.is_none() => {
            let augment = plan.sds.as_ref().is_some_and(|s| s.augment);
            let mut rng = ChaCha8Rng::seed_from_u64(plan.seeds.init);
            plan.style
                .init_scene(render_size(size, augment), plan.paths as usize, &mut rng)
                .map_err(|e| failed("initial scene", e))?
        }
        (None, Start::Method) => from_samples(models, plan, caption, &mut detail, sink, cancel)?,
    };
    if cancel.is_cancelled() {
        return Err(PipelineError::Cancelled);
    }

    // 2. Score distillation.
    let mut scene = start_scene;
    if let Some(sp) = &plan.sds {
        let mut cfg = SdsConfig::for_style(plan.style, caption, sp.steps, size);
        cfg.prompt = plan.prompt.clone();
        cfg.guidance = sp.guidance;
        cfg.seed = plan.seeds.sds;
        cfg.snapshot_every = plan.snapshot_every;
        cfg.t_min = sp.t_min;
        cfg.t_max = sp.t_max;
        cfg.t_max_end = sp.t_max_end;
        cfg.grad_clip = sp.grad_clip;
        cfg.schedules = cfg.schedules.scaled(sp.lr_scale);
        if !sp.augment {
            cfg.augment = None;
        }
        if let Some(r) = cfg.reinit.as_mut() {
            r.min_area = sp.reinit_min_area;
        }
        let render = cfg.render_size(size);
        let state = match resume_sds {
            Some(s) => s,
            None => SdsState::start(scaled(&scene, render), &cfg),
        };
        let checkpoints = ctx.map(|ctx| JobCheckpoints {
            ctx,
            key,
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
        detail["sds"]["augment"] = json!(sp.augment);
        scene = scaled(&out.scene, size);
    }

    // 3. Prune faint/tiny shapes (styles of filled free-form shapes).
    let before = scene.shapes.len();
    let mut pruned = 0usize;
    if plan.style.spec().prune_weak() {
        let weak = weak_paths(&scene, MIN_OPACITY, min_area_at(size));
        if weak.len() < scene.shapes.len() {
            for &i in weak.iter().rev() {
                scene.shapes.remove(i);
            }
            pruned = weak.len();
        }
    }
    // 4. The vector stage's finish: simple outlines, no hidden paths, the colours asked for.
    let finish =
        crate::vector::finish_scene(&mut scene, &plan.colors, plan.style.spec().prune_weak());
    detail["finish"] = json!(finish);
    detail["editability"] = json!(crate::vector::check::check(&scene));
    detail["paths_initial"] = json!(before);
    detail["paths_pruned"] = json!(pruned);
    detail["paths_needed"] = json!(scene.shapes.len());
    detail["seconds"] = json!(t0.elapsed().as_secs_f64());
    scene.validate().map_err(|e| failed("final scene", e))?;
    let svg = crate::vector::write_svg(&scene, &plan.colors);
    // A drawing that started from a retrieved icon names it and its licence.
    let svg = match serde_json::from_value::<Hit>(detail["retrieval"]["chosen"].clone()) {
        Ok(h) => crate::svg::with_metadata(
            &svg,
            &format!(
                "Started from the icon \"{}\" of the {} {} icon set ({}, licence {}), redrawn by \
                 vectorfusion for the caption \"{}\".",
                h.icon.name, h.icon.set, h.icon.version, h.icon.caption, h.icon.license, caption
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
