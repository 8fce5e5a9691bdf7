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
//! reported in the run's [`RunReport`]. The SDS stage checkpoints through the job context and a
//! restarted job resumes from it to the identical SVG.

use super::canvas::{kept_inside, map_shape, placed, stretched};
use super::context::{resume_as, save_checkpoint};
use super::plan::{MIN_OPACITY, TextPlan, min_area_at};
use super::report::{
    RerankReport, ResumePoint, RetrievalReport, RunMethod, SdsReport, TraceReport,
};
use super::{JobContext, Models, PipelineError, RunOutput, RunReport};
use crate::caption::ColourSteer;
use crate::image::Image;
use crate::image::ops::resize;
use crate::models::scorer::ImageTextScorer;
use crate::progress::{CancelToken, CheckpointError, Progress, ProgressSink, Stage};
use crate::retrieval::Hit;
use crate::scene::Scene;
use crate::stages::live;
use crate::stages::live::prune::weak_paths;
use crate::stages::sample::{NoStarts, Ranked, RetrievalPick, retrieved_count, sample_and_rerank};
use crate::stages::sds::{RasterBackend, SdsCheckpoint, SdsState, run_sds_resumable};
use crate::stages::styles::SampleStart;
use crate::teacher::SampleConfig;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

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

/// A sampled start without a sample plan (a plan `resolve` never makes).
fn no_sample_plan() -> PipelineError {
    PipelineError::Failed("plan: a sampled start needs a sample plan".into())
}

/// What a text run checkpoints (the service stores it with the job): the SDS loop's state and
/// what the stages before it produced, so a resumed run skips sampling, rerank and tracing.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TextCheckpoint {
    /// The plan the state belongs to ([`super::RunPlan::key`]); another plan ignores it.
    pub key: String,
    /// The run's report when SDS started (rerank scores, LIVE statistics).
    pub detail: RunReport,
    pub sds: SdsState,
}

struct JobCheckpoints<'a> {
    ctx: &'a JobContext,
    key: &'a str,
    detail: &'a RunReport,
}

