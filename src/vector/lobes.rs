//! Exact repair of a looping outline: cut the closed cubic path at the point where it meets
//! itself and close each part on its own ("lobes").
//!
//! A closed curve `C(s)`, `s ∈ [0, n)` over its `n` cubic segments, that meets itself at
//! `C(s₁) = C(s₂)` is two closed curves: `C[s₁, s₂]` and `C[s₂, n) ∪ C[0, s₁]`. Each is cut out of
//! the original segments with de Casteljau subdivision, so every point of every lobe lies on
//! the original outline: the pieces carry the same curves (at most two more segments in all)
//! instead of a polygon refitted to the union. Lobes that still meet themselves are cut again;
//! lobes of negligible area (the folded spikes and the tiny twists LIVE leaves at corners) are
//! dropped. Under the nonzero rule the lobes' union is the original fill wherever the lobes
//! have the same orientation; a lobe of opposite orientation nested in another marks a hole
//! in the original, which the lobes fill (the tracer re-optimises after every cut).

use crate::scene::{Point, Shape};

use super::simple::P;

/// Contact distance (px): non-adjacent edges of the flattened outline closer than this meet.
const CONTACT: f64 = 1e-3;
/// Deepest nesting of cuts, and most cuts of one shape: what is left then goes to the caller's
/// other repair (a fold along a line meets itself at every vertex).
const MAX_DEPTH: usize = 12;
const MAX_CUTS: usize = 24;

fn lerp(a: P, b: P, t: f64) -> P {
    (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t)
}

pub(super) fn eval(s: &[P; 4], t: f64) -> P {
    split(s, t).0[3]
}

/// De Casteljau: cubic `s` split at `t` into its parts over `[0, t]` and `[t, 1]`.
fn split(s: &[P; 4], t: f64) -> ([P; 4], [P; 4]) {
    let ab = lerp(s[0], s[1], t);
    let bc = lerp(s[1], s[2], t);
    let cd = lerp(s[2], s[3], t);
    let abc = lerp(ab, bc, t);
    let bcd = lerp(bc, cd, t);
    let m = lerp(abc, bcd, t);
    ([s[0], ab, abc, m], [m, bcd, cd, s[3]])
}

/// The part of cubic `s` between parameters `t0 <= t1`.
fn sub_cubic(s: &[P; 4], t0: f64, t1: f64) -> [P; 4] {
    // Left part [0, t1], then its right part from t0 / t1.
    let left = if t1 < 1.0 { split(s, t1).0 } else { *s };
    if t0 <= 0.0 || t1 <= 0.0 {
        return left;
    }
    split(&left, (t0 / t1).clamp(0.0, 1.0)).1
}

pub(super) fn segments(shape: &Shape) -> Vec<[P; 4]> {
    let f = |p: Point| (p.x as f64, p.y as f64);
    (0..shape.num_segments())
        .map(|i| {
            let [a, b, c, d] = shape.segment(i);
            [f(a), f(b), f(c), f(d)]
        })
        .collect()
}

/// The outline flattened with the curve parameter of every vertex (`segment + t`).
fn flatten(segs: &[[P; 4]]) -> (Vec<P>, Vec<f64>) {
    flatten_at(segs, 0.75, 4, 64)
}

/// [`flatten`] with pieces of about `step` px, `lo..=hi` per segment.
fn flatten_at(segs: &[[P; 4]], step: f64, lo: usize, hi: usize) -> (Vec<P>, Vec<f64>) {
    let mut pts = Vec::new();
    let mut par = Vec::new();
    for (k, s) in segs.iter().enumerate() {
        let len = (1..4)
            .map(|i| (s[i].0 - s[i - 1].0).hypot(s[i].1 - s[i - 1].1))
            .sum::<f64>();
        let pieces = ((len / step).ceil() as usize).clamp(lo, hi);
        for m in 0..pieces {
            let t = m as f64 / pieces as f64;
            pts.push(eval(s, t));
            par.push(k as f64 + t);
        }
    }
    (pts, par)
}

fn sub(a: P, b: P) -> P {
    (a.0 - b.0, a.1 - b.1)
}

fn cross(a: P, b: P) -> f64 {
    a.0 * b.1 - a.1 * b.0
}

