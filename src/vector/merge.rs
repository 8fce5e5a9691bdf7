//! Fewer paths at equal quality: two closed paths of the same fill whose outlines cross (they
//! overlap), with nothing between them in the paint order drawn over the part that would move,
//! become one path: the union of their outlines, made of their own cubics cut at the two
//! crossings ([`union_shape`]), kept only when it is one simple outline
//! ([`super::simple::is_simple`]), has no more segments than the two had together, and the
//! render stays within [`MergeTolerance`] of the render before.

use super::simple::{P, piece_ok, ring_area, ring_contains, snapped};
use crate::image::Image;
use crate::scene::{Scene, Shape};
use crate::svg::written_color;
use kurbo::{CubicBez, ParamCurve, ParamCurveNearest};

/// How close the render after a merge must stay to the render before, over the box of the two
/// paths grown by [`BOX_MARGIN`] px (premultiplied RGBA values, 0..=1 scale).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MergeTolerance {
    /// Largest mean absolute difference per channel value in the box.
    pub mean_abs: f64,
    /// Largest absolute difference of any channel value: enough for the anti-aliasing seam
    /// where two paths only abut (the union closes it), far below a pixel that changes colour.
    pub max_abs: f64,
}

impl Default for MergeTolerance {
    fn default() -> Self {
        MergeTolerance {
            mean_abs: 2.0 / 255.0,
            max_abs: 0.3,
        }
    }
}

/// Margin (px) around the two paths' box where the renders are compared.
const BOX_MARGIN: f64 = 2.0;
/// Paths whose boxes are this close (px) may touch.
const TOUCH: f64 = 0.5;

type Box2 = [f64; 4];

/// The box of a shape's control points (it holds the curve).
fn shape_box(s: &Shape) -> Box2 {
    let mut b = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for p in &s.points {
        b = [
            b[0].min(p.x as f64),
            b[1].min(p.y as f64),
            b[2].max(p.x as f64),
            b[3].max(p.y as f64),
        ];
    }
    b
}

fn boxes_meet(a: &Box2, b: &Box2, grow: f64) -> bool {
    a[0] <= b[2] + grow && b[0] <= a[2] + grow && a[1] <= b[3] + grow && b[1] <= a[3] + grow
}

/// Whether two shapes paint alike: closed, no stroke, the same opaque flat fill as the SVG
/// writes it (a gradient paints differently wherever it is).
fn same_paint(a: &Shape, b: &Shape) -> bool {
    let paint = |s: &Shape| {
        s.fill
            .filter(|f| s.is_closed() && s.stroke.is_none() && f.a >= 1.0)
            .filter(|_| s.gradients.is_none())
            .map(|f| written_color(f, super::export::MAX_DECIMALS))
    };
    paint(a).is_some() && paint(a) == paint(b)
}

/// The union of two shapes' outlines as one simple closed cubic shape with `a`'s paint, built
/// from their own curves: when the outlines cross at exactly two points, the arc of `a` outside
/// `b` followed by the arc of `b` outside `a`, each cut at the crossings. `None` when they do
/// not cross twice, the result is not simple, or it has more segments than the two together.
pub fn union_shape(a: &Shape, b: &Shape) -> Option<Shape> {
    if !a.is_closed() || !b.is_closed() {
        return None;
    }
    let sa = segments(a);
    let mut sb = segments(b);
    let (pa, pb) = (samples(&sa), samples(&sb));
    if (ring_area(&points(&pa)) > 0.0) != (ring_area(&points(&pb)) > 0.0) {
        sb = sb
            .iter()
            .rev()
            .map(|c| CubicBez::new(c.p3, c.p2, c.p1, c.p0))
            .collect();
    }
    let pb = samples(&sb);
    let [x, y] = crossings(&sa, &pa, &sb, &pb)?;
    // The arc of `a` outside `b` runs from one crossing to the other (in `a`'s direction).
    let ring_b = points(&pb);
    let mid = |c0: f64, c1: f64| {
        let m = if c1 > c0 {
            0.5 * (c0 + c1)
        } else {
            0.5 * (c0 + c1 + sa.len() as f64)
        };
        eval(&sa, m)
    };
    let (first, second) = if !ring_contains(&ring_b, mid(x.0, y.0)) {
        (x, y)
    } else if !ring_contains(&ring_b, mid(y.0, x.0)) {
        (y, x)
    } else {
        return None;
    };
    let mut out = arc(&sa, first.0, second.0);
    out.extend(arc(&sb, second.1, first.1));
    let shape = Shape {
        points: snapped(joined(&out)?),
        ..a.clone()
    };
    let fewer = shape.num_segments() <= a.num_segments() + b.num_segments();
    (fewer && piece_ok(&shape)).then_some(shape)
}

fn kpt(p: crate::scene::Point) -> kurbo::Point {
    kurbo::Point::new(p.x as f64, p.y as f64)
}

/// A closed shape's segments as kurbo cubics.
fn segments(s: &Shape) -> Vec<CubicBez> {
    (0..s.num_segments())
        .map(|i| {
            let [p0, p1, p2, p3] = s.segment(i).map(kpt);
            CubicBez::new(p0, p1, p2, p3)
        })
        .collect()
}

