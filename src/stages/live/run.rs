//! One LIVE run's state and steps ([`Run`]): the optimiser loop of a stage, the stages that add
//! paths, the vtracer start, clean geometry between steps (looping outlines cut into lobes); the
//! finish at the output size is [`super::finish`]. [`super::vectorize_resumable`] sets a run up
//! and drives it.

use super::finish::svg_bytes;
use super::{
    LiveCheckpoint, LiveConfig, LiveError, LiveState, PathBudget, StageReport, init, prune,
    schedule, tracer,
};
use crate::image::Image;
use crate::image::ops::resize;
use crate::losses::{
    LossError, outline, udf_weights, weighted_l2_grad_slices, weighted_l2_slices, xing_loss,
};
use crate::optim::{Adam, AdamConfig, GroupSchedules, LrSchedule};
use crate::progress::{CancelToken, Progress, ProgressSink, Stage};
use crate::scene::{ParamGroup, Params, Rgba, Scene, Trainable};
use crate::vector::lobes;
use crate::vector::palette;
use rand_chacha::ChaCha8Rng;
use std::ops::Range;

pub(super) struct Run<'a> {
    pub(super) cfg: &'a LiveConfig,
    /// The target at the current working size (over white).
    pub(super) target: Image,
    /// Coarse-to-fine: the target at the full working size, until [`Run::switch_to_full`] switches.
    pub(super) full: Option<Image>,
    /// Width of the full working size.
    pub(super) full_width: u32,
    pub(super) sink: &'a dyn ProgressSink,
    pub(super) cancel: &'a CancelToken,
    pub(super) step: u32,
    pub(super) total: u32,
    pub(super) out_width: u32,
    pub(super) out_height: u32,
    /// The palette fills are chosen from (`--palette`, or k-means of the target for
    /// `--colors`); `None`: fills are optimised freely.
    pub(super) palette: Option<Vec<Rgba>>,
    /// The background is optimised with the paths (`auto` with an opaque border).
    pub(super) background_free: bool,
}

