//! Latent score distillation (SDS / LSDS): optimise a vector scene so that a diffusion teacher
//! finds its (augmented, encoded) render likely.
//!
//! One step: render (with a tape) → random perspective + crop ([`crate::augment`]) → encode →
//! `t ~ U(t_min, t_max)`, `ε ~ N(0, I)`, `z_t = √ᾱ z + √(1−ᾱ) ε` → `ε̂` with classifier-free
//! guidance → latent gradient `w(t)(ε̂ − ε)` → encoder VJP → augmentation VJP (+ image-space
//! penalties) → rasteriser backward → gradient clipping → Adam with the paper's schedules.
//!
//! Guards: a non-finite gradient skips the step; non-finite parameters after a step are rolled
//! back and the learning rate is halved. Both are counted in [`SdsStats`]; no NaN ever reaches the
//! scene or an SVG. Faint paths (opacity < 0.05, optionally tiny area) are re-initialised every
//! `reinit.every` steps until the last quarter. Progress events go to a [`ProgressSink`] with an
//! SVG snapshot every `snapshot_every` steps; the [`CancelToken`] is polled between steps.
//!
//! The loop is generic over a [`Backend`] (render with tape, backward, SVG text) so it can be
//! driven by the CPU rasteriser in production and by exact toy renderers in tests.

#![allow(clippy::needless_range_loop)] // index loops read clearest in pixel code

mod config;
mod reinit;
use reinit::reinit_faint;

pub use config::*;

use crate::augment::Warp;
use crate::image::Image;
use crate::optim::{Adam, StepOutcome};
use crate::progress::{CancelToken, CheckpointError, Progress, ProgressSink, Stage};
use crate::scene::{ParamGroup, Params, Scene};
use crate::teacher::{Conditioning, Latent, Teacher};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// What the SDS loop needs from a differentiable renderer.
pub trait Backend {
    /// Whatever the forward pass records for the backward pass.
    type Tape;
    /// Renders `scene` at its own size (premultiplied RGBA, background composited).
    fn render_tape(&self, scene: &Scene) -> (Image, Self::Tape);
    /// dL/d(params) from dL/d(rendered premultiplied RGBA data).
    fn backward(&self, scene: &Scene, tape: &Self::Tape, d_image: &[f32]) -> Params;
    /// SVG text for progress snapshots.
    fn svg(&self, scene: &Scene) -> String;
}

/// The production backend: the CPU rasteriser ([`crate::raster`]) and SVG export
/// ([`crate::svg`]).
#[derive(Clone, Copy, Debug, Default)]
pub struct RasterBackend;

impl RasterBackend {
    /// SVG text of a scene with the default export options.
    pub fn svg_text(scene: &Scene) -> String {
        crate::svg::to_svg(scene, &crate::svg::SvgOptions::default())
    }
}

impl Backend for RasterBackend {
    type Tape = crate::raster::Tape;
    fn render_tape(&self, scene: &Scene) -> (Image, Self::Tape) {
        crate::raster::render_tape(scene)
    }
    fn backward(&self, scene: &Scene, tape: &Self::Tape, d_image: &[f32]) -> Params {
        crate::raster::backward(scene, tape, d_image)
    }
    fn svg(&self, scene: &Scene) -> String {
        Self::svg_text(scene)
    }
}

/// Counters of what the loop did.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SdsStats {
    pub steps_done: u32,
    /// Steps skipped because a gradient held NaN/inf.
    pub skipped_nonfinite: u32,
    /// Times the parameters went non-finite, were rolled back and the lr halved.
    pub lr_halvings: u32,
    /// Paths re-initialised.
    pub reinits: u32,
    /// Steps whose gradient was clipped.
    pub clipped: u32,
    pub cancelled: bool,
    /// Mean `w(t)·|ε̂ − ε|²` per latent element at the last step.
    #[serde(deserialize_with = "crate::stages::live::null_as_nan")]
    pub last_loss: f64,
}

/// The result of [`run_sds`].
#[derive(Clone, Debug)]
pub struct SdsOutcome {
    pub scene: Scene,
    pub stats: SdsStats,
}

