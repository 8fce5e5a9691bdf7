//! Stroke coverage from the distance to the polyline.
//!
//! **Round caps and joins** (what optimisation creates): for a pixel centre `p` at distance `d`
//! from the polyline and half-width `r`, coverage is the length of `[d - 1/2, d + 1/2] ∩ [-r, r]`:
//! the exact box-filtered coverage of a straight, axis-aligned stroke, and a close
//! approximation elsewhere. Taking the minimum distance over segments gives the exact union of
//! capsules (no double counting at joins), and the result is differentiable in the segment end
//! points (through the closest point) and in `r`.
//!
//! **Butt and square caps, miter and bevel joins** (imported SVG strokes, see `shaped`): each
//! edge is a piece — its body between its end lines, with that same coverage of its distance to
//! the edge's line; beyond an open end the cap (a half-plane falloff `clamp(1/2 - u, 0, 1)` of
//! the distance `u` past the end, or past `r` beyond it for a square cap, times the body's);
//! beyond a joining end, inside the wedge between the two edges' outer normals, the join
//! (miter: the larger of the distances to the two outer edge lines; bevel, or a miter longer
//! than the limit: the distance past the line through the two outer corners, divided by the
//! cosine of half the turn so that it meets the bodies' distances). A pixel takes the
//! largest piece coverage (the union). These pieces differentiate by central differences of the
//! piece at the pixel in `f64` (`h = 1e-4` px): exact up to `O(h²)` away from a piece's kinks.

use super::real::Real;
use super::walk::Clip;
use crate::scene::{LineCap, LineJoin, Stroke};

/// How a stroke layer ends and turns: the scene's caps, joins and miter limit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Style {
    pub cap: LineCap,
    pub join: LineJoin,
    pub miter_limit: f32,
}

impl Style {
    pub fn of(st: &Stroke) -> Self {
        Style {
            cap: st.cap,
            join: st.join,
            miter_limit: st.miter_limit,
        }
    }

    fn is_round(&self) -> bool {
        self.cap.is_round() && self.join.is_round()
    }

    /// How far beyond the polyline (in half-widths) the stroke can reach.
    pub fn reach(&self) -> f32 {
        let cap: f32 = if self.cap == LineCap::Square {
            std::f32::consts::SQRT_2
        } else {
            1.0
        };
        let join = if self.join == LineJoin::Miter {
            self.miter_limit.max(1.0)
        } else {
            1.0
        };
        cap.max(join)
    }
}

#[inline]
fn seg_count(n: usize, closed: bool) -> usize {
    if closed { n } else { n.saturating_sub(1) }
}

/// Closest-point parameter on segment `a → b` and squared distance from `p`.
#[inline]
fn closest<T: Real>(p: [T; 2], a: [T; 2], b: [T; 2]) -> (T, T) {
    let d = [b[0] - a[0], b[1] - a[1]];
    let ap = [p[0] - a[0], p[1] - a[1]];
    let dd = d[0] * d[0] + d[1] * d[1];
    let s = if dd > T::zero() {
        ((ap[0] * d[0] + ap[1] * d[1]) / dd)
            .max(T::zero())
            .min(T::one())
    } else {
        // Zero-length segment: the distance does not depend on s; splitting the gradient
        // evenly between both ends is the symmetric subgradient.
        T::c(0.5)
    };
    let q = [ap[0] - s * d[0], ap[1] - s * d[1]];
    (s, q[0] * q[0] + q[1] * q[1])
}

/// Coverage from distance `d` and half-width `r`, with `(dcov/dd, dcov/dr)`.
#[inline]
pub(crate) fn cov_of<T: Real>(d: T, r: T) -> (T, T, T) {
    let h = T::c(0.5);
    let (up, up_d) = if d + h < r {
        (d + h, T::one())
    } else {
        (r, T::zero())
    };
    let (lo, lo_d) = if d - h > -r {
        (d - h, T::one())
    } else {
        (-r, T::zero())
    };
    let c = up - lo;
    if c > T::zero() {
        // d(up)/dr = 1 - up_d, d(lo)/dr = -(1 - lo_d).
        (c, up_d - lo_d, (T::one() - up_d) + (T::one() - lo_d))
    } else {
        (T::zero(), T::zero(), T::zero())
    }
}

