//! Blend modes of a group's layer (W3C Compositing and Blending Level 1), forward and backward.
//!
//! With the group's layer `G` (premultiplied), its factor `m = opacity × clip × mask` and the
//! layer below `P`: the source is `s = m G` with `αs = m G.a`, the backdrop alpha is
//! `αb = P.a`, the straight colours are `Cs = G.rgb / G.a` and `Cb = P.rgb / P.a` (0 where the
//! alpha is 0), and
//!
//! `out.rgb = s.rgb (1 - αb) + P.rgb (1 - αs) + αs αb B(Cb, Cs)`, `out.a = αs + αb - αs αb`
//!
//! (the spec's "blend, then source-over", premultiplied). `B` is the mode's blend function:
//! channel by channel for the separable modes, through `Lum`/`Sat`/`ClipColor` for hue,
//! saturation, color and luminosity, exactly as the spec writes them. `Normal` (`B = Cs`) is
//! plain source-over and never comes here (see `layer`).
//!
//! The backward pass is exact for every mode (up to the kinks of `min`, `max`, the clamps and
//! the branches of the piecewise modes): the blend functions are generic over [`Num`] and are
//! evaluated once more with forward-mode dual numbers carrying `∂B/∂Cb` and `∂B/∂Cs`, which
//! the chain rule above takes to `P`, `G` and `m`. Where `G.a` or `P.a` is 0 the straight
//! colour is taken as 0 (the function is not differentiable there; the set is measure-zero
//! for anti-aliased shapes).

use super::real::Real;
use crate::scene::BlendMode;
use std::ops::{Add, Div, Mul, Sub};

/// What the blend functions compute with: a real, or a dual number carrying derivatives.
trait Num:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self>
{
    fn k(v: f64) -> Self;
    /// The value, for comparisons and branches.
    fn v(self) -> f64;
    fn sqrt(self) -> Self;
}

impl<T: Real> Num for T {
    #[inline]
    fn k(v: f64) -> Self {
        T::c(v)
    }
    #[inline]
    fn v(self) -> f64 {
        self.to_f64().unwrap_or(0.0)
    }
    #[inline]
    fn sqrt(self) -> Self {
        num_traits::Float::sqrt(self)
    }
}

/// Tangents carried by the non-separable modes: `∂/∂Cb` (3) then `∂/∂Cs` (3); a separable
/// mode carries `∂/∂Cb` and `∂/∂Cs` of one channel.
const N: usize = 6;

/// A forward-mode dual number: a value and its derivatives with respect to `K` inputs.
#[derive(Clone, Copy, Debug)]
struct Dual<T, const K: usize> {
    v: T,
    d: [T; K],
}

impl<T: Real, const K: usize> Dual<T, K> {
    fn var(v: T, i: usize) -> Self {
        let mut d = [T::zero(); K];
        d[i] = T::one();
        Dual { v, d }
    }

    fn map(self, v: T, k: T) -> Self {
        Dual {
            v,
            d: self.d.map(|x| x * k),
        }
    }

    fn zip(self, o: Self, v: T, (ka, kb): (T, T)) -> Self {
        let mut d = self.d;
        for i in 0..K {
            d[i] = d[i] * ka + o.d[i] * kb;
        }
        Dual { v, d }
    }
}

impl<T: Real, const K: usize> Add for Dual<T, K> {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        self.zip(o, self.v + o.v, (T::one(), T::one()))
    }
}

impl<T: Real, const K: usize> Sub for Dual<T, K> {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        self.zip(o, self.v - o.v, (T::one(), -T::one()))
    }
}

impl<T: Real, const K: usize> Mul for Dual<T, K> {
    type Output = Self;
    fn mul(self, o: Self) -> Self {
        self.zip(o, self.v * o.v, (o.v, self.v))
    }
}

impl<T: Real, const K: usize> Div for Dual<T, K> {
    type Output = Self;
    fn div(self, o: Self) -> Self {
        let q = self.v / o.v;
        self.zip(o, q, (T::one() / o.v, -q / o.v))
    }
}

impl<T: Real, const K: usize> Num for Dual<T, K> {
    fn k(v: f64) -> Self {
        Dual {
            v: T::c(v),
            d: [T::zero(); K],
        }
    }
    fn v(self) -> f64 {
        self.v.to_f64().unwrap_or(0.0)
    }
    fn sqrt(self) -> Self {
        let r = num_traits::Float::sqrt(self.v);
        let k = if r > T::zero() {
            T::one() / (T::c(2.0) * r)
        } else {
            T::zero()
        };
        self.map(r, k)
    }
}

