//! Noise schedules from `scheduler/scheduler_config.json` and the DDIM / Euler samplers.

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
    /// DDIM: `Some(r)` clamps `x̂₀` to `[-r, r]` (diffusers `clip_sample`).
    clip_x0: Option<f64>,
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
        let spaced = spaced_timesteps(cfg, steps)?;
        let (timesteps, sigmas) = match kind {
            SamplerKind::Ddim => {
                let t: Vec<f64> = if cfg.timestep_spacing == "linspace" {
                    spaced.iter().map(|x| x.round()).collect()
                } else {
                    spaced
                };
                (t, Vec::new())
            }
            SamplerKind::Euler => {
                let s = euler_sigmas(&ac, &spaced);
                (spaced, s)
            }
        };
        for &t in &timesteps {
            if t < 0.0 || t >= n as f64 {
                return Err(bad_config(format!(
                    "timestep {t} out of range for {steps} steps"
                )));
            }
        }
        let final_alpha_cumprod = if cfg.set_alpha_to_one { 1.0 } else { ac[0] };
        let _ = &cfg.class_name;
        Ok(Self {
            kind,
            prediction_type: cfg.prediction_type,
            alphas_cumprod: ac,
            timesteps,
            sigmas,
            final_alpha_cumprod,
            step_ratio: n / steps,
            clip_x0: cfg.clip_sample.then_some(cfg.clip_sample_range),
        })
    }

    /// Scale for the initial Gaussian noise.
    pub fn init_noise_sigma(&self, spacing_trailing_or_linspace: bool) -> f64 {
        match self.kind {
            SamplerKind::Ddim => 1.0,
            SamplerKind::Euler => {
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
        match self.kind {
            SamplerKind::Ddim => Ok(x.clone()),
            SamplerKind::Euler => {
                let s = self.sigmas[i];
                Ok((x / (s * s + 1.0).sqrt())?)
            }
        }
    }

    /// One step: `x` at step `i` and the (guided) raw model output → `x` at step `i + 1`.
    pub fn step(&self, model_out: &Tensor, i: usize, x: &Tensor) -> Result<Tensor> {
        if i >= self.timesteps.len() {
            return Err(ModelError::InvalidInput(format!("step {i} out of range")));
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
                let x0 = match self.clip_x0 {
                    Some(r) => x0.clamp(-r, r)?,
                    None => x0,
                };
                Ok(((x0 * a_prev.sqrt())? + (eps * (1.0 - a_prev).sqrt())?)?)
            }
            SamplerKind::Euler => {
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
                Ok((x + (d * (s_next - s))?)?)
            }
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
mod tests {
    use super::*;
    use candle_core::Device;

    fn cfg(extra: &str) -> SchedulerConfig {
        serde_json::from_str(&format!(
            r#"{{"beta_schedule": "squaredcos_cap_v2", "prediction_type": "v_prediction",
                "timestep_spacing": "trailing"{extra}}}"#
        ))
        .unwrap()
    }

    /// `clip_sample` clamps x̂₀ (so a wild model output cannot push x outside the data range at
    /// the last step) and leaves in-range predictions alone.
    #[test]
    fn clip_sample_clamps_the_predicted_x0_only() {
        let x = Tensor::from_vec(vec![0.5f32, -0.2, 0.1, 0.0], (1, 1, 2, 2), &Device::Cpu).unwrap();
        // v = -x0 at t = 999 (ᾱ ≈ 0): outputs of ±5 mean x̂₀ ≈ ∓5, far outside [-1, 1].
        let v = Tensor::from_vec(vec![5f32, -5.0, 0.3, -0.3], (1, 1, 2, 2), &Device::Cpu).unwrap();
        let plain = Sampler::new(&cfg(""), SamplerKind::Ddim, 1).unwrap();
        let clip = Sampler::new(&cfg(r#", "clip_sample": true"#), SamplerKind::Ddim, 1).unwrap();
        assert_eq!(clip.timesteps, vec![999.0]);
        let run = |s: &Sampler| -> Vec<f32> {
            s.step(&v, 0, &x)
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1()
                .unwrap()
        };
        let (a, b) = (run(&plain), run(&clip));
        assert!(a[0] < -4.0 && a[1] > 4.0, "{a:?}");
        assert!(b[0] >= -1.0 - 1e-6 && b[1] <= 1.0 + 1e-6, "{b:?}");
        assert!((a[2] - b[2]).abs() < 1e-6 && (a[3] - b[3]).abs() < 1e-6);
    }

    #[test]
    fn thresholding_and_bad_clip_range_are_refused() {
        let e = Sampler::new(&cfg(r#", "thresholding": true"#), SamplerKind::Ddim, 4).unwrap_err();
        assert!(e.to_string().contains("thresholding"), "{e}");
        let e = Sampler::new(
            &cfg(r#", "clip_sample": true, "clip_sample_range": 0.0"#),
            SamplerKind::Ddim,
            4,
        )
        .unwrap_err();
        assert!(e.to_string().contains("clip_sample_range"), "{e}");
    }
}
