//! What an SDS run is asked to do ([`SdsConfig`] and its parts) and how it can fail.

use crate::augment::{AugmentConfig, AugmentError};
use crate::models::guided::SizeConditioning;
use crate::optim::{AdamConfig, GroupSchedules};
use crate::scene::{SceneError, Trainable};
use crate::stages::live::MIN_OPACITY;
use crate::stages::styles::Style;
use crate::teacher::TeacherError;
use serde::{Deserialize, Serialize};

/// The paper's timestep range `[T_MIN, T_MAX]` (of 1000 training timesteps).
pub const T_MIN: usize = 50;
/// See [`T_MIN`].
pub const T_MAX: usize = 950;

/// Why SDS could not run.
#[derive(Debug, thiserror::Error)]
pub enum SdsError {
    #[error(transparent)]
    Teacher(#[from] TeacherError),
    #[error(transparent)]
    Augment(#[from] AugmentError),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("invalid SDS settings: {0}")]
    Config(String),
    #[error("cannot resume SDS: {0}")]
    Resume(String),
    #[error("saving an SDS checkpoint failed: {0}")]
    Checkpoint(String),
    #[error("saving an SDS checkpoint failed: {0}")]
    Save(#[from] crate::progress::CheckpointError),
}

/// The weighting `w(t)` of the SDS gradient.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Weighting {
    /// `w(t) = 1 − ᾱ_t` (DreamFusion, VectorFusion).
    OneMinusAlpha,
    /// `w(t) = 1`.
    Uniform,
    /// `w(t) = √ᾱ_t · √(1 − ᾱ_t)`.
    SqrtAlphaSigma,
}

impl Weighting {
    pub fn weight(self, alpha_bar: f32) -> f32 {
        match self {
            Weighting::OneMinusAlpha => 1.0 - alpha_bar,
            Weighting::Uniform => 1.0,
            Weighting::SqrtAlphaSigma => (alpha_bar * (1.0 - alpha_bar)).sqrt(),
        }
    }
}

/// Re-initialisation of faint (and optionally tiny) closed paths.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReinitConfig {
    /// Check every this many steps.
    pub every: u32,
    /// Paths with fill opacity below this are re-initialised.
    pub min_opacity: f32,
    /// Paths whose control-polygon area is below this many px² are re-initialised too.
    pub min_area: Option<f32>,
    /// Stop re-initialising after this fraction of the steps (paper: the last quarter is left
    /// alone → 0.75).
    pub until_fraction: f32,
}

impl Default for ReinitConfig {
    fn default() -> Self {
        Self {
            every: 50,
            min_opacity: MIN_OPACITY,
            min_area: None,
            until_fraction: 0.75,
        }
    }
}

/// SDS settings. [`SdsConfig::for_style`] gives the paper's defaults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SdsConfig {
    pub steps: u32,
    /// Caption with style suffix (what the teacher is conditioned on).
    pub prompt: String,
    pub negative_prompt: String,
    /// SDXL's size and crop conditioning of the teacher's time ids (`None`: the teacher's
    /// drawn size, no crop); models without time ids ignore it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub size_conditioning: Option<SizeConditioning>,
    /// Timestep range `[t_min, t_max]` (inclusive) at the start …
    pub t_min: usize,
    pub t_max: usize,
    /// … and `t_max` at the last step (linear annealing); `None` = no annealing.
    pub t_max_end: Option<usize>,
    pub guidance: f32,
    pub weighting: Weighting,
    /// Maximum L2 norm of the parameter gradient of each group (`None` = no clipping).
    pub grad_clip: Option<f32>,
    /// Augmentation (`None` = the render is only resized to the teacher's input size).
    pub augment: Option<AugmentConfig>,
    pub adam: AdamConfig,
    pub schedules: GroupSchedules,
    pub trainable: Trainable,
    /// Fill opacities stay as they are (their gradient is dropped): low-poly's opaque fills.
    #[serde(default)]
    pub opaque_fills: bool,
    pub reinit: Option<ReinitConfig>,
    /// Weight of the pixel-art saturation penalty `mean(R²+G²+B²)/3` on the render scaled to
    /// `[-1, 1]` (paper: 0.05 for pixel art, 0 otherwise).
    pub saturation_penalty: f32,
    /// Weight of LIVE's Xing (self-intersection) loss on closed cubic paths (0 = off).
    pub xing_weight: f32,
    /// Send an SVG snapshot every this many steps (0 = only at the end).
    pub snapshot_every: u32,
    pub seed: u64,
}

impl SdsConfig {
    /// The paper's settings for `style` over `steps` steps, with augmentation producing
    /// `teacher_size` px encoder inputs (render at [`AugmentConfig::render_size`]).
    pub fn for_style(style: Style, caption: &str, steps: u32, teacher_size: u32) -> Self {
        let spec = style.spec();
        Self {
            steps,
            prompt: style.prompt(caption),
            negative_prompt: String::new(),
            size_conditioning: None,
            t_min: T_MIN,
            t_max: T_MAX,
            t_max_end: None,
            guidance: 100.0,
            weighting: Weighting::OneMinusAlpha,
            grad_clip: None,
            augment: Some(AugmentConfig::vectorfusion(teacher_size)),
            adam: AdamConfig::default(),
            schedules: spec.schedules(steps),
            trainable: spec.trainable(),
            opaque_fills: spec.opaque_fills(),
            reinit: spec.reinit_faint_paths().then(ReinitConfig::default),
            saturation_penalty: spec.saturation_penalty(),
            xing_weight: spec.xing_weight(),
            snapshot_every: 50,
            seed: 0,
        }
    }

    /// The scene side to render at for a teacher of `teacher_size` px.
    pub fn render_size(&self, teacher_size: u32) -> u32 {
        self.augment
            .as_ref()
            .map_or(teacher_size, AugmentConfig::render_size)
    }

    pub(super) fn validate(&self, num_timesteps: usize) -> Result<(), SdsError> {
        let t_hi = self.t_max.max(self.t_max_end.unwrap_or(0));
        if self.t_min > self.t_max || t_hi >= num_timesteps {
            return Err(SdsError::Config(format!(
                "timestep range [{}, {}] must be ordered and below {num_timesteps}",
                self.t_min, t_hi
            )));
        }
        if let Some(e) = self.t_max_end
            && e < self.t_min
        {
            return Err(SdsError::Config("t_max_end must be >= t_min".into()));
        }
        if !self.guidance.is_finite() || self.grad_clip.is_some_and(|c| c.is_nan() || c <= 0.0) {
            return Err(SdsError::Config(
                "guidance must be finite and grad_clip positive".into(),
            ));
        }
        Ok(())
    }
}
