//! Outlines cut to the canvas: a closed path that reaches past the canvas keeps only what lies
//! on it, so every point of the file lies on the designer's artboard. Nothing drawn changes
//! (the canvas clips the render anyway) and the file carries no geometry no one sees.
//!
//! The cut keeps the outline's own cubics, split where they cross an edge (de Casteljau, as
//! [`super::lobes`] cuts), joined by straight segments along the canvas's edges: the
//! Weiler–Atherton walk of a simple outline against a rectangle. Both are oriented alike
//! (positive shoelace area on screen, y down); leaving the canvas at an exit, the cut outline
//! follows the canvas's edge forward to the next entry. A shape whose outline encloses the whole
//! canvas becomes the canvas's rectangle. Only filled, unstroked, simple closed cubic shapes
//! are cut (a stroke would show along the cut); a gradient fill is placed in canvas space
//! (exported `userSpaceOnUse`), so every piece keeps it and paints as the whole did. A texture
//! fill stays whole (each piece would write its pixels again). Any piece that would not be a
//! valid simple outline leaves the shape as it was.

use super::lobes::{arc, area, at, eval, segments, to_shape};
use super::simple::{P, flatten_f64, is_simple, piece_ok, ring_area, ring_contains};
use crate::scene::{MAX_PATHS, Scene, Shape, ShapeKind};
use kurbo::common::solve_cubic;

type Seg = [P; 4];

/// Two crossings closer than this in curve parameter are one (an outline through a corner
/// meets both edges there).
const SAME_S: f64 = 1e-7;
/// How far past an edge (px) a point still counts as on the canvas.
const ON_EDGE: f64 = 1e-6;
/// Pieces smaller than this (px²) are dropped.
const MIN_PIECE_AREA: f64 = 0.05;

/// Where the outline meets the canvas's edge: curve parameter `s` (segment + t) and position
/// `u` along the edge, forward in the canvas's orientation (see [`along`]).
#[derive(Clone, Copy, Debug)]
struct Crossing {
    s: f64,
    u: f64,
    at: P,
}

/// The canvas `[0, w] × [0, h]` with its edge walked top left → right, down the right side,
/// bottom right → left, up the left side: positive shoelace area on screen.
#[derive(Clone, Copy)]
struct Canvas {
    w: f64,
    h: f64,
}

impl Canvas {
    fn perimeter(self) -> f64 {
        2.0 * (self.w + self.h)
    }

    fn inside(self, p: P) -> bool {
        p.0 > -ON_EDGE && p.0 < self.w + ON_EDGE && p.1 > -ON_EDGE && p.1 < self.h + ON_EDGE
    }

    /// Strictly inside, away from the edge: where a piece of outline between two crossings
    /// lies when it is on the canvas.
    fn within(self, p: P) -> bool {
        p.0 > 0.0 && p.0 < self.w && p.1 > 0.0 && p.1 < self.h
    }

    /// Position along the edge of a point on it (the nearest side's).
    fn along(self, p: P) -> f64 {
        let Canvas { w, h } = self;
        let (x, y) = (p.0.clamp(0.0, w), p.1.clamp(0.0, h));
        let d = [p.1.abs(), (p.0 - w).abs(), (p.1 - h).abs(), p.0.abs()];
        let side = (0..4).min_by(|&a, &b| d[a].total_cmp(&d[b])).unwrap_or(0);
        match side {
            0 => x,
            1 => w + y,
            2 => w + h + (w - x),
            _ => 2.0 * w + h + (h - y),
        }
    }

    /// The point of the edge at position `u`.
    fn at(self, u: f64) -> P {
        let Canvas { w, h } = self;
        let u = u.rem_euclid(self.perimeter());
        if u <= w {
            (u, 0.0)
        } else if u <= w + h {
            (w, u - w)
        } else if u <= 2.0 * w + h {
            (w - (u - w - h), h)
        } else {
            (0.0, h - (u - 2.0 * w - h))
        }
    }

    /// Straight segments along the edge from position `from` forward to `to`, through the
    /// corners between.
    fn walk(self, from: f64, to: f64) -> Vec<Seg> {
        let len = (to - from).rem_euclid(self.perimeter());
        let corners = [0.0, self.w, self.w + self.h, 2.0 * self.w + self.h];
        let mut stops: Vec<f64> = corners
            .iter()
            .map(|&c| (c - from).rem_euclid(self.perimeter()))
            .filter(|&d| d > 1e-9 && d < len - 1e-9)
            .collect();
        stops.sort_by(f64::total_cmp);
        stops.push(len);
        let mut out = Vec::with_capacity(stops.len());
        let mut a = self.at(from);
        for d in stops {
            let b = self.at(from + d);
            if (b.0 - a.0).hypot(b.1 - a.1) > 1e-9 {
                out.push(line(a, b));
            }
            a = b;
        }
        out
    }
}

