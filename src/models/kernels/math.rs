//! Branch-free `exp`, `erf` and GELU that the compiler can vectorise, and a helper that runs a
//! loop compiled for AVX2 + FMA when the CPU has them.
//!
//! The standard library's `f32::exp` is a scalar libm call: in the UNet's attention softmax at
//! 512 px (1.3 G exponentials per guided step) it alone would cost seconds. These versions are
//! within 1e-7 relative of `exp` over the range used and 5e-7 absolute of `erf` (float32 rounding on top of the formula's 1.5e-7).

/// The constants of [`exp_fast`] (and of its sixteen-lane copy, operation for operation).
mod exp_consts {
    /// The clamp: `e^x` is finite and normal for `x` in here.
    pub const LO: f32 = -87.0;
    pub const HI: f32 = 88.0;
    pub const LOG2_E: f32 = std::f32::consts::LOG2_E;
    /// ln 2 split so that `n · LN2_HI` is exact for |n| ≤ 128 (Cephes' constants).
    pub const LN2_HI: f32 = 0.693_359_4;
    pub const LN2_LO: f32 = -2.121_944_4e-4;
    /// 1.5 · 2^23: adding it rounds to the nearest integer, kept in the low mantissa bits.
    pub const MAGIC: f32 = 12_582_912.0;
    /// e^y for |y| ≤ ln2/2: Taylor to degree 7 (truncation error < 6e-9), highest power first,
    /// evaluated `p = p · y + c`.
    pub const TAYLOR: [f32; 8] = [
        1.0 / 5040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ];
}

/// `e^x`, relative error ≤ 1e-7 for `x ∈ [-87, 88]`; inputs outside are clamped (so
/// `exp_fast(-1000) ≈ 1e-38`, not 0; callers use it where that is negligible).
#[inline(always)]
pub fn exp_fast(x: f32) -> f32 {
    use exp_consts::*;
    let x = x.clamp(LO, HI);
    let r = x * LOG2_E + MAGIC;
    let n = r - MAGIC;
    let ni = (r.to_bits() as i32).wrapping_sub(MAGIC.to_bits() as i32);
    let y = x - n * LN2_HI - n * LN2_LO;
    let mut p = TAYLOR[0];
    for c in &TAYLOR[1..] {
        p = p * y + c;
    }
    p * f32::from_bits((ni.wrapping_add(127) as u32) << 23)
}

/// `erf(x)`, absolute error ≤ 5e-7 (Abramowitz & Stegun 7.1.26, with the exponential above).
#[inline(always)]
pub fn erf(x: f32) -> f32 {
    // A&S 7.1.26 has |ε| ≤ 1.5e-7
    const P: f32 = 0.327_591_1;
    const A1: f32 = 0.254_829_6;
    const A2: f32 = -0.284_496_74;
    const A3: f32 = 1.421_413_7;
    const A4: f32 = -1.453_152_1;
    const A5: f32 = 1.061_405_4;
    let ax = x.abs();
    let t = 1.0 / (1.0 + P * ax);
    let poly = ((((A5 * t + A4) * t + A3) * t + A2) * t + A1) * t;
    let y = 1.0 - poly * exp_fast(-ax * ax);
    y.copysign(x)
}

/// The exact (erf) GELU, `x · Φ(x)`, as PyTorch's `F.gelu` computes it.
#[inline(always)]
pub fn gelu(x: f32) -> f32 {
    0.5 * x * (1.0 + erf(x * std::f32::consts::FRAC_1_SQRT_2))
}

/// Runs `f`, compiled for AVX2 + FMA when the CPU has them (the body is inlined into a copy with
/// those target features), else as built. Pass the body as an `#[inline(always)]` closure: a
/// closure LLVM does not inline is compiled apart, for the baseline (SSE). Rust neither fuses
/// `a * b + c` into an FMA nor reorders a sum, so both copies give the same bits. (An AVX-512F
/// copy measured no faster on the UNet, TAESD or VAE: only the softmax pass has one,
/// [`exp_shifted_sum_wide`].)
#[inline(always)]
pub fn vectorised<T>(f: impl FnOnce() -> T) -> T {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx2,fma")]
        unsafe fn avx2<T>(f: impl FnOnce() -> T) -> T {
            f()
        }
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the features were just detected on this CPU.
            return unsafe { avx2(f) };
        }
    }
    f()
}