fn min<X: Num>(a: X, b: X) -> X {
    if a.v() <= b.v() { a } else { b }
}

fn max<X: Num>(a: X, b: X) -> X {
    if a.v() >= b.v() { a } else { b }
}

/// A separable mode's `B(cb, cs)` for one channel.
fn separable<X: Num>(mode: BlendMode, cb: X, cs: X) -> X {
    use BlendMode::*;
    let (one, two) = (X::k(1.0), X::k(2.0));
    match mode {
        Multiply => cb * cs,
        Screen => cb + cs - cb * cs,
        Overlay => separable(HardLight, cs, cb),
        Darken => min(cb, cs),
        Lighten => max(cb, cs),
        ColorDodge if cb.v() <= 0.0 => X::k(0.0),
        ColorDodge if cs.v() >= 1.0 => one,
        ColorDodge => min(one, cb / (one - cs)),
        ColorBurn if cb.v() >= 1.0 => one,
        ColorBurn if cs.v() <= 0.0 => X::k(0.0),
        ColorBurn => one - min(one, (one - cb) / cs),
        HardLight if cs.v() <= 0.5 => cb * (two * cs),
        HardLight => separable(Screen, cb, two * cs - one),
        SoftLight if cs.v() <= 0.5 => cb - (one - two * cs) * cb * (one - cb),
        SoftLight => {
            let d = if cb.v() <= 0.25 {
                ((X::k(16.0) * cb - X::k(12.0)) * cb + X::k(4.0)) * cb
            } else {
                cb.sqrt()
            };
            cb + (two * cs - one) * (d - cb)
        }
        Difference => max(cb - cs, cs - cb),
        Exclusion => cb + cs - two * cb * cs,
        // Normal and the non-separable modes do not come here.
        _ => cs,
    }
}

fn lum<X: Num>(c: [X; 3]) -> X {
    X::k(0.3) * c[0] + X::k(0.59) * c[1] + X::k(0.11) * c[2]
}

fn clip_color<X: Num>(c: [X; 3]) -> [X; 3] {
    let l = lum(c);
    let n = min(min(c[0], c[1]), c[2]);
    let x = max(max(c[0], c[1]), c[2]);
    let mut c = c;
    // (The second conditions only keep rounding from dividing by zero.)
    if n.v() < 0.0 && (l - n).v() > 0.0 {
        c = c.map(|v| l + (v - l) * l / (l - n));
    }
    if x.v() > 1.0 && (x - l).v() > 0.0 {
        c = c.map(|v| l + (v - l) * (X::k(1.0) - l) / (x - l));
    }
    c
}

fn set_lum<X: Num>(c: [X; 3], l: X) -> [X; 3] {
    let d = l - lum(c);
    clip_color(c.map(|v| v + d))
}

fn sat<X: Num>(c: [X; 3]) -> X {
    max(max(c[0], c[1]), c[2]) - min(min(c[0], c[1]), c[2])
}

fn set_sat<X: Num>(c: [X; 3], s: X) -> [X; 3] {
    // Indices of the smallest, middle and largest channel.
    let mut i = [0, 1, 2];
    i.sort_by(|&a, &b| c[a].v().total_cmp(&c[b].v()));
    let [lo, mid, hi] = i;
    let zero = X::k(0.0);
    let mut out = [zero; 3];
    if c[hi].v() > c[lo].v() {
        out[mid] = (c[mid] - c[lo]) * s / (c[hi] - c[lo]);
        out[hi] = s;
    }
    out
}

/// `B(cb, cs)` of a (non-normal) mode for one pixel's straight colours.
fn blend_rgb<X: Num>(mode: BlendMode, cb: [X; 3], cs: [X; 3]) -> [X; 3] {
    use BlendMode::*;
    match mode {
        Hue => set_lum(set_sat(cs, sat(cb)), lum(cb)),
        Saturation => set_lum(set_sat(cb, sat(cs)), lum(cb)),
        Color => set_lum(cs, lum(cb)),
        Luminosity => set_lum(cb, lum(cs)),
        _ => [0, 1, 2].map(|k| separable(mode, cb[k], cs[k])),
    }
}

/// Straight colour of a premultiplied pixel (0 where its alpha is 0).
fn straight<T: Real>(p: &[T]) -> [T; 3] {
    if p[3] > T::zero() {
        [p[0] / p[3], p[1] / p[3], p[2] / p[3]]
    } else {
        [T::zero(); 3]
    }
}