/// Minimum squared distance and closest segment for every pixel centre in `clip`.
fn nearest<T: Real>(
    poly: &[[T; 2]],
    closed: bool,
    r: T,
    clip: Clip,
    d2: &mut Vec<T>,
    idx: &mut Vec<u32>,
) {
    let cw = (clip.x1 - clip.x0) as usize;
    let rows = (clip.y1 - clip.y0) as usize;
    d2.clear();
    d2.resize(cw * rows, T::infinity());
    idx.clear();
    idx.resize(cw * rows, u32::MAX);
    let n = poly.len();
    let reach = (r + T::c(0.5)).as_f32();
    let half = T::c(0.5);
    for e in 0..seg_count(n, closed) {
        let (a, b) = (poly[e], poly[(e + 1) % n]);
        let (ax, ay, bx, by) = (a[0].as_f32(), a[1].as_f32(), b[0].as_f32(), b[1].as_f32());
        let x0 = ((ax.min(bx) - reach).floor() as i32).max(clip.x0);
        let x1 = ((ax.max(bx) + reach).ceil() as i32).min(clip.x1);
        let y0 = ((ay.min(by) - reach).floor() as i32).max(clip.y0);
        let y1 = ((ay.max(by) + reach).ceil() as i32).min(clip.y1);
        for y in y0..y1 {
            let py = T::c(y as f64) + half;
            let row = (y - clip.y0) as usize * cw;
            for x in x0..x1 {
                let p = [T::c(x as f64) + half, py];
                let (_, dist2) = closest(p, a, b);
                let i = row + (x - clip.x0) as usize;
                if dist2 < d2[i] {
                    d2[i] = dist2;
                    idx[i] = e as u32;
                }
            }
        }
    }
}

/// Scratch buffers reused across layers.
#[derive(Default)]
pub(crate) struct Scratch<T> {
    d2: Vec<T>,
    idx: Vec<u32>,
}

/// Writes the stroke coverage of every pixel of `clip` into `out` (`cw * rows`).
pub(crate) fn coverage<T: Real>(
    poly: &[[T; 2]],
    closed: bool,
    r: T,
    style: Style,
    clip: Clip,
    out: &mut [T],
    s: &mut Scratch<T>,
) {
    if !style.is_round() {
        return shaped::coverage(poly, closed, r, style, clip, out, &mut s.idx);
    }
    nearest(poly, closed, r, clip, &mut s.d2, &mut s.idx);
    for (o, &d2) in out.iter_mut().zip(&s.d2) {
        *o = if d2.is_finite() {
            cov_of(d2.sqrt(), r).0
        } else {
            T::zero()
        };
    }
}

/// Given `g = dL/dcoverage` over `clip`, adds gradients to the polyline vertices and returns
/// dL/dr.
#[allow(clippy::too_many_arguments)]
pub(crate) fn backward<T: Real>(
    poly: &[[T; 2]],
    closed: bool,
    r: T,
    style: Style,
    clip: Clip,
    g: &[T],
    dpoly: &mut [[T; 2]],
    s: &mut Scratch<T>,
) -> T {
    if !style.is_round() {
        return shaped::backward(poly, closed, r, style, clip, g, dpoly, &mut s.idx);
    }
    nearest(poly, closed, r, clip, &mut s.d2, &mut s.idx);
    let cw = (clip.x1 - clip.x0) as usize;
    let n = poly.len();
    let half = T::c(0.5);
    let mut dr = T::zero();
    for (i, (&gv, &e)) in g.iter().zip(&s.idx).enumerate() {
        if gv == T::zero() || e == u32::MAX {
            continue;
        }
        let e = e as usize;
        let (a, b) = (poly[e], poly[(e + 1) % n]);
        let p = [
            T::c((clip.x0 + (i % cw) as i32) as f64) + half,
            T::c((clip.y0 + (i / cw) as i32) as f64) + half,
        ];
        let (t, d2) = closest(p, a, b);
        let d = d2.sqrt();
        let (c, dc_dd, dc_dr) = cov_of(d, r);
        if c == T::zero() {
            continue;
        }
        dr += gv * dc_dr;
        if dc_dd != T::zero() && d > T::c(1e-9) {
            // d = |p - q|, q = a + t (b - a); dd/dq = (q - p) / d (t fixed by the envelope
            // theorem).
            let q = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
            let k = gv * dc_dd / d;
            let gq = [k * (q[0] - p[0]), k * (q[1] - p[1])];
            let ib = (e + 1) % n;
            for c in 0..2 {
                dpoly[e][c] += (T::one() - t) * gq[c];
                dpoly[ib][c] += t * gq[c];
            }
        }
    }
    dr
}

#[path = "stroke_shaped.rs"]
mod shaped;