fn line(a: P, b: P) -> Seg {
    let l = |t: f64| (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t);
    [a, l(1.0 / 3.0), l(2.0 / 3.0), b]
}

/// The parameters `t ∈ [0, 1)` where coordinate `axis` of cubic `seg` equals `c`.
fn level(seg: &Seg, axis: usize, c: f64) -> Vec<f64> {
    let v: [f64; 4] = std::array::from_fn(|i| if axis == 0 { seg[i].0 } else { seg[i].1 } - c);
    if v.iter().all(|&x| x > 0.0) || v.iter().all(|&x| x < 0.0) {
        return Vec::new();
    }
    let c3 = -v[0] + 3.0 * v[1] - 3.0 * v[2] + v[3];
    let c2 = 3.0 * v[0] - 6.0 * v[1] + 3.0 * v[2];
    let c1 = 3.0 * (v[1] - v[0]);
    solve_cubic(v[0], c1, c2, c3)
        .into_iter()
        .filter(|t| t.is_finite() && (0.0..1.0).contains(t))
        .collect()
}

/// Every point where the outline `segs` meets the canvas's edge, by curve parameter.
fn crossings(segs: &[Seg], cv: Canvas) -> Vec<Crossing> {
    let mut out = Vec::new();
    for (i, seg) in segs.iter().enumerate() {
        for (axis, c) in [(0, 0.0), (0, cv.w), (1, 0.0), (1, cv.h)] {
            for t in level(seg, axis, c) {
                let mut p = eval(seg, t);
                if axis == 0 {
                    p.0 = c;
                } else {
                    p.1 = c;
                }
                if cv.inside(p) {
                    let s = i as f64 + t;
                    out.push(Crossing {
                        s,
                        u: cv.along(p),
                        at: p,
                    });
                }
            }
        }
    }
    out.sort_by(|a, b| a.s.total_cmp(&b.s));
    let n = segs.len() as f64;
    out.dedup_by(|b, a| (b.s - a.s).abs() < SAME_S);
    if out.len() > 1 && (out[0].s + n - out[out.len() - 1].s) < SAME_S {
        out.pop();
    }
    out
}

/// The outline's point halfway (in parameter) from `a` to `b`, wrapping past the end.
fn between(segs: &[Seg], a: f64, b: f64) -> P {
    let b = if b <= a { b + segs.len() as f64 } else { b };
    at(segs, 0.5 * (a + b)).0
}

/// For each crossing, whether the outline from it to the next one lies on the canvas.
fn sides(segs: &[Seg], cuts: &[Crossing], cv: Canvas) -> Vec<bool> {
    let k = cuts.len();
    (0..k)
        .map(|i| cv.within(between(segs, cuts[i].s, cuts[(i + 1) % k].s)))
        .collect()
}

/// The pieces of `shape` on the canvas `w × h`: `None` when it stays as it is (it lies on the
/// canvas, is not a shape this cuts, or a piece would not be a simple outline), else the
/// pieces (none when nothing of it is on the canvas).
pub fn cut_to_canvas(shape: &Shape, w: u32, h: u32) -> Option<Vec<Shape>> {
    cut_to(shape, w as f64, h as f64)
}

