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
pub mod prune;
pub mod schedule;
pub mod tracer;

use crate::losses::LossError;
use crate::scene::SceneError;
use serde::{Deserialize, Serialize};

/// Why vectorisation failed.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    #[error("invalid configuration: {0}")]
    Config(String),
    #[error("invalid target image: {0}")]
    Target(String),
    #[error("cancelled")]
    Cancelled,
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Loss(#[from] LossError),
    #[error("vtracer failed: {0}")]
    Tracer(String),
    #[error("saving a checkpoint failed: {0}")]
    Checkpoint(String),
}

/// How many paths to use.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum PathBudget {
    /// Add paths in these stages (e.g. `[8, 8, 16, 16, 16]`).
    Schedule { stages: Vec<usize> },
    /// Add `stage` paths at a time while the PSNR gain per added path exceeds
    /// `min_gain_db_per_path`, up to `max_paths`; then prune paths whose removal changes the
    /// render by less than `prune_tolerance` (MSE over white).
    Auto {
        stage: usize,
        max_paths: usize,
        min_gain_db_per_path: f64,
        prune_tolerance: f64,
    },
}

impl PathBudget {
    /// The most paths this budget can create.
    pub fn max_paths(&self) -> usize {
        match self {
            PathBudget::Schedule { stages } => stages.iter().sum(),
            PathBudget::Auto { max_paths, .. } => *max_paths,
        }
    }

    /// `n` paths in LIVE's proportions ([`schedule::schedule_for`]).
    pub fn fixed(n: usize) -> Self {
        PathBudget::Schedule {
            stages: schedule::schedule_for(n),
        }
    }

    /// The default `auto` budget: stages of 8 up to 64 paths, continue while each added path
    /// gains more than 0.05 dB, prune paths worth less than 2e-5 MSE.
    pub fn auto() -> Self {
        PathBudget::Auto {
            stage: 8,
            max_paths: 64,
            min_gain_db_per_path: 0.05,
            prune_tolerance: 2e-5,
        }
    }
}

/// Where the paths come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InitMode {
    /// LIVE: circles at high-error regions, stage by stage.
    Circles,
    /// Start from vtracer's trace (simple closed paths), refine, then add what it misses.
    Vtracer,
}

/// Named speed/quality trade-offs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Preset {
    Fast,
    Balanced,
    Quality,
}

/// User-facing LIVE settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LiveConfig {
    /// Longest side (pixels) of the canvas the optimisation runs at (never more than the
    /// target's); the result is scaled back to the target's size.
    pub size: u32,
    pub budget: PathBudget,
    pub init: InitMode,
    /// Adam iterations per stage.
    pub iters_per_stage: u32,
    /// Extra iterations over all paths after the last stage.
    pub final_iters: u32,
    /// Peak learning rates (pixels per step for points).
    pub lr_points: f32,
    pub lr_fill: f32,
    pub lr_background: f32,
    /// Weight of the UDF-weighted L2 term relative to the plain mean L2.
    pub udf_weight: f32,
    /// UDF threshold `tau` in pixels (at the working size).
    pub udf_tau: f32,
    /// Weight of the Xing loss (LIVE uses 0.01).
    pub xing_weight: f32,
    /// New-path circle radius (pixels at the working size) and its segment count.
    pub init_radius: f32,
    pub init_segments: usize,
    /// Grow each new circle to fill its region (its inscribed radius, at least `init_radius`)
    /// instead of LIVE's fixed small circle: far fewer steps are needed to cover large regions.
    pub init_fit_region: bool,
    /// Keep every fill fully opaque (smaller SVGs, no faint layers); otherwise opacity is
    /// optimised too.
    pub opaque: bool,
    /// Re-initialise paths with opacity below this...
    pub reinit_min_opacity: f32,
    /// ... or area below this (square pixels at the working size); 0 disables.
    pub reinit_min_area: f32,
    pub seed: u64,
    /// Attach the current SVG to a progress event every this many steps (0 = never).
    pub snapshot_every: u32,
}

