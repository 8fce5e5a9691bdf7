//! LIVE (Ma et al., CVPR 2022): layer-wise image vectorisation through our differentiable
//! rasteriser.
//!
//! Paths are added in stages. Each new path starts as a small circle at one of the largest
//! connected regions of high error, coloured from the target ([`init`]); then all paths so far are
//! optimised with Adam in groups (points, fills, background), each with its own learning-rate
//! schedule, on an L2 loss plus LIVE's unsigned-distance-weighted L2 around the newest paths and
//! the self-intersection ("Xing") loss ([`crate::losses`]). Faint or tiny paths are
//! re-initialised between stages. `--paths auto` keeps adding stages while the PSNR gain per
//! added path is large enough and prunes paths that do not change the render ([`prune`],
//! [`schedule`]). `--init vtracer` starts from the vtracer crate's trace ([`tracer`]).
//!
//! Entry point: [`vectorize`]. Everything is deterministic for a given [`LiveConfig::seed`].
//! [`vectorize_resumable`] also hands a [`LiveState`] to a [`LiveCheckpoint`] after every
//! stage; a run resumed from one ends exactly as the uninterrupted run.

pub mod init;
pub mod pixels;
pub mod prune;
pub mod schedule;
pub mod tracer;

mod border;
mod config;
mod finish;
mod run;

pub use config::{CANVAS_SIDES, InitMode, LiveConfig, LiveError, MIN_OPACITY, PathBudget};

pub use crate::scene::MAX_PATHS;

use serde::{Deserialize, Serialize};

use crate::image::Image;
use crate::image::ops::resize;
use crate::progress::{CancelToken, CheckpointError, ProgressSink};
use crate::scene::{Rgba, Scene};
use crate::vector::check::Editability;
use crate::vector::palette::{self, Background};
use border::{border_alpha, border_colour};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use run::Run;

/// What one stage did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StageReport {
    /// 1-based stage number (stage 0 is the vtracer start, if any).
    pub stage: usize,
    /// Paths added by the stage.
    pub added: usize,
    /// Paths after the stage.
    pub paths: usize,
    /// Paths re-initialised after the stage.
    pub reinitialised: usize,
    /// PSNR at the working size after the stage.
    #[serde(deserialize_with = "null_as_nan")]
    pub psnr: f64,
    /// Loss at the last step.
    #[serde(deserialize_with = "null_as_nan")]
    pub loss: f64,
}

/// The result of [`vectorize`].
#[derive(Clone, Debug, PartialEq)]
pub struct LiveResult {
    /// The traced scene at the target's size.
    pub scene: Scene,
    /// Number of paths in `scene` (the chosen count for `--paths auto`).
    pub paths: usize,
    /// PSNR (dB, RGB over white) of our render of `scene` against the target.
    pub psnr: f64,
    pub stages: Vec<StageReport>,
    /// Paths removed by pruning (`auto` only).
    pub pruned: usize,
    /// Paths merged into a touching path of the same fill ([`crate::vector::merge`]).
    pub merged: usize,
    /// Paths that reached past the canvas, cut to it ([`crate::vector::canvas`]).
    pub cut: usize,
    /// Adam steps taken.
    pub steps: u32,
    /// What a designer finds in the SVG: self-intersecting, hidden and sliver paths, colours.
    pub editability: Editability,
}

/// Where a LIVE run stands after a stage: enough to finish it exactly as if uninterrupted.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LiveState {
    /// Index into the stage plan of the next stage to run.
    pub next_stage: usize,
    /// No more stages: the budget is spent or `auto` decided to stop.
    pub stages_done: bool,
    /// The scene at the working size.
    pub scene: Scene,
    pub reports: Vec<StageReport>,
    /// PSNR after the last stage (the `auto` budget compares against it), stored as its bit
    /// pattern so a JSON round trip is exact and infinity (a perfect fit) survives.
    #[serde(with = "f64_bits")]
    pub prev_psnr: f64,
    /// Adam steps taken so far.
    pub step: u32,
    /// Position of the seeded ChaCha8 stream (path initialisation and re-initialisation).
    pub rng_word_pos: u64,
}