/// Where segments `ab` and `cd` meet: fractions along each, for a proper crossing or a
/// contact closer than [`CONTACT`] (an endpoint on the other segment).
fn meet(a: P, b: P, c: P, d: P) -> Option<(f64, f64)> {
    let r = sub(b, a);
    let s = sub(d, c);
    let den = cross(r, s);
    if den.abs() > 1e-18 {
        let t = cross(sub(c, a), s) / den;
        let u = cross(sub(c, a), r) / den;
        if (0.0..=1.0).contains(&t) && (0.0..=1.0).contains(&u) {
            return Some((t, u));
        }
    }
    let proj = |p: P, a: P, b: P| -> (f64, f64) {
        let ab = sub(b, a);
        let l2 = ab.0 * ab.0 + ab.1 * ab.1;
        let t = if l2 > 0.0 {
            ((p.0 - a.0) * ab.0 + (p.1 - a.1) * ab.1) / l2
        } else {
            0.0
        }
        .clamp(0.0, 1.0);
        let q = lerp(a, b, t);
        ((p.0 - q.0).hypot(p.1 - q.1), t)
    };
    let cands = [
        (proj(a, c, d), 0.0, true),
        (proj(b, c, d), 1.0, true),
        (proj(c, a, b), 0.0, false),
        (proj(d, a, b), 1.0, false),
    ];
    cands
        .iter()
        .filter(|c| c.0.0 <= CONTACT)
        .min_by(|x, y| x.0.0.total_cmp(&y.0.0))
        .map(|&((_, t), e, on_cd)| if on_cd { (e, t) } else { (t, e) })
}

/// The first place (in edge order) where the outline meets itself: parameters `s1 < s2`.
fn first_contact(pts: &[P], par: &[f64], n_segs: usize) -> Option<(f64, f64)> {
    let n = pts.len();
    if n < 4 {
        return None;
    }
    let end_par = |i: usize| {
        if i + 1 == n {
            n_segs as f64
        } else {
            par[i + 1]
        }
    };
    let boxes = super::simple::edge_boxes(pts, true, CONTACT);
    for i in 0..n {
        for j in i + 2..n {
            if i == 0 && j == n - 1 {
                continue; // neighbours across the closing vertex
            }
            let (bi, bj) = (boxes[i], boxes[j]);
            if bi[0] > bj[2] || bj[0] > bi[2] || bi[1] > bj[3] || bj[1] > bi[3] {
                continue;
            }
            let Some((t, u)) = meet(pts[i], pts[(i + 1) % n], pts[j], pts[(j + 1) % n]) else {
                continue;
            };
            // Contacts at a shared vertex of edges two apart are the same vertex only when the
            // edge between them has zero length: skip those.
            if j == i + 2 && t >= 1.0 && u <= 0.0 {
                continue;
            }
            let s1 = par[i] + t * (end_par(i) - par[i]);
            let s2 = par[j] + u * (end_par(j) - par[j]);
            if s2 - s1 > 1e-9 {
                return Some((s1, s2));
            }
        }
    }
    None
}

/// The outline from parameter `from` to `to` (`to` may pass `n`: it wraps), as cubics.
pub(super) fn arc(segs: &[[P; 4]], from: f64, to: f64) -> Vec<[P; 4]> {
    let n = segs.len() as f64;
    let mut out = Vec::new();
    let mut s = from;
    while s < to - 1e-12 {
        let k = s.floor();
        let end = (k + 1.0).min(to);
        let seg = &segs[(k.rem_euclid(n)) as usize];
        let (t0, t1) = (s - k, end - k);
        if t1 - t0 > 1e-9 {
            out.push(sub_cubic(seg, t0, t1));
        }
        s = end;
    }
    out
}

/// Signed area of the closed curve made of `segs` (flattened finely).
pub(super) fn area(segs: &[[P; 4]]) -> f64 {
    let mut a = 0.0;
    for s in segs {
        let mut prev = s[0];
        for m in 1..=16 {
            let p = eval(s, m as f64 / 16.0);
            a += cross(prev, p);
            prev = p;
        }
    }
    0.5 * a
}

pub(super) fn to_shape(segs: &[[P; 4]], template: &Shape) -> Option<Shape> {
    let f = |p: P| Point::new(p.0 as f32, p.1 as f32);
    let mut points = Vec::with_capacity(3 * segs.len());
    for s in segs {
        points.extend_from_slice(&[f(s[0]), f(s[1]), f(s[2])]);
    }
    let shape = template.closed_cubic_like(points);
    shape.validate(0).ok().map(|_| shape)
}

/// The curve's point and derivative at parameter `s` (wrapping).
pub(super) fn at(segs: &[[P; 4]], s: f64) -> (P, P) {
    let n = segs.len() as f64;
    let s = s.rem_euclid(n);
    let k = (s.floor() as usize).min(segs.len() - 1);
    let t = s - k as f64;
    let c = &segs[k];
    let d = [sub(c[1], c[0]), sub(c[2], c[1]), sub(c[3], c[2])];
    let q = |a: P, b: P, c: P, t: f64| lerp(lerp(a, b, t), lerp(b, c, t), t);
    let dv = q(d[0], d[1], d[2], t);
    (eval(c, t), (3.0 * dv.0, 3.0 * dv.1))
}

