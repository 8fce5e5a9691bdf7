//! Simple outlines: find closed paths whose outline crosses itself, touches itself or folds back
//! into a zero-width spike, and split them into simple pieces that paint the same picture.
//!
//! # The measure
//! A closed, filled shape is flattened to a polygon ([`flatten`] at [`FLATTEN_TOLERANCE`] px)
//! and that ring is tested the way shapely's `Polygon(ring).is_valid` tests a one-ring polygon
//! ([`ring_is_simple`]), with a contact tolerance of [`CONTACT_EPS`] px instead of exact
//! arithmetic:
//! - consecutive vertices closer than `CONTACT_EPS` are merged (a duplicate point is no defect);
//!   fewer than 3 distinct vertices left is a zero-area ring: not simple;
//! - a vertex where the outline reverses direction (the shorter of the two edges lies within
//!   `CONTACT_EPS` of the longer one's line, pointing back) is a fold: not simple;
//! - two edges that are not neighbours and come within `CONTACT_EPS` of each other (cross,
//!   touch or overlap) make the ring not simple.
//!
//! Open shapes (strokes) and shapes with no fill or a fully transparent fill count as simple.
//!
//! # The repair
//! [`split_simple`] flattens the outline, resolves it with i_overlay's nonzero self-union into
//! OGC-valid polygons (outer ring + holes), cuts every polygon with holes by axis-parallel lines
//! through its holes (on whole pixels where the hole is wide enough, so the cut makes no seam in
//! an exact-area renderer) until no piece has a hole, then fits cubics back with kurbo. A fit that
//! is not simple falls back to the polygon itself (straight cubic segments).

use crate::scene::{MAX_PATHS, Point, Scene, Shape, ShapeKind};
use i_overlay::core::fill_rule::FillRule;
use i_overlay::core::overlay_rule::OverlayRule;
use i_overlay::float::overlay::{FloatOverlay, OverlayOptions};
use kurbo::{BezPath, PathEl};

/// Flattening tolerance (px) used by [`is_simple`]: the largest distance between the curve and
/// the polygon that stands for it.
pub const FLATTEN_TOLERANCE: f32 = 0.01;

/// Contact tolerance (px) of [`ring_is_simple`]: points closer than this are one point, edges
/// closer than this touch. Far below what a renderer or a designer can see, far above f32
/// rounding at canvas sizes up to [`crate::scene::MAX_SIDE`].
pub const CONTACT_EPS: f64 = 1e-3;

/// Tangent of the angle above which the cubic fit keeps a polygon vertex as a corner (35°):
/// flattened smooth curves turn far less per vertex, cuts and real corners more.
const CORNER_TAN: f64 = 0.7;

pub(super) type P = (f64, f64);

/// The outline of `shape` as a polyline at `tolerance` px (kurbo's flattening; clamped to at
/// least 1e-4 px). Closed shapes give a ring that does not repeat its first vertex; open shapes
/// give the polyline from the first to the last point.
pub fn flatten(shape: &Shape, tolerance: f32) -> Vec<(f32, f32)> {
    flatten_f64(shape, tolerance as f64)
        .into_iter()
        .map(|(x, y)| (x as f32, y as f32))
        .collect()
}

fn shape_path(shape: &Shape) -> BezPath {
    let kp = |p: Point| kurbo::Point::new(p.x as f64, p.y as f64);
    let mut path = BezPath::new();
    if shape.points.is_empty() {
        return path;
    }
    path.move_to(kp(shape.points[0]));
    for i in 0..shape.num_segments() {
        let [_, c1, c2, b] = shape.segment(i);
        match shape.kind {
            ShapeKind::Polygon => path.line_to(kp(b)),
            _ => path.curve_to(kp(c1), kp(c2), kp(b)),
        }
    }
    if shape.is_closed() {
        path.close_path();
    }
    path
}

pub(super) fn flatten_f64(shape: &Shape, tolerance: f64) -> Vec<P> {
    let mut out: Vec<P> = Vec::new();
    kurbo::flatten(shape_path(shape), tolerance.max(1e-4), |el| match el {
        PathEl::MoveTo(p) | PathEl::LineTo(p) => out.push((p.x, p.y)),
        _ => {}
    });
    if shape.is_closed() && out.len() > 1 && out.first() == out.last() {
        out.pop();
    }
    out
}

