//! Noise schedules from `scheduler/scheduler_config.json` and the samplers a model names there:
//! DDIM, Euler, Euler ancestral (SD-Turbo / SDXL-Turbo) and LCM, each as diffusers steps it.

use super::{ConfigIssue, ModelError, Result};
use crate::models::serde_defaults::num;
use candle_core::Tensor;
use serde::Deserialize;

/// What the UNet predicts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum PredictionType {
    #[default]
    Epsilon,
    VPrediction,
    Sample,
}

/// `scheduler/scheduler_config.json` (the fields that matter for SD).
#[derive(Debug, Clone, Deserialize)]
pub struct SchedulerConfig {
    #[serde(rename = "_class_name", default)]
    pub class_name: String,
    #[serde(default = "num::<1000>")]
    pub num_train_timesteps: usize,
    #[serde(default = "beta_start")]
    pub beta_start: f64,
    #[serde(default = "beta_end")]
    pub beta_end: f64,
    #[serde(default = "scaled_linear")]
    pub beta_schedule: String,
    #[serde(default)]
    pub trained_betas: Option<Vec<f64>>,
    #[serde(default)]
    pub prediction_type: PredictionType,
    #[serde(default)]
    pub set_alpha_to_one: bool,
    #[serde(default)]
    pub steps_offset: usize,
    #[serde(default = "leading")]
    pub timestep_spacing: String,
    #[serde(default)]
    pub rescale_betas_zero_snr: bool,
    /// DDIM: clamp the predicted `x₀` to `±clip_sample_range` each step (pixel-space models).
    #[serde(default)]
    pub clip_sample: bool,
    #[serde(default = "one")]
    pub clip_sample_range: f64,
    /// Dynamic thresholding (Imagen); not supported, refused when set.
    #[serde(default)]
    pub thresholding: bool,
    /// LCM: the teacher's step count its timesteps are drawn from (`LCMScheduler`).
    #[serde(default = "num::<50>")]
    pub original_inference_steps: usize,
    /// LCM: the factor on the timestep in the consistency boundary condition.
    #[serde(default = "ten")]
    pub timestep_scaling: f64,
}

fn ten() -> f64 {
    10.0
}

fn one() -> f64 {
    1.0
}

fn beta_start() -> f64 {
    0.00085
}
fn beta_end() -> f64 {
    0.012
}
fn scaled_linear() -> String {
    "scaled_linear".into()
}
fn leading() -> String {
    "leading".into()
}

impl SchedulerConfig {
    /// The SD 1.x/2.x training schedule (used when a benchmark needs one without files).
    pub fn sd() -> Self {
        serde_json::from_str("{}").unwrap_or_else(|_| unreachable!())
    }

