//! Strokes with butt or square caps, or miter or bevel joins: the union of per-edge pieces
//! described in the parent module's docs.

use super::super::real::Real;
use super::super::walk::Clip;
use super::{Style, cov_of, seg_count};
use crate::scene::{LineCap, LineJoin};

type V = [f64; 2];

/// Central-difference step of the backward pass, in pixels.
const H: f64 = 1e-4;

fn sub(a: V, b: V) -> V {
    [a[0] - b[0], a[1] - b[1]]
}

fn dot(a: V, b: V) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

fn len(a: V) -> f64 {
    dot(a, a).sqrt()
}

fn scale(a: V, k: f64) -> V {
    [a[0] * k, a[1] * k]
}

fn cov(d: f64, r: f64) -> f64 {
    cov_of(d, r).0
}

/// What lies beyond one end of an edge.
#[derive(Clone, Copy, Debug, PartialEq)]
enum End {
    Cap,
    Join,
}

/// Edge `e` of the polyline: the indices of the vertex before it, its two ends and the vertex
/// after it (an end's own index where that end is a cap), and what lies beyond each end.
#[derive(Clone, Copy, Debug)]
struct Edge {
    idx: [usize; 4],
    start: End,
    end: End,
}

fn edge(n: usize, closed: bool, e: usize) -> Edge {
    let (a, b) = (e, (e + 1) % n);
    let start = if !closed && e == 0 {
        End::Cap
    } else {
        End::Join
    };
    let end = if !closed && e + 2 == n {
        End::Cap
    } else {
        End::Join
    };
    let prev = if start == End::Join {
        (e + n - 1) % n
    } else {
        a
    };
    let next = if end == End::Join { (e + 2) % n } else { b };
    Edge {
        idx: [prev, a, b, next],
        start,
        end,
    }
}

/// Coverage of pixel centre `p` by the piece of edge `ed` (`x`: the vertices of `ed.idx`).
fn piece(p: V, x: [V; 4], r: f64, ed: Edge, st: Style) -> f64 {
    let [u, a, b, w] = x;
    let d = sub(b, a);
    let l = len(d);
    if !(l > 1e-9) {
        return dot_piece(sub(p, a), r, ed, st);
    }
    let t = scale(d, 1.0 / l);
    let q = sub(p, a);
    let s = dot(q, t);
    let capped = !st.cap.is_round();
    let ext = if st.cap == LineCap::Square { r } else { 0.0 };
    let falloff = |u: f64| (0.5 - u).clamp(0.0, 1.0);
    let body = || {
        let dn = (q[1] * t[0] - q[0] * t[1]).abs();
        let f0 = if ed.start == End::Cap && capped {
            falloff(-s - ext)
        } else {
            1.0
        };
        let f1 = if ed.end == End::Cap && capped {
            falloff(s - l - ext)
        } else {
            1.0
        };
        cov(dn, r) * f0 * f1
    };
    if s < 0.0 {
        match ed.start {
            End::Cap if capped => body(),
            End::Cap => cov(len(q), r),
            End::Join => join(p, u, a, b, r, st),
        }
    } else if s > l {
        match ed.end {
            End::Cap if capped => body(),
            End::Cap => cov(len(sub(p, b)), r),
            End::Join => join(p, a, b, w, r, st),
        }
    } else {
        body()
    }
}

/// Coverage by a zero-length edge at offset `q`: alone (a zero-length subpath), a disc for
/// round caps, a square along the x axis for square caps and nothing for butt caps, as SVG
/// draws them; inside a polyline (a repeated vertex), a disc for round joins, else nothing.
fn dot_piece(q: V, r: f64, ed: Edge, st: Style) -> f64 {
    let alone = ed.start == End::Cap && ed.end == End::Cap;
    let round = if alone {
        st.cap.is_round()
    } else {
        st.join.is_round()
    };
    if round {
        cov(len(q), r)
    } else if alone && st.cap == LineCap::Square {
        cov(q[0].abs(), r) * cov(q[1].abs(), r)
    } else {
        0.0
    }
}

/// Coverage of `p` by the join at `v` between edges `u → v` and `v → w`, inside the wedge
/// between their outer normals (outside it the neighbouring bodies cover).
fn join(p: V, u: V, v: V, w: V, r: f64, st: Style) -> f64 {
    let q = sub(p, v);
    let (da, db) = (sub(v, u), sub(w, v));
    let (la, lb) = (len(da), len(db));
    if st.join.is_round() || !(la > 1e-9 && lb > 1e-9) {
        return cov(len(q), r);
    }
    let (ta, tb) = (scale(da, 1.0 / la), scale(db, 1.0 / lb));
    if dot(q, ta) < 0.0 || dot(q, tb) > 0.0 {
        return 0.0;
    }
    // The outer side is away from the turn.
    let sgn = if ta[0] * tb[1] - ta[1] * tb[0] >= 0.0 {
        1.0
    } else {
        -1.0
    };
    let na = [sgn * ta[1], -sgn * ta[0]];
    let nb = [sgn * tb[1], -sgn * tb[0]];
    // cos of half the turn: the miter is 1 / cos_half widths long.
    let cos_half = ((1.0 + dot(ta, tb)) / 2.0).max(0.0).sqrt();
    let dist = if st.join == LineJoin::Miter && cos_half * f64::from(st.miter_limit) >= 1.0 {
        dot(q, na).max(dot(q, nb))
    } else {
        let m = [na[0] + nb[0], na[1] + nb[1]];
        let lm = len(m);
        let m = if lm > 1e-9 { scale(m, 1.0 / lm) } else { ta };
        // The distance past the bevel line (r·cos_half from v), measured along the edges'
        // normals (÷ cos_half) so that it meets the bodies' distances on the wedge's sides.
        let c = cos_half.max(1e-3);
        (dot(q, m) - r * c) / c + r
    };
    cov(dist.max(0.0), r)
}