/// Composites one pixel of a group's layer `g` with factor `m` onto `p` by `mode` (module docs).
#[inline]
pub(crate) fn blend_px<T: Real>(mode: BlendMode, p: &mut [T], g: &[T], m: T) {
    let ga = g[3];
    if ga == T::zero() {
        return;
    }
    let (sa, ba) = (m * ga, p[3]);
    let b = blend_rgb(mode, straight(p), straight(g));
    for c in 0..3 {
        p[c] = m * g[c] * (T::one() - ba) + p[c] * (T::one() - sa) + sa * ba * b[c];
    }
    p[3] = sa + ba - sa * ba;
}

/// `B(cb, cs)` and `Σ_c go_c ∂B_c/∂x` for `x` = `cb` (3) then `cs` (3).
fn blend_jacobian<T: Real>(mode: BlendMode, cb: [T; 3], cs: [T; 3], go: &[T]) -> ([T; 3], [T; N]) {
    let mut jt = [T::zero(); N];
    if matches!(
        mode,
        BlendMode::Hue | BlendMode::Saturation | BlendMode::Color | BlendMode::Luminosity
    ) {
        let db: [Dual<T, N>; 3] = [0, 1, 2].map(|k| Dual::var(cb[k], k));
        let ds: [Dual<T, N>; 3] = [0, 1, 2].map(|k| Dual::var(cs[k], 3 + k));
        let b = blend_rgb(mode, db, ds);
        for c in 0..3 {
            for i in 0..N {
                jt[i] += go[c] * b[c].d[i];
            }
        }
        return (b.map(|x| x.v), jt);
    }
    // Separable: channel `c` depends on `cb[c]` and `cs[c]` only.
    let mut b = [T::zero(); 3];
    for c in 0..3 {
        let x = separable(mode, Dual::<T, 2>::var(cb[c], 0), Dual::var(cs[c], 1));
        b[c] = x.v;
        jt[c] = go[c] * x.d[0];
        jt[3 + c] = go[c] * x.d[1];
    }
    (b, jt)
}

/// Backward of [`blend_px`] given what lay below (`p`), the group's layer (`g`) and `m`: `go`
/// (the gradient of the result) becomes the gradient of `p`, `gi` is set to the gradient of
/// `g`; returns the gradient of `m`.
#[inline]
pub(crate) fn blend_px_back<T: Real>(
    mode: BlendMode,
    (p, g, m): (&[T], &[T], T),
    go: &mut [T],
    gi: &mut [T],
) -> T {
    let (ga, ba) = (g[3], p[3]);
    let sa = m * ga;
    let (cb, cs) = (straight(p), straight(g));
    let (b, jt) = blend_jacobian(mode, cb, cs, go);
    let one = T::one();
    let (mut gb, mut gg, mut gpc, mut dm) = (T::zero(), T::zero(), T::zero(), T::zero());
    for c in 0..3 {
        gb += go[c] * b[c];
        gg += go[c] * g[c];
        gpc += go[c] * p[c];
        dm += go[c] * (g[c] * (one - ba) - p[c] * ga + ga * ba * b[c]);
    }
    dm += go[3] * ga * (one - ba);
    let jb_cb: T = (0..3).map(|k| jt[k] * cb[k]).fold(T::zero(), |a, v| a + v);
    let js_cs: T = (0..3)
        .map(|k| jt[3 + k] * cs[k])
        .fold(T::zero(), |a, v| a + v);
    for k in 0..3 {
        gi[k] = go[k] * m * (one - ba) + m * ba * jt[3 + k];
    }
    gi[3] = go[3] * m * (one - ba) - m * gpc + m * ba * (gb - js_cs);
    let ga_out = go[3] * (one - sa) - m * gg + sa * (gb - jb_cb);
    for k in 0..3 {
        go[k] = go[k] * (one - sa) + sa * jt[k];
    }
    go[3] = ga_out;
    dm
}

#[cfg(test)]
mod tests {
    use super::*;
    use BlendMode::*;

    const ALL: [BlendMode; 15] = [
        Multiply, Screen, Overlay, Darken, Lighten, ColorDodge, ColorBurn, HardLight, SoftLight,
        Difference, Exclusion, Hue, Saturation, Color, Luminosity,
    ];