impl LiveConfig {
    /// A preset with a path budget of `paths` (LIVE proportions).
    pub fn preset(preset: Preset) -> Self {
        let base = LiveConfig {
            size: 128,
            budget: PathBudget::fixed(64),
            init: InitMode::Circles,
            iters_per_stage: 100,
            final_iters: 50,
            lr_points: 1.0,
            lr_fill: 0.02,
            lr_background: 0.01,
            udf_weight: 0.5,
            udf_tau: 4.0,
            xing_weight: 0.01,
            init_radius: 3.0,
            init_segments: 4,
            init_fit_region: true,
            opaque: true,
            reinit_min_opacity: 0.05,
            reinit_min_area: 16.0,
            seed: 0,
            snapshot_every: 50,
        };
        match preset {
            Preset::Fast => base,
            Preset::Balanced => LiveConfig {
                size: 160,
                iters_per_stage: 200,
                final_iters: 100,
                init_radius: 4.0,
                udf_tau: 6.0,
                reinit_min_area: 36.0,
                ..base
            },
            Preset::Quality => LiveConfig {
                size: 256,
                iters_per_stage: 300,
                final_iters: 150,
                init_radius: 5.0,
                udf_tau: 8.0,
                reinit_min_area: 64.0,
                ..base
            },
        }
    }

    /// Checks ranges; called by [`vectorize`].
    pub fn validate(&self) -> Result<(), LiveError> {
        /// Per-stage iteration limit: keeps step counters far from `u32` overflow.
        const MAX_ITERS: u32 = 100_000;
        let bad = |m: &str| Err(LiveError::Config(m.to_string()));
        if !(8..=2048).contains(&self.size) {
            return bad("size must be in 8..=2048");
        }
        match &self.budget {
            PathBudget::Schedule { stages } => {
                if stages.contains(&0) {
                    return bad("schedule stages must add at least one path");
                }
                if stages.iter().fold(0usize, |a, &n| a.saturating_add(n)) > MAX_PATHS {
                    return Err(LiveError::Config(format!(
                        "schedule adds more than {MAX_PATHS} paths"
                    )));
                }
            }
            PathBudget::Auto {
                stage, max_paths, ..
            } => {
                if *stage == 0 || *max_paths == 0 || *max_paths > MAX_PATHS {
                    return Err(LiveError::Config(format!(
                        "auto budget needs stage >= 1 and 1 <= max_paths <= {MAX_PATHS}"
                    )));
                }
            }
        }
        let finite = [
            self.lr_points,
            self.lr_fill,
            self.lr_background,
            self.udf_weight,
            self.udf_tau,
            self.xing_weight,
            self.init_radius,
            self.reinit_min_opacity,
            self.reinit_min_area,
        ];
        if finite.iter().any(|v| !v.is_finite() || *v < 0.0) {
            return bad("rates, weights, radii and thresholds must be finite and >= 0");
        }
        if self.init_segments == 0 || self.init_segments > 64 {
            return bad("init_segments must be in 1..=64");
        }
        if self.iters_per_stage > MAX_ITERS || self.final_iters > MAX_ITERS {
            return bad("iterations per stage must be at most 100000");
        }
        Ok(())
    }
}

impl Default for LiveConfig {
    fn default() -> Self {
        LiveConfig::preset(Preset::Balanced)
    }
}

pub use crate::scene::MAX_PATHS;

use crate::image::Image;
use crate::image::ops::resize;
use crate::losses::{outline, udf_weights, weighted_l2, xing_loss};
use crate::optim::{Adam, AdamConfig, GroupSchedules, LrSchedule};
use crate::progress::{CancelToken, Progress, ProgressSink};
use crate::scene::{ParamGroup, Params, Rgba, Scene, Trainable};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::ops::Range;

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
    pub psnr: f64,
    /// Loss at the last step.
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
    /// Adam steps taken.
    pub steps: u32,
}

struct Run<'a> {
    cfg: &'a LiveConfig,
    target: Image,
    sink: &'a dyn ProgressSink,
    cancel: &'a CancelToken,
    step: u32,
    total: u32,
    out_width: u32,
}

