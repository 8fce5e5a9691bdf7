//! Source-over of one layer's coverage onto a band, forward and backward, generic over the
//! colour source ([`Shade`]: a flat colour or a gradient).

use super::engine::BandTape;
use super::paint::Shade;
use super::real::Real;
use super::walk::Clip;

/// Coverage of a fill from its winding integral `A`: `min(|A|, 1)` (nonzero), or the distance
/// of `A` to the nearest even integer (even-odd: 0 on even windings, 1 on odd ones, linear in
/// between, exact where one edge crosses a pixel).
#[inline]
pub(crate) fn coverage<T: Real>(a: T, even_odd: bool) -> T {
    if even_odd {
        (a - T::c(2.0) * (a * T::c(0.5)).round()).abs()
    } else {
        a.abs().min(T::one())
    }
}

/// `d coverage / dA` (see [`coverage`]; 0 where the nonzero coverage saturates).
#[inline]
fn coverage_slope<T: Real>(a: T, even_odd: bool) -> T {
    let r = if even_odd {
        a - T::c(2.0) * (a * T::c(0.5)).round()
    } else if a.abs() < T::one() {
        a
    } else {
        return T::zero();
    };
    if r < T::zero() { -T::one() } else { T::one() }
}

/// Where a layer is composited within a band: its clip, the band's first row and the canvas
/// width, whether `out` holds winding integrals (fills) or coverages (strokes), and a fill's
/// rule.
pub(crate) struct Area {
    pub clip: Clip,
    pub y0: i32,
    pub w: usize,
    pub fill: bool,
    pub even_odd: bool,
}

impl Area {
    /// The per-pixel rule as a constant for [`composite_as`] and [`composite_back_as`]: 0 a
    /// stroke's coverage, 1 a nonzero fill, 2 an even-odd fill.
    fn mode(&self) -> u8 {
        match (self.fill, self.even_odd) {
            (false, _) => STROKE,
            (true, false) => NONZERO,
            (true, true) => EVEN_ODD,
        }
    }
}

const STROKE: u8 = 0;
const NONZERO: u8 = 1;
const EVEN_ODD: u8 = 2;

/// Whether all four channels are zero: `gp == [0; 4]` without short-circuiting, so that the
/// four comparisons can run as one.
#[inline(always)]
pub(crate) fn all_zero<T: Real>(gp: &[T]) -> bool {
    let z = T::zero();
    (gp[0] == z) & (gp[1] == z) & (gp[2] == z) & (gp[3] == z)
}

/// The coverage of a pixel's value under rule `MODE` (see [`Area::mode`]).
#[inline(always)]
fn coverage_as<T: Real, const MODE: u8>(v: T) -> T {
    match MODE {
        STROKE => v,
        NONZERO => coverage(v, false),
        _ => coverage(v, true),
    }
}

/// Source-over of one layer's per-pixel values `out` onto the band `img`, recording the colour
/// underneath into `dst` when taping.
#[inline(always)]
pub(crate) fn composite<T: Real, S: Shade<T>>(
    at: &Area,
    out: &[T],
    img: &mut [T],
    dst: Option<&mut Vec<T>>,
    shade: &S,
) {
    // The rule is a constant of each copy of the pixel loop.
    match at.mode() {
        STROKE => composite_as::<T, S, STROKE>(at, out, img, dst, shade),
        NONZERO => composite_as::<T, S, NONZERO>(at, out, img, dst, shade),
        _ => composite_as::<T, S, EVEN_ODD>(at, out, img, dst, shade),
    }
}