impl Run<'_> {
    /// Pixels of the current working size per pixel of the full one (1 once at full size):
    /// the lengths of the configuration, given at the full size, scale by it.
    fn px(&self) -> f32 {
        self.target.width as f32 / self.full_width as f32
    }

    /// Switches a coarse-to-fine run to the full working size: `scene` scaled up, the loss on
    /// the full-size target from now on. Does nothing once at full size.
    pub(super) fn switch_to_full(&mut self, scene: &mut Scene) {
        let Some(full) = self.full.take() else { return };
        if scene.width != full.width {
            let mut up = scene.scaled_to_width(full.width);
            up.height = full.height;
            *scene = up;
        }
        self.target = full;
    }

    fn schedules(&self, iters: u32) -> GroupSchedules {
        let sched = |lr: f32| LrSchedule::WarmupCosine {
            start: 0.2 * lr,
            peak: lr,
            warmup: (iters / 10).max(1),
            end: 0.1 * lr,
            total: iters,
        };
        GroupSchedules {
            points: sched(self.cfg.lr_points * self.px()),
            fill: sched(self.cfg.lr_fill),
            stroke: LrSchedule::Constant { lr: 0.0 },
            width: LrSchedule::Constant { lr: 0.0 },
            background: sched(self.cfg.lr_background),
            paint_geometry: sched(self.cfg.lr_paint[0] * self.px()),
            paint_stops: sched(self.cfg.lr_paint[1]),
        }
    }

    /// Optimises every path of `scene` for `iters` steps; the UDF term focuses on `focus`.
    /// Fills are optimised only when `fills` is set and no palette is in force.
    pub(super) fn optimise(
        &mut self,
        scene: &mut Scene,
        focus: Range<usize>,
        iters: u32,
        stage: usize,
        fills: bool,
    ) -> Result<f64, LiveError> {
        let mut params = Params::from_scene(scene);
        let trainable = Trainable {
            points: true,
            fill: fills && self.palette.is_none(),
            stroke: false,
            width: false,
            background: self.background_free,
            paint: fills,
        };
        let mut adam = Adam::new(
            &params,
            AdamConfig::default(),
            self.schedules(iters),
            trainable,
        );
        let mut last = f64::NAN;
        // Which paths the UDF term focuses on (kept through untwisting, which moves indices).
        let mut in_focus: Vec<bool> = (0..scene.shapes.len())
            .map(|i| focus.contains(&i))
            .collect();
        let mut window: Vec<f64> = Vec::with_capacity(CONVERGE_WINDOW);
        let mut previous: Option<f64> = None;
        let mut weights = Vec::new();
        for it in 0..iters {
            if self.cancel.is_cancelled() {
                return Err(LiveError::Cancelled);
            }
            if it % UDF_EVERY == 0 {
                weights = self.loss_weights(scene, &in_focus);
            }
            // The loss's value is needed where it is reported, checked or returned only.
            let value = it + 1 == iters
                || self.cfg.converge_tol > 0.0
                || self.reports_at(self.step + 1).is_some();
            let (loss, mut grad) = self.loss_and_grad(scene, &weights, value)?;
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
            self.pin_opacity(&mut params);
            params.write_to(scene)?;
            if (it + 1) % UNTWIST_EVERY == 0 && untwist(scene, &mut in_focus) {
                adam.relayout(&Params::from_scene(scene));
            }
            // Keep the optimiser's copy inside the valid (clamped) range.
            params = Params::from_scene(scene);
            last = loss + xing;
            self.step += 1;
            self.report(scene, stage, last);
            window.push(last);
            if self.converged(&mut window, &mut previous) {
                // The rest of the stage's steps are not taken: progress counts them as done.
                self.step += iters - it - 1;
                break;
            }
        }
        Ok(last)
    }

    /// The weighted L2 loss of `scene`'s render against the target and its gradient, in one
    /// fused forward, loss and backward pass over the rasteriser's row bands. Without `value`
    /// the loss is not summed and 0 is returned in its place (the gradient is the same).
    fn loss_and_grad(
        &self,
        scene: &Scene,
        weights: &[f32],
        value: bool,
    ) -> Result<(f64, Params), LiveError> {
        let t = &self.target;
        if (scene.width, scene.height) != (t.width, t.height) {
            let e = LossError::SizeMismatch(scene.width, scene.height, t.width, t.height);
            return Err(e.into());
        }
        if weights.len() != t.len_pixels() {
            let e = LossError::WeightLength {
                got: weights.len(),
                expected: t.len_pixels(),
            };
            return Err(e.into());
        }
        let band = |px: Range<usize>, img: &[f32], grad: &mut [f32]| {
            let target = &t.data[4 * px.start..4 * px.end];
            if value {
                weighted_l2_slices(img, target, &weights[px], grad)
            } else {
                weighted_l2_grad_slices(img, target, &weights[px], grad);
                0.0
            }
        };
        Ok(crate::raster::render_loss_backward(scene, &band))
    }

    /// Per-pixel weights of the L2 loss: uniform, plus LIVE's unsigned-distance term around
    /// the outlines of the paths `in_focus` (when `udf_weight` is on).
    fn loss_weights(&self, scene: &Scene, in_focus: &[bool]) -> Vec<f32> {
        let n = self.target.len_pixels();
        let uniform = 1.0 / (3.0 * n as f32);
        let mut weights = vec![uniform; n];
        if self.cfg.udf_weight > 0.0 && in_focus.contains(&true) {
            let outlines: Vec<Vec<(f32, f32)>> = scene
                .shapes
                .iter()
                .zip(in_focus)
                .filter(|(_, f)| **f)
                .map(|(s, _)| outline(s, 8))
                .collect();
            let tau = self.cfg.udf_tau * self.px();
            let udf = udf_weights(scene.width, scene.height, &outlines, tau);
            let k = self.cfg.udf_weight / 3.0;
            for (w, u) in weights.iter_mut().zip(&udf) {
                *w += k * u;
            }
        }
        weights
    }

    /// Keeps fills opaque (`opaque`) and an optimised background opaque after a step.
    fn pin_opacity(&self, params: &mut Params) {
        if self.cfg.opaque {
            for a in params
                .get_mut(ParamGroup::Fill)
                .iter_mut()
                .skip(3)
                .step_by(4)
            {
                *a = 1.0;
            }
            for a in crate::vector::fill::stop_alphas(params.get_mut(ParamGroup::PaintStops)) {
                *a = 1.0;
            }
        }
        if self.background_free
            && let Some(a) = params.get_mut(ParamGroup::Background).get_mut(3)
        {
            *a = 1.0;
        }
    }

    /// The early stop: after every [`CONVERGE_WINDOW`] steps, whether the window's mean loss
    /// improved on the previous window's by less than `converge_tol` (relative). Off at 0.
    fn converged(&self, window: &mut Vec<f64>, previous: &mut Option<f64>) -> bool {
        if self.cfg.converge_tol <= 0.0 || window.len() < CONVERGE_WINDOW {
            return false;
        }
        let mean = window.iter().sum::<f64>() / window.len() as f64;
        window.clear();
        let done =
            previous.is_some_and(|p| p > 0.0 && (p - mean) / p < self.cfg.converge_tol as f64);
        *previous = Some(mean);
        done
    }

    /// Whether a progress event goes out after step `step` (`Some`), and with a snapshot.
    fn reports_at(&self, step: u32) -> Option<bool> {
        let every = self.cfg.snapshot_every;
        let snapshot = every > 0 && (step.is_multiple_of(every) || step == self.total);
        (snapshot || step.is_multiple_of(10)).then_some(snapshot)
    }

    fn report(&self, scene: &Scene, stage: usize, loss: f64) {
        let Some(snapshot) = self.reports_at(self.step) else {
            return;
        };
        let mut ev = Progress::new(Stage::Live, self.step, self.total);
        ev.loss = Some(loss);
        ev.detail = Some(serde_json::json!({"live_stage": stage, "paths": scene.shapes.len()}));
        if snapshot {
            let out = scene.scaled_to_width(self.out_width);
            ev.svg = Some(crate::svg::to_svg(&out, &crate::svg::SvgOptions::default()));
        }
        self.sink.report(ev);
    }

    /// The last progress event: the traced scene `out` (at the output size) and its `psnr`.
    pub(super) fn report_done(&self, out: &Scene, psnr: f64) {
        let mut done = Progress::new(Stage::Live, self.total, self.total);
        done.svg = Some(crate::svg::to_svg(out, &crate::svg::SvgOptions::default()));
        done.detail =
            Some(serde_json::json!({"paths": out.shapes.len(), "psnr": psnr, "done": true}));
        self.sink.report(done);
    }

    /// Replaces faint or tiny paths by circles at the current high-error regions, tagged as
    /// added by `stage`.
    fn reinit_weak(&self, scene: &mut Scene, rng: &mut ChaCha8Rng, stage: usize) -> usize {
        let min_area = self.cfg.reinit_min_area * self.px() * self.px();
        let weak = prune::weak_paths(scene, self.cfg.reinit_min_opacity, min_area);
        if weak.is_empty() {
            return 0;
        }
        let current = crate::raster::render(scene);
        let fresh = init::init_paths(&current, &self.target, weak.len(), &self.init_cfg(), rng);
        let fresh = tagged(fresh, stage);
        let count = fresh.len();
        for (i, shape) in weak.into_iter().zip(fresh) {
            scene.shapes[i] = shape;
        }
        count
    }

    fn init_cfg(&self) -> init::InitConfig {
        init::InitConfig {
            radius: self.cfg.init_radius * self.px(),
            segments: self.cfg.init_segments,
            fit_region: self.cfg.init_fit_region,
            ..init::InitConfig::default()
        }
    }

    pub(super) fn psnr(&self, scene: &Scene) -> f64 {
        crate::image::psnr(&crate::raster::render(scene), &self.target)
    }

    /// Gives the paths their palette colours (when a palette is in force) and new paths the
    /// gradient paint of a gradient fill (painting as their flat colour does).
    pub(super) fn choose_colours(&self, scene: &mut Scene) {
        if let Some(p) = &self.palette {
            palette::choose_fills(scene, Some(&self.target), p);
        }
        self.cfg.fill.paint_new(scene);
    }

    /// Splits every path whose outline crosses itself or folds into a spike into simple pieces
    /// that cover the same pixels (see [`crate::vector::simple`]). Returns how many were split.
    pub(super) fn make_simple(&self, scene: &mut Scene) -> usize {
        crate::vector::make_simple(scene, crate::vector::SIMPLE_MIN_AREA)
    }
}

