//! What a LIVE run is asked to do ([`LiveConfig`] and its parts) and how it can fail.

use super::schedule;
use crate::losses::LossError;
use crate::scene::{MAX_PATHS, SceneError};
use crate::vector::fill::FillKind;
use crate::vector::palette::ColorPlan;
use crate::vector::{check_max_bytes, check_target_psnr};
use serde::{Deserialize, Serialize};
use std::ops::RangeInclusive;

/// Canvas sides (pixels) a run may work at: LIVE's working size and a text run's teacher size.
pub const CANVAS_SIDES: RangeInclusive<u32> = 8..=2048;

/// Paths with fill opacity below this are faint: LIVE and SDS re-initialise them, and a text
/// run prunes them at the end.
pub const MIN_OPACITY: f32 = 0.05;

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
    #[error("saving a checkpoint failed: {0}")]
    Save(#[from] crate::progress::CheckpointError),
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

    /// The default `auto` budget: [`PathBudget::auto_up_to`] 64 paths.
    pub fn auto() -> Self {
        PathBudget::auto_up_to(64)
    }

    /// An `auto` budget of at most `max_paths`: stages of 8 (or fewer, when `max_paths` is
    /// smaller), continue while each added path gains more than 0.05 dB, prune paths worth less
    /// than 2e-5 MSE.
    pub fn auto_up_to(max_paths: usize) -> Self {
        PathBudget::Auto {
            stage: 8.min(max_paths),
            max_paths,
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
    /// No tracing: a square per pixel, merged into one outline per region of a colour (pixel
    /// art, up to [`super::pixels::MAX_PIXELS_SIDE`] px a side; [`super::pixels`]).
    Pixels,
}

/// User-facing LIVE settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LiveConfig {
    /// Working side (pixels): the optimisation runs on the target scaled to the area of a
    /// `size`×`size` square (a square target: `size` a side; never larger than the target);
    /// the result is scaled back to the target's size.
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
    /// Fill colours (palette, colour cap, background, grouping); plans stored before it
    /// existed take the default: near-equal fills merged, background `auto`.
    #[serde(default)]
    pub colors: ColorPlan,
    /// Stop adding paths once the PSNR (dB, at the working size) reaches this.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_psnr: Option<f64>,
    /// Keep the SVG at most this many bytes: stop adding paths when it is reached, then drop
    /// the paths whose removal costs least until it fits (one path always stays).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_bytes: Option<usize>,
    /// End a stage (and the final pass) early once the mean loss of 20 steps improves on the
    /// previous 20's by less than this fraction; 0 (the presets', and plans stored before it
    /// existed) runs every step.
    #[serde(default)]
    pub converge_tol: f32,
    /// Coarse-to-fine: the working side (pixels) of every stage but the last; the last stage
    /// and the final pass run at `size`. 0 (and plans stored before it existed) or a side not
    /// below `size` works at `size` throughout.
    #[serde(default)]
    pub coarse_size: u32,
    /// What the paths are painted with: flat colours (the default, left out of the JSON so
    /// the plan's key is unchanged) or a linear or radial gradient each.
    #[serde(default, skip_serializing_if = "FillKind::is_flat")]
    pub fill: FillKind,
    /// Peak learning rates of gradient paints: geometry (pixels per step at the full working
    /// size, like `lr_points`) and stop offsets and colours (like `lr_fill`).
    #[serde(
        default = "lr_paint_default",
        skip_serializing_if = "is_lr_paint_default"
    )]
    pub lr_paint: [f32; 2],
}

/// [`LiveConfig::lr_paint`]'s default: geometry as fast as points, stops as fast as fills.
pub const LR_PAINT: [f32; 2] = [1.0, 0.02];

fn lr_paint_default() -> [f32; 2] {
    LR_PAINT
}

fn is_lr_paint_default(v: &[f32; 2]) -> bool {
    *v == LR_PAINT
}

impl LiveConfig {
    /// Checks ranges; called by [`vectorize`].
    pub fn validate(&self) -> Result<(), LiveError> {
        /// Per-stage iteration limit: keeps step counters far from `u32` overflow.
        const MAX_ITERS: u32 = 100_000;
        let bad = |m: &str| Err(LiveError::Config(m.to_string()));
        if !CANVAS_SIDES.contains(&self.size) {
            return Err(LiveError::Config(format!(
                "size must be in {}..={}",
                CANVAS_SIDES.start(),
                CANVAS_SIDES.end()
            )));
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
            self.lr_paint[0],
            self.lr_paint[1],
            self.udf_weight,
            self.udf_tau,
            self.xing_weight,
            self.init_radius,
            self.reinit_min_opacity,
            self.reinit_min_area,
            self.converge_tol,
        ];
        if finite.iter().any(|v| !v.is_finite() || *v < 0.0) {
            return bad("rates, weights, radii and thresholds must be finite and >= 0");
        }
        if self.init_segments == 0 || self.init_segments > 64 {
            return bad("init_segments must be in 1..=64");
        }
        self.colors
            .validate()
            .map_err(|(field, e)| LiveError::Config(format!("{field}: {e}")))?;
        self.fill
            .check_with_palette(self.colors.colors.is_some() || self.colors.palette.is_some())
            .map_err(|e| LiveError::Config(format!("fill: {e}")))?;
        if let Some(v) = self.target_psnr {
            check_target_psnr(v).map_err(|e| LiveError::Config(format!("target_psnr: {e}")))?;
        }
        if let Some(v) = self.max_bytes {
            check_max_bytes(v).map_err(|e| LiveError::Config(format!("max_bytes: {e}")))?;
        }
        if self.init == InitMode::Pixels && (self.target_psnr.is_some() || self.max_bytes.is_some())
        {
            return bad("init pixels copies every pixel: target_psnr and max_bytes do not apply");
        }
        if self.coarse_size != 0 && !CANVAS_SIDES.contains(&self.coarse_size) {
            return Err(LiveError::Config(format!(
                "coarse_size must be 0 or in {}..={}",
                CANVAS_SIDES.start(),
                CANVAS_SIDES.end()
            )));
        }
        if self.iters_per_stage > MAX_ITERS || self.final_iters > MAX_ITERS {
            return bad("iterations per stage must be at most 100000");
        }
        Ok(())
    }
}

impl Default for LiveConfig {
    /// LIVE's own settings (the `fast` vectorize preset's): 128 px, 64 paths in LIVE's
    /// proportions, 100 iterations per stage and 50 for the final pass. The other presets and
    /// a text run's trace change a few of them.
    fn default() -> Self {
        LiveConfig {
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
            reinit_min_opacity: MIN_OPACITY,
            reinit_min_area: 16.0,
            seed: 0,
            snapshot_every: 50,
            colors: ColorPlan::default(),
            target_psnr: None,
            max_bytes: None,
            converge_tol: 0.0,
            coarse_size: 0,
            fill: FillKind::Flat,
            lr_paint: LR_PAINT,
        }
    }
}