impl Run<'_> {
    fn schedules(&self, iters: u32) -> GroupSchedules {
        let sched = |lr: f32| LrSchedule::WarmupCosine {
            start: 0.2 * lr,
            peak: lr,
            warmup: (iters / 10).max(1),
            end: 0.1 * lr,
            total: iters,
        };
        GroupSchedules {
            points: sched(self.cfg.lr_points),
            fill: sched(self.cfg.lr_fill),
            stroke: LrSchedule::Constant { lr: 0.0 },
            width: LrSchedule::Constant { lr: 0.0 },
            background: sched(self.cfg.lr_background),
        }
    }

    /// Optimises every path of `scene` for `iters` steps; the UDF term focuses on `focus`.
    fn optimise(
        &mut self,
        scene: &mut Scene,
        focus: Range<usize>,
        iters: u32,
        stage: usize,
    ) -> Result<f64, LiveError> {
        let mut params = Params::from_scene(scene);
        let trainable = Trainable {
            points: true,
            fill: true,
            stroke: false,
            width: false,
            background: true,
        };
        let mut adam = Adam::new(
            &params,
            AdamConfig::default(),
            self.schedules(iters),
            trainable,
        );
        let n = self.target.len_pixels();
        let uniform = 1.0 / (3.0 * n as f32);
        let mut last = f64::NAN;
        for _ in 0..iters {
            if self.cancel.is_cancelled() {
                return Err(LiveError::Cancelled);
            }
            let (img, tape) = crate::raster::render_tape(scene);
            let mut weights = vec![uniform; n];
            if self.cfg.udf_weight > 0.0 && !focus.is_empty() {
                let outlines: Vec<Vec<(f32, f32)>> = scene.shapes[focus.clone()]
                    .iter()
                    .map(|s| outline(s, 8))
                    .collect();
                let udf = udf_weights(scene.width, scene.height, &outlines, self.cfg.udf_tau);
                let k = self.cfg.udf_weight / 3.0;
                for (w, u) in weights.iter_mut().zip(&udf) {
                    *w += k * u;
                }
            }
            let (loss, d_image) = weighted_l2(&img, &self.target, &weights)?;
            let mut grad = crate::raster::backward(scene, &tape, &d_image);
            let xing = if self.cfg.xing_weight > 0.0 {
                xing_loss(
                    scene,
                    0..scene.shapes.len(),
                    self.cfg.xing_weight,
                    &mut grad,
                )
            } else {
                0.0
            };
            adam.step(&mut params, &grad);
            if self.cfg.opaque {
                for a in params
                    .get_mut(ParamGroup::Fill)
                    .iter_mut()
                    .skip(3)
                    .step_by(4)
                {
                    *a = 1.0;
                }
            }
            if let Some(a) = params.get_mut(ParamGroup::Background).get_mut(3) {
                *a = 1.0;
            }
            params.write_to(scene)?;
            // Keep the optimiser's copy inside the valid (clamped) range.
            params = Params::from_scene(scene);
            last = loss + xing;
            self.step += 1;
            self.report(scene, stage, last);
        }
        Ok(last)
    }

    fn report(&self, scene: &Scene, stage: usize, loss: f64) {
        let every = self.cfg.snapshot_every;
        let snapshot = every > 0 && (self.step % every == 0 || self.step == self.total);
        if !(snapshot || self.step % 10 == 0) {
            return;
        }
        let mut ev = Progress::new("live", self.step, self.total);
        ev.loss = Some(loss);
        ev.detail = Some(serde_json::json!({"live_stage": stage, "paths": scene.shapes.len()}));
        if snapshot {
            let out = scene.scaled_to_width(self.out_width);
            ev.svg = Some(crate::svg::to_svg(&out, &crate::svg::SvgOptions::default()));
        }
        self.sink.report(ev);
    }

    /// Replaces faint or tiny paths by circles at the current high-error regions.
    fn reinit_weak(&self, scene: &mut Scene, rng: &mut ChaCha8Rng) -> usize {
        let weak = prune::weak_paths(scene, self.cfg.reinit_min_opacity, self.cfg.reinit_min_area);
        if weak.is_empty() {
            return 0;
        }
        let current = crate::raster::render(scene);
        let fresh = init::init_paths(&current, &self.target, weak.len(), &self.init_cfg(), rng);
        let count = fresh.len();
        for (i, shape) in weak.into_iter().zip(fresh) {
            scene.shapes[i] = shape;
        }
        count
    }

    fn init_cfg(&self) -> init::InitConfig {
        init::InitConfig {
            radius: self.cfg.init_radius,
            segments: self.cfg.init_segments,
            fit_region: self.cfg.init_fit_region,
            ..init::InitConfig::default()
        }
    }

    fn psnr(&self, scene: &Scene) -> f64 {
        crate::image::psnr(&crate::raster::render(scene), &self.target)
    }
}

/// Mean colour of the image border (over white): the starting background.
fn border_colour(img: &Image) -> Rgba {
    let (w, h) = (img.width, img.height);
    let mut s = [0.0f64; 3];
    let mut n = 0.0f64;
    for y in 0..h {
        for x in 0..w {
            if x == 0 || y == 0 || x + 1 == w || y + 1 == h {
                let p = img.pixel(x, y);
                for c in 0..3 {
                    s[c] += (p[c] + 1.0 - p[3]) as f64;
                }
                n += 1.0;
            }
        }
    }
    let n = n.max(1.0);
    Rgba::new((s[0] / n) as f32, (s[1] / n) as f32, (s[2] / n) as f32, 1.0).clamped()
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

mod f64_bits {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u64(v.to_bits())
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        u64::deserialize(d).map(f64::from_bits)
    }
}

