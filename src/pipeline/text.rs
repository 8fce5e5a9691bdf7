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

use super::canvas::{kept_inside, placed};
use super::context::{resume_as, save_checkpoint};
use super::plan::{MIN_OPACITY, TextPlan, min_area_at};
use super::report::{ResumePoint, SdsReport, TraceReport};
use super::{JobContext, Models, PipelineError, RunOutput, RunReport};
use crate::caption::ColourSteer;
use crate::image::Image;
use crate::image::ops::resize;
use crate::progress::{CancelToken, CheckpointError, Progress, ProgressSink, Stage};
use crate::retrieval::Hit;
use crate::scene::Scene;
use crate::stages::live;
use crate::stages::live::prune::weak_paths;
use crate::stages::sds::{RasterBackend, SdsCheckpoint, SdsState, run_sds_resumable};
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
    let t0 = std::time::Instant::now();
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
    let report = TraceReport {
        seconds: Some(t0.elapsed().as_secs_f64()),
        ..TraceReport::from(&r)
    };
    Ok((r.scene, report))
}

fn scaled(scene: &Scene, width: u32) -> Scene {
    if scene.width == width {
        scene.clone()
    } else {
        scene.scaled_to_width(width)
    }
}

mod start;
pub use start::sample_ranked;
use start::{render_dims, start_scenes};

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
    let (width, _) = plan.sample_dims();
    let (render, _) = render_dims(plan);
    let state = match run.resume_sds.take() {
        Some(s) => s,
        None => {
            // A start without gradients (from scratch, a given SVG) gets them here.
            let mut start = scaled(&run.current.scene, render);
            plan.fill.paint_new(&mut start);
            SdsState::start(start, &cfg)
        }
    };
    let checkpoints = ctx.map(|ctx| JobCheckpoints {
        ctx,
        key,
        detail: &run.current.detail,
        done: &run.done,
        pending: &run.pending,
    });
    let t0 = std::time::Instant::now();
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
        seconds: Some(t0.elapsed().as_secs_f64()),
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
                scene.remove_shape(i);
            }
            pruned = weak.len();
        }
    }
    recolour_svg(scene, plan, report);
    let finish = crate::vector::finish_scene(scene, &plan.colors, plan.style.spec().prune_weak());
    if !plan.fill.is_flat() {
        crate::vector::fill::tidy_gradients(scene);
    }
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

/// The finished output of a variation distilled to `scene` as `plan` says: pruned and
/// finished ([`finish`]), validated and written, naming the icon it started from.
fn output(
    mut scene: Scene,
    plan: &TextPlan,
    mut report: RunReport,
    caption: &str,
    t0: std::time::Instant,
) -> Result<RunOutput, PipelineError> {
    // On a canvas of its own, no shape reaches past the sample's edge, where the canvas now
    // goes on ...
    if plan.canvas.is_some() {
        kept_inside(&mut scene);
    }
    finish(&mut scene, plan, &mut report);
    // ... then the sample fitted and centred on the SVG's canvas.
    if let Some(c) = plan.canvas {
        scene = placed(&scene, c.width, c.height);
    }
    report.seconds = Some(t0.elapsed().as_secs_f64());
    scene.validate().map_err(PipelineError::scene("final"))?;
    let svg = crate::vector::write_svg(&scene, &plan.colors);
    let svg = with_origin(svg, &report, caption);
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
    let dims = models.teacher().image_dims();
    if dims != plan.sample_dims() {
        return Err(PipelineError::Failed(format!(
            "models: loaded for {dims:?} px, the plan says {:?} px",
            plan.sample_dims()
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
    let out = outputs
        .next()
        .ok_or_else(|| PipelineError::Failed("plan: a run of no variations".into()))?
        .with_variations(outputs.collect());
    let mut done = Progress::new(Stage::Done, 1, 1);
    done.svg = Some(out.svg.clone());
    sink.report(done);
    Ok(out)
}