/// Newton's method on `C(s1) = C(s2)` from the polyline's estimate, so the lobes close
/// exactly; the estimate stands where it does not converge (a touch without a crossing).
fn refine(segs: &[[P; 4]], s1: f64, s2: f64) -> (f64, f64) {
    let (mut a, mut b) = (s1, s2);
    for _ in 0..8 {
        let (p, dp) = at(segs, a);
        let (q, dq) = at(segs, b);
        let f = sub(p, q);
        if f.0.hypot(f.1) < 1e-10 {
            break;
        }
        // J = [dp, -dq]; solve J [da, db] = -f.
        let det = cross(dp, (-dq.0, -dq.1));
        if det.abs() < 1e-12 {
            return (s1, s2);
        }
        let da = cross((-f.0, -f.1), (-dq.0, -dq.1)) / det;
        let db = cross(dp, (-f.0, -f.1)) / det;
        a += da;
        b += db;
    }
    let (p, _) = at(segs, a);
    let (q, _) = at(segs, b);
    // Accept only a nearby, ordered solution that really closes.
    if (a - s1).abs() < 0.25
        && (b - s2).abs() < 0.25
        && b - a > 1e-9
        && sub(p, q).0.hypot(sub(p, q).1) < 1e-6
    {
        (a, b)
    } else {
        (s1, s2)
    }
}

fn cut(
    segs: Vec<[P; 4]>,
    min_area: f64,
    depth: usize,
    cuts_left: &mut usize,
    out: &mut Vec<Vec<[P; 4]>>,
) {
    if segs.is_empty() {
        return;
    }
    let (pts, par) = flatten(&segs);
    let contact = if depth < MAX_DEPTH && *cuts_left > 0 {
        first_contact(&pts, &par, segs.len())
    } else {
        None
    };
    match contact {
        None => {
            if area(&segs).abs() >= min_area {
                out.push(segs);
            }
        }
        Some((s1, s2)) => {
            *cuts_left -= 1;
            let (s1, s2) = refine(&segs, s1, s2);
            let n = segs.len() as f64;
            let inner = arc(&segs, s1, s2);
            let outer = arc(&segs, s2, s1 + n);
            cut(inner, min_area, depth + 1, cuts_left, out);
            cut(outer, min_area, depth + 1, cuts_left, out);
        }
    }
}

/// A quick test for optimisers: whether the closed shape's outline, flattened coarsely (pieces
/// of about 2 px, 4 to 16 per segment), meets itself. Misses contacts finer than the
/// flattening, which [`split_lobes`] and [`crate::vector::simple::is_simple`] still see.
pub fn meets_itself(shape: &Shape) -> bool {
    if !shape.is_closed() {
        return false;
    }
    let segs = segments(shape);
    let (pts, par) = flatten_at(&segs, 2.0, 4, 16);
    first_contact(&pts, &par, segs.len()).is_some()
}