/// Whether the flattened outline of a closed, filled shape is a simple ring (see the module
/// docs). Open shapes and shapes without a visible fill are simple.
pub fn is_simple(shape: &Shape) -> bool {
    if !shape.is_closed() || shape.fill.is_none_or(|f| f.a <= 0.0) {
        return true;
    }
    ring_is_simple(&flatten_f64(shape, FLATTEN_TOLERANCE as f64))
}

/// Merges consecutive vertices closer than [`CONTACT_EPS`] (also last with first).
pub(super) fn dedup(ring: &[P]) -> Vec<P> {
    let mut out: Vec<P> = Vec::with_capacity(ring.len());
    for &p in ring {
        if out.last().is_none_or(|&q| dist(p, q) > CONTACT_EPS) {
            out.push(p);
        }
    }
    while out.len() > 1 && dist(out[0], out[out.len() - 1]) <= CONTACT_EPS {
        out.pop();
    }
    out
}

fn dist(a: P, b: P) -> f64 {
    (a.0 - b.0).hypot(a.1 - b.1)
}

fn sub(a: P, b: P) -> P {
    (a.0 - b.0, a.1 - b.1)
}

fn cross(a: P, b: P) -> f64 {
    a.0 * b.1 - a.1 * b.0
}

fn dot(a: P, b: P) -> f64 {
    a.0 * b.0 + a.1 * b.1
}

fn point_segment_dist(p: P, a: P, b: P) -> f64 {
    let ab = sub(b, a);
    let l2 = dot(ab, ab);
    if l2 <= 0.0 {
        return dist(p, a);
    }
    let t = (dot(sub(p, a), ab) / l2).clamp(0.0, 1.0);
    dist(p, (a.0 + ab.0 * t, a.1 + ab.1 * t))
}

/// Whether segments `ab` and `cd` cross properly (each separates the other's endpoints).
fn proper_cross(a: P, b: P, c: P, d: P) -> Option<P> {
    let r = sub(b, a);
    let s = sub(d, c);
    let den = cross(r, s);
    if den == 0.0 {
        return None;
    }
    let t = cross(sub(c, a), s) / den;
    let u = cross(sub(c, a), r) / den;
    ((0.0..=1.0).contains(&t) && (0.0..=1.0).contains(&u)).then_some((a.0 + r.0 * t, a.1 + r.1 * t))
}

/// Where segments `ab` and `cd` meet within [`CONTACT_EPS`]: the crossing point, or the closest
/// endpoint; `None` when they stay apart.
fn contact(a: P, b: P, c: P, d: P) -> Option<P> {
    if let Some(x) = proper_cross(a, b, c, d) {
        return Some(x);
    }
    let cands = [
        (point_segment_dist(a, c, d), a),
        (point_segment_dist(b, c, d), b),
        (point_segment_dist(c, a, b), c),
        (point_segment_dist(d, a, b), d),
    ];
    let (dmin, p) = cands
        .iter()
        .copied()
        .fold((f64::INFINITY, a), |m, x| if x.0 < m.0 { x } else { m });
    (dmin <= CONTACT_EPS).then_some(p)
}

/// Whether two segments overlap along a common line over more than [`CONTACT_EPS`].
fn collinear_overlap(a: P, b: P, c: P, d: P) -> bool {
    let (long, short) = if dist(a, b) >= dist(c, d) {
        ((a, b), (c, d))
    } else {
        ((c, d), (a, b))
    };
    let l = dist(long.0, long.1);
    if l <= 0.0 {
        return false;
    }
    let dir = ((long.1.0 - long.0.0) / l, (long.1.1 - long.0.1) / l);
    let off = |p: P| cross(dir, sub(p, long.0)).abs();
    if off(short.0) > CONTACT_EPS || off(short.1) > CONTACT_EPS {
        return false;
    }
    let t0 = dot(sub(short.0, long.0), dir).clamp(0.0, l);
    let t1 = dot(sub(short.1, long.0), dir).clamp(0.0, l);
    (t1 - t0).abs() > CONTACT_EPS
}

