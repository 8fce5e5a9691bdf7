//! What a layer is painted with, pixel by pixel: a flat colour or a gradient
//! ([`crate::scene::paint`] describes the model), forward and backward.
//!
//! The engine's compositing loops are generic over [`Shade`]; the flat colour's implementation
//! is a constant, so flat layers compile to the same loop as before gradients existed.
//! Gradients are evaluated at pixel centres; their backward goes through the stop colours,
//! the stop offsets (the linear interpolation weight) and the geometry (the implicit
//! derivative of `t`). The gradient transform is fixed (not a parameter).

use super::real::Real;
use crate::scene::{Gradient, GradientGeometry, Spread};

/// The colour source of one layer's compositing.
pub(crate) trait Shade<T: Real> {
    /// Straight RGBA at pixel `(x, y)`.
    fn color(&self, x: i32, y: i32) -> [T; 4];
    /// Adds `dL/d colour` at pixel `(x, y)` into the source's parameter gradients.
    fn grad(&mut self, x: i32, y: i32, dc: [T; 4]);
}

/// A flat colour; `dc` collects its gradient.
pub(crate) struct Flat<T> {
    pub c: [T; 4],
    pub dc: [T; 4],
}

impl<T: Real> Shade<T> for Flat<T> {
    #[inline(always)]
    fn color(&self, _: i32, _: i32) -> [T; 4] {
        self.c
    }
    #[inline(always)]
    fn grad(&mut self, _: i32, _: i32, dc: [T; 4]) {
        for c in 0..4 {
            self.dc[c] += dc[c];
        }
    }
}

/// A gradient in the working precision; parameters in [`Gradient::params`] order.
#[derive(Clone, Debug)]
pub(crate) struct PaintT<T> {
    pub radial: bool,
    /// `x1, y1, x2, y2` (linear; the last two unused) or `cx, cy, r, fx, fy, fr`.
    pub geom: [T; 6],
    /// Canvas → gradient space (fixed).
    pub inv: [T; 6],
    pub spread: Spread,
    pub offsets: Vec<T>,
    pub colors: Vec<[T; 4]>,
}

impl<T: Real> PaintT<T> {
    pub fn of(g: &Gradient) -> Self {
        let mut geom = [T::zero(); 6];
        for (k, v) in g.geometry.values().into_iter().enumerate() {
            geom[k] = T::of(v);
        }
        PaintT {
            radial: matches!(g.geometry, GradientGeometry::Radial { .. }),
            geom,
            inv: g.transform.inverse_f64().map(T::c),
            spread: g.spread,
            offsets: g.stops.iter().map(|s| T::of(s.offset)).collect(),
            colors: g
                .stops
                .iter()
                .map(|s| s.color.to_array().map(T::of))
                .collect(),
        }
    }

    fn n_geom(&self) -> usize {
        if self.radial { 6 } else { 4 }
    }

    /// Scalars in the parameter layout.
    pub fn num_params(&self) -> usize {
        self.n_geom() + 5 * self.offsets.len()
    }

    /// Mutable parameter `k` (tests).
    #[cfg(test)]
    pub fn param_mut(&mut self, k: usize) -> &mut T {
        let ng = self.n_geom();
        if k < ng {
            return &mut self.geom[k];
        }
        let (i, j) = ((k - ng) / 5, (k - ng) % 5);
        if j == 0 {
            &mut self.offsets[i]
        } else {
            &mut self.colors[i][j - 1]
        }
    }

    /// The pixel centre in gradient space.
    #[inline]
    fn local(&self, x: i32, y: i32) -> [T; 2] {
        let h = T::c(0.5);
        let (px, py) = (T::c(x as f64) + h, T::c(y as f64) + h);
        let m = &self.inv;
        [m[0] * px + m[2] * py + m[4], m[1] * px + m[3] * py + m[5]]
    }

    /// The gradient parameter `t` at `q`, if the pixel is painted.
    fn t_at(&self, q: [T; 2]) -> Option<T> {
        let g = &self.geom;
        if !self.radial {
            let u = [g[2] - g[0], g[3] - g[1]];
            let dd = u[0] * u[0] + u[1] * u[1];
            if !(dd > T::c(1e-12)) {
                return Some(T::one());
            }
            return Some(((q[0] - g[0]) * u[0] + (q[1] - g[1]) * u[1]) / dd);
        }
        let (d, e, dr) = conic(g, q);
        let a = d[0] * d[0] + d[1] * d[1] - dr * dr;
        let b = e[0] * d[0] + e[1] * d[1] + g[5] * dr;
        let cc = e[0] * e[0] + e[1] * e[1] - g[5] * g[5];
        let ok = |t: T| g[5] + t * dr >= T::zero();
        if a.abs() <= T::c(1e-9) * (d[0] * d[0] + d[1] * d[1] + dr * dr) {
            let t = cc / (T::c(2.0) * b);
            return (t.is_finite() && ok(t)).then_some(t);
        }
        let disc = b * b - a * cc;
        if disc < T::zero() {
            return None;
        }
        let s = disc.sqrt();
        let (t1, t2) = ((b + s) / a, (b - s) / a);
        let (hi, lo) = if t1 > t2 { (t1, t2) } else { (t2, t1) };
        if ok(hi) {
            Some(hi)
        } else if ok(lo) {
            Some(lo)
        } else {
            None
        }
    }