/// The lobes of a closed shape (see the module docs): closed cubic shapes with its fill and
/// stroke, cut out of its outline wherever it meets itself; lobes under `min_area` px² are
/// dropped. A shape that does not meet itself comes back as it is (polygons as cubics only when
/// cut). Open shapes come back unchanged.
pub fn split_lobes(shape: &Shape, min_area: f32) -> Vec<Shape> {
    if !shape.is_closed() {
        return vec![shape.clone()];
    }
    let segs = segments(shape);
    let (pts, par) = flatten(&segs);
    if first_contact(&pts, &par, segs.len()).is_none() {
        return vec![shape.clone()];
    }
    let mut lobes = Vec::new();
    let mut cuts_left = MAX_CUTS;
    cut(
        segs,
        min_area.max(0.0) as f64,
        0,
        &mut cuts_left,
        &mut lobes,
    );
    lobes.iter().filter_map(|l| to_shape(l, shape)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::mse_rgb_over_white;
    use crate::scene::{Rgba, Scene};
    use crate::vector::simple::is_simple;

    fn red() -> Rgba {
        Rgba::new(0.8, 0.1, 0.1, 1.0)
    }

    /// A figure eight: two lobes of opposite orientation crossing at the centre.
    fn figure_eight() -> Shape {
        Shape::closed_cubic(
            Point::list(&[
                (8.0, 8.0),
                (16.0, 8.0),
                (16.0, 24.0),
                (24.0, 24.0),
                (32.0, 24.0),
                (32.0, 8.0),
                (24.0, 8.0),
                (16.0, 8.0),
                (16.0, 24.0),
                (8.0, 24.0),
                (0.0, 24.0),
                (0.0, 8.0),
            ]),
            red(),
        )
        .unwrap()
    }

    fn render(shapes: Vec<Shape>) -> crate::image::Image {
        let mut s = Scene::new(40, 32, Rgba::WHITE).unwrap();
        s.shapes = shapes;
        crate::raster::render(&s)
    }

    #[test]
    fn sub_cubic_lies_on_the_curve() {
        let s = [(0.0, 0.0), (1.0, 3.0), (4.0, 3.0), (5.0, 0.0)];
        let part = sub_cubic(&s, 0.25, 0.75);
        for m in 0..=8 {
            let u = m as f64 / 8.0;
            let (a, b) = (eval(&part, u), eval(&s, 0.25 + 0.5 * u));
            assert!((a.0 - b.0).abs() < 1e-12 && (a.1 - b.1).abs() < 1e-12);
        }
        assert_eq!(sub_cubic(&s, 0.0, 1.0), s);
    }

    #[test]
    fn a_figure_eight_becomes_two_simple_lobes_with_the_same_pixels() {
        let eight = figure_eight();
        assert!(!is_simple(&eight));
        let lobes = split_lobes(&eight, 0.5);
        assert_eq!(lobes.len(), 2);
        assert!(lobes.iter().all(is_simple));
        // Each lobe keeps the original curves: 2 + 2 segments, plus at most one cut each.
        let segs: usize = lobes.iter().map(|l| l.num_segments()).sum();
        assert!(segs <= 8, "{segs} segments");
        let before = render(vec![eight]);
        let after = render(lobes);
        let mse = mse_rgb_over_white(&before, &after);
        assert!(mse < 1e-5, "mse {mse}");
    }

    #[test]
    fn a_small_twist_at_a_corner_is_cut_into_its_own_lobe() {
        // A square whose corner handles cross, making a tiny loop at the top-right corner.
        let sq = Shape::closed_cubic(
            Point::list(&[
                (4.0, 4.0),
                (12.0, 4.0),
                (31.0, 7.0),
                (28.0, 4.0),
                (25.0, 1.0),
                (28.0, 20.0),
                (28.0, 28.0),
                (20.0, 28.0),
                (12.0, 28.0),
                (4.0, 28.0),
                (4.0, 20.0),
                (4.0, 12.0),
            ]),
            red(),
        )
        .unwrap();
        assert!(!is_simple(&sq));
        // The loop sticks out of the corner (about 2 px²): kept as its own lobe at a 1 px²
        // threshold, dropped at 4 px².
        let lobes = split_lobes(&sq, 1.0);
        assert_eq!(lobes.len(), 2, "{lobes:?}");
        assert!(lobes.iter().all(is_simple));
        assert_eq!(split_lobes(&sq, 4.0).len(), 1);
        let mse = mse_rgb_over_white(&render(vec![sq]), &render(lobes));
        assert!(mse < 1e-4, "mse {mse}");
    }

    #[test]
    fn the_quick_test_sees_crossings() {
        assert!(meets_itself(&figure_eight()));
        assert!(!meets_itself(
            &Shape::circle(16.0, 16.0, 8.0, 4, red()).unwrap()
        ));
    }

    #[test]
    fn simple_and_open_shapes_come_back_unchanged() {
        let c = Shape::circle(16.0, 16.0, 8.0, 4, red()).unwrap();
        assert_eq!(split_lobes(&c, 1.0), vec![c.clone()]);
        let sq = Shape::square(2.0, 2.0, 5.0, red()).unwrap();
        assert_eq!(split_lobes(&sq, 1.0), vec![sq]);
    }

    #[test]
    fn random_twisted_paths_become_simple_lobes() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut simple_after = 0;
        let mut looping = 0;
        for _ in 0..200 {
            let n = rng.random_range(3..7usize);
            let mut p = Vec::new();
            for _ in 0..3 * n {
                p.push(Point::new(
                    rng.random_range(0.0..32.0f32),
                    rng.random_range(0.0..32.0f32),
                ));
            }
            let s = Shape::closed_cubic(p, red()).unwrap();
            if is_simple(&s) {
                continue;
            }
            looping += 1;
            let lobes = split_lobes(&s, 0.0);
            if lobes.iter().all(is_simple) {
                simple_after += 1;
            }
        }
        assert!(looping > 150, "{looping}");
        // Cusps and tangential folds without a crossing are left to the union repair.
        assert!(
            simple_after * 10 >= looping * 9,
            "{simple_after} of {looping}"
        );
    }
}