#[inline(always)]
fn composite_as<T: Real, S: Shade<T>, const MODE: u8>(
    at: &Area,
    out: &[T],
    img: &mut [T],
    mut dst: Option<&mut Vec<T>>,
    shade: &S,
) {
    let clip = at.clip;
    let cw = (clip.x1 - clip.x0) as usize;
    for row in 0..(clip.y1 - clip.y0) as usize {
        let vrow = &out[row * cw..(row + 1) * cw];
        let iy = (clip.y0 - at.y0) as usize + row;
        let base = 4 * (iy * at.w + clip.x0 as usize);
        let prow = &mut img[base..base + 4 * cw];
        if let Some(d) = dst.as_deref_mut() {
            d.extend_from_slice(prow);
        }
        let y = clip.y0 + row as i32;
        for (ix, (&v, p)) in vrow.iter().zip(prow.chunks_exact_mut(4)).enumerate() {
            let cov = coverage_as::<T, MODE>(v);
            if cov == T::zero() {
                continue;
            }
            let [r, g, b, ca] = shade.color(clip.x0 + ix as i32, y);
            let alpha = cov * ca;
            if alpha > T::zero() {
                let keep = T::one() - alpha;
                p[0] = r * alpha + p[0] * keep;
                p[1] = g * alpha + p[1] * keep;
                p[2] = b * alpha + p[2] * keep;
                p[3] = alpha + p[3] * keep;
            }
        }
    }
}

/// The backward of [`composite`] for one layer: takes `dL/d out` of the band (`g`, updated to
/// `dL/d below`), gives the colour source its gradients and writes `dL/d value` per pixel into
/// `gbuf` (the winding integral for fills, the coverage for strokes). Returns whether any of
/// those is non-zero.
#[inline(always)]
pub(crate) fn composite_back<T: Real, S: Shade<T>>(
    at: &Area,
    offset: usize,
    tape: &BandTape<T>,
    g: &mut [T],
    gbuf: &mut [T],
    shade: &mut S,
) -> bool {
    match at.mode() {
        STROKE => composite_back_as::<T, S, STROKE>(at, offset, tape, g, gbuf, shade),
        NONZERO => composite_back_as::<T, S, NONZERO>(at, offset, tape, g, gbuf, shade),
        _ => composite_back_as::<T, S, EVEN_ODD>(at, offset, tape, g, gbuf, shade),
    }
}

#[inline(always)]
fn composite_back_as<T: Real, S: Shade<T>, const MODE: u8>(
    at: &Area,
    offset: usize,
    tape: &BandTape<T>,
    g: &mut [T],
    gbuf: &mut [T],
    shade: &mut S,
) -> bool {
    let clip = at.clip;
    let cw = (clip.x1 - clip.x0) as usize;
    let mut any = false;
    for row in 0..(clip.y1 - clip.y0) as usize {
        let iy = (clip.y0 - at.y0) as usize + row;
        let base = 4 * (iy * at.w + clip.x0 as usize);
        let grow = &mut g[base..base + 4 * cw];
        let off = offset + row * cw;
        let arow = &tape.area[off..off + cw];
        let drow = &tape.dst[4 * off..4 * (off + cw)];
        let gb = &mut gbuf[row * cw..(row + 1) * cw];
        let y = clip.y0 + row as i32;
        for (ix, (((&a, d), gp), gbv)) in arow
            .iter()
            .zip(drow.chunks_exact(4))
            .zip(grow.chunks_exact_mut(4))
            .zip(gb.iter_mut())
            .enumerate()
        {
            *gbv = T::zero();
            if a == T::zero() || all_zero(gp) {
                // No coverage and no edge inside, or no gradient from above (under an opaque
                // layer): nothing flows through this layer here (the skipped updates would add
                // and scale zeros only).
                continue;
            }
            let x = clip.x0 + ix as i32;
            let [cr, cg, cb, ca] = shade.color(x, y);
            let cov = coverage_as::<T, MODE>(a);
            let alpha = cov * ca;
            let galpha = gp[0] * (cr - d[0])
                + gp[1] * (cg - d[1])
                + gp[2] * (cb - d[2])
                + gp[3] * (T::one() - d[3]);
            shade.grad(
                x,
                y,
                [gp[0] * alpha, gp[1] * alpha, gp[2] * alpha, galpha * cov],
            );
            let slope = match MODE {
                STROKE => T::one(),
                NONZERO => coverage_slope(a, false),
                _ => coverage_slope(a, true),
            };
            if slope != T::zero() {
                let dcov = galpha * ca;
                let v = if slope < T::zero() { -dcov } else { dcov };
                any |= v != T::zero();
                *gbv = v;
            }
            let keep = T::one() - alpha;
            for c in gp.iter_mut() {
                *c *= keep;
            }
        }
    }
    any
}
