//! Adam over scene parameter groups, learning-rate schedules and NaN guards.
//!
//! The state is plain data (serde) so the service can checkpoint a running optimisation.

use crate::scene::{ParamGroup, Params, Trainable};
use serde::{Deserialize, Serialize};

/// Learning rate as a function of the step (0-based).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum LrSchedule {
    Constant {
        lr: f32,
    },
    /// Linear warm-up from `start` to `peak` over `warmup` steps, then cosine decay from `peak` to
    /// `end` at step `total` (constant `end` afterwards). The VectorFusion schedule for points is
    /// `start = 0.02, peak = 0.2, warmup = 500, end = 0.05`.
    WarmupCosine {
        start: f32,
        peak: f32,
        warmup: u32,
        end: f32,
        total: u32,
    },
}

impl LrSchedule {
    /// A rate of 0 (the group does not move).
    pub fn zero() -> LrSchedule {
        LrSchedule::Constant { lr: 0.0 }
    }

    pub fn lr(&self, step: u32) -> f32 {
        match *self {
            LrSchedule::Constant { lr } => lr,
            LrSchedule::WarmupCosine {
                start,
                peak,
                warmup,
                end,
                total,
            } => {
                if step < warmup {
                    start + (peak - start) * step as f32 / warmup.max(1) as f32
                } else if step >= total {
                    end
                } else {
                    let span = (total - warmup).max(1) as f32;
                    let t = (step - warmup) as f32 / span;
                    end + 0.5 * (peak - end) * (1.0 + (std::f32::consts::PI * t).cos())
                }
            }
        }
    }

    /// The same schedule with every rate multiplied by `k` (e.g. colours 20x lower than points);
    /// the step counts stay.
    pub fn scaled(&self, k: f32) -> LrSchedule {
        let mut s = self.clone();
        match &mut s {
            LrSchedule::Constant { lr } => *lr *= k,
            LrSchedule::WarmupCosine {
                start, peak, end, ..
            } => {
                for rate in [start, peak, end] {
                    *rate *= k;
                }
            }
        }
        s
    }
}

/// Adam hyper-parameters shared by all groups.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AdamConfig {
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
}

impl Default for AdamConfig {
    /// VectorFusion's settings: betas (0.9, 0.9), eps 1e-6.
    fn default() -> Self {
        Self {
            beta1: 0.9,
            beta2: 0.9,
            eps: 1e-6,
        }
    }
}

/// One learning-rate schedule per trainable group.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroupSchedules {
    pub points: LrSchedule,
    pub fill: LrSchedule,
    pub stroke: LrSchedule,
    pub width: LrSchedule,
    pub background: LrSchedule,
    /// Gradient paints' geometry (pixels; zero in settings stored before it existed).
    #[serde(default = "LrSchedule::zero")]
    pub paint_geometry: LrSchedule,
    /// Gradient paints' stop offsets and colours (`[0, 1]`).
    #[serde(default = "LrSchedule::zero")]
    pub paint_stops: LrSchedule,
}

impl GroupSchedules {
    /// Every group's schedule with its rates multiplied by `k` (step counts unchanged).
    pub fn scaled(&self, k: f32) -> GroupSchedules {
        GroupSchedules {
            points: self.points.scaled(k),
            fill: self.fill.scaled(k),
            stroke: self.stroke.scaled(k),
            width: self.width.scaled(k),
            background: self.background.scaled(k),
            paint_geometry: self.paint_geometry.scaled(k),
            paint_stops: self.paint_stops.scaled(k),
        }
    }

    pub fn get(&self, g: ParamGroup) -> &LrSchedule {
        match g {
            ParamGroup::Points => &self.points,
            // Group opacities are colour parameters, trained at the fill rate.
            ParamGroup::Fill | ParamGroup::Opacity => &self.fill,
            ParamGroup::Stroke => &self.stroke,
            ParamGroup::Width => &self.width,
            ParamGroup::Background => &self.background,
            ParamGroup::PaintGeometry => &self.paint_geometry,
            ParamGroup::PaintStops => &self.paint_stops,
        }
    }
}

/// Adam with per-group schedules and a trainable mask.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Adam {
    pub config: AdamConfig,
    pub schedules: GroupSchedules,
    pub trainable: Trainable,
    /// Steps taken (skipped steps do not count).
    pub step: u32,
    /// Steps skipped because a gradient was not finite.
    pub skipped: u32,
    m: Params,
    v: Params,
}

/// What one [`Adam::step`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepOutcome {
    Applied,
    /// The gradient held NaN/inf; parameters and moments were left unchanged.
    SkippedNonFinite,
}

impl Adam {
    pub fn new(
        like: &Params,
        config: AdamConfig,
        schedules: GroupSchedules,
        trainable: Trainable,
    ) -> Self {
        let mut zeros = like.clone();
        for g in ParamGroup::ALL {
            zeros.get_mut(g).fill(0.0);
        }
        Self {
            config,
            schedules,
            trainable,
            step: 0,
            skipped: 0,
            m: zeros.clone(),
            v: zeros,
        }
    }

    /// Resets the moments of a range of a group (used when a path is re-initialised).
    pub fn reset_range(&mut self, g: ParamGroup, range: std::ops::Range<usize>) {
        self.m.get_mut(g)[range.clone()].fill(0.0);
        self.v.get_mut(g)[range].fill(0.0);
    }