/// Reads a JSON `null` (what serde_json writes for NaN and infinities) as NaN, so a report or
/// checkpoint with a non-finite number reads back.
pub fn null_as_nan<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Option::<f64>::deserialize(d).map(|v| v.unwrap_or(f64::NAN))
}

mod f64_bits {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u64(v.to_bits())
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        u64::deserialize(d).map(f64::from_bits)
    }
}

impl LiveState {
    /// The state before the first stage: `scene` (the background alone), no PSNR yet.
    fn start(scene: Scene) -> Self {
        LiveState {
            next_stage: 0,
            stages_done: false,
            scene,
            reports: Vec::new(),
            prev_psnr: f64::NAN,
            step: 0,
            rng_word_pos: 0,
        }
    }
}

/// Receives the state after every completed stage.
pub trait LiveCheckpoint: Sync {
    fn save(&self, state: &LiveState) -> Result<(), CheckpointError>;
}

/// Traces `target` into closed cubic paths (see the module docs). Emits progress events with
/// stage `"live"` and checks `cancel` before every step. [`vectorize_resumable`] without
/// checkpoints.
pub fn vectorize(
    target: &Image,
    cfg: &LiveConfig,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<LiveResult, LiveError> {
    vectorize_resumable(target, cfg, sink, cancel, None, None)
}

/// Rejects an empty, malformed, oversized or non-finite target.
fn check_target(target: &Image) -> Result<(), LiveError> {
    let (tw, th) = (target.width, target.height);
    if tw == 0 || th == 0 || target.data.len() != 4 * target.len_pixels() {
        return Err(LiveError::Target("empty or malformed image".into()));
    }
    if tw > crate::scene::MAX_SIDE || th > crate::scene::MAX_SIDE {
        return Err(LiveError::Target(format!(
            "{tw}x{th} is larger than {} px per side",
            crate::scene::MAX_SIDE
        )));
    }
    if target.data.iter().any(|v| !v.is_finite()) {
        return Err(LiveError::Target("image has non-finite values".into()));
    }
    Ok(())
}

/// The working size for a `tw`×`th` target and a working side of `size`: the target scaled to
/// the area of a `size`×`size` square (a square target: `size` a side; a 16:1 banner keeps
/// the pixels of each of its parts instead of shrinking them 4× further), never upsampled, so
/// small inputs are optimised at their own size.
fn working_size(size: u32, tw: u32, th: u32) -> (u32, u32) {
    // A square's side is exact, so a square target scales by `size / side` as it always did.
    let side = (f64::from(tw) * f64::from(th)).sqrt() as f32;
    let k = (size as f32 / side).min(1.0);
    (
        ((tw as f32 * k).round() as u32).max(1),
        ((th as f32 * k).round() as u32).max(1),
    )
}

/// The starting background of a trace of `target` (`work` at the working size) and whether
/// it is optimised with the paths (`auto` with an opaque border and no palette).
fn start_background(cfg: &LiveConfig, target: &Image, work: &Image, palette: bool) -> (Rgba, bool) {
    match cfg.colors.background {
        Background::Transparent => (Rgba::TRANSPARENT, false),
        Background::Color(c) => (c.to_rgba(), false),
        Background::Auto if border_alpha(target) < 0.5 => (Rgba::TRANSPARENT, false),
        Background::Auto => (border_colour(work), !palette),
    }
}

/// The paths each stage adds, and the most paths the budget allows in all.
fn stage_plan(budget: &PathBudget) -> (Vec<usize>, usize) {
    match budget {
        PathBudget::Schedule { stages } => (stages.clone(), stages.iter().sum()),
        PathBudget::Auto {
            stage, max_paths, ..
        } => (vec![*stage; max_paths.div_ceil(*stage)], *max_paths),
    }
}

/// Traces `target`, saving a [`LiveState`] through `checkpoint` after each stage, and continuing
/// from `resume` when given. A state that does not fit this run (another working size or stage
/// plan) is ignored and the run starts over.
pub fn vectorize_resumable(
    target: &Image,
    cfg: &LiveConfig,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
    resume: Option<LiveState>,
    checkpoint: Option<&dyn LiveCheckpoint>,
) -> Result<LiveResult, LiveError> {
    // The whole run on a pool of its own, as many threads as rayon's: each step's parallel pass
    // then wakes the pool's other thread instead of parking the calling thread (about 10 % of
    // the time per icon), and runs side by side in one process (the service's thread isolation)
    // cannot take up each other's whole runs while waiting. No pool: the calling thread.
    let run = || traced(target, cfg, sink, cancel, resume, checkpoint);
    match rayon::ThreadPoolBuilder::new()
        .num_threads(rayon::current_num_threads())
        .thread_name(|i| format!("vf-live-{i}"))
        .build()
    {
        Ok(pool) => pool.install(run),
        Err(_) => run(),
    }
}

fn traced(
    target: &Image,
    cfg: &LiveConfig,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
    resume: Option<LiveState>,
    checkpoint: Option<&dyn LiveCheckpoint>,
) -> Result<LiveResult, LiveError> {
    cfg.validate()?;
    check_target(target)?;
    if cfg.init == InitMode::Pixels {
        return pixels::trace_pixels(target, cfg);
    }
    let (tw, th) = (target.width, target.height);
    let (ww, wh) = working_size(cfg.size, tw, th);
    let over = target.over([1.0, 1.0, 1.0]);
    let work = resize(&over, ww, wh);
    let palette = cfg.colors.resolve(|k| palette::palette_of_image(&work, k));
    let (background, background_free) = start_background(cfg, target, &work, palette.is_some());
    // Coarse-to-fine: the stages before the last work on a smaller copy of the target.
    let (cw, ch) = working_size(cfg.coarse_size, tw, th);
    let coarse = cfg.coarse_size > 0 && cw < ww;
    let (first, full) = if coarse {
        (resize(&over, cw, ch), Some(work))
    } else {
        (work, None)
    };
    let mut scene = Scene::new(first.width, first.height, background)?;
    if let (Some(p), Background::Auto) = (&palette, cfg.colors.background) {
        palette::snap_background(&mut scene, p);
    }
    let (stages_plan, max_total) = stage_plan(&cfg.budget);
    let vtracer_stage = cfg.init == InitMode::Vtracer;
    let total =
        cfg.iters_per_stage * (stages_plan.len() as u32 + vtracer_stage as u32) + cfg.final_iters;
    let mut run = Run {
        cfg,
        target: first,
        full,
        full_width: ww,
        sink,
        cancel,
        step: 0,
        total,
        out_width: tw,
        out_height: th,
        palette,
        background_free,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let resume = resume.filter(|r| {
        let size = (r.scene.width, r.scene.height);
        (size == (ww, wh) || (coarse && size == (cw, ch)))
            && r.next_stage <= stages_plan.len()
            && r.scene.validate().is_ok()
    });
    let mut st = match resume {
        Some(mut r) => {
            if r.scene.width == ww {
                run.switch_to_full(&mut r.scene);
            }
            run.step = r.step;
            rng.set_word_pos(u128::from(r.rng_word_pos));
            r
        }
        None => {
            let mut st = LiveState::start(scene);
            if vtracer_stage {
                run.vtracer_start(&mut st, &mut rng, target, max_total)?;
                run.save(&mut st, &rng, checkpoint)?;
            }
            st
        }
    };
    if st.prev_psnr.is_nan() {
        st.prev_psnr = run.psnr(&st.scene);
    }
    run.add_stages(&mut st, &mut rng, &stages_plan, max_total, checkpoint)?;
    let (out, done) = run.finish(st.scene, st.reports.len())?;
    let psnr = crate::image::psnr(&crate::raster::render(&out), target);
    run.report_done(&out, psnr);
    Ok(LiveResult {
        paths: out.shapes.len(),
        editability: crate::vector::check::check(&out),
        scene: out,
        psnr,
        stages: st.reports,
        pruned: done.pruned,
        merged: done.merged,
        cut: done.cut,
        steps: run.step,
    })
}

#[cfg(test)]
mod tests;