/// In place: `row[i] = e^(row[i] − max(row))`; returns `Σ row[i]` after (8-lane accumulators so
/// the reductions vectorise).
#[inline(always)]
pub fn exp_shifted_sum(row: &mut [f32]) -> f32 {
    let mut mx = [f32::NEG_INFINITY; 8];
    let mut chunks = row.chunks_exact(8);
    for c in &mut chunks {
        for l in 0..8 {
            mx[l] = mx[l].max(c[l]);
        }
    }
    let mut m = chunks
        .remainder()
        .iter()
        .fold(f32::NEG_INFINITY, |a, &b| a.max(b));
    for v in mx {
        m = m.max(v);
    }
    exp_shifted_sum_from(row, m, [0f32; 8])
}

/// The exponential pass of [`exp_shifted_sum`] with the maximum `m` known, the eight lane sums
/// starting at `acc` (what the values before `row` left there).
#[inline(always)]
fn exp_shifted_sum_from(row: &mut [f32], m: f32, mut acc: [f32; 8]) -> f32 {
    let mut chunks = row.chunks_exact_mut(8);
    for c in &mut chunks {
        for l in 0..8 {
            let e = exp_fast(c[l] - m);
            c[l] = e;
            acc[l] += e;
        }
    }
    let mut s = 0f32;
    for v in chunks.into_remainder() {
        *v = exp_fast(*v - m);
        s += *v;
    }
    s + acc.iter().sum::<f32>()
}

/// [`exp_shifted_sum`] with AVX-512 where the CPU has it, else [`exp_shifted_sum`]: the same
/// operations in the same order (sixteen exponentials at a time, summed into the same eight
/// lanes one half after the other), so the same bits.
#[inline(always)]
pub fn exp_shifted_sum_wide(row: &mut [f32]) -> f32 {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx512f") {
        // SAFETY: the feature was just detected on this CPU.
        return unsafe { avx512::exp_shifted_sum(row) };
    }
    exp_shifted_sum(row)
}

#[cfg(target_arch = "x86_64")]
mod avx512 {
    use std::arch::x86_64::*;

    /// [`super::exp_fast`] on sixteen lanes, operation for operation (no fused multiply-adds;
    /// `max(lo, x)` then `min(hi, ·)` keep a NaN as `clamp` does).
    #[inline]
    #[target_feature(enable = "avx512f")]
    fn exp16(x: __m512) -> __m512 {
        use super::exp_consts::*;
        let x = _mm512_min_ps(_mm512_set1_ps(HI), _mm512_max_ps(_mm512_set1_ps(LO), x));
        let r = _mm512_add_ps(
            _mm512_mul_ps(x, _mm512_set1_ps(LOG2_E)),
            _mm512_set1_ps(MAGIC),
        );
        let n = _mm512_sub_ps(r, _mm512_set1_ps(MAGIC));
        let ni = _mm512_sub_epi32(
            _mm512_castps_si512(r),
            _mm512_set1_epi32(MAGIC.to_bits() as i32),
        );
        let y = _mm512_sub_ps(x, _mm512_mul_ps(n, _mm512_set1_ps(LN2_HI)));
        let y = _mm512_sub_ps(y, _mm512_mul_ps(n, _mm512_set1_ps(LN2_LO)));
        let mut p = _mm512_set1_ps(TAYLOR[0]);
        for c in &TAYLOR[1..] {
            p = _mm512_add_ps(_mm512_mul_ps(p, y), _mm512_set1_ps(*c));
        }
        let scale = _mm512_slli_epi32::<23>(_mm512_add_epi32(ni, _mm512_set1_epi32(127)));
        _mm512_mul_ps(p, _mm512_castsi512_ps(scale))
    }

