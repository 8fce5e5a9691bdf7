//! The scalar type the rasteriser is generic over: `f32` in production, `f64` for the
//! finite-difference gradient tests.

use num_traits::Float;
use std::ops::{AddAssign, MulAssign, SubAssign};

pub(crate) trait Real:
    Float + AddAssign + SubAssign + MulAssign + Default + Send + Sync + std::fmt::Debug + 'static
{
    fn c(v: f64) -> Self;
    fn of(v: f32) -> Self;
    fn as_f32(self) -> f32;
}

impl Real for f32 {
    #[inline(always)]
    fn c(v: f64) -> Self {
        v as f32
    }
    #[inline(always)]
    fn of(v: f32) -> Self {
        v
    }
    #[inline(always)]
    fn as_f32(self) -> f32 {
        self
    }
}

impl Real for f64 {
    #[inline(always)]
    fn c(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn of(v: f32) -> Self {
        v as f64
    }
    #[inline(always)]
    fn as_f32(self) -> f32 {
        self as f32
    }
}
