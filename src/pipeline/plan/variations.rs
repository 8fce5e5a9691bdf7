//! Variations of a text run: how many results it returns ([`TextPlan::variations`], checked
//! by [`check_variations`]) and the seeds and plan of each ([`Seeds::variation`],
//! [`TextPlan::variation`]).

use super::{JobKind, Limits, PlanRequest, Seeds, SpecError, TextPlan, check_range};

pub(super) fn one() -> u32 {
    1
}
pub(super) fn is_one(n: &u32) -> bool {
    *n == 1
}

/// The most variations a text run may return.
pub const MAX_VARIATIONS: u32 = 6;

impl Seeds {
    /// The seeds of variation `i` (0-based) of a run: variation 0 runs with these seeds, every
    /// other with its own trace, init, top-up and SDS seeds (derived from these, within
    /// [`crate::pipeline::MAX_SEED`]); the sample seed is shared (the variations are the best of one
    /// set of samples).
    pub fn variation(self, i: usize) -> Self {
        if i == 0 {
            return self;
        }
        let k = (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        let mix = |s: u64| (s ^ k).rotate_left(17) & crate::pipeline::MAX_SEED;
        Seeds {
            sample: self.sample,
            trace: mix(self.trace),
            init: mix(self.init),
            top_up: mix(self.top_up),
            sds: mix(self.sds),
        }
    }
}

impl TextPlan {
    /// The plan of variation `i` (0-based): this plan for the first, the same plan with the
    /// variation's seeds ([`Seeds::variation`]) for the others.
    pub fn variation(&self, i: usize) -> std::borrow::Cow<'_, TextPlan> {
        if i == 0 {
            return std::borrow::Cow::Borrowed(self);
        }
        std::borrow::Cow::Owned(TextPlan {
            seeds: self.seeds.variation(i),
            ..self.clone()
        })
    }
}

/// `req.variations`, within `1..=MAX_VARIATIONS`, for a text job (a vectorize job, even one
/// fine-tuned to a caption, has one result), and the sample count of a run that samples
/// (`samples`, raised to it) within `limits`.
pub(super) fn check_variations(
    req: &PlanRequest,
    samples: Option<u32>,
    limits: &Limits,
) -> Result<u32, SpecError> {
    let v = check_range("variations", req.variations, MAX_VARIATIONS)?;
    if v > 1 && req.kind != JobKind::Text {
        return Err(SpecError::new(
            "variations",
            "only applies to kind \"text\" (a vectorize job has one result)",
        ));
    }
    if samples.is_some_and(|k| v > k) && v > limits.max_samples {
        return Err(SpecError::new(
            "variations",
            format!(
                "needs {v} samples, and at most {} are allowed (limits.max_samples)",
                limits.max_samples
            ),
        ));
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::super::{ModelFacts, RunPlan, resolve};
    use super::*;
    use crate::pipeline::{Method, StartKind};

    fn plan(req: &PlanRequest) -> Result<RunPlan, SpecError> {
        resolve(req, Some(&ModelFacts::paper("m")), &Limits::default())
    }

    fn asking(n: u32) -> PlanRequest {
        PlanRequest {
            variations: n,
            samples: Some(2),
            ..PlanRequest::text("a crown")
        }
    }

    #[test]
    fn variations_are_bounded_and_raise_the_samples() {
        for bad in [0, MAX_VARIATIONS + 1] {
            assert_eq!(plan(&asking(bad)).unwrap_err().field, "variations");
        }
        let one = plan(&asking(1)).unwrap();
        // One variation leaves the plan (and so its checkpoint key) as it was.
        assert!(!serde_json::to_string(&one).unwrap().contains("variations"));
        assert_eq!((one.variations(), one.samples()), (1, Some(2)));
        let five = plan(&asking(5)).unwrap();
        assert_eq!((five.variations(), five.samples()), (5, Some(5)));
        let back: RunPlan = serde_json::from_str(&serde_json::to_string(&five).unwrap()).unwrap();
        assert_eq!(back, five);
        let tight = Limits {
            max_samples: 4,
            ..Limits::default()
        };
        let e = resolve(&asking(5), Some(&ModelFacts::paper("m")), &tight).unwrap_err();
        assert_eq!(e.field, "variations");
        let scratch = PlanRequest {
            method: Method::Scratch,
            ..asking(3)
        };
        assert_eq!(plan(&scratch).unwrap().variations(), 3);
    }

    #[test]
    fn only_text_runs_take_variations() {
        let svg = PlanRequest {
            start: StartKind::Svg,
            ..asking(2)
        };
        assert_eq!(plan(&svg).unwrap().variations(), 2);
        let vectorize = PlanRequest {
            kind: JobKind::Vectorize,
            caption: None,
            ..asking(2)
        };
        assert_eq!(plan(&vectorize).unwrap_err().field, "variations");
    }

    #[test]
    fn the_first_variation_keeps_the_seeds_and_the_others_differ() {
        let s = Seeds::from_seed(7);
        assert_eq!(s.variation(0), s);
        let (a, b) = (s.variation(1), s.variation(2));
        assert_eq!((a.sample, b.sample), (s.sample, s.sample));
        assert!(a.sds != s.sds && b.sds != a.sds && a.trace != s.trace && a.init != s.init);
        assert!(a.sds <= crate::pipeline::MAX_SEED);
    }
}
