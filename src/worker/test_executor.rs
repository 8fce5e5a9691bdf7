//! A test double for the service, NOT a product feature: an [`Executor`] that draws a small,
//! deterministic scene of circles (one per requested path, laid out from the seed) with
//! [`crate::scene`], pretending to optimise it for `steps` steps of `step_ms` each. It emits
//! progress and SVG snapshots, checkpoints `{ "step": n }` when due and when cancelled, resumes
//! from a checkpoint, honours cancellation between steps, and validates input images by decoding them. It exists so
//! the queue, workers, SSE and crash recovery can be tested end to end before (and independently
//! of) the real pipeline. The server binary enables it only through the hidden
//! `serve --test-executor STEP_MS` flag.

use crate::pipeline::{
    Executor, JobContext, JobKind, JobSpec, PipelineError, ResumePoint, RunOutput, RunPlan,
    RunReport,
};
use crate::progress::{Progress, Stage};
use crate::scene::{Rgba, Scene, Shape, ShapeKind};
use std::fmt::Write;
use std::time::Duration;

/// Side of the drawn canvas, pixels.
const SIDE: u32 = 64;
/// Snapshot cadence in steps.
const SNAPSHOT_EVERY: u32 = 2;

/// See the module docs.
#[derive(Clone, Debug)]
pub struct TestExecutor {
    pub step_ms: u64,
    pub text_ready: bool,
}

impl TestExecutor {
    pub fn new(step_ms: u64) -> Self {
        TestExecutor {
            step_ms,
            text_ready: true,
        }
    }
}

fn splitmix(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = x;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn unit(seed: u64, i: u64) -> f32 {
    (splitmix(seed ^ splitmix(i)) >> 40) as f32 / (1u64 << 24) as f32
}

/// The scene after `step` of `total` steps: circles drift from the centre to their places.
pub fn scene_at(seed: u64, paths: u32, step: u32, total: u32) -> Result<Scene, PipelineError> {
    let mut scene =
        Scene::new(SIDE, SIDE, Rgba::WHITE).map_err(|e| PipelineError::Failed(e.to_string()))?;
    let t = if total == 0 {
        1.0
    } else {
        step as f32 / total as f32
    };
    let c = SIDE as f32 / 2.0;
    for i in 0..paths as u64 {
        let tx = 6.0 + unit(seed, 5 * i) * (SIDE as f32 - 12.0);
        let ty = 6.0 + unit(seed, 5 * i + 1) * (SIDE as f32 - 12.0);
        let r = 2.0 + unit(seed, 5 * i + 2) * 6.0;
        let fill = Rgba::new(
            unit(seed, 5 * i + 3),
            unit(seed, 5 * i + 4),
            unit(seed ^ 1, i),
            1.0,
        );
        let shape = Shape::circle(c + (tx - c) * t, c + (ty - c) * t, r, 4, fill)
            .map_err(|e| PipelineError::Failed(e.to_string()))?;
        scene.shapes.push(shape);
    }
    Ok(scene)
}

/// Minimal SVG writer for the test scenes (closed cubic paths with fills).
pub fn scene_svg(scene: &Scene) -> String {
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\">",
        w = scene.width,
        h = scene.height
    );
    let col = |c: Rgba| {
        format!(
            "rgb({},{},{})",
            (c.r * 255.0).round(),
            (c.g * 255.0).round(),
            (c.b * 255.0).round()
        )
    };
    let _ = write!(
        s,
        "<rect width=\"{}\" height=\"{}\" fill=\"{}\"/>",
        scene.width,
        scene.height,
        col(scene.background)
    );
    for shape in &scene.shapes {
        if shape.kind != ShapeKind::ClosedCubic || shape.points.is_empty() {
            continue;
        }
        let p = &shape.points;
        let mut d = format!("M{:.2} {:.2}", p[0].x, p[0].y);
        for seg in 0..p.len() / 3 {
            let q = |k: usize| p[(3 * seg + k) % p.len()];
            let _ = write!(
                d,
                "C{:.2} {:.2} {:.2} {:.2} {:.2} {:.2}",
                q(1).x,
                q(1).y,
                q(2).x,
                q(2).y,
                q(3).x,
                q(3).y
            );
        }
        d.push('Z');
        let fill = shape.fill.map_or("none".to_string(), col);
        let _ = write!(s, "<path d=\"{d}\" fill=\"{fill}\"/>");
    }
    s.push_str("</svg>");
    s
}