/// Axis-aligned boxes of the edges `i -> i+1` of a (closed or open) polyline, grown by `grow`.
pub(super) fn edge_boxes(pts: &[P], closed: bool, grow: f64) -> Vec<[f64; 4]> {
    let n = pts.len();
    let m = if closed { n } else { n.saturating_sub(1) };
    (0..m)
        .map(|i| {
            let (a, b) = (pts[i], pts[(i + 1) % n]);
            [
                a.0.min(b.0) - grow,
                a.1.min(b.1) - grow,
                a.0.max(b.0) + grow,
                a.1.max(b.1) + grow,
            ]
        })
        .collect()
}

/// Calls `f(i, j)` for every pair of edges (`i` from `a`, `j` from `b`) whose boxes overlap
/// (sweep over x). With `same`, `a` and `b` are one set and each unordered pair comes once.
fn box_pairs(
    a: &[[f64; 4]],
    b: &[[f64; 4]],
    same: bool,
    mut f: impl FnMut(usize, usize) -> bool,
) -> bool {
    // Events: (min x, set, index); sorted deterministically.
    let mut ev: Vec<(f64, u8, usize)> = a.iter().enumerate().map(|(i, r)| (r[0], 0, i)).collect();
    if !same {
        ev.extend(b.iter().enumerate().map(|(j, r)| (r[0], 1, j)));
    }
    ev.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)).then(x.2.cmp(&y.2)));
    let rect = |set: u8, i: usize| if set == 0 { a[i] } else { b[i] };
    for (k, &(_, s1, i1)) in ev.iter().enumerate() {
        let r1 = rect(s1, i1);
        for &(x2, s2, i2) in &ev[k + 1..] {
            if x2 > r1[2] {
                break;
            }
            if !same && s1 == s2 {
                continue;
            }
            let r2 = rect(s2, i2);
            if r2[1] > r1[3] || r1[1] > r2[3] {
                continue;
            }
            let (i, j) = if same || s1 == 0 { (i1, i2) } else { (i2, i1) };
            if f(i, j) {
                return true;
            }
        }
    }
    false
}

/// Whether the closed ring (first vertex not repeated; a repeated one is ignored) is simple in
/// the sense of the module docs: at least 3 distinct vertices, no fold, no contact between
/// edges that are not neighbours.
pub fn ring_is_simple(ring: &[P]) -> bool {
    let r = dedup(ring);
    let n = r.len();
    if n < 3 {
        return false;
    }
    // Folds: the outline reverses at a vertex.
    for i in 0..n {
        let (a, b, c) = (r[(i + n - 1) % n], r[i], r[(i + 1) % n]);
        let (u, v) = (sub(b, a), sub(c, b));
        let l = dist(a, b).max(dist(b, c));
        if dot(u, v) < 0.0 && cross(u, v).abs() / l <= CONTACT_EPS {
            return false;
        }
    }
    if n == 3 {
        return true;
    }
    let boxes = edge_boxes(&r, true, CONTACT_EPS);
    let hit = box_pairs(&boxes, &boxes, true, |i, j| {
        let (i, j) = (i.min(j), i.max(j));
        if j == i + 1 || (i == 0 && j == n - 1) {
            return false;
        }
        contact(r[i], r[(i + 1) % n], r[j], r[(j + 1) % n]).is_some()
    });
    !hit
}

/// Whether two closed rings meet in more than one point (cross, overlap along an edge, or touch
/// at two places or more): shapely's rule for the rings of one polygon, where a hole may touch
/// its shell at a single point.
pub fn rings_cross(a: &[P], b: &[P]) -> bool {
    let (ra, rb) = (dedup(a), dedup(b));
    if ra.len() < 2 || rb.len() < 2 {
        return false;
    }
    let (na, nb) = (ra.len(), rb.len());
    let (ba, bb) = (
        edge_boxes(&ra, true, CONTACT_EPS),
        edge_boxes(&rb, true, CONTACT_EPS),
    );
    let mut first: Option<P> = None;
    box_pairs(&ba, &bb, false, |i, j| {
        let (p, q, s, t) = (ra[i], ra[(i + 1) % na], rb[j], rb[(j + 1) % nb]);
        let Some(x) = contact(p, q, s, t) else {
            return false;
        };
        if collinear_overlap(p, q, s, t) {
            return true;
        }
        match first {
            None => {
                first = Some(x);
                false
            }
            Some(f) => dist(f, x) > 4.0 * CONTACT_EPS,
        }
    })
}