    /// `ᾱ_t` for `t = 0..num_train_timesteps`.
    pub fn alphas_cumprod(&self) -> std::result::Result<Vec<f64>, ConfigIssue> {
        let n = self.num_train_timesteps;
        if !(2..=100_000).contains(&n) {
            return Err(ConfigIssue::Inconsistent(format!(
                "num_train_timesteps must be in 2..=100000, got {n}"
            )));
        }
        let lin = |a: f64, b: f64| -> Vec<f64> {
            (0..n)
                .map(|i| a + (b - a) * i as f64 / (n - 1) as f64)
                .collect()
        };
        let mut betas = if let Some(b) = &self.trained_betas {
            if b.len() != n {
                return Err(ConfigIssue::Inconsistent(format!(
                    "trained_betas has {} entries, expected {n}",
                    b.len()
                )));
            }
            b.clone()
        } else {
            match self.beta_schedule.as_str() {
                "linear" => lin(self.beta_start, self.beta_end),
                "scaled_linear" => lin(self.beta_start.sqrt(), self.beta_end.sqrt())
                    .into_iter()
                    .map(|x| x * x)
                    .collect(),
                "squaredcos_cap_v2" => {
                    let f = |t: f64| {
                        ((t + 0.008) / 1.008 * std::f64::consts::FRAC_PI_2)
                            .cos()
                            .powi(2)
                    };
                    (0..n)
                        .map(|i| {
                            let t1 = i as f64 / n as f64;
                            let t2 = (i + 1) as f64 / n as f64;
                            (1.0 - f(t2) / f(t1)).min(0.999)
                        })
                        .collect()
                }
                other => {
                    return Err(ConfigIssue::Unsupported {
                        setting: "beta_schedule",
                        value: Some(format!("{other:?}")),
                    });
                }
            }
        };
        let mut ac = Vec::with_capacity(n);
        let mut p = 1.0;
        for b in &betas {
            p *= 1.0 - b;
            ac.push(p);
        }
        if self.rescale_betas_zero_snr {
            let s: Vec<f64> = ac.iter().map(|a| a.sqrt()).collect();
            let (a0, at) = (s[0], s[n - 1]);
            let s: Vec<f64> = s.iter().map(|x| (x - at) * a0 / (a0 - at)).collect();
            let bar: Vec<f64> = s.iter().map(|x| x * x).collect();
            betas = (0..n)
                .map(|i| {
                    if i == 0 {
                        1.0 - bar[0]
                    } else {
                        1.0 - bar[i] / bar[i - 1]
                    }
                })
                .collect();
            ac.clear();
            let mut p = 1.0;
            for b in &betas {
                p *= 1.0 - b;
                ac.push(p);
            }
        }
        Ok(ac)
    }
}

/// Which sampler to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SamplerKind {
    /// DDIM with η = 0.
    Ddim,
    /// Euler (diffusers `EulerDiscreteScheduler`, no churn).
    Euler,
    /// Euler ancestral (diffusers `EulerAncestralDiscreteScheduler`): each step lands at
    /// `σ_down` and adds fresh noise of `σ_up`; SD-Turbo and SDXL-Turbo sample with it in 1–4
    /// steps.
    EulerAncestral,
    /// Latent consistency (diffusers `LCMScheduler`): each step predicts the clean latent
    /// through the consistency boundary condition and re-noises it to the next timestep.
    Lcm,
}

impl SamplerKind {
    /// The sampler a model's `scheduler_config.json` names (`_class_name`): Euler, Euler
    /// ancestral and LCM as named; DDIM for DDIM and for every other class (PNDM, the SD 1.x
    /// default, and the multistep solvers), whose training schedule DDIM samples as well.
    pub fn of(cfg: &SchedulerConfig) -> SamplerKind {
        match cfg.class_name.as_str() {
            "EulerDiscreteScheduler" => SamplerKind::Euler,
            "EulerAncestralDiscreteScheduler" => SamplerKind::EulerAncestral,
            "LCMScheduler" => SamplerKind::Lcm,
            _ => SamplerKind::Ddim,
        }
    }

    /// Whether step `i` of `steps` adds fresh noise (and so needs it passed to
    /// [`Sampler::step`]).
    pub fn adds_noise(self, i: usize, steps: usize) -> bool {
        match self {
            SamplerKind::Ddim | SamplerKind::Euler => false,
            SamplerKind::EulerAncestral => true,
            SamplerKind::Lcm => i + 1 < steps,
        }
    }

    fn uses_sigmas(self) -> bool {
        matches!(self, SamplerKind::Euler | SamplerKind::EulerAncestral)
    }
}

/// How a sampling run goes: the sampler, its steps and, for a stochastic sampler
/// ([`SamplerKind::adds_noise`]), the standard-normal noise its steps add, in order.
#[derive(Debug, Clone, Copy)]
pub struct SamplerRun<'a> {
    pub kind: SamplerKind,
    pub steps: usize,
    pub step_noise: &'a [Tensor],
}

impl SamplerRun<'_> {
    /// A run of a deterministic sampler (DDIM, Euler).
    pub fn plain(kind: SamplerKind, steps: usize) -> SamplerRun<'static> {
        SamplerRun {
            kind,
            steps,
            step_noise: &[],
        }
    }

    /// How many noise tensors a run of `kind` for `steps` steps takes.
    pub fn noise_count(kind: SamplerKind, steps: usize) -> usize {
        (0..steps).filter(|&i| kind.adds_noise(i, steps)).count()
    }
}