/// Samples per segment when looking for crossings.
const SAMPLES: usize = 32;

/// Points along the outline with their parameter (segment index + t).
fn samples(segs: &[CubicBez]) -> Vec<(f64, kurbo::Point)> {
    let mut out = Vec::with_capacity(SAMPLES * segs.len());
    for (i, c) in segs.iter().enumerate() {
        for k in 0..SAMPLES {
            let t = k as f64 / SAMPLES as f64;
            out.push((i as f64 + t, c.eval(t)));
        }
    }
    out
}

fn points(s: &[(f64, kurbo::Point)]) -> Vec<P> {
    s.iter().map(|(_, p)| (p.x, p.y)).collect()
}

/// The outline at parameter `u` (segment index + t, wrapping).
fn eval(segs: &[CubicBez], u: f64) -> kurbo::Point {
    let n = segs.len() as f64;
    let u = u.rem_euclid(n);
    let i = (u.floor() as usize).min(segs.len() - 1);
    segs[i].eval(u - i as f64)
}

/// The parameters `(on a, on b)` of the two places where the outlines cross, refined on the
/// curves; `None` unless there are exactly two.
fn crossings(
    sa: &[CubicBez],
    pa: &[(f64, kurbo::Point)],
    sb: &[CubicBez],
    pb: &[(f64, kurbo::Point)],
) -> Option<[(f64, f64); 2]> {
    let mut found = Vec::new();
    for i in 0..pa.len() {
        let (a0, a1) = (pa[i], pa[(i + 1) % pa.len()]);
        for j in 0..pb.len() {
            let (b0, b1) = (pb[j], pb[(j + 1) % pb.len()]);
            let Some((ta, tb)) = segment_cross(a0.1, a1.1, b0.1, b1.1) else {
                continue;
            };
            let step = 1.0 / SAMPLES as f64;
            found.push((a0.0 + ta * step, b0.0 + tb * step));
            if found.len() > 2 {
                return None;
            }
        }
    }
    let [x, y] = found.as_slice() else {
        return None;
    };
    Some([refine(sa, sb, *x), refine(sa, sb, *y)])
}

/// Where segments `p0p1` and `q0q1` cross: the parameters along each, in `[0, 1)` (a crossing
/// at a shared sample counts once).
fn segment_cross(
    p0: kurbo::Point,
    p1: kurbo::Point,
    q0: kurbo::Point,
    q1: kurbo::Point,
) -> Option<(f64, f64)> {
    let (r, s) = (p1 - p0, q1 - q0);
    let den = r.cross(s);
    if den.abs() < 1e-12 {
        return None;
    }
    let w = q0 - p0;
    let (t, u) = (w.cross(s) / den, w.cross(r) / den);
    ((0.0..1.0).contains(&t) && (0.0..1.0).contains(&u)).then_some((t, u))
}

/// A crossing's parameters moved onto the curves (alternating nearest points).
fn refine(sa: &[CubicBez], sb: &[CubicBez], (mut u, mut v): (f64, f64)) -> (f64, f64) {
    let near = |segs: &[CubicBez], w: f64, p: kurbo::Point| {
        let i = (w.floor() as usize).min(segs.len() - 1);
        i as f64 + segs[i].nearest(p, 1e-9).t
    };
    for _ in 0..4 {
        v = near(sb, v, eval(sa, u));
        u = near(sa, u, eval(sb, v));
    }
    (u, v)
}

/// The outline from parameter `from` to `to` (forward, wrapping), cut at both ends.
fn arc(segs: &[CubicBez], from: f64, to: f64) -> Vec<CubicBez> {
    let n = segs.len();
    let to = if to > from { to } else { to + n as f64 };
    let mut out = Vec::new();
    let mut u = from;
    while u < to - 1e-9 {
        let i = u.floor() as usize;
        let end = ((i + 1) as f64).min(to);
        let (t0, t1) = (u - i as f64, end - i as f64);
        if t1 - t0 > 1e-3 {
            out.push(segs[i % n].subsegment(t0..t1));
        }
        u = end;
    }
    out
}

/// Closed-cubic points of consecutive segments, each joined to the one before (the small gap
/// a dropped sliver of a segment or a crossing leaves is closed by moving the start).
fn joined(segs: &[CubicBez]) -> Option<Vec<crate::scene::Point>> {
    let pt = |p: kurbo::Point| crate::scene::Point::new(p.x as f32, p.y as f32);
    if segs.len() < 2 {
        return None;
    }
    let mut out = Vec::with_capacity(3 * segs.len());
    for (k, c) in segs.iter().enumerate() {
        let prev = segs[(k + segs.len() - 1) % segs.len()].p3;
        let shift = prev - c.p0;
        if shift.hypot() > 0.5 {
            return None;
        }
        out.extend([pt(prev), pt(c.p1 + shift), pt(c.p2)]);
    }
    Some(out)
}