/// The steps and paths a job pretends to run: its plan's, or as given, or (the steps of a
/// vectorize job, the paths of a job without a plan) the preset's.
fn steps_and_paths(spec: &JobSpec) -> (u32, u32) {
    let plan = spec.plan.as_ref();
    let preset = spec.preset.settings();
    let steps = plan.and_then(RunPlan::sds_steps).or(spec.steps);
    let paths = plan.and_then(RunPlan::paths).or(spec.paths);
    (
        steps.unwrap_or(preset.steps),
        paths.unwrap_or(u32::try_from(preset.paths).unwrap_or(u32::MAX)),
    )
}

impl Executor for TestExecutor {
    fn run(&self, spec: &JobSpec, ctx: &JobContext) -> Result<RunOutput, PipelineError> {
        if spec.kind == JobKind::Vectorize {
            let bytes = spec
                .image
                .as_deref()
                .ok_or_else(|| PipelineError::InvalidInput("vectorize needs an image".into()))?;
            crate::image::Image::decode(bytes)
                .map_err(|e| PipelineError::InvalidInput(e.to_string()))?;
        }
        let (steps, paths) = steps_and_paths(spec);
        let resumed_from = ctx
            .resume_state()
            .and_then(|v| v.get("step").and_then(|s| s.as_u64()))
            .map_or(0, |s| s.min(steps as u64) as u32);
        for step in resumed_from + 1..=steps {
            if ctx.is_cancelled() {
                // Save the work done so far, so a shutdown loses nothing (a failed save only
                // means the next attempt resumes from the previous checkpoint).
                if step > 1 {
                    let _ = ctx.checkpoint(serde_json::json!({ "step": step - 1 }));
                }
                return Err(PipelineError::Cancelled);
            }
            std::thread::sleep(Duration::from_millis(self.step_ms));
            let mut p = Progress::new(Stage::Test, step, steps);
            p.loss = Some(1.0 / step as f64);
            if step % SNAPSHOT_EVERY == 0 || step == steps {
                p.svg = Some(scene_svg(&scene_at(spec.seed, paths, step, steps)?));
            }
            ctx.report(p);
            if ctx.checkpoint_due(step) && step < steps {
                ctx.checkpoint(serde_json::json!({ "step": step }))?;
            }
        }
        let scene = scene_at(spec.seed, paths, steps, steps)?;
        let report = RunReport {
            resumed: Some(ResumePoint::Step(resumed_from)),
            ..RunReport::default()
        };
        let svg = scene_svg(&scene);
        // A text job of several variations: variation i drawn with the seed moved on by i.
        let n = spec.plan.as_ref().map_or(1, RunPlan::variations);
        let others = (1..n)
            .map(|i| {
                let scene = scene_at(spec.seed.wrapping_add(u64::from(i)), paths, steps, steps)?;
                let svg = scene_svg(&scene);
                Ok(RunOutput::new(scene, svg, RunReport::default()))
            })
            .collect::<Result<_, PipelineError>>()?;
        Ok(RunOutput::new(scene, svg, report).with_variations(others))
    }

    fn text_ready(&self) -> Result<(), crate::pipeline::NotReady> {
        if self.text_ready {
            Ok(())
        } else {
            Err(crate::pipeline::NotReady::Disabled)
        }
    }

    /// An SDXL-like model: Stable Diffusion's presets and sample shapes, a negative prompt and
    /// size conditioning accepted, so every request the API spec allows is planned.
    fn model_facts(&self) -> crate::pipeline::ModelFacts {
        crate::pipeline::ModelFacts {
            size_conditioning: true,
            ..crate::pipeline::ModelFacts::stable_diffusion("test executor")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn test_scene_svg_parses_with_usvg_and_is_deterministic() {
        let a = scene_svg(&scene_at(7, 5, 10, 10).unwrap());
        let b = scene_svg(&scene_at(7, 5, 10, 10).unwrap());
        assert_eq!(a, b);
        assert_ne!(a, scene_svg(&scene_at(8, 5, 10, 10).unwrap()));
        let tree = resvg::usvg::Tree::from_str(&a, &resvg::usvg::Options::default()).unwrap();
        assert_eq!(tree.size().width(), 64.0);
        assert_eq!(a.matches("<path").count(), 5);
    }
}