    #[test]
    fn blend_functions_match_the_spec_at_known_points() {
        let b = |m, cb: f64, cs: f64| blend_rgb(m, [cb; 3], [cs; 3])[0];
        let blend_rgb = blend_rgb::<f64>;
        assert_eq!(b(Multiply, 0.5, 0.4), 0.2);
        assert!((b(Screen, 0.5, 0.4) - 0.7).abs() < 1e-12);
        assert!((b(Overlay, 0.25, 0.8) - 0.4).abs() < 1e-12);
        assert_eq!(b(Darken, 0.3, 0.6), 0.3);
        assert_eq!(b(Lighten, 0.3, 0.6), 0.6);
        assert_eq!(b(ColorDodge, 0.3, 0.5), 0.6);
        assert_eq!(b(ColorDodge, 0.6, 0.5), 1.0);
        assert!((b(ColorBurn, 0.7, 0.5) - 0.4).abs() < 1e-12);
        assert!((b(SoftLight, 0.64, 0.75) - 0.72).abs() < 1e-12);
        assert!((b(Difference, 0.2, 0.7) - 0.5).abs() < 1e-12);
        assert!((b(Exclusion, 0.5, 0.5) - 0.5).abs() < 1e-12);
        // Non-separable: pure red's hue on a grey backdrop keeps the grey's luminosity.
        let c = blend_rgb(Color, [0.5; 3], [1.0, 0.0, 0.0]);
        assert!((lum(c) - 0.5).abs() < 1e-12, "{c:?}");
        assert!(c[0] > c[1] && (c[1] - c[2]).abs() < 1e-12, "{c:?}");
        let c = blend_rgb(Luminosity, [1.0, 0.0, 0.0], [0.2; 3]);
        assert!((lum(c) - 0.2).abs() < 1e-12, "{c:?}");
        let c = blend_rgb(Saturation, [0.2, 0.4, 0.6], [0.5; 3]);
        assert!(c.iter().all(|v| (v - 0.362).abs() < 1e-12), "{c:?}");
    }

    #[test]
    fn extreme_pixels_give_finite_values_and_gradients() {
        let vals = [0.0f32, 1e-30, 0.5, 1.0];
        for mode in ALL {
            for &a in &vals {
                for &c in &vals {
                    for &pa in &vals {
                        // Grey and coloured, premultiplied (channel ≤ alpha).
                        let g = [c * a, c * a * 0.3, c * a, a];
                        let p = [pa * 0.7, pa, pa * c, pa];
                        let mut o = p;
                        blend_px(mode, &mut o, &g, 0.8);
                        let (mut gp, mut gg) = ([1.0f32; 4], [0.0; 4]);
                        let gm = blend_px_back(mode, (&p, &g, 0.8), &mut gp, &mut gg);
                        let all = o.iter().chain(&gp).chain(&gg).chain([&gm]);
                        assert!(
                            all.clone().all(|v| v.is_finite()),
                            "{mode:?} {g:?} {p:?}: {o:?} {gp:?} {gg:?} {gm}"
                        );
                    }
                }
            }
        }
    }

    /// `[p, g, m]` of one pixel from `k` (premultiplied, varied enough to take every branch).
    fn pixel(k: usize) -> ([f64; 4], [f64; 4], f64) {
        let f = |i: usize| ((k * 7 + i * 13) % 17) as f64 / 17.0 + 0.02;
        let (pa, ga) = (0.3 + 0.6 * f(9), 0.2 + 0.7 * f(10));
        let p = [f(0) * pa, f(1) * pa, f(2) * pa, pa];
        let g = [f(3) * ga, f(4) * ga, f(5) * ga, ga];
        (p, g, 0.4 + 0.5 * f(11))
    }

    #[test]
    fn pixel_backward_matches_finite_differences_for_every_mode() {
        for mode in ALL {
            for k in 0..12 {
                let (p, g, m) = pixel(k);
                let w = [0.3, -0.7, 0.5, 0.9];
                let loss = |p: [f64; 4], g: [f64; 4], m: f64| {
                    let mut o = p;
                    blend_px(mode, &mut o, &g, m);
                    o.iter().zip(&w).map(|(a, b)| a * b).sum::<f64>()
                };
                let (mut gp, mut gg) = (w, [0.0; 4]);
                let gm = blend_px_back(mode, (&p, &g, m), &mut gp, &mut gg);
                let h = 1e-6;
                let fd = |f: &dyn Fn(f64) -> f64| (f(h) - f(-h)) / (2.0 * h);
                let check = |what: &str, a: f64, b: f64| {
                    assert!(
                        (a - b).abs() < 1e-5 * (1.0 + b.abs()),
                        "{mode:?} pixel {k} {what}: {a} vs {b}"
                    );
                };
                for i in 0..4 {
                    let dp = fd(&|e| {
                        let mut q = p;
                        q[i] += e;
                        loss(q, g, m)
                    });
                    check(&format!("dP{i}"), gp[i], dp);
                    let dg = fd(&|e| {
                        let mut q = g;
                        q[i] += e;
                        loss(p, q, m)
                    });
                    check(&format!("dG{i}"), gg[i], dg);
                }
                check("dm", gm, fd(&|e| loss(p, g, m + e)));
            }
        }
    }
}