    /// `dt / d geometry` at `q` where the parameter is `t`.
    fn dt_dgeom(&self, q: [T; 2], t: T) -> [T; 6] {
        let g = &self.geom;
        let z = T::zero();
        let two = T::c(2.0);
        if !self.radial {
            let u = [g[2] - g[0], g[3] - g[1]];
            let dd = u[0] * u[0] + u[1] * u[1];
            if !(dd > T::c(1e-12)) {
                return [z; 6];
            }
            let v = [q[0] - g[0], q[1] - g[1]];
            let p1 = |c: usize| (-u[c] - v[c] + two * t * u[c]) / dd;
            let p2 = |c: usize| (v[c] - two * t * u[c]) / dd;
            return [p1(0), p1(1), p2(0), p2(1), z, z];
        }
        // F(t, θ) = a t² - 2 b t + cc = 0, so dt/dθ = -(∂F/∂θ) / (∂F/∂t).
        let (d, e, dr) = conic(g, q);
        let fr = g[5];
        let a = d[0] * d[0] + d[1] * d[1] - dr * dr;
        let b = e[0] * d[0] + e[1] * d[1] + fr * dr;
        let df_dt = two * (a * t - b);
        if df_dt == z {
            return [z; 6];
        }
        let k = -T::one() / df_dt;
        let tt = t * t;
        let dc = |c: usize| k * (two * tt * d[c] - two * t * e[c]);
        let df = |c: usize| k * (-two * tt * d[c] + two * t * (d[c] + e[c]) - two * e[c]);
        let d_r = k * (-two * dr * tt - two * t * fr);
        let d_fr = k * (two * dr * tt - two * t * (dr - fr) - two * fr);
        [dc(0), dc(1), d_r, df(0), df(1), d_fr]
    }

    /// Where `s` (after spreading) falls among the stops: `(i, Some(w))` means
    /// `colour = colors[i] (1 - w) + colors[i + 1] w`; `(i, None)` is stop `i`'s colour held
    /// before the first or after the last stop. On an offset of exactly the first or last stop
    /// the colour holds (the one-sided derivative into the held region: zero).
    fn segment(&self, s: T) -> (usize, Option<T>) {
        let o = &self.offsets;
        let n = o.len();
        if n < 2 || s <= o[0] {
            return (0, None);
        }
        if s >= o[n - 1] {
            return (n - 1, None);
        }
        let mut i = 0;
        while i + 2 < n && s >= o[i + 1] {
            i += 1;
        }
        (i, Some((s - o[i]) / (o[i + 1] - o[i])))
    }

    fn mix(&self, i: usize, w: Option<T>) -> [T; 4] {
        let a = self.colors[i];
        let Some(w) = w else {
            return a;
        };
        let b = self.colors[i + 1];
        std::array::from_fn(|c| a[c] + (b[c] - a[c]) * w)
    }
}

/// `c - f`, `q - f` and `r - fr` of a radial geometry.
#[inline]
fn conic<T: Real>(g: &[T; 6], q: [T; 2]) -> ([T; 2], [T; 2], T) {
    (
        [g[0] - g[3], g[1] - g[4]],
        [q[0] - g[3], q[1] - g[4]],
        g[2] - g[5],
    )
}

/// `t` after the spread method, and its derivative.
fn spread<T: Real>(mode: Spread, t: T) -> (T, T) {
    let (one, z) = (T::one(), T::zero());
    match mode {
        Spread::Pad if t < z => (z, z),
        Spread::Pad if t > one => (one, z),
        Spread::Pad => (t, one),
        Spread::Repeat => (t - t.floor(), one),
        Spread::Reflect => {
            let m = t - T::c(2.0) * (t * T::c(0.5)).floor();
            if m <= one {
                (m, one)
            } else {
                (T::c(2.0) - m, -one)
            }
        }
    }
}

/// A gradient layer's shader and its parameter gradients.
pub(crate) struct GradientShade<'a, T> {
    pub p: &'a PaintT<T>,
    pub d: Vec<T>,
}

impl<'a, T: Real> GradientShade<'a, T> {
    pub fn new(p: &'a PaintT<T>) -> Self {
        GradientShade { p, d: Vec::new() }
    }
}

impl<T: Real> Shade<T> for GradientShade<'_, T> {
    fn color(&self, x: i32, y: i32) -> [T; 4] {
        let p = self.p;
        match p.t_at(p.local(x, y)) {
            Some(t) => {
                let (i, w) = p.segment(spread(p.spread, t).0);
                p.mix(i, w)
            }
            None => [T::zero(); 4],
        }
    }

    fn grad(&mut self, x: i32, y: i32, dc: [T; 4]) {
        let p = self.p;
        if self.d.is_empty() {
            self.d.resize(p.num_params(), T::zero());
        }
        let q = p.local(x, y);
        let Some(t) = p.t_at(q) else {
            return;
        };
        let (s, ds) = spread(p.spread, t);
        let (i, w) = p.segment(s);
        let ng = p.n_geom();
        let d = &mut self.d;
        let col = |k: usize| ng + 5 * k + 1;
        let Some(w) = w else {
            for c in 0..4 {
                d[col(i) + c] += dc[c];
            }
            return;
        };
        let (a, b) = (p.colors[i], p.colors[i + 1]);
        let mut gw = T::zero();
        for c in 0..4 {
            d[col(i) + c] += dc[c] * (T::one() - w);
            d[col(i + 1) + c] += dc[c] * w;
            gw += dc[c] * (b[c] - a[c]);
        }
        let span = p.offsets[i + 1] - p.offsets[i];
        d[ng + 5 * i] += gw * (w - T::one()) / span;
        d[ng + 5 * (i + 1)] -= gw * w / span;
        let gt = gw / span * ds;
        if gt != T::zero() {
            for (k, v) in p.dt_dgeom(q, t).iter().enumerate().take(ng) {
                d[k] += gt * *v;
            }
        }
    }
}
