//! Where a text run starts SDS, one scene per variation: the K samples and their rerank (the
//! best distinct ones traced or restyled), a given image traced, a given SVG, or the style's
//! random init.

use super::{Start, VariationStart, no_sample_plan, scaled, trace};
use crate::image::Image;
use crate::image::ops::resize;
use crate::models::scorer::ImageTextScorer;
use crate::pipeline::canvas::{map_shape, stretched};
use crate::pipeline::plan::TextPlan;
use crate::pipeline::report::{RerankReport, RetrievalReport, RunMethod};
use crate::pipeline::{Models, PipelineError, RunReport};
use crate::progress::{CancelToken, Progress, ProgressSink, Stage};
use crate::scene::Scene;
use crate::stages::sample::{NoStarts, Ranked, RetrievalPick, retrieved_count, sample_and_rerank};
use crate::stages::styles::SampleStart;
use crate::teacher::SampleConfig;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

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
        size_conditioning: plan.size_conditioning,
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
        seconds: None,
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
pub(super) fn render_dims(plan: &TextPlan) -> (u32, u32) {
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

/// The starting scenes from the best [`TextPlan::variations`] of K samples (`sd_live*`), each
/// with the rerank and retrieval (its own sample chosen) in its report.
fn from_samples(
    models: &Models,
    plan: &TextPlan,
    caption: &str,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<Vec<VariationStart>, PipelineError> {
    let t0 = std::time::Instant::now();
    let (ranked, why_not) = sample_ranked(models, plan, caption, sink, cancel)?;
    let (mut rerank, retrieval) = rerank_reports(models, plan, &ranked, why_not)?;
    rerank.seconds = Some(t0.elapsed().as_secs_f64());
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
        detail.caption = ranked.caption().cloned();
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
    let (width, height) = plan.sample_dims();
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
        fill: (!plan.fill.is_flat()).then_some(plan.fill),
        ..RunReport::default()
    }
}

/// The scenes a text run starts SDS from, one per variation, each with its report.
pub(super) fn start_scenes(
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
    let (size, _) = plan.sample_dims();
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
                Start::Method => init_scene(&vplan, render_dims(&vplan))?,
            };
            Ok(VariationStart { detail, scene })
        })
        .collect()
}