/// A configured sampler for a fixed number of steps.
#[derive(Debug, Clone)]
pub struct Sampler {
    pub kind: SamplerKind,
    pub prediction_type: PredictionType,
    alphas_cumprod: Vec<f64>,
    /// Timesteps passed to the UNet, one per step.
    pub timesteps: Vec<f64>,
    /// Euler: σ per step plus a final 0.
    sigmas: Vec<f64>,
    final_alpha_cumprod: f64,
    step_ratio: usize,
    /// DDIM and LCM: `Some(r)` clamps `x̂₀` to `[-r, r]` (diffusers `clip_sample`).
    clip_x0: Option<f64>,
    /// LCM: the factor on the timestep in the boundary condition.
    timestep_scaling: f64,
}

/// A scheduler config this sampler cannot use.
fn bad_config(reason: String) -> ModelError {
    ModelError::Config {
        path: "scheduler_config.json".into(),
        reason,
    }
}

/// The `steps` timesteps of `cfg.timestep_spacing` (as diffusers spaces them), from the last.
fn spaced_timesteps(cfg: &SchedulerConfig, steps: usize) -> Result<Vec<f64>> {
    let n = cfg.num_train_timesteps;
    let ratio = n / steps;
    Ok(match cfg.timestep_spacing.as_str() {
        "leading" => (0..steps)
            .rev()
            .map(|i| (i * ratio + cfg.steps_offset) as f64)
            .collect(),
        "trailing" => {
            let r = n as f64 / steps as f64;
            (0..steps)
                // numpy's round: halves to even (1000 / 16 steps: 812.5 → 812)
                .map(|i| (n as f64 - i as f64 * r).round_ties_even() - 1.0)
                .collect()
        }
        "linspace" => (0..steps)
            .rev()
            .map(|i| {
                if steps == 1 {
                    0.0
                } else {
                    i as f64 * (n - 1) as f64 / (steps - 1) as f64
                }
            })
            .collect(),
        other => {
            return Err(bad_config(format!(
                "timestep_spacing {other:?} is not supported"
            )));
        }
    })
}

/// LCM's `steps` timesteps: evenly spaced indices into the `original_inference_steps`
/// timesteps of the distilled teacher's schedule, from the last (as diffusers' `LCMScheduler`).
fn lcm_timesteps(cfg: &SchedulerConfig, steps: usize) -> Result<Vec<f64>> {
    let n = cfg.num_train_timesteps;
    let orig = cfg.original_inference_steps;
    if orig == 0 || orig > n || steps > orig {
        return Err(bad_config(format!(
            "original_inference_steps {orig} must be in 1..={n} and at least the {steps} steps"
        )));
    }
    let k = n / orig;
    let origin: Vec<usize> = (1..=orig).rev().map(|i| i * k - 1).collect();
    Ok((0..steps)
        .map(|i| origin[(i as f64 * orig as f64 / steps as f64).floor() as usize] as f64)
        .collect())
}

/// Euler's σ at each of `timesteps` (interpolated between the training steps of `ac`), plus a
/// final 0.
fn euler_sigmas(ac: &[f64], timesteps: &[f64]) -> Vec<f64> {
    let n = ac.len();
    let all: Vec<f64> = ac.iter().map(|a| ((1.0 - a) / a).sqrt()).collect();
    let interp = |t: f64| {
        let t = t.clamp(0.0, (n - 1) as f64);
        let i = t.floor() as usize;
        let f = t - i as f64;
        if i + 1 < n {
            all[i] * (1.0 - f) + all[i + 1] * f
        } else {
            all[n - 1]
        }
    };
    let mut s: Vec<f64> = timesteps.iter().map(|&t| interp(t)).collect();
    s.push(0.0);
    s
}