/// Steps between two updates of the loss weights (the UDF band around the newest paths moves
/// little in a few steps; untwisting, which happens on multiples of this, updates them anyway).
const UDF_EVERY: u32 = 5;

/// Steps per window of the early stop ([`LiveConfig::converge_tol`]).
const CONVERGE_WINDOW: usize = 20;

/// Steps between two checks for paths that meet themselves during optimisation.
const UNTWIST_EVERY: u32 = 10;
/// Lobes below this area (px² at the working size) are dropped when a path is untwisted.
const UNTWIST_MIN_AREA: f32 = 4.0;

/// Cuts every closed path that meets itself (the quick check) into its lobes, dropping lobes
/// under [`UNTWIST_MIN_AREA`]: the optimisation goes on from simple outlines instead of
/// folding further. `in_focus` follows the paths. Returns whether the scene changed.
fn untwist(scene: &mut Scene, in_focus: &mut Vec<bool>) -> bool {
    if !scene.shapes.iter().any(lobes::meets_itself) {
        return false;
    }
    let old = std::mem::take(&mut scene.shapes);
    let mut focus = Vec::with_capacity(old.len());
    for (sh, f) in old.into_iter().zip(in_focus.iter().copied()) {
        if scene.shapes.len() >= crate::scene::MAX_PATHS {
            break;
        }
        let pieces = if lobes::meets_itself(&sh) {
            lobes::split_lobes(&sh, UNTWIST_MIN_AREA)
        } else {
            vec![sh]
        };
        focus.extend(std::iter::repeat_n(f, pieces.len()));
        scene.shapes.extend(pieces);
    }
    scene.shapes.truncate(crate::scene::MAX_PATHS);
    focus.truncate(scene.shapes.len());
    *in_focus = focus;
    true
}