/// The SDS loop's whole state at a step boundary: resuming from it continues the run exactly
/// as if it had never stopped (same scene, optimiser moments, learning-rate scale, counters and
/// random stream). Serde, so service checkpoints can hold it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SdsState {
    /// Steps completed.
    pub step: u32,
    /// The scene after `step` steps (at the render size).
    pub scene: Scene,
    pub adam: Adam,
    /// Position of the loop's ChaCha8 stream (seeded with [`SdsConfig::seed`]), in 32-bit words.
    pub rng_word_pos: u64,
    /// Learning-rate scale after non-finite roll-backs (halved each time).
    pub lr_scale: f32,
    pub stats: SdsStats,
}

impl SdsState {
    /// The state before the first step of a run of `cfg` on `scene`.
    pub fn start(scene: Scene, cfg: &SdsConfig) -> Self {
        let params = Params::from_scene(&scene);
        SdsState {
            step: 0,
            adam: Adam::new(
                &params,
                cfg.adam.clone(),
                cfg.schedules.clone(),
                cfg.trainable,
            ),
            scene,
            rng_word_pos: 0,
            lr_scale: 1.0,
            stats: SdsStats::default(),
        }
    }
}

/// Where [`run_sds_resumable`] saves its state.
pub trait SdsCheckpoint {
    /// Whether a checkpoint is due after `step` (1-based) completed steps.
    fn due(&self, step: u32) -> bool;
    /// Saves the state; called when due and once more when the run is cancelled.
    fn save(&self, state: &SdsState) -> Result<(), CheckpointError>;
}

pub use crate::teacher::gaussian;

/// The SDS latent gradient `w(t)(ε̂ − ε)` for an encoded latent `z`, timestep `t` and noise `ε`.
/// Returns the gradient and the mean `w·|ε̂ − ε|²`.
pub fn sds_latent_grad(
    teacher: &dyn Teacher,
    z: &Latent,
    t: usize,
    noise: &[f32],
    cond: &Conditioning,
    guidance: f32,
    weighting: Weighting,
) -> Result<(Latent, f64), SdsError> {
    let alphas = teacher.alphas_cumprod();
    crate::teacher::check_timestep(t, alphas.len())?;
    let ab = alphas[t];
    if noise.len() != z.len() {
        return Err(SdsError::Config("noise length differs from latent".into()));
    }
    let (sa, s) = (ab.sqrt(), (1.0 - ab).sqrt());
    let z_t = Latent {
        shape: z.shape,
        data: z
            .data
            .iter()
            .zip(noise)
            .map(|(z, e)| sa * z + s * e)
            .collect(),
    };
    let eps_hat = teacher.predict_noise(&z_t, t, cond, guidance)?;
    let w = weighting.weight(ab);
    let mut loss = 0.0f64;
    let data = eps_hat
        .data
        .iter()
        .zip(noise)
        .map(|(h, e)| {
            let d = h - e;
            loss += (w * d * d) as f64;
            w * d
        })
        .collect();
    let n = z.len().max(1) as f64;
    Ok((
        Latent {
            shape: z.shape,
            data,
        },
        loss / n,
    ))
}

/// The SDS image-space gradient for a fixed teacher input image, `t` and noise: encode, latent
/// gradient, encoder VJP. Returns dL/d(image data) and the loss value.
pub fn sds_image_grad(
    teacher: &dyn Teacher,
    image: &Image,
    t: usize,
    noise: &[f32],
    cond: &Conditioning,
    guidance: f32,
    weighting: Weighting,
) -> Result<(Vec<f32>, f64), SdsError> {
    // One encoder pass serves the latent and the VJP (teachers with a taped encoder).
    let (z, pullback) = teacher.encode_linearised(image)?;
    let (gz, loss) = sds_latent_grad(teacher, &z, t, noise, cond, guidance, weighting)?;
    Ok((pullback(&gz)?, loss))
}