/// Receives the state after every completed stage.
pub trait LiveCheckpoint {
    fn save(&self, state: &LiveState) -> Result<(), String>;
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
    cfg.validate()?;
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
    // Never upsample: small inputs are optimised at their own size.
    let k = (cfg.size as f32 / tw.max(th) as f32).min(1.0);
    let (ww, wh) = (
        ((tw as f32 * k).round() as u32).max(1),
        ((th as f32 * k).round() as u32).max(1),
    );
    let work = resize(&target.over([1.0, 1.0, 1.0]), ww, wh);
    let mut scene = Scene::new(ww, wh, border_colour(&work))?;
    let stages_plan: Vec<usize> = match &cfg.budget {
        PathBudget::Schedule { stages } => stages.clone(),
        PathBudget::Auto {
            stage, max_paths, ..
        } => vec![*stage; max_paths.div_ceil(*stage)],
    };
    let max_total = match &cfg.budget {
        PathBudget::Schedule { stages } => stages.iter().sum(),
        PathBudget::Auto { max_paths, .. } => *max_paths,
    };
    let vtracer_stage = cfg.init == InitMode::Vtracer;
    let total =
        cfg.iters_per_stage * (stages_plan.len() as u32 + vtracer_stage as u32) + cfg.final_iters;
    let mut run = Run {
        cfg,
        target: work,
        sink,
        cancel,
        step: 0,
        total,
        out_width: tw,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let mut reports = Vec::new();
    let save = |scene: &Scene,
                reports: &[StageReport],
                next_stage: usize,
                stages_done: bool,
                prev_psnr: f64,
                step: u32,
                rng: &ChaCha8Rng|
     -> Result<(), LiveError> {
        let Some(c) = checkpoint else { return Ok(()) };
        let state = LiveState {
            next_stage,
            stages_done,
            scene: scene.clone(),
            reports: reports.to_vec(),
            prev_psnr,
            step,
            rng_word_pos: u64::try_from(rng.get_word_pos())
                .map_err(|_| LiveError::Checkpoint("random stream position overflow".into()))?,
        };
        c.save(&state).map_err(LiveError::Checkpoint)
    };
    let resume = resume.filter(|r| {
        r.scene.width == ww
            && r.scene.height == wh
            && r.next_stage <= stages_plan.len()
            && r.scene.validate().is_ok()
    });
    let mut first_stage = 0;
    let mut stages_done = false;
    let mut prev_psnr = f64::NAN;
    if let Some(r) = resume {
        scene = r.scene;
        reports = r.reports;
        first_stage = r.next_stage;
        stages_done = r.stages_done;
        prev_psnr = r.prev_psnr;
        run.step = r.step;
        rng.set_word_pos(u128::from(r.rng_word_pos));
    } else if vtracer_stage {
        let small = resize(target, ww, wh);
        let traced =
            tracer::trace(&small, &tracer::TracerSetting::default()).map_err(LiveError::Tracer)?;
        let start = tracer::traced_to_scene(&traced, ww, wh, max_total, 12)?;
        scene.shapes = start.shapes;
        scene.background = start.background;
        let n = scene.shapes.len();
        let loss = run.optimise(&mut scene, 0..n, cfg.iters_per_stage, 0)?;
        let reinit = run.reinit_weak(&mut scene, &mut rng);
        reports.push(StageReport {
            stage: 0,
            added: n,
            paths: n,
            reinitialised: reinit,
            psnr: run.psnr(&scene),
            loss,
        });
        prev_psnr = run.psnr(&scene);
        save(&scene, &reports, 0, false, prev_psnr, run.step, &rng)?;
    }
    if prev_psnr.is_nan() {
        prev_psnr = run.psnr(&scene);
    }
    let plan = if stages_done {
        &stages_plan[..0]
    } else {
        &stages_plan[first_stage..]
    };
    for (si, &want) in plan.iter().enumerate() {
        let si = si + first_stage;
        let room = max_total.saturating_sub(scene.shapes.len());
        let want = want.min(room);
        if want == 0 {
            break;
        }
        let current = crate::raster::render(&scene);
        let fresh = init::init_paths(&current, &run.target, want, &run.init_cfg(), &mut rng);
        let added = fresh.len();
        if added == 0 {
            break;
        }
        let start = scene.shapes.len();
        scene.shapes.extend(fresh);
        let end = scene.shapes.len();
        let loss = run.optimise(&mut scene, start..end, cfg.iters_per_stage, si + 1)?;
        let reinit = run.reinit_weak(&mut scene, &mut rng);
        let psnr = run.psnr(&scene);
        reports.push(StageReport {
            stage: si + 1,
            added,
            paths: end,
            reinitialised: reinit,
            psnr,
            loss,
        });
        let stop = match cfg.budget {
            PathBudget::Auto {
                min_gain_db_per_path,
                ..
            } => !schedule::auto_should_continue(prev_psnr, psnr, added, min_gain_db_per_path),
            PathBudget::Schedule { .. } => false,
        };
        save(&scene, &reports, si + 1, stop, psnr, run.step, &rng)?;
        if stop {
            break;
        }
        prev_psnr = psnr;
    }
    if cfg.final_iters > 0 && !scene.shapes.is_empty() {
        let n = scene.shapes.len();
        run.optimise(&mut scene, n..n, cfg.final_iters, reports.len() + 1)?;
    }
    // Drop paths that stayed faint or tiny after the last re-initialisation.
    let weak = prune::weak_paths(&scene, cfg.reinit_min_opacity, 1.0);
    for &i in weak.iter().rev() {
        scene.shapes.remove(i);
    }
    let mut pruned = 0;
    if let PathBudget::Auto {
        prune_tolerance, ..
    } = cfg.budget
    {
        pruned = prune::prune_paths(&mut scene, prune_tolerance, crate::raster::render).len();
    }
    let mut out = scene.scaled_to_width(tw);
    out.height = th;
    out.validate()?;
    let psnr = crate::image::psnr(&crate::raster::render(&out), target);
    let mut done = Progress::new("live", run.total, run.total);
    done.svg = Some(crate::svg::to_svg(&out, &crate::svg::SvgOptions::default()));
    done.detail = Some(serde_json::json!({"paths": out.shapes.len(), "psnr": psnr, "done": true}));
    sink.report(done);
    Ok(LiveResult {
        paths: out.shapes.len(),
        scene: out,
        psnr,
        stages: reports,
        pruned,
        steps: run.step,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_valid_and_ordered_by_effort() {
        let f = LiveConfig::preset(Preset::Fast);
        let b = LiveConfig::preset(Preset::Balanced);
        let q = LiveConfig::preset(Preset::Quality);
        for c in [&f, &b, &q] {
            c.validate().unwrap();
            assert_eq!(c.budget, PathBudget::fixed(64));
            assert_eq!(c.reinit_min_opacity, 0.05);
        }
        assert!(f.size < b.size && b.size < q.size);
        assert!(f.iters_per_stage < b.iters_per_stage && b.iters_per_stage < q.iters_per_stage);
        assert_eq!(q.reinit_min_area, 64.0);
        assert_eq!(LiveConfig::default(), b);
    }

    #[test]
    fn validate_rejects_bad_settings() {
        let ok = LiveConfig::default();
        let cases = [
            LiveConfig {
                lr_points: f32::NAN,
                ..ok.clone()
            },
            LiveConfig {
                xing_weight: -1.0,
                ..ok.clone()
            },
            LiveConfig {
                init_segments: 0,
                ..ok.clone()
            },
            LiveConfig {
                budget: PathBudget::Auto {
                    stage: 0,
                    max_paths: 8,
                    min_gain_db_per_path: 0.1,
                    prune_tolerance: 0.0,
                },
                ..ok.clone()
            },
            LiveConfig {
                budget: PathBudget::Schedule {
                    stages: vec![MAX_PATHS, 1],
                },
                ..ok.clone()
            },
        ];
        for c in cases {
            assert!(matches!(c.validate(), Err(LiveError::Config(_))), "{c:?}");
        }
    }

    #[test]
    fn border_colour_is_the_frame_mean() {
        let mut im = Image::filled(8, 8, [0.0, 0.0, 1.0, 1.0]);
        // Transparent frame counts as white.
        for y in 0..8u32 {
            for x in 0..8u32 {
                if x == 0 || y == 0 || x == 7 || y == 7 {
                    let i = 4 * (y * 8 + x) as usize;
                    im.data[i..i + 4].copy_from_slice(&[0.0; 4]);
                }
            }
        }
        assert_eq!(border_colour(&im), Rgba::WHITE);
    }
}