    /// See [`super::exp_shifted_sum_wide`].
    #[target_feature(enable = "avx512f")]
    pub(super) fn exp_shifted_sum(row: &mut [f32]) -> f32 {
        let m = row.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
        let (pairs, rest) = row.split_at_mut(row.len() / 16 * 16);
        let shift = _mm512_set1_ps(m);
        let mut acc = _mm256_setzero_ps();
        for c in pairs.chunks_exact_mut(16) {
            // SAFETY: `c` holds 16 floats.
            let e = unsafe {
                let e = exp16(_mm512_sub_ps(_mm512_loadu_ps(c.as_ptr()), shift));
                _mm512_storeu_ps(c.as_mut_ptr(), e);
                e
            };
            acc = _mm256_add_ps(acc, _mm512_castps512_ps256(e));
            let high = _mm512_extractf64x4_pd::<1>(_mm512_castps_pd(e));
            acc = _mm256_add_ps(acc, _mm256_castpd_ps(high));
        }
        let mut lanes = [0f32; 8];
        // SAFETY: `lanes` holds 8 floats.
        unsafe { _mm256_storeu_ps(lanes.as_mut_ptr(), acc) };
        super::exp_shifted_sum_from(rest, m, lanes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_matches_std_to_a_few_ulp() {
        let mut worst = 0f64;
        for i in -86_990..=87_990 {
            let x = i as f32 * 1e-3;
            let (got, want) = (exp_fast(x) as f64, (x as f64).exp());
            worst = worst.max(((got - want) / want).abs());
        }
        assert!(worst < 2e-7, "worst relative error {worst}");
        assert!(exp_fast(-1e4) < 1e-37 && exp_fast(-1e4) >= 0.0);
        assert!(exp_fast(f32::NEG_INFINITY) < 1e-37);
    }

    #[test]
    fn erf_and_gelu_match_reference_values() {
        // erf from the series / tables (Abramowitz & Stegun table 7.1)
        for (x, want) in [
            (0.0f32, 0.0f64),
            (0.1, 0.112_462_916),
            (0.5, 0.520_499_878),
            (1.0, 0.842_700_793),
            (2.0, 0.995_322_265),
            (3.5, 0.999_999_257),
        ] {
            assert!((erf(x) as f64 - want).abs() < 5e-7, "erf({x})");
            assert!((erf(-x) as f64 + want).abs() < 5e-7, "erf(-{x})");
        }
        // gelu(1) = Φ(1) = 0.841344746
        assert!((gelu(1.0) - 0.841_344_7).abs() < 5e-7);
        assert!((gelu(-1.0) + 0.158_655_25).abs() < 5e-7);
        assert_eq!(gelu(-20.0), 0.0);
    }

    /// The AVX-512 softmax pass gives the very bits of the 8-lane one (where the CPU has it):
    /// lengths around the 8- and 16-lane boundaries, scores up to ±90 (the clamp), and a 4096-key
    /// row as the UNet's attention at 512 px has.
    #[test]
    fn the_wide_softmax_pass_gives_the_same_bits() {
        let mut seed = 7u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1 << 24) as f32 * 2.0 - 1.0
        };
        for len in (0..50).chain([255, 256, 257, 1000, 4096]) {
            for spread in [1.0f32, 12.0, 90.0] {
                let a: Vec<f32> = (0..len).map(|_| next() * spread).collect();
                let (mut x, mut y) = (a.clone(), a.clone());
                let sx = exp_shifted_sum(&mut x);
                let sy = exp_shifted_sum_wide(&mut y);
                assert_eq!(sx.to_bits(), sy.to_bits(), "sum, {len} values ±{spread}");
                let same = x.iter().zip(&y).all(|(p, q)| p.to_bits() == q.to_bits());
                assert!(same, "values, {len} values ±{spread}");
            }
        }
    }

    #[test]
    fn softmax_pieces_vectorised_or_not_agree() {
        // Bit for bit: the vectorised copies differ from the baseline only in vector width.
        let mut a: Vec<f32> = (0..301).map(|i| (i as f32 * 0.7).sin() * 9.0).collect();
        let mut b = a.clone();
        let sa = exp_shifted_sum(&mut a);
        let sb = vectorised(
            #[inline(always)]
            || exp_shifted_sum(&mut b),
        );
        assert_eq!(sa.to_bits(), sb.to_bits());
        assert!(a.contains(&1.0), "the maximum maps to e^0");
        assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
        let xs: Vec<f32> = (0..301).map(|i| (i as f32 - 150.0) * 0.04).collect();
        let plain: Vec<u32> = xs.iter().map(|&x| gelu(x).to_bits()).collect();
        let wide: Vec<u32> = vectorised(
            #[inline(always)]
            || xs.iter().map(|&x| gelu(x).to_bits()).collect(),
        );
        assert_eq!(plain, wide);
    }
}