impl SdsCheckpoint for JobCheckpoints<'_> {
    fn due(&self, step: u32) -> bool {
        self.ctx.checkpoint_due(step)
    }

    fn save(&self, state: &SdsState) -> Result<(), CheckpointError> {
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

/// Traces `image` as the plan says ([`TextPlan::trace_config`]), downscaled to its canvas.
fn trace(
    image: &Image,
    plan: &TextPlan,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<(Scene, TraceReport), PipelineError> {
    let cfg = plan.trace_config();
    let size = cfg.size;
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
    let r = live::vectorize(&img, &cfg, sink, cancel)?;
    let report = TraceReport::from(&r);
    Ok((r.scene, report))
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
    let sp = plan.sample.as_ref().ok_or_else(no_sample_plan)?;
    let n = retrieved_count(sp.samples, sp.retrieval_share);
    let retrieval = if !sp.retrieval {
        Err(&NoStarts::Off)
    } else if n == 0 {
        Err(&NoStarts::NoShare)
    } else {
        models.retrieval.as_deref().map(|i| {
            let pick = RetrievalPick {
                n,
                per_caption: sp.retrieval_per_caption as usize,
                seed: plan.seeds.sample,
            };
            (i, pick)
        })
    };
    let cfg = SampleConfig {
        k: sp.samples,
        steps: sp.steps as usize,
        guidance: f64::from(sp.guidance),
        seed: plan.seeds.sample,
        strength: sp.strength,
        negative_prompt: plan.negative_prompt.clone().unwrap_or_default(),
    };
    sample_and_rerank(
        models.teacher(),
        models.scorer.as_ref(),
        retrieval,
        &plan.prompt,
        caption,
        plan.caption.as_ref(),
        &cfg,
        sink,
        cancel,
    )
    .map_err(PipelineError::from)
}

/// The rerank and retrieval of `ranked`, the samples of `plan` (`why_not`: why none started
/// from a retrieved icon).
fn rerank_reports(
    models: &Models,
    plan: &TextPlan,
    ranked: &Ranked,
    why_not: Option<String>,
) -> Result<(RerankReport, RetrievalReport), PipelineError> {
    let sp = plan.sample.as_ref().ok_or_else(no_sample_plan)?;
    let rerank = RerankReport {
        scorer: models.scorer.as_ref().map(|s| s.name().to_string()),
        scores: ranked.scores().iter().map(|&s| f64::from(s)).collect(),
        chosen: ranked.best(),
        samples: sp.samples,
        sources: ranked.sources().to_vec(),
    };
    let retrieval = RetrievalReport {
        strength: sp.strength,
        share: sp.retrieval_share,
        per_caption: sp.retrieval_per_caption,
        starts: ranked.sources().iter().flatten().cloned().collect(),
        chosen: ranked.best_source().cloned(),
        unavailable: why_not,
    };
    Ok((rerank, retrieval))
}

/// `image` scaled up so its longer side is `side` (small samples of a 32 px pixel-space prior
/// are traced on the larger canvas); a large enough image as it is.
fn upscaled(image: &Image, side: u32) -> std::borrow::Cow<'_, Image> {
    let longer = image.width.max(image.height);
    if longer >= side {
        return std::borrow::Cow::Borrowed(image);
    }
    let k = side as f32 / longer as f32;
    std::borrow::Cow::Owned(resize(
        image,
        ((image.width as f32 * k).round() as u32).max(1),
        ((image.height as f32 * k).round() as u32).max(1),
    ))
}

/// Tops `scene` up with the style's random shapes to the style's minimum for `plan` (a flat
/// sample can trace to (almost) nothing, and SDS needs something to move). Returns how many
/// were added.
fn top_up(scene: &mut Scene, plan: &TextPlan) -> Result<usize, PipelineError> {
    let spec = plan.style.spec();
    let want = spec.min_shapes(plan.paths as usize);
    let mut rng = ChaCha8Rng::seed_from_u64(plan.seeds.top_up);
    let mut added = 0usize;
    // Drawn on a square of the sample's longer side, stretched to the sample.
    let (w, h) = plan.sample_dims();
    let side = w.max(h);
    let k = (w as f32 / side as f32, h as f32 / side as f32);
    while scene.shapes.len() < want {
        let shape = spec
            .extra_shape(side, &mut rng)
            .map_err(PipelineError::scene("initial"))?;
        scene.shapes.push(if w == h {
            shape
        } else {
            map_shape(&shape, k, (0.0, 0.0))
        });
        added += 1;
    }
    Ok(added)
}

/// `(width, height)` SDS renders `plan`'s scene at: the sample's, or larger where
/// augmentation crops.
fn render_dims(plan: &TextPlan) -> (u32, u32) {
    plan.sds_config()
        .and_then(|c| c.augment)
        .map_or(plan.sample_dims(), |a| a.render_dims())
}

/// The style's random from-scratch scene at `(w, h)`: drawn on a square of the longer side,
/// stretched to a non-square canvas.
fn init_scene(plan: &TextPlan, (w, h): (u32, u32)) -> Result<Scene, PipelineError> {
    let mut rng = ChaCha8Rng::seed_from_u64(plan.seeds.init);
    let scene = plan
        .style
        .init_scene(w.max(h), plan.paths as usize, &mut rng)
        .map_err(PipelineError::scene("initial"))?;
    Ok(if w == h {
        scene
    } else {
        stretched(&scene, w, h)
    })
}

/// The starting scene from the best of K samples (`sd_live*`), with the rerank and retrieval
/// in `report`.
fn from_samples(
    models: &Models,
    plan: &TextPlan,
    caption: &str,
    report: &mut RunReport,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<Scene, PipelineError> {
    let size = plan.size;
    let (width, height) = plan.sample_dims();
    let (ranked, why_not) = sample_ranked(models, plan, caption, sink, cancel)?;
    let (rerank, retrieval) = rerank_reports(models, plan, &ranked, why_not)?;
    let mut ev = Progress::new(Stage::Rerank, 1, 1);
    ev.detail = serde_json::to_value(&rerank).ok();
    sink.report(ev);
    report.rerank = Some(rerank);
    report.retrieval = Some(retrieval);
    report.caption = ranked.caption().cloned();
    let spec = plan.style.spec();
    if spec.sample_start() == SampleStart::Image {
        return spec
            .scene_from_image(ranked.best_image(), size)
            .map_err(PipelineError::scene("initial"));
    }
    let best_img = upscaled(ranked.best_image(), plan.trace.size);
    let (scene, traced) = trace(&best_img, plan, sink, cancel)?;
    report.live = Some(traced);
    let mut scene = spec
        .restyle_trace(scaled(&scene, width), width.min(height))
        .map_err(PipelineError::scene("initial"))?;
    report.topped_up = Some(top_up(&mut scene, plan)?);
    Ok(scene)
}

/// The report a text run starts with: what runs, with which teacher.
fn first_report(models: &Models, plan: &TextPlan) -> RunReport {
    let teacher = models.teacher();
    RunReport {
        method: Some(RunMethod::from(plan.method)),
        style: Some(plan.style),
        teacher: Some(teacher.name()),
        encoder: Some(teacher.encoder().to_string()),
        size: Some(plan.size),
        prompt: Some(plan.prompt.clone()),
        ..RunReport::default()
    }
}

/// The scene a text run starts SDS from, and the saved SDS state when `resumed` (an
/// interrupted attempt's checkpoint of this plan) is given; fills `report`.
#[allow(clippy::too_many_arguments)]
fn start_scene(
    models: &Models,
    plan: &TextPlan,
    caption: &str,
    start: &Start,
    resumed: Option<TextCheckpoint>,
    report: &mut RunReport,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<(Scene, Option<SdsState>), PipelineError> {
    let (size, _) = plan.sample_dims();
    let scene = match (resumed, start) {
        (Some(r), _) => {
            *report = r.detail;
            report.resumed = Some(ResumePoint::Step(r.sds.step));
            return Ok((r.sds.scene.clone(), Some(r.sds)));
        }
        (None, Start::Svg(scene)) => scaled(scene, size),
        (None, Start::Image(image)) => {
            let (scene, traced) = trace(image, plan, sink, cancel)?;
            report.live = Some(traced);
            scaled(&scene, size)
        }
        (None, Start::Method) if plan.sample.is_none() => init_scene(plan, render_dims(plan))?,
        (None, Start::Method) => from_samples(models, plan, caption, report, sink, cancel)?,
    };
    Ok((scene, None))
}

/// Score distillation of `scene` (or on from `resume_sds`) as `plan` says, checkpointed
/// through `ctx` with `report` under `key`; the distilled scene at the teacher's size.
#[allow(clippy::too_many_arguments)]
fn distil(
    models: &Models,
    plan: &TextPlan,
    key: &str,
    scene: Scene,
    resume_sds: Option<SdsState>,
    report: &mut RunReport,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
    ctx: Option<&JobContext>,
) -> Result<Scene, PipelineError> {
    let (Some(sp), Some(cfg)) = (&plan.sds, plan.sds_config()) else {
        return Ok(scene);
    };
    let (width, _) = plan.sample_dims();
    let (render, _) = render_dims(plan);
    let state = match resume_sds {
        Some(s) => s,
        None => SdsState::start(scaled(&scene, render), &cfg),
    };
    let checkpoints = ctx.map(|ctx| JobCheckpoints {
        ctx,
        key,
        detail: report,
    });
    let out = run_sds_resumable(
        &RasterBackend,
        models.teacher(),
        state,
        &cfg,
        sink,
        cancel,
        checkpoints.as_ref().map(|c| c as &dyn SdsCheckpoint),
    )?;
    if out.stats.cancelled {
        return Err(PipelineError::Cancelled);
    }
    report.sds = Some(SdsReport {
        stats: out.stats,
        augment: sp.augment,
    });
    Ok(scaled(&out.scene, width))
}

/// The end of a text run: the style's faint/tiny shapes pruned, then the vector stage's
/// finish (simple outlines, no hidden paths, the colours asked for); the counts in `report`.
fn finish(scene: &mut Scene, plan: &TextPlan, report: &mut RunReport) {
    let before = scene.shapes.len();
    let mut pruned = 0usize;
    if plan.style.spec().prune_weak() {
        let weak = weak_paths(scene, MIN_OPACITY, min_area_at(plan.size));
        if weak.len() < scene.shapes.len() {
            for &i in weak.iter().rev() {
                scene.shapes.remove(i);
            }
            pruned = weak.len();
        }
    }
    recolour_svg(scene, plan, report);
    let finish = crate::vector::finish_scene(scene, &plan.colors, plan.style.spec().prune_weak());
    report.finish = Some(finish);
    report.editability = Some(crate::vector::check::check(scene));
    report.paths_initial = Some(before);
    report.paths_pruned = Some(pruned);
    report.paths_needed = Some(scene.shapes.len());
}

/// The final scene's largest colour family moved into the caption's colour, when the model's
/// steering goes that far ([`ColourSteer::Svg`]) and the run sampled (one object, one colour).
fn recolour_svg(scene: &mut Scene, plan: &TextPlan, report: &mut RunReport) {
    let (Some(cp), Some(r)) = (&plan.caption, report.caption.as_mut()) else {
        return;
    };
    if cp.steer < ColourSteer::Svg || cp.is_pair() {
        return;
    }
    if let Some(c) = cp.colour() {
        r.svg_recoloured = crate::caption::recolour::recolour_scene(scene, c);
    }
}

/// A retrieved icon for the SVG's metadata: name, set, version, caption and licence.
fn icon_credit(h: &Hit) -> String {
    format!(
        "the icon \"{}\" of the {} {} icon set ({}, licence {})",
        h.icon.name, h.icon.set, h.icon.version, h.icon.caption, h.icon.license
    )
}

/// `svg` naming the retrieved icon the kept sample started from and its licence (and the
/// second icon composed into that start, for a caption of two things), if any.
fn with_origin(svg: String, report: &RunReport, caption: &str) -> String {
    let Some(h) = report.retrieval.as_ref().and_then(|r| r.chosen.as_ref()) else {
        return svg;
    };
    let chosen = report.rerank.as_ref().map_or(0, |r| r.chosen);
    let second = report
        .caption
        .as_ref()
        .and_then(|c| c.composed_with.get(chosen))
        .map(|o| format!(" composed with {}", icon_credit(o)))
        .unwrap_or_default();
    crate::svg::with_metadata(
        &svg,
        &format!(
            "Started from {}{second}, redrawn by vectorfusion for the caption \"{caption}\".",
            icon_credit(h)
        ),
    )
}

/// Runs `plan` (key `key`, [`super::RunPlan::key`]) for `caption` from `start` with `models`:
/// progress (with SVG snapshots) goes to `sink`, `cancel` is polled between steps. With a job
/// context the SDS stage is checkpointed every `ctx.checkpoint_due` steps (and when cancelled),
/// and a [`TextCheckpoint`] of the same plan in `ctx.resume_state()` skips the stages before
/// SDS; a resumed run ends with the same SVG as an uninterrupted one
/// ([`RunReport::resumed`]).
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
) -> Result<RunOutput, PipelineError> {
    let dims = models.teacher().image_dims();
    if dims != plan.sample_dims() {
        return Err(PipelineError::Failed(format!(
            "models: loaded for {dims:?} px, the plan says {:?} px",
            plan.sample_dims()
        )));
    }
    let mut report = first_report(models, plan);
    let t0 = std::time::Instant::now();
    let resumed = resume_as::<TextCheckpoint>(ctx).filter(|c| c.key == key);
    // 1. The starting scene (or the saved SDS state of an interrupted attempt).
    let (scene, resume_sds) = start_scene(
        models,
        plan,
        caption,
        start,
        resumed,
        &mut report,
        sink,
        cancel,
    )?;
    if cancel.is_cancelled() {
        return Err(PipelineError::Cancelled);
    }
    // 2. Score distillation.
    let mut scene = distil(
        models,
        plan,
        key,
        scene,
        resume_sds,
        &mut report,
        sink,
        cancel,
        ctx,
    )?;
    // 3. Pruning and the vector stage's finish (on a canvas of its own, no shape reaches past
    // the sample's edge, where the canvas now goes on) ...
    if plan.canvas.is_some() {
        kept_inside(&mut scene);
    }
    finish(&mut scene, plan, &mut report);
    // 4. ... then the sample fitted and centred on the SVG's canvas.
    if let Some(c) = plan.canvas {
        scene = placed(&scene, c.width, c.height);
    }
    report.seconds = Some(t0.elapsed().as_secs_f64());
    scene.validate().map_err(PipelineError::scene("final"))?;
    let svg = crate::vector::write_svg(&scene, &plan.colors);
    let svg = with_origin(svg, &report, caption);
    let mut done = Progress::new(Stage::Done, 1, 1);
    done.svg = Some(svg.clone());
    sink.report(done);
    Ok(RunOutput::new(scene, svg, report))
}