fn to64<T: Real>(v: T) -> f64 {
    v.to_f64().unwrap_or(f64::NAN)
}

/// For every pixel of `clip`: the largest piece coverage (`best`) and its edge (`idx`).
fn union<T: Real>(
    poly: &[[T; 2]],
    closed: bool,
    r: f64,
    st: Style,
    clip: Clip,
    best: &mut [f64],
    idx: &mut Vec<u32>,
) {
    let cw = (clip.x1 - clip.x0) as usize;
    idx.clear();
    idx.resize(best.len(), u32::MAX);
    best.fill(0.0);
    let n = poly.len();
    if n < 2 {
        return;
    }
    let pv: Vec<V> = poly.iter().map(|v| [to64(v[0]), to64(v[1])]).collect();
    let reach = r * f64::from(st.reach()) + 1.0;
    for e in 0..seg_count(n, closed) {
        let ed = edge(n, closed, e);
        let x = ed.idx.map(|i| pv[i]);
        let (a, b) = (x[1], x[2]);
        let bound = |lo: f64, hi: f64, c0: i32, c1: i32| {
            let l = (lo - reach).floor().max(f64::from(c0)) as i32;
            let h = (hi + reach).ceil().min(f64::from(c1)) as i32;
            (l, h)
        };
        let (x0, x1) = bound(a[0].min(b[0]), a[0].max(b[0]), clip.x0, clip.x1);
        let (y0, y1) = bound(a[1].min(b[1]), a[1].max(b[1]), clip.y0, clip.y1);
        for y in y0..y1 {
            let row = (y - clip.y0) as usize * cw;
            for px in x0..x1 {
                let p = [f64::from(px) + 0.5, f64::from(y) + 0.5];
                let c = piece(p, x, r, ed, st);
                let i = row + (px - clip.x0) as usize;
                if c > best[i] {
                    best[i] = c;
                    idx[i] = e as u32;
                }
            }
        }
    }
}

/// Writes the coverage of every pixel of `clip` into `out`.
pub(super) fn coverage<T: Real>(
    poly: &[[T; 2]],
    closed: bool,
    r: T,
    st: Style,
    clip: Clip,
    out: &mut [T],
    idx: &mut Vec<u32>,
) {
    let mut best = vec![0.0; out.len()];
    union(poly, closed, to64(r), st, clip, &mut best, idx);
    for (o, b) in out.iter_mut().zip(best) {
        *o = T::c(b);
    }
}

/// Given `g = dL/dcoverage` over `clip`, adds gradients to the polyline vertices and returns
/// dL/dr (central differences of each pixel's winning piece).
#[allow(clippy::too_many_arguments)]
pub(super) fn backward<T: Real>(
    poly: &[[T; 2]],
    closed: bool,
    r: T,
    st: Style,
    clip: Clip,
    g: &[T],
    dpoly: &mut [[T; 2]],
    idx: &mut Vec<u32>,
) -> T {
    let r = to64(r);
    let mut best = vec![0.0; g.len()];
    union(poly, closed, r, st, clip, &mut best, idx);
    let cw = (clip.x1 - clip.x0) as usize;
    let n = poly.len();
    let pv: Vec<V> = poly.iter().map(|v| [to64(v[0]), to64(v[1])]).collect();
    // A step across a piece's edge (a wedge boundary) is a jump, not a slope: dropped.
    let slope = |hi: f64, lo: f64| {
        let d = hi - lo;
        if d.abs() > 100.0 * H {
            0.0
        } else {
            d / (2.0 * H)
        }
    };
    let mut dr = 0.0;
    for (i, (&gv, &e)) in g.iter().zip(idx.iter()).enumerate() {
        if gv == T::zero() || e == u32::MAX {
            continue;
        }
        let gv = to64(gv);
        let ed = edge(n, closed, e as usize);
        let x = ed.idx.map(|k| pv[k]);
        let p = [
            f64::from(clip.x0 + (i % cw) as i32) + 0.5,
            f64::from(clip.y0 + (i / cw) as i32) + 0.5,
        ];
        dr += gv * slope(piece(p, x, r + H, ed, st), piece(p, x, r - H, ed, st));
        for k in 0..4 {
            let cap = (k == 0 && ed.start == End::Cap) || (k == 3 && ed.end == End::Cap);
            if cap {
                continue;
            }
            for c in 0..2 {
                let (mut hi, mut lo) = (x, x);
                hi[k][c] += H;
                lo[k][c] -= H;
                let d = slope(piece(p, hi, r, ed, st), piece(p, lo, r, ed, st));
                dpoly[ed.idx[k]][c] += T::c(gv * d);
            }
        }
    }
    T::c(dr)
}
