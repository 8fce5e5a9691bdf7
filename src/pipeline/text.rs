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

use super::context::{resume_as, save_checkpoint};
use super::plan::{MIN_OPACITY, TextPlan, min_area_at, render_size};
use super::report::{
    RerankReport, ResumePoint, RetrievalReport, RunMethod, SdsReport, TraceReport, VariationReport,
};
use super::{JobContext, Models, PipelineError, RunOutput, RunReport};
use crate::image::Image;
use crate::image::ops::resize;
use crate::models::scorer::ImageTextScorer;
use crate::progress::{CancelToken, CheckpointError, Progress, ProgressSink, Stage};
use crate::retrieval::Hit;
use crate::scene::Scene;
use crate::stages::live;
use crate::stages::live::prune::weak_paths;
use crate::stages::sample::{Ranked, RetrievalPick, retrieved_count, sample_and_rerank};
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
/// A run of several variations checkpoints the SDS of the one it is on (the finished ones
/// and the starts of the later ones with it), and goes on from that one.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TextCheckpoint {
    /// The plan the state belongs to ([`super::RunPlan::key`]); another plan ignores it.
    pub key: String,
    /// The run's report when SDS started (rerank scores, LIVE statistics).
    pub detail: RunReport,
    pub sds: SdsState,
    /// The variations finished before this one.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub done: Vec<RunOutput>,
    /// The starts of the variations after this one.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub pending: Vec<VariationStart>,
}

/// Where one variation of a text run starts SDS: its report so far and its scene.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct VariationStart {
    pub detail: RunReport,
    pub scene: Scene,
}

/// A text run between its stages: the variations finished, the one it is on (with its saved
/// SDS state when resumed) and the starts of the later ones.
struct Variations {
    done: Vec<RunOutput>,
    current: VariationStart,
    resume_sds: Option<SdsState>,
    pending: std::collections::VecDeque<VariationStart>,
}

struct JobCheckpoints<'a> {
    ctx: &'a JobContext,
    key: &'a str,
    detail: &'a RunReport,
    done: &'a [RunOutput],
    pending: &'a std::collections::VecDeque<VariationStart>,
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
                done: self.done.to_vec(),
                pending: self.pending.iter().cloned().collect(),
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
    while scene.shapes.len() < want {
        let shape = spec
            .extra_shape(plan.size, &mut rng)
            .map_err(PipelineError::scene("initial"))?;
        scene.shapes.push(shape);
        added += 1;
    }
    Ok(added)
}