/// The pixel rows and columns `[x0, x1) × [y0, y1)` of `bx` grown by [`BOX_MARGIN`], clipped to a
/// `w × h` canvas.
fn box_pixels(bx: &Box2, w: u32, h: u32) -> [usize; 4] {
    let (w, h) = (w as f64, h as f64);
    [
        (bx[0] - BOX_MARGIN).floor().clamp(0.0, w) as usize,
        (bx[1] - BOX_MARGIN).floor().clamp(0.0, h) as usize,
        (bx[2] + BOX_MARGIN).ceil().clamp(0.0, w) as usize,
        (bx[3] + BOX_MARGIN).ceil().clamp(0.0, h) as usize,
    ]
}

/// Mean and largest absolute difference of `a` and the rows of the same image size `b` holds
/// from row `b_first` on, over `bx` (px, grown by the margin and clipped); those rows must hold
/// the box's.
fn box_diff(a: &Image, b_first: usize, b: &[f32], bx: &Box2) -> (f64, f64) {
    let [x0, y0, x1, y1] = box_pixels(bx, a.width, a.height);
    let row = 4 * a.width as usize;
    let (mut sum, mut max, mut n) = (0.0f64, 0.0f64, 0usize);
    for y in y0..y1 {
        let (ra, rb) = (y * row, (y - b_first) * row);
        for (p, q) in a.data[ra + 4 * x0..ra + 4 * x1]
            .iter()
            .zip(&b[rb + 4 * x0..rb + 4 * x1])
        {
            let d = (*p as f64 - *q as f64).abs();
            sum += d;
            max = max.max(d);
            n += 1;
        }
    }
    (sum / n.max(1) as f64, max)
}

/// The scene with shapes `i < j` replaced by `merged` at `pos` (`i` or `j`).
fn with_merged(scene: &Scene, i: usize, j: usize, pos: usize, merged: Shape) -> Scene {
    let mut out = scene.clone();
    out.shapes[pos] = merged;
    // Groups keep their shapes; a merge across a group's edge changes the picture and is
    // refused by the render comparison.
    out.remove_shape(if pos == i { j } else { i });
    out
}

/// Where the union of shapes `i < j` may go in the paint order: at `j` when nothing between
/// them overlaps `i` (it moves up), at `i` when nothing between them overlaps `j` (it moves
/// down). Boxes decide here; the render comparison decides in the end.
fn positions(scene: &Scene, i: usize, j: usize, boxes: &[Box2]) -> Vec<usize> {
    let clear = |k: usize| {
        (i + 1..j).all(|m| {
            same_paint(&scene.shapes[m], &scene.shapes[k]) || !boxes_meet(&boxes[m], &boxes[k], 0.0)
        })
    };
    let mut out = Vec::new();
    if clear(i) {
        out.push(j);
    }
    if clear(j) {
        out.push(i);
    }
    out
}

/// Tries to merge shape `i` with a later shape; returns the new scene and its render.
fn merge_one(
    scene: &Scene,
    current: &Image,
    i: usize,
    tol: MergeTolerance,
) -> Option<(Scene, Image)> {
    let boxes: Vec<Box2> = scene.shapes.iter().map(shape_box).collect();
    for j in i + 1..scene.shapes.len() {
        let (a, b) = (&scene.shapes[i], &scene.shapes[j]);
        if !same_paint(a, b) || !boxes_meet(&boxes[i], &boxes[j], TOUCH) {
            continue;
        }
        let pos = positions(scene, i, j, &boxes);
        if pos.is_empty() {
            continue;
        }
        let Some(merged) = union_shape(a, b) else {
            continue;
        };
        let bx = [
            boxes[i][0].min(boxes[j][0]),
            boxes[i][1].min(boxes[j][1]),
            boxes[i][2].max(boxes[j][2]),
            boxes[i][3].max(boxes[j][3]),
        ];
        let [_, y0, _, y1] = box_pixels(&bx, scene.width, scene.height);
        for p in pos {
            let trial = with_merged(scene, i, j, p, merged.clone());
            // Only the box's rows can change (the union stays within the two paths' control
            // points).
            let (first, rows) = super::changed_rows(scene, &trial, y0 as u32..y1 as u32);
            let (mean, max) = box_diff(current, first as usize, &rows, &bx);
            if mean <= tol.mean_abs && max <= tol.max_abs {
                let mut img = current.clone();
                let at = first as usize * 4 * scene.width as usize;
                img.data[at..at + rows.len()].copy_from_slice(&rows);
                return Some((trial, img));
            }
        }
    }
    None
}

/// Merges touching same-fill paths of `scene` (see the module docs), lowest first, until no
/// pair merges. Returns how many merges were made (paths removed). Deterministic.
pub fn merge_touching(scene: &mut Scene, tol: MergeTolerance) -> usize {
    let mut current = crate::raster::render(scene);
    let mut merged = 0;
    let mut i = 0;
    while i < scene.shapes.len() {
        match merge_one(scene, &current, i, tol) {
            Some((s, img)) => {
                *scene = s;
                current = img;
                merged += 1;
            }
            None => i += 1,
        }
    }
    merged
}

#[cfg(test)]
#[path = "tests_merge.rs"]
mod tests;