/// Adds the gradient of `weight · mean_pixels((R²+G²+B²)/3)` (image composited over white and
/// scaled to `[-1, 1]`) to `d_image` and returns the penalty value.
pub fn saturation_penalty(image: &Image, weight: f32, d_image: &mut [f32]) -> f64 {
    let n = image.len_pixels().max(1) as f32;
    let mut total = 0.0f64;
    for (p, d) in image.data.chunks_exact(4).zip(d_image.chunks_exact_mut(4)) {
        for c in 0..3 {
            let y = 2.0 * (p[c] + 1.0 - p[3]) - 1.0;
            total += (y * y) as f64;
            // d/dy = 2y·w/(3n); dy/dp_c = 2, dy/dp_a = −2.
            let g = 2.0 * y * weight / (3.0 * n) * 2.0;
            d[c] += g;
            d[3] -= g;
        }
    }
    weight as f64 * total / (3.0 * n as f64)
}

/// Clips each group's gradient to an L2 norm of at most `max`; returns whether anything changed.
fn clip_groups(g: &mut Params, max: f32) -> bool {
    let mut clipped = false;
    for grp in ParamGroup::ALL {
        let v = g.get_mut(grp);
        let norm = v.iter().map(|x| (x * x) as f64).sum::<f64>().sqrt() as f32;
        if norm > max {
            let k = max / norm;
            v.iter_mut().for_each(|x| *x *= k);
            clipped = true;
        }
    }
    clipped
}

/// Runs SDS on `scene` (rendered at its own size) with `teacher`. The scene should be
/// [`SdsConfig::render_size`] px wide for the teacher's input size.
pub fn run_sds<B: Backend>(
    backend: &B,
    teacher: &dyn Teacher,
    scene: Scene,
    cfg: &SdsConfig,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
) -> Result<SdsOutcome, SdsError> {
    let start = SdsState::start(scene, cfg);
    run_sds_resumable(backend, teacher, start, cfg, sink, cancel, None)
}

/// What every step of one SDS run shares.
struct Fixed<'a, B: Backend> {
    backend: &'a B,
    teacher: &'a dyn Teacher,
    cfg: &'a SdsConfig,
    cond: Conditioning,
    /// The deterministic resize to the teacher's size when not augmenting.
    resize: Option<Warp>,
    /// Re-initialisation stops at this step.
    reinit_until: u32,
    latent_len: usize,
}

/// The loop's moving parts: an [`SdsState`] with live parameters and random stream.
struct Moving {
    scene: Scene,
    params: Params,
    adam: Adam,
    rng: ChaCha8Rng,
    lr_scale: f32,
    stats: SdsStats,
}

impl Moving {
    /// The state after `step` steps, to save.
    fn snapshot(&self, step: u32) -> Result<SdsState, SdsError> {
        Ok(SdsState {
            step,
            scene: self.scene.clone(),
            adam: self.adam.clone(),
            rng_word_pos: u64::try_from(self.rng.get_word_pos())
                .map_err(|_| SdsError::Checkpoint("random stream position overflow".into()))?,
            lr_scale: self.lr_scale,
            stats: self.stats.clone(),
        })
    }

    /// An Adam step on `grad`, clipped as `cfg` says; a step that makes the parameters
    /// non-finite is rolled back and the learning rate halved.
    fn apply(&mut self, cfg: &SdsConfig, mut grad: Params) -> Result<(), SdsError> {
        if let Some(c) = cfg.grad_clip
            && grad.all_finite()
            && clip_groups(&mut grad, c)
        {
            self.stats.clipped += 1;
        }
        let before = self.params.clone();
        match self.adam.step(&mut self.params, &grad) {
            StepOutcome::SkippedNonFinite => self.stats.skipped_nonfinite += 1,
            StepOutcome::Applied => {
                if self.params.all_finite() {
                    self.params.write_to(&mut self.scene)?;
                    // Keep params consistent with the clamped scene.
                    self.params = Params::from_scene(&self.scene);
                } else {
                    self.params = before;
                    self.lr_scale *= 0.5;
                    self.adam.schedules = cfg.schedules.scaled(self.lr_scale);
                    self.stats.lr_halvings += 1;
                }
            }
        }
        Ok(())
    }
}