impl Sampler {
    pub fn new(cfg: &SchedulerConfig, kind: SamplerKind, steps: usize) -> Result<Self> {
        let ac = cfg
            .alphas_cumprod()
            .map_err(|e| bad_config(e.to_string()))?;
        if cfg.thresholding {
            return Err(bad_config(
                "thresholding (dynamic x0 thresholding) is not supported".into(),
            ));
        }
        if cfg.clip_sample && (cfg.clip_sample_range.is_nan() || cfg.clip_sample_range <= 0.0) {
            return Err(bad_config(format!(
                "clip_sample_range must be positive, got {}",
                cfg.clip_sample_range
            )));
        }
        let n = cfg.num_train_timesteps;
        if steps == 0 || steps > n {
            return Err(ModelError::InvalidInput(format!(
                "steps must be in 1..={n}, got {steps}"
            )));
        }
        let (timesteps, sigmas) = match kind {
            SamplerKind::Ddim => {
                let spaced = spaced_timesteps(cfg, steps)?;
                let t: Vec<f64> = if cfg.timestep_spacing == "linspace" {
                    spaced.iter().map(|x| x.round()).collect()
                } else {
                    spaced
                };
                (t, Vec::new())
            }
            SamplerKind::Euler | SamplerKind::EulerAncestral => {
                let spaced = spaced_timesteps(cfg, steps)?;
                let s = euler_sigmas(&ac, &spaced);
                (spaced, s)
            }
            SamplerKind::Lcm => (lcm_timesteps(cfg, steps)?, Vec::new()),
        };
        for &t in &timesteps {
            if t < 0.0 || t >= n as f64 {
                return Err(bad_config(format!(
                    "timestep {t} out of range for {steps} steps"
                )));
            }
        }
        let final_alpha_cumprod = if cfg.set_alpha_to_one { 1.0 } else { ac[0] };
        Ok(Self {
            kind,
            prediction_type: cfg.prediction_type,
            alphas_cumprod: ac,
            timesteps,
            sigmas,
            final_alpha_cumprod,
            step_ratio: n / steps,
            clip_x0: cfg.clip_sample.then_some(cfg.clip_sample_range),
            timestep_scaling: cfg.timestep_scaling,
        })
    }

    /// Scale for the initial Gaussian noise.
    pub fn init_noise_sigma(&self, spacing_trailing_or_linspace: bool) -> f64 {
        match self.kind {
            SamplerKind::Ddim | SamplerKind::Lcm => 1.0,
            SamplerKind::Euler | SamplerKind::EulerAncestral => {
                let m = self.sigmas.iter().copied().fold(0.0, f64::max);
                if spacing_trailing_or_linspace {
                    m
                } else {
                    (m * m + 1.0).sqrt()
                }
            }
        }
    }

    /// The model input for step `i` (Euler divides by `sqrt(σ² + 1)`).
    pub fn scale_model_input(&self, x: &Tensor, i: usize) -> Result<Tensor> {
        if self.kind.uses_sigmas() {
            let s = self.sigmas[i];
            Ok((x / (s * s + 1.0).sqrt())?)
        } else {
            Ok(x.clone())
        }
    }