    /// Replaces the moment buffers' layout after the scene changed shape (paths added/removed):
    /// moments are reset to zero for the new layout.
    pub fn relayout(&mut self, like: &Params) {
        let fresh = Adam::new(
            like,
            self.config.clone(),
            self.schedules.clone(),
            self.trainable,
        );
        self.m = fresh.m;
        self.v = fresh.v;
    }

    /// Whether the moment buffers have the layout of `like` (e.g. after loading a checkpoint).
    pub fn fits(&self, like: &Params) -> bool {
        ParamGroup::ALL.iter().all(|&g| {
            let n = like.get(g).len();
            self.m.get(g).len() == n && self.v.get(g).len() == n
        })
    }

    /// One Adam update of `params` with `grad` (minimisation). Frozen groups are untouched.
    pub fn step(&mut self, params: &mut Params, grad: &Params) -> StepOutcome {
        let active = |g: ParamGroup| self.trainable.contains(g);
        if ParamGroup::ALL
            .iter()
            .filter(|g| active(**g))
            .any(|g| grad.get(*g).iter().any(|v| !v.is_finite()))
        {
            self.skipped += 1;
            return StepOutcome::SkippedNonFinite;
        }
        let t = self.step + 1;
        let AdamConfig { beta1, beta2, eps } = self.config;
        let bc1 = 1.0 - beta1.powi(t as i32);
        let bc2 = 1.0 - beta2.powi(t as i32);
        for g in ParamGroup::ALL {
            if !active(g) {
                continue;
            }
            let lr = self.schedules.get(g).lr(self.step);
            let (p, gr) = (params.get_mut(g), grad.get(g));
            let m = self.m.get_mut(g);
            let v = self.v.get_mut(g);
            for i in 0..p.len() {
                m[i] = beta1 * m[i] + (1.0 - beta1) * gr[i];
                v[i] = beta2 * v[i] + (1.0 - beta2) * gr[i] * gr[i];
                let mh = m[i] / bc1;
                let vh = v[i] / bc2;
                p[i] -= lr * mh / (vh.sqrt() + eps);
            }
        }
        self.step = t;
        StepOutcome::Applied
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Rgba, Scene, Shape};

    #[test]
    fn warmup_cosine_matches_endpoints() {
        let s = LrSchedule::WarmupCosine {
            start: 0.02,
            peak: 0.2,
            warmup: 500,
            end: 0.05,
            total: 1000,
        };
        assert!((s.lr(0) - 0.02).abs() < 1e-7);
        assert!((s.lr(250) - 0.11).abs() < 1e-6);
        assert!((s.lr(500) - 0.2).abs() < 1e-6);
        assert!((s.lr(750) - 0.125).abs() < 1e-6);
        assert!((s.lr(1000) - 0.05).abs() < 1e-6);
        assert!((s.scaled(0.05).lr(500) - 0.01).abs() < 1e-7);
    }

    fn setup() -> (Scene, Params) {
        let mut s = Scene::new(32, 32, Rgba::WHITE).unwrap();
        s.shapes
            .push(Shape::circle(10.0, 10.0, 4.0, 4, Rgba::new(0.2, 0.2, 0.2, 1.0)).unwrap());
        let p = Params::from_scene(&s);
        (s, p)
    }

    fn schedules(lr: f32) -> GroupSchedules {
        let c = LrSchedule::Constant { lr };
        GroupSchedules {
            points: c.clone(),
            fill: c.clone(),
            stroke: c.clone(),
            width: c.clone(),
            background: c.clone(),
            paint_geometry: c.clone(),
            paint_stops: c,
        }
    }

    #[test]
    fn adam_minimises_a_quadratic_and_respects_mask() {
        let (_, mut p) = setup();
        let target = p.clone();
        p.get_mut(ParamGroup::Points)
            .iter_mut()
            .for_each(|v| *v += 3.0);
        let frozen_bg = p.get(ParamGroup::Background).to_vec();
        let mut adam = Adam::new(
            &p,
            AdamConfig::default(),
            schedules(0.1),
            Trainable {
                background: false,
                ..Trainable::ALL
            },
        );
        for _ in 0..300 {
            let mut g = p.clone();
            g.add_scaled(&target, -1.0); // d/dp 0.5|p - target|^2
            g.get_mut(ParamGroup::Background).fill(1.0);
            assert_eq!(adam.step(&mut p, &g), StepOutcome::Applied);
        }
        let err: f32 = p
            .get(ParamGroup::Points)
            .iter()
            .zip(target.get(ParamGroup::Points))
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(err < 0.05, "max error {err}");
        assert_eq!(p.get(ParamGroup::Background), frozen_bg.as_slice());
    }

    #[test]
    fn non_finite_gradient_is_skipped() {
        let (_, mut p) = setup();
        let before = p.clone();
        let mut adam = Adam::new(&p, AdamConfig::default(), schedules(0.1), Trainable::ALL);
        let mut g = p.clone();
        g.get_mut(ParamGroup::Fill)[1] = f32::NAN;
        assert_eq!(adam.step(&mut p, &g), StepOutcome::SkippedNonFinite);
        assert_eq!(p, before);
        assert_eq!((adam.step, adam.skipped), (0, 1));
    }
}