/// [`cut_to_canvas`] against the rectangle `[0, w] × [0, h]` of any size (`w`, `h` > 0): the
/// canvas of a scene that is drawn at another scale than it is written.
fn cut_to(shape: &Shape, w: f64, h: f64) -> Option<Vec<Shape>> {
    if shape.kind != ShapeKind::ClosedCubic
        || shape.stroke.is_some()
        || shape
            .gradients
            .as_ref()
            .is_some_and(|g| g.texture.is_some())
        || shape.fill.is_none_or(|f| f.a <= 0.0)
        || !is_simple(shape)
    {
        return None;
    }
    let cv = Canvas { w, h };
    let (lo, hi) = shape.control_bounds();
    if lo.x >= 0.0 && lo.y >= 0.0 && hi.x as f64 <= cv.w && hi.y as f64 <= cv.h {
        return None;
    }
    let mut segs = segments(shape);
    if area(&segs) < 0.0 {
        segs.reverse();
        for s in &mut segs {
            s.reverse();
        }
    }
    let mut cuts = crossings(&segs, cv);
    // Keep only crossings between a piece on the canvas and one off it (drop touches).
    let mut on = sides(&segs, &cuts, cv);
    while cuts.len() >= 2 {
        let k = cuts.len();
        let keep: Vec<bool> = (0..k).map(|i| on[(i + k - 1) % k] != on[i]).collect();
        if keep.iter().all(|&x| x) {
            break;
        }
        cuts = cuts
            .into_iter()
            .zip(keep)
            .filter_map(|(c, x)| x.then_some(c))
            .collect();
        on = sides(&segs, &cuts, cv);
    }
    if cuts.len() < 2 {
        // No crossing: all on the canvas (its box only touched past an edge), all off it, or
        // around it.
        let on = cv.within(between(&segs, 0.0, 0.5));
        if on {
            return None;
        }
        let centre = kurbo::Point::new(0.5 * cv.w, 0.5 * cv.h);
        if !ring_contains(&flatten_f64(shape, 0.05), centre) {
            return Some(Vec::new());
        }
        let corners = [(0.0, 0.0), (cv.w, 0.0), (cv.w, cv.h), (0.0, cv.h)];
        let rect: Vec<Seg> = (0..4)
            .map(|i| line(corners[i], corners[(i + 1) % 4]))
            .collect();
        return to_shape(&rect, shape).map(|s| vec![s]);
    }
    // The pieces on the canvas, each from an entry to an exit.
    let k = cuts.len();
    let pieces: Vec<(Crossing, Crossing)> = (0..k)
        .filter(|&i| on[i])
        .map(|i| (cuts[i], cuts[(i + 1) % k]))
        .collect();
    let n = segs.len() as f64;
    let per = cv.perimeter();
    let mut used = vec![false; pieces.len()];
    let mut out = Vec::new();
    for start in 0..pieces.len() {
        if used[start] {
            continue;
        }
        let mut ring: Vec<Seg> = Vec::new();
        let mut i = start;
        loop {
            used[i] = true;
            let (entry, exit) = pieces[i];
            let to = if exit.s <= entry.s {
                exit.s + n
            } else {
                exit.s
            };
            let mut part = arc(&segs, entry.s, to);
            if let Some(first) = part.first_mut() {
                first[0] = entry.at;
            }
            if let Some(last) = part.last_mut() {
                last[3] = exit.at;
            }
            ring.extend(part);
            // Along the edge to the nearest crossing ahead: it must be an entry.
            let ahead = |c: &Crossing| {
                let d = (c.u - exit.u).rem_euclid(per);
                if d < 1e-9 { per } else { d }
            };
            let next_exit = pieces
                .iter()
                .map(|p| ahead(&p.1))
                .fold(f64::INFINITY, f64::min);
            let (j, d) = pieces
                .iter()
                .enumerate()
                .map(|(j, p)| (j, ahead(&p.0)))
                .min_by(|a, b| a.1.total_cmp(&b.1))?;
            if next_exit < d {
                return None;
            }
            ring.extend(cv.walk(exit.u, exit.u + d));
            if j == start {
                break;
            }
            if used[j] {
                return None;
            }
            i = j;
        }
        let piece = to_shape(&ring, shape)?;
        if ring_area(&flatten_f64(&piece, 0.1)).abs() < MIN_PIECE_AREA {
            continue;
        }
        if !piece_ok(&piece) {
            return None;
        }
        out.push(piece);
    }
    Some(out)
}

/// Cuts every shape of `scene` that reaches past its canvas to the canvas ([`cut_to_canvas`]),
/// in place (pieces where the shape was in the paint order; groups kept on them). Returns how
/// many shapes were cut. The scene never grows past `MAX_PATHS`: a shape whose pieces would
/// pass it stays whole.
pub fn cut_scene_to_canvas(scene: &mut Scene) -> usize {
    let (w, h) = (scene.width as f64, scene.height as f64);
    cut_scene_to(scene, w, h)
}

/// [`cut_scene_to_canvas`] against `[0, w] × [0, h]` instead of the scene's canvas: a trace
/// at its working size cut to the canvas it will be written at (`w`, `h` > 0, in the scene's
/// units).
pub fn cut_scene_to(scene: &mut Scene, w: f64, h: f64) -> usize {
    let mut count = scene.shapes.len();
    let mut cut = 0;
    let mut pieces = Vec::with_capacity(scene.shapes.len());
    for s in &scene.shapes {
        match cut_to(s, w, h) {
            Some(p) if count + p.len() <= MAX_PATHS + 1 => {
                count = count + p.len() - 1;
                cut += 1;
                pieces.push(p);
            }
            _ => pieces.push(vec![s.clone()]),
        }
    }
    if cut > 0 {
        scene.replace_shapes(pieces);
    }
    cut
}

#[cfg(test)]
#[path = "tests_canvas.rs"]
mod tests;