    /// One step: `x` at step `i` and the (guided) raw model output → `x` at step `i + 1`.
    /// `noise` (standard normal, `x`'s shape) is what a stochastic step adds
    /// ([`SamplerKind::adds_noise`]); it must be given exactly then.
    pub fn step(
        &self,
        model_out: &Tensor,
        i: usize,
        x: &Tensor,
        noise: Option<&Tensor>,
    ) -> Result<Tensor> {
        if i >= self.timesteps.len() {
            return Err(ModelError::InvalidInput(format!("step {i} out of range")));
        }
        if self.kind.adds_noise(i, self.timesteps.len()) != noise.is_some() {
            return Err(ModelError::InvalidInput(format!(
                "step {i} of {:?} takes noise exactly when it adds noise",
                self.kind
            )));
        }
        match self.kind {
            SamplerKind::Ddim => {
                let t = self.timesteps[i] as usize;
                let a = self.alphas_cumprod[t];
                let a_prev = if t >= self.step_ratio {
                    self.alphas_cumprod[t - self.step_ratio]
                } else {
                    self.final_alpha_cumprod
                };
                let (x0, eps) = split_prediction(self.prediction_type, model_out, x, a)?;
                // As diffusers: the clamped x̂₀ is used, ε̂ stays the model's.
                let x0 = self.clipped(x0)?;
                Ok(((x0 * a_prev.sqrt())? + (eps * (1.0 - a_prev).sqrt())?)?)
            }
            SamplerKind::Euler | SamplerKind::EulerAncestral => {
                let s = self.sigmas[i];
                let s_next = self.sigmas[i + 1];
                let x0 = match self.prediction_type {
                    PredictionType::Epsilon => (x - (model_out * s)?)?,
                    PredictionType::VPrediction => {
                        ((model_out * (-s / (s * s + 1.0).sqrt()))? + (x / (s * s + 1.0))?)?
                    }
                    PredictionType::Sample => model_out.clone(),
                };
                let d = ((x - x0)? / s)?;
                match noise {
                    None => Ok((x + (d * (s_next - s))?)?),
                    Some(z) => {
                        // σ_up² = σ_next² (σ² − σ_next²) / σ²; σ_down² = σ_next² − σ_up².
                        let up = (s_next * s_next * (s * s - s_next * s_next) / (s * s)).sqrt();
                        let down = (s_next * s_next - up * up).max(0.0).sqrt();
                        Ok(((x + (d * (down - s))?)? + (z * up)?)?)
                    }
                }
            }
            SamplerKind::Lcm => self.lcm_step(model_out, i, x, noise),
        }
    }

    /// `x̂₀` clamped to `±clip_sample_range` when the config asks (diffusers `clip_sample`).
    fn clipped(&self, x0: Tensor) -> Result<Tensor> {
        Ok(match self.clip_x0 {
            Some(r) => x0.clamp(-r, r)?,
            None => x0,
        })
    }

    /// LCM: the clean latent by the boundary condition `c_skip·x + c_out·x̂₀`, re-noised to the
    /// next timestep (the last step returns it as it is).
    fn lcm_step(
        &self,
        model_out: &Tensor,
        i: usize,
        x: &Tensor,
        noise: Option<&Tensor>,
    ) -> Result<Tensor> {
        let t = self.timesteps[i];
        let a = self.alphas_cumprod[t as usize];
        let (x0, _) = split_prediction(self.prediction_type, model_out, x, a)?;
        let x0 = self.clipped(x0)?;
        // diffusers' boundary condition with σ_data = 0.5 on the scaled timestep
        let st = t * self.timestep_scaling;
        let c_skip = 0.25 / (st * st + 0.25);
        let c_out = st / (st * st + 0.25).sqrt();
        let denoised = ((x0 * c_out)? + (x * c_skip)?)?;
        match (noise, self.timesteps.get(i + 1)) {
            (Some(z), Some(&t_next)) => {
                let a_next = self.alphas_cumprod[t_next as usize];
                Ok(((denoised * a_next.sqrt())? + (z * (1.0 - a_next).sqrt())?)?)
            }
            _ => Ok(denoised),
        }
    }
}

/// `(x̂₀, ε̂)` from a raw model output at a timestep with `ᾱ = a`.
pub fn split_prediction(
    p: PredictionType,
    out: &Tensor,
    x: &Tensor,
    a: f64,
) -> candle_core::Result<(Tensor, Tensor)> {
    let (sa, sb) = (a.sqrt(), (1.0 - a).sqrt());
    match p {
        PredictionType::Epsilon => {
            let x0 = ((x - (out * sb)?)? / sa)?;
            Ok((x0, out.clone()))
        }
        PredictionType::VPrediction => {
            let x0 = ((x * sa)? - (out * sb)?)?;
            let eps = ((out * sa)? + (x * sb)?)?;
            Ok((x0, eps))
        }
        PredictionType::Sample => {
            let eps = ((x - (out * sa)?)? / sb)?;
            Ok((out.clone(), eps))
        }
    }
}

#[cfg(test)]
#[path = "scheduler_tests.rs"]
mod tests;