/// `shapes` tagged as added by LIVE stage `stage` ([`crate::scene::Shape::stage`]).
fn tagged(mut shapes: Vec<crate::scene::Shape>, stage: usize) -> Vec<crate::scene::Shape> {
    let tag = u16::try_from(stage).ok();
    for s in &mut shapes {
        s.stage = tag;
    }
    shapes
}

impl Run<'_> {
    /// Saves `state` through `checkpoint` (if any), with the step and the position of `rng`.
    pub(super) fn save(
        &self,
        state: &mut LiveState,
        rng: &ChaCha8Rng,
        checkpoint: Option<&dyn LiveCheckpoint>,
    ) -> Result<(), LiveError> {
        let Some(c) = checkpoint else { return Ok(()) };
        state.step = self.step;
        state.rng_word_pos = u64::try_from(rng.get_word_pos())
            .map_err(|_| LiveError::Checkpoint("random stream position overflow".into()))?;
        Ok(c.save(state)?)
    }

    /// Stage 0 of `--init vtracer`: the vtracer crate's trace of `target` (at most `max_total`
    /// paths), optimised for one stage.
    pub(super) fn vtracer_start(
        &mut self,
        st: &mut LiveState,
        rng: &mut ChaCha8Rng,
        target: &Image,
        max_total: usize,
    ) -> Result<(), LiveError> {
        let (ww, wh) = (st.scene.width, st.scene.height);
        let small = resize(target, ww, wh);
        let traced =
            tracer::trace(&small, &tracer::TracerSetting::default()).map_err(LiveError::Tracer)?;
        let start = tracer::traced_to_scene(&traced, ww, wh, max_total, 12)?;
        let scene = &mut st.scene;
        scene.shapes = tagged(start.shapes, 0);
        if self.background_free {
            scene.background = start.background;
        }
        self.choose_colours(scene);
        let n = scene.shapes.len();
        let loss = self.optimise(scene, 0..n, self.cfg.iters_per_stage, 0, true)?;
        let reinit = self.reinit_weak(scene, rng, 0);
        self.make_simple(scene);
        self.choose_colours(scene);
        let psnr = self.psnr(scene);
        st.reports.push(StageReport {
            stage: 0,
            added: n,
            paths: n,
            reinitialised: reinit,
            psnr,
            loss,
        });
        st.prev_psnr = psnr;
        Ok(())
    }

    /// Whether the stage that took the PSNR from `prev_psnr` to `psnr` by adding `added`
    /// paths ends the stages: the `auto` budget's gain per path, `target_psnr` or `max_bytes`.
    fn should_stop(&self, scene: &Scene, prev_psnr: f64, psnr: f64, added: usize) -> bool {
        let cfg = self.cfg;
        let budget_stop = match cfg.budget {
            PathBudget::Auto {
                min_gain_db_per_path,
                ..
            } => !schedule::auto_should_continue(prev_psnr, psnr, added, min_gain_db_per_path),
            PathBudget::Schedule { .. } => false,
        };
        budget_stop
            || cfg.target_psnr.is_some_and(|t| psnr >= t)
            || cfg.max_bytes.is_some_and(|max| {
                svg_bytes(scene, self.out_width, self.out_height, &cfg.colors) >= max
            })
    }

    /// Stage `si`: up to `want` new paths (within `max_total` added in all) at the regions of
    /// highest error, then all paths optimised. `None` when no path could be added; else
    /// whether a stop rule ends the stages. `st` then names the next stage.
    fn add_stage(
        &mut self,
        st: &mut LiveState,
        rng: &mut ChaCha8Rng,
        si: usize,
        want: usize,
        max_total: usize,
    ) -> Result<Option<bool>, LiveError> {
        // The budget counts paths added: a looping path split into simple pieces is one.
        let added_so_far: usize = st.reports.iter().map(|r| r.added).sum();
        let want = want.min(max_total.saturating_sub(added_so_far));
        if want == 0 {
            return Ok(None);
        }
        let current = crate::raster::render(&st.scene);
        let fresh = init::init_paths(&current, &self.target, want, &self.init_cfg(), rng);
        let fresh = tagged(fresh, si + 1);
        let added = fresh.len();
        if added == 0 {
            return Ok(None);
        }
        let scene = &mut st.scene;
        let start = scene.shapes.len();
        scene.shapes.extend(fresh);
        let end = scene.shapes.len();
        self.choose_colours(scene);
        let loss = self.optimise(scene, start..end, self.cfg.iters_per_stage, si + 1, true)?;
        let reinit = self.reinit_weak(scene, rng, si + 1);
        self.make_simple(scene);
        self.choose_colours(scene);
        let psnr = self.psnr(scene);
        st.reports.push(StageReport {
            stage: si + 1,
            added,
            paths: end,
            reinitialised: reinit,
            psnr,
            loss,
        });
        let stop = self.should_stop(&st.scene, st.prev_psnr, psnr, added);
        st.next_stage = si + 1;
        st.stages_done = stop;
        st.prev_psnr = psnr;
        Ok(Some(stop))
    }

    /// Runs the stages of `plan` from `st.next_stage` on, saving after each, until the plan,
    /// the budget or a stop rule ends them.
    pub(super) fn add_stages(
        &mut self,
        st: &mut LiveState,
        rng: &mut ChaCha8Rng,
        plan: &[usize],
        max_total: usize,
        checkpoint: Option<&dyn LiveCheckpoint>,
    ) -> Result<(), LiveError> {
        if st.stages_done {
            return Ok(());
        }
        for (si, &want) in plan.iter().enumerate().skip(st.next_stage) {
            if si + 1 == plan.len() {
                self.switch_to_full(&mut st.scene);
            }
            match self.add_stage(st, rng, si, want, max_total)? {
                None => break,
                Some(stop) => {
                    self.save(st, rng, checkpoint)?;
                    if stop {
                        break;
                    }
                }
            }
        }
        Ok(())
    }
}