/// The deterministic resize of a `scene`-sized render to the teacher's `(width, height)`
/// when `cfg` does not augment and the sizes differ.
fn fixed_resize(cfg: &SdsConfig, scene: &Scene, (width, height): (u32, u32)) -> Option<Warp> {
    let identity = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    (cfg.augment.is_none() && (scene.width != width || scene.height != height)).then(|| {
        Warp::build(
            scene.width,
            scene.height,
            width,
            height,
            &identity,
            0.0,
            0.0,
            scene.width as f64,
            scene.height as f64,
            [1.0; 4],
            false,
        )
    })
}

/// The largest timestep at `step`: `t_max`, annealed linearly to `t_max_end` when set, and
/// never below `t_min`.
fn t_max_at(cfg: &SdsConfig, step: u32) -> usize {
    match cfg.t_max_end {
        Some(end) if cfg.steps > 1 => {
            let f = step as f32 / (cfg.steps - 1) as f32;
            (cfg.t_max as f32 + (end as f32 - cfg.t_max as f32) * f).round() as usize
        }
        _ => cfg.t_max,
    }
    .max(cfg.t_min)
}

impl<B: Backend> Fixed<'_, B> {
    /// The gradient of step `step` with respect to the scene's parameters (augmented or
    /// resized render → SDS → back through the warp and the rasteriser, plus the Xing loss),
    /// masked to what `cfg` trains; and the step's SDS loss.
    fn gradient(&self, m: &mut Moving, step: u32) -> Result<(Params, f64), SdsError> {
        let cfg = self.cfg;
        let (render, tape) = self.backend.render_tape(&m.scene);
        let warp = match &cfg.augment {
            Some(a) => Some(Warp::sample(a, render.width, render.height, &mut m.rng)?),
            None => self.resize.clone(),
        };
        let input = match &warp {
            Some(w) => w.apply(&render)?,
            None => render.clone(),
        };
        let t = m.rng.random_range(cfg.t_min..=t_max_at(cfg, step));
        let noise: Vec<f32> = (0..self.latent_len).map(|_| gaussian(&mut m.rng)).collect();
        let (d_input, loss) = sds_image_grad(
            self.teacher,
            &input,
            t,
            &noise,
            &self.cond,
            cfg.guidance,
            cfg.weighting,
        )?;
        let mut d_render = match &warp {
            Some(w) => w.vjp(&d_input)?,
            None => d_input,
        };
        if cfg.saturation_penalty > 0.0 {
            saturation_penalty(&render, cfg.saturation_penalty, &mut d_render);
        }
        let scene = &m.scene;
        let mut grad = self.backend.backward(scene, &tape, &d_render);
        if cfg.xing_weight > 0.0 {
            // LIVE's Xing loss on closed cubic paths keeps them free of self-intersections.
            for (i, sh) in scene.shapes.iter().enumerate() {
                if sh.kind == crate::scene::ShapeKind::ClosedCubic {
                    crate::losses::xing_loss(scene, i..i + 1, cfg.xing_weight, &mut grad);
                }
            }
        }
        grad.mask(&cfg.trainable);
        // The background is there or not: its colour is trained, its opacity stays as it
        // started (an SVG's background rectangle drawn 99.6 % opaque is no one's intent).
        if let Some(a) = grad.get_mut(ParamGroup::Background).get_mut(3) {
            *a = 0.0;
        }
        if cfg.opaque_fills {
            for rgba in grad.get_mut(ParamGroup::Fill).chunks_exact_mut(4) {
                rgba[3] = 0.0;
            }
            for a in crate::vector::fill::stop_alphas(grad.get_mut(ParamGroup::PaintStops)) {
                *a = 0.0;
            }
        }
        Ok((grad, loss))
    }

    /// The progress event after step `step` (0-based) with its `loss`: a snapshot when one
    /// is due, the counts of skipped and rolled-back steps once there are any.
    fn report(&self, m: &Moving, step: u32, loss: f64, sink: &dyn ProgressSink) {
        let cfg = self.cfg;
        let mut ev = Progress::new(Stage::Sds, step + 1, cfg.steps);
        ev.loss = Some(loss);
        if cfg.snapshot_every > 0 && (step + 1).is_multiple_of(cfg.snapshot_every) {
            ev.svg = Some(self.backend.svg(&m.scene));
        }
        if m.stats.skipped_nonfinite + m.stats.lr_halvings > 0 {
            ev.detail = Some(serde_json::json!({
                "skipped_nonfinite": m.stats.skipped_nonfinite,
                "lr_halvings": m.stats.lr_halvings,
            }));
        }
        sink.report(ev);
    }
}