/// Signed area of a ring (shoelace).
/// Even-odd point-in-polygon (for a simple ring, the same as nonzero).
pub(super) fn ring_contains(ring: &[P], p: kurbo::Point) -> bool {
    let mut c = false;
    let n = ring.len();
    for i in 0..n {
        let (a, b) = (ring[i], ring[(i + 1) % n]);
        if (a.1 > p.y) != (b.1 > p.y) && p.x < a.0 + (p.y - a.1) / (b.1 - a.1) * (b.0 - a.0) {
            c = !c;
        }
    }
    c
}

pub(super) fn ring_area(r: &[P]) -> f64 {
    let n = r.len();
    (0..n).map(|i| cross(r[i], r[(i + 1) % n])).sum::<f64>() * 0.5
}

type Poly = Vec<Vec<[f64; 2]>>;

fn to_p(c: &[[f64; 2]]) -> Vec<P> {
    c.iter().map(|p| (p[0], p[1])).collect()
}

pub(super) fn overlay_opts() -> OverlayOptions<f64> {
    OverlayOptions::ogc()
}

/// Cuts polygons with holes by axis-parallel lines through a hole until no piece has a hole.
fn cut_holes(polys: Vec<Poly>) -> Vec<Vec<P>> {
    let mut done = Vec::new();
    let mut todo = polys;
    let mut guard = 0usize;
    while let Some(poly) = todo.pop() {
        if poly.is_empty() {
            continue;
        }
        if poly.len() == 1 || guard > 10_000 {
            done.push(to_p(&poly[0]));
            continue;
        }
        guard += 1;
        let hole = &poly[1];
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for q in poly.iter().flatten() {
            for k in 0..2 {
                lo[k] = lo[k].min(q[k]);
                hi[k] = hi[k].max(q[k]);
            }
        }
        let (mut hlo, mut hhi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for q in hole {
            for k in 0..2 {
                hlo[k] = hlo[k].min(q[k]);
                hhi[k] = hhi[k].max(q[k]);
            }
        }
        // A cut on a whole pixel (no antialiasing seam) where the hole spans one, else the middle.
        let whole = |k: usize| {
            let m = 0.5 * (hlo[k] + hhi[k]);
            let c = m.round();
            (c > hlo[k] + 1e-6 && c < hhi[k] - 1e-6).then_some(c)
        };
        let (axis, c) = match (whole(0), whole(1)) {
            (Some(c), _) => (0, c),
            (None, Some(c)) => (1, c),
            _ if hhi[0] - hlo[0] >= hhi[1] - hlo[1] => (0, 0.5 * (hlo[0] + hhi[0])),
            _ => (1, 0.5 * (hlo[1] + hhi[1])),
        };
        let pad = 1.0 + (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let (x0, y0, x1, y1) = (lo[0] - pad, lo[1] - pad, hi[0] + pad, hi[1] + pad);
        let halves: [[[f64; 2]; 4]; 2] = if axis == 0 {
            [
                [[x0, y0], [c, y0], [c, y1], [x0, y1]],
                [[c, y0], [x1, y0], [x1, y1], [c, y1]],
            ]
        } else {
            [
                [[x0, y0], [x1, y0], [x1, c], [x0, c]],
                [[x0, c], [x1, c], [x1, y1], [x0, y1]],
            ]
        };
        for half in halves {
            let clip = vec![half.to_vec()];
            let res = FloatOverlay::with_subj_and_clip_custom(
                &poly,
                &clip,
                overlay_opts(),
                Default::default(),
            )
            .overlay(OverlayRule::Intersect, FillRule::NonZero);
            // Newest pieces last: popped next (depth first, deterministic).
            todo.extend(res.into_iter().rev());
        }
    }
    done
}

fn kp(p: P) -> kurbo::Point {
    kurbo::Point::new(p.0, p.1)
}

fn fp(p: kurbo::Point) -> Point {
    Point::new(p.x as f32, p.y as f32)
}

/// Closed-cubic points of a ring drawn with straight segments (handles at 1/3 and 2/3).
fn polygon_cubic_points(ring: &[P]) -> Vec<Point> {
    let n = ring.len();
    let mut pts = Vec::with_capacity(3 * n);
    for i in 0..n {
        let (a, b) = (ring[i], ring[(i + 1) % n]);
        let lerp = |t: f64| {
            Point::new(
                (a.0 + (b.0 - a.0) * t) as f32,
                (a.1 + (b.1 - a.1) * t) as f32,
            )
        };
        pts.extend_from_slice(&[lerp(0.0), lerp(1.0 / 3.0), lerp(2.0 / 3.0)]);
    }
    pts
}

/// Closed-cubic points of a closed kurbo path (one subpath).
fn bez_cubic_points(path: &BezPath) -> Vec<Point> {
    let mut pts = Vec::new();
    let (mut start, mut cur) = (kurbo::Point::ZERO, kurbo::Point::ZERO);
    let line = |pts: &mut Vec<Point>, a: kurbo::Point, b: kurbo::Point| {
        pts.extend_from_slice(&[fp(a), fp(a.lerp(b, 1.0 / 3.0)), fp(a.lerp(b, 2.0 / 3.0))]);
    };
    for el in path.elements() {
        match *el {
            PathEl::MoveTo(p) => {
                start = p;
                cur = p;
            }
            PathEl::LineTo(p) => {
                line(&mut pts, cur, p);
                cur = p;
            }
            PathEl::QuadTo(q, p) => {
                let c1 = cur + (q - cur) * (2.0 / 3.0);
                let c2 = p + (q - p) * (2.0 / 3.0);
                pts.extend_from_slice(&[fp(cur), fp(c1), fp(c2)]);
                cur = p;
            }
            PathEl::CurveTo(c1, c2, p) => {
                pts.extend_from_slice(&[fp(cur), fp(c1), fp(c2)]);
                cur = p;
            }
            PathEl::ClosePath => {
                if cur.distance(start) > 1e-9 {
                    line(&mut pts, cur, start);
                }
                cur = start;
            }
        }
    }
    pts
}

/// One simple piece from a simple ring: the cubic fit at `tolerance` if it is simple, else the
/// ring itself with straight segments.
pub(super) fn fit_piece(ring: &[P], template: &Shape, tolerance: f64) -> Option<Shape> {
    let make = |points: Vec<Point>| template.closed_cubic_like(points);
    let mut path = BezPath::new();
    path.move_to(kp(ring[0]));
    for &p in &ring[1..] {
        path.line_to(kp(p));
    }
    path.line_to(kp(ring[0]));
    path.close_path();
    let opts = kurbo::simplify::SimplifyOptions::default().angle_thresh(CORNER_TAN);
    let fit = kurbo::simplify::simplify_bezpath(path, tolerance, &opts);
    let pts = bez_cubic_points(&fit);
    if !pts.is_empty() && pts.iter().all(|p| p.x.is_finite() && p.y.is_finite()) {
        let s = make(snapped(pts));
        if piece_ok(&s) {
            return Some(s);
        }
    }
    let s = make(snapped(polygon_cubic_points(ring)));
    if piece_ok(&s) {
        return Some(s);
    }
    let s = make(polygon_cubic_points(ring));
    s.validate(0).is_ok().then_some(s)
}

/// Grid (px) the pieces' points are snapped to: the exporter's default precision (2
/// decimals), so that a piece verified simple stays simple as written.
const SNAP: f32 = 0.01;

pub(super) fn snapped(pts: Vec<Point>) -> Vec<Point> {
    let s = |v: f32| (v / SNAP).round() * SNAP;
    pts.into_iter()
        .map(|p| Point::new(s(p.x), s(p.y)))
        .collect()
}

/// A piece is accepted when it is valid, [`is_simple`], and simple at a tenth of
/// [`FLATTEN_TOLERANCE`] too: a fit may hide a loop smaller than the usual flattening (a
/// near-cusp handle), and a finer outside measure would see it.
pub(super) fn piece_ok(s: &Shape) -> bool {
    s.validate(0).is_ok()
        && is_simple(s)
        && ring_is_simple(&flatten_f64(s, 0.1 * FLATTEN_TOLERANCE as f64))
}

/// Simple polygons (rings) covering `shape`'s nonzero fill, flattened at `tolerance`.
fn simple_rings(shape: &Shape, tolerance: f64) -> Vec<Vec<P>> {
    let ring = dedup(&flatten_f64(shape, tolerance));
    if ring.len() < 3 {
        return Vec::new();
    }
    let contour: Vec<[f64; 2]> = ring.iter().map(|p| [p.0, p.1]).collect();
    let subj = vec![contour];
    let shapes = FloatOverlay::with_subj_custom(&subj, overlay_opts(), Default::default())
        .overlay(OverlayRule::Subject, FillRule::NonZero);
    cut_holes(shapes.into_iter().rev().collect())
}

/// The pieces of `shape`: simple closed cubic shapes with its fill and stroke whose union
/// (nonzero) covers its nonzero fill within about `tolerance` px (flattening and fitting each
/// use half of it); pieces of area under `min_area` px² are dropped. Open shapes and shapes
/// without a visible fill come back unchanged (one piece). Deterministic.
pub fn split_simple(shape: &Shape, tolerance: f32, min_area: f32) -> Vec<Shape> {
    if !shape.is_closed() || shape.fill.is_none_or(|f| f.a <= 0.0) {
        return vec![shape.clone()];
    }
    let tol = (tolerance as f64).max(1e-3);
    simple_rings(shape, 0.5 * tol)
        .into_iter()
        .filter(|r| r.len() >= 3 && ring_area(r).abs() >= min_area as f64)
        .filter_map(|r| fit_piece(&r, shape, 0.5 * tol))
        .collect()
}

/// Replaces every non-simple closed shape of `scene`, in place, by its [`split_simple`] pieces
/// (same place in the paint order, pieces consecutive). Returns how many shapes were replaced.
/// The scene stays valid and never grows past [`MAX_PATHS`] shapes: when it would, the
/// smallest new pieces are left out.
pub fn make_scene_simple(scene: &mut Scene, tolerance: f32, min_area: f32) -> usize {
    let mut repaired = 0usize;
    // For each shape: None = keep as is; Some(pieces) = replace.
    let mut plan: Vec<Option<Vec<Shape>>> = Vec::with_capacity(scene.shapes.len());
    for s in &scene.shapes {
        if is_simple(s) {
            plan.push(None);
        } else {
            repaired += 1;
            plan.push(Some(split_simple(s, tolerance, min_area)));
        }
    }
    if repaired == 0 {
        return 0;
    }
    let kept = plan.iter().filter(|p| p.is_none()).count();
    let budget = MAX_PATHS.saturating_sub(kept);
    let total: usize = plan.iter().flatten().map(Vec::len).sum();
    let mut keep_piece: Vec<Vec<bool>> = plan
        .iter()
        .map(|p| vec![true; p.as_ref().map_or(0, Vec::len)])
        .collect();
    if total > budget {
        let mut all: Vec<(f64, usize, usize)> = Vec::with_capacity(total);
        for (i, p) in plan.iter().enumerate() {
            for (j, s) in p.iter().flatten().enumerate() {
                all.push((ring_area(&flatten_f64(s, 0.25)).abs(), i, j));
            }
        }
        all.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
        for &(_, i, j) in &all[budget..] {
            keep_piece[i][j] = false;
        }
    }
    let old = std::mem::take(&mut scene.shapes);
    for ((s, p), keep) in old.into_iter().zip(plan).zip(keep_piece) {
        match p {
            None => scene.shapes.push(s),
            Some(pieces) => scene.shapes.extend(
                pieces
                    .into_iter()
                    .zip(keep)
                    .filter_map(|(piece, k)| k.then_some(piece)),
            ),
        }
    }
    repaired
}

#[cfg(test)]
#[path = "tests_simple.rs"]
mod tests;