/// The starting scenes from the best [`TextPlan::variations`] of K samples (`sd_live*`), each
/// with the rerank and retrieval (its own sample chosen) in its report.
fn from_samples(
    models: &Models,
    plan: &TextPlan,
    caption: &str,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<Vec<VariationStart>, PipelineError> {
    let (ranked, why_not) = sample_ranked(models, plan, caption, sink, cancel)?;
    let (rerank, retrieval) = rerank_reports(models, plan, &ranked, why_not)?;
    let mut ev = Progress::new(Stage::Rerank, 1, 1);
    ev.detail = serde_json::to_value(&rerank).ok();
    sink.report(ev);
    let picks = ranked.top(plan.variations as usize);
    let mut starts = Vec::with_capacity(picks.len());
    for (i, &chosen) in picks.iter().enumerate() {
        let mut detail = first_report(models, plan);
        detail.rerank = Some(RerankReport {
            chosen,
            ..rerank.clone()
        });
        detail.retrieval = Some(RetrievalReport {
            chosen: ranked.sources()[chosen].clone(),
            ..retrieval.clone()
        });
        let image = &ranked.images()[chosen];
        let scene = from_sample(image, &plan.variation(i), &mut detail, sink, cancel)?;
        starts.push(VariationStart { detail, scene });
    }
    Ok(starts)
}

/// The starting scene of `plan` from the sampled `image`: the style's scene of the image, or
/// its LIVE trace (restyled, topped up; the statistics in `report`).
fn from_sample(
    image: &Image,
    plan: &TextPlan,
    report: &mut RunReport,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<Scene, PipelineError> {
    let size = plan.size;
    let spec = plan.style.spec();
    if spec.sample_start() == SampleStart::Image {
        return spec
            .scene_from_image(image, size)
            .map_err(PipelineError::scene("initial"));
    }
    let best_img = upscaled(image, plan.trace.size);
    let (scene, traced) = trace(&best_img, plan, sink, cancel)?;
    report.live = Some(traced);
    let mut scene = spec
        .restyle_trace(scaled(&scene, size), size)
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

/// The scenes a text run starts SDS from, one per variation, each with its report.
fn start_scenes(
    models: &Models,
    plan: &TextPlan,
    caption: &str,
    start: &Start,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<Vec<VariationStart>, PipelineError> {
    if matches!(start, Start::Method) && plan.sample.is_some() {
        return from_samples(models, plan, caption, sink, cancel);
    }
    let size = plan.size;
    let augment = plan.sds.as_ref().is_some_and(|s| s.augment);
    // Each variation from the same input, with its own seeds (trace, init, SDS).
    (0..plan.variations as usize)
        .map(|i| {
            let vplan = plan.variation(i);
            let mut detail = first_report(models, plan);
            let scene = match start {
                Start::Svg(scene) => scaled(scene, size),
                Start::Image(image) => {
                    let (scene, traced) = trace(image, &vplan, sink, cancel)?;
                    detail.live = Some(traced);
                    scaled(&scene, size)
                }
                Start::Method => {
                    let mut rng = ChaCha8Rng::seed_from_u64(vplan.seeds.init);
                    plan.style
                        .init_scene(render_size(size, augment), plan.paths as usize, &mut rng)
                        .map_err(PipelineError::scene("initial"))?
                }
            };
            Ok(VariationStart { detail, scene })
        })
        .collect()
}

/// Where a text run starts: from `resumed` (an interrupted attempt's checkpoint of this plan)
/// when given, otherwise from the start scenes of every variation.
fn begin(
    models: &Models,
    plan: &TextPlan,
    caption: &str,
    start: &Start,
    resumed: Option<TextCheckpoint>,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<Variations, PipelineError> {
    if let Some(r) = resumed {
        let mut detail = r.detail;
        detail.resumed = Some(ResumePoint::Step(r.sds.step));
        return Ok(Variations {
            done: r.done,
            current: VariationStart {
                detail,
                scene: r.sds.scene.clone(),
            },
            resume_sds: Some(r.sds),
            pending: r.pending.into(),
        });
    }
    let mut starts: std::collections::VecDeque<VariationStart> =
        start_scenes(models, plan, caption, start, sink, cancel)?.into();
    let current = starts
        .pop_front()
        .ok_or_else(|| PipelineError::Failed("plan: a run of no variations".into()))?;
    Ok(Variations {
        done: Vec::new(),
        current,
        resume_sds: None,
        pending: starts,
    })
}

/// Score distillation of `run`'s current variation (or on from its saved state) as `plan`
/// says, checkpointed through `ctx` with the run under `key`; the distilled scene at the
/// teacher's size, the SDS statistics in the variation's report.
fn distil(
    models: &Models,
    plan: &TextPlan,
    key: &str,
    run: &mut Variations,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
    ctx: Option<&JobContext>,
) -> Result<Scene, PipelineError> {
    let (Some(sp), Some(cfg)) = (&plan.sds, plan.sds_config()) else {
        return Ok(run.current.scene.clone());
    };
    let render = cfg.render_size(plan.size);
    let state = match run.resume_sds.take() {
        Some(s) => s,
        None => SdsState::start(scaled(&run.current.scene, render), &cfg),
    };
    let checkpoints = ctx.map(|ctx| JobCheckpoints {
        ctx,
        key,
        detail: &run.current.detail,
        done: &run.done,
        pending: &run.pending,
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
    run.current.detail.sds = Some(SdsReport {
        stats: out.stats,
        augment: sp.augment,
    });
    Ok(scaled(&out.scene, plan.size))
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
    let finish = crate::vector::finish_scene(scene, &plan.colors, plan.style.spec().prune_weak());
    report.finish = Some(finish);
    report.editability = Some(crate::vector::check::check(scene));
    report.paths_initial = Some(before);
    report.paths_pruned = Some(pruned);
    report.paths_needed = Some(scene.shapes.len());
}

/// `svg` naming the retrieved icon `origin` it started from and its licence, if any.
fn with_origin(svg: String, origin: Option<&Hit>, caption: &str) -> String {
    match origin {
        Some(h) => crate::svg::with_metadata(
            &svg,
            &format!(
                "Started from the icon \"{}\" of the {} {} icon set ({}, licence {}), redrawn by \
                 vectorfusion for the caption \"{}\".",
                h.icon.name, h.icon.set, h.icon.version, h.icon.caption, h.icon.license, caption
            ),
        ),
        None => svg,
    }
}

/// The finished output of a variation distilled to `scene` as `plan` says: pruned and
/// finished ([`finish`]), validated and written, naming the icon it started from.
fn output(
    mut scene: Scene,
    plan: &TextPlan,
    mut report: RunReport,
    caption: &str,
    t0: std::time::Instant,
) -> Result<RunOutput, PipelineError> {
    finish(&mut scene, plan, &mut report);
    report.seconds = Some(t0.elapsed().as_secs_f64());
    scene.validate().map_err(PipelineError::scene("final"))?;
    let svg = crate::vector::write_svg(&scene, &plan.colors);
    let origin = report.retrieval.as_ref().and_then(|r| r.chosen.as_ref());
    let svg = with_origin(svg, origin, caption);
    Ok(RunOutput::new(scene, svg, report))
}

/// Runs `plan` (key `key`, [`super::RunPlan::key`]) for `caption` from `start` with `models`:
/// progress (with SVG snapshots) goes to `sink`, `cancel` is polled between steps. With a job
/// context the SDS stage is checkpointed every `ctx.checkpoint_due` steps (and when cancelled),
/// and a [`TextCheckpoint`] of the same plan in `ctx.resume_state()` skips the stages before
/// SDS; a resumed run ends with the same SVG as an uninterrupted one
/// ([`RunReport::resumed`]). A plan of several variations distils them one after the other
/// (variation `i` with [`TextPlan::variation`]'s seeds); the output is the first, with the
/// others in [`RunOutput::variations`] and a summary of all in [`RunReport::variations`].
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
    let size = models.teacher().image_size();
    if size != plan.size {
        return Err(PipelineError::Failed(format!(
            "models: loaded for {size} px, the plan says {} px",
            plan.size
        )));
    }
    let t0 = std::time::Instant::now();
    let resumed = resume_as::<TextCheckpoint>(ctx).filter(|c| c.key == key);
    // 1. The starting scenes (or the saved state of an interrupted attempt).
    let mut run = begin(models, plan, caption, start, resumed, sink, cancel)?;
    loop {
        if cancel.is_cancelled() {
            return Err(PipelineError::Cancelled);
        }
        let vplan = plan.variation(run.done.len());
        // 2. Score distillation.
        let scene = distil(models, &vplan, key, &mut run, sink, cancel, ctx)?;
        // 3. Pruning and the vector stage's finish.
        let detail = std::mem::take(&mut run.current.detail);
        run.done.push(output(scene, &vplan, detail, caption, t0)?);
        match run.pending.pop_front() {
            Some(next) => run.current = next,
            None => break,
        }
    }
    let mut outputs = run.done.into_iter();
    let mut out = outputs
        .next()
        .ok_or_else(|| PipelineError::Failed("plan: a run of no variations".into()))?;
    out.variations = outputs.collect();
    if !out.variations.is_empty() {
        out.report.variations = std::iter::once(&out)
            .chain(&out.variations)
            .zip(1..)
            .map(|(o, n)| VariationReport::of(n, &o.report, o.paths))
            .collect();
    }
    let mut done = Progress::new(Stage::Done, 1, 1);
    done.svg = Some(out.svg.clone());
    sink.report(done);
    Ok(out)
}
