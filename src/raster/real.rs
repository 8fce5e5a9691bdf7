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
    /// `floor` as an integer, saturating (NaN → 0); avoids the `floorf` libcall on baseline
    /// x86-64.
    fn floor_i32(self) -> i32;
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
    #[inline(always)]
    fn floor_i32(self) -> i32 {
        let t = self as i32;
        t - ((t as f32) > self) as i32
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
    #[inline(always)]
    fn floor_i32(self) -> i32 {
        let t = self as i32;
        t - ((t as f64) > self) as i32
    }
}