/// [`run_sds`] from a saved [`SdsState`] (or [`SdsState::start`]), saving the state through
/// `checkpoint` when it is due and when cancelled. Resuming a state saved by a run of the same
/// `cfg` gives exactly the scene an uninterrupted run gives.
pub fn run_sds_resumable<B: Backend>(
    backend: &B,
    teacher: &dyn Teacher,
    state: SdsState,
    cfg: &SdsConfig,
    sink: &dyn ProgressSink,
    cancel: &CancelToken,
    checkpoint: Option<&dyn SdsCheckpoint>,
) -> Result<SdsOutcome, SdsError> {
    let first_step = state.step;
    let (f, mut m) = prepare(backend, teacher, state, cfg)?;
    for step in first_step..cfg.steps {
        if cancel.is_cancelled() {
            // Save the work done so far (a shutdown resumes from here). A failed save only
            // means a later attempt resumes from the previous checkpoint.
            if let Some(c) = checkpoint
                && step > first_step
                && let Ok(st) = m.snapshot(step)
            {
                let _ = c.save(&st);
            }
            m.stats.cancelled = true;
            break;
        }
        let (grad, loss) = f.gradient(&mut m, step)?;
        m.apply(cfg, grad)?;
        m.stats.last_loss = loss;
        m.stats.steps_done = step + 1;
        if let Some(r) = &cfg.reinit
            && r.every > 0
            && (step + 1) % r.every == 0
            && step + 1 < f.reinit_until
        {
            let n = reinit_faint(&mut m.scene, &mut m.params, &mut m.adam, r, &mut m.rng)?;
            m.stats.reinits += n;
        }
        f.report(&m, step, loss, sink);
        if let Some(c) = checkpoint
            && step + 1 < cfg.steps
            && c.due(step + 1)
        {
            c.save(&m.snapshot(step + 1)?)?;
        }
    }
    let Moving { scene, stats, .. } = m;
    scene.validate()?;
    let mut ev = Progress::new(Stage::Sds, stats.steps_done, cfg.steps);
    ev.loss = Some(stats.last_loss);
    ev.svg = Some(backend.svg(&scene));
    ev.detail = Some(serde_json::to_value(&stats).unwrap_or_default());
    sink.report(ev);
    Ok(SdsOutcome { scene, stats })
}

/// Checks `state` against `cfg` and the teacher and sets the run up from it.
fn prepare<'a, B: Backend>(
    backend: &'a B,
    teacher: &'a dyn Teacher,
    state: SdsState,
    cfg: &'a SdsConfig,
) -> Result<(Fixed<'a, B>, Moving), SdsError> {
    let SdsState {
        step: first_step,
        scene,
        adam,
        rng_word_pos,
        lr_scale,
        stats,
    } = state;
    scene.validate()?;
    cfg.validate(teacher.alphas_cumprod().len())?;
    let params = Params::from_scene(&scene);
    if first_step > cfg.steps || !adam.fits(&params) || !(lr_scale > 0.0 && lr_scale <= 1.0) {
        return Err(SdsError::Resume(format!(
            "the saved state (step {first_step} of {}) does not fit this run",
            cfg.steps
        )));
    }
    let cond = teacher
        .condition(&cfg.prompt, &cfg.negative_prompt)?
        .sized(cfg.size_conditioning.as_ref(), teacher.image_dims());
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    rng.set_word_pos(u128::from(rng_word_pos));
    let fixed = Fixed {
        backend,
        teacher,
        cfg,
        cond,
        resize: fixed_resize(cfg, &scene, teacher.image_dims()),
        reinit_until: cfg
            .reinit
            .as_ref()
            .map_or(0, |r| (r.until_fraction * cfg.steps as f32) as u32),
        latent_len: teacher.latent_shape().iter().product(),
    };
    let moving = Moving {
        scene,
        params,
        adam,
        rng,
        lr_scale,
        stats,
    };
    Ok((fixed, moving))
}

#[cfg(test)]
mod tests;
