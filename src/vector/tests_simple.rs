//! Tests of [`super`]: detection, repair, and that the repair keeps the picture.

use super::*;
use crate::scene::{Rgba, Stroke};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

const RED: Rgba = Rgba::new(0.8, 0.1, 0.1, 1.0);

/// A closed cubic path through `pts` with straight handles.
fn straight(pts: &[(f32, f32)]) -> Shape {
    let ring: Vec<P> = pts.iter().map(|&(x, y)| (x as f64, y as f64)).collect();
    Shape::closed_cubic(polygon_cubic_points(&ring), RED).unwrap()
}

/// A figure-eight: two round lobes joined by a crossing, as one closed cubic path.
fn figure_eight() -> Shape {
    let p = |x: f32, y: f32| Point::new(x, y);
    let pts = vec![
        p(50.0, 50.0),
        p(70.0, 30.0),
        p(95.0, 30.0),
        p(95.0, 50.0),
        p(95.0, 70.0),
        p(70.0, 70.0),
        p(50.0, 50.0),
        p(30.0, 30.0),
        p(5.0, 30.0),
        p(5.0, 50.0),
        p(5.0, 70.0),
        p(30.0, 70.0),
    ];
    Shape::closed_cubic(pts, RED).unwrap()
}

/// A ring with a hole: the outer loop, a bridge in, the inner loop backwards, the bridge out
/// (how SVG imports keep holes). The bridge folds back on itself.
fn ring_with_hole() -> Shape {
    let outer = Shape::circle(50.0, 50.0, 40.0, 6, RED).unwrap();
    let inner = Shape::circle(50.0, 50.0, 15.0, 4, RED).unwrap();
    let mut pts = outer.points.clone();
    let (a, b) = (outer.points[0], inner.points[0]);
    let lerp = |t: f32| Point::new(a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t);
    pts.extend_from_slice(&[a, lerp(1.0 / 3.0), lerp(2.0 / 3.0)]);
    // Inner loop reversed: segments in reverse order with swapped handles.
    let n = inner.num_segments();
    for i in (0..n).rev() {
        let [p0, c1, c2, p3] = inner.segment(i);
        let _ = p0;
        pts.extend_from_slice(&[p3, c2, c1]);
    }
    let lerp2 = |t: f32| Point::new(b.x + (a.x - b.x) * t, b.y + (a.y - b.y) * t);
    pts.extend_from_slice(&[b, lerp2(1.0 / 3.0), lerp2(2.0 / 3.0)]);
    Shape::closed_cubic(pts, RED).unwrap()
}

fn scene_of(shapes: Vec<Shape>) -> Scene {
    let mut s = Scene::new(100, 100, Rgba::WHITE).unwrap();
    s.shapes = shapes;
    s.validate().unwrap();
    s
}

/// Bound on the mean squared RGB difference a repair at `tol` px may cause. A pixel changes
/// only by its change in coverage `dc` times the fill's contrast with white `k` per channel, so
/// `mse <= mean_k(k²) · sum(dc²) / (w h) <= mean_k(k²) · area(sym. diff.) / (w h)`; the fill
/// moves by at most `tol` along the outline (length `perimeter`), the dropped pieces add at
/// most `dropped` px² and the rasteriser's own flattening of both versions 2 × 0.05 px more.
fn mse_bound(shape: &Shape, tol: f32, dropped: f32, w: u32, h: u32) -> f64 {
    let ring = flatten_f64(shape, 0.01);
    let n = ring.len();
    let perimeter: f64 = (0..n).map(|i| dist(ring[i], ring[(i + 1) % n])).sum();
    let f = shape.fill.unwrap_or(Rgba::BLACK);
    let k2 = [f.r, f.g, f.b]
        .iter()
        .map(|c| ((1.0 - c) * f.a).powi(2) as f64)
        .sum::<f64>()
        / 3.0;
    k2 * (perimeter * (tol as f64 + 0.1) + dropped as f64) / (w as f64 * h as f64)
}

/// Fixed ceiling on the repair's mean squared error on these 100 × 100 scenes (PSNR 33 dB):
/// losing any real piece costs far more (a 10-px-radius disc of this red: 314 px² × 0.55 /
/// 10⁴ ≈ 1.7e-2), while the fits measured at most 1.2e-4 when this was written.
const MSE_CEILING: f64 = 5e-4;

fn check_repair(shape: &Shape, tol: f32, min_area: f32) -> (usize, f64, f64) {
    let before = scene_of(vec![shape.clone()]);
    let mut after = before.clone();
    let repaired = make_scene_simple(&mut after, tol, min_area);
    after.validate().unwrap();
    for (i, s) in after.shapes.iter().enumerate() {
        assert!(is_simple(s), "piece {i} is not simple: {:?}", s.points);
        assert_eq!(s.kind, ShapeKind::ClosedCubic);
        assert_eq!(s.fill, shape.fill);
    }
    let mse = crate::image::mse_rgb_over_white(
        &crate::raster::render(&before),
        &crate::raster::render(&after),
    );
    let bound = mse_bound(shape, tol, min_area * 8.0, 100, 100).min(MSE_CEILING);
    (repaired, mse, bound)
}

#[test]
fn circle_is_simple_and_untouched() {
    let c = Shape::circle(50.0, 50.0, 30.0, 4, RED).unwrap();
    assert!(is_simple(&c));
    let mut s = scene_of(vec![c.clone()]);
    assert_eq!(make_scene_simple(&mut s, 0.25, 0.5), 0);
    assert_eq!(s.shapes, vec![c]);
}

#[test]
fn open_and_unfilled_shapes_are_simple() {
    let st = Stroke::round(RED, 2.0);
    let p = |x, y| Point::new(x, y);
    let open = Shape::open_cubic(
        vec![p(0.0, 0.0), p(100.0, 100.0), p(100.0, 0.0), p(0.0, 100.0)],
        st,
    )
    .unwrap();
    assert!(is_simple(&open));
    let mut clear = figure_eight();
    clear.fill = Some(Rgba::TRANSPARENT);
    assert!(is_simple(&clear));
}

#[test]
fn duplicate_and_collinear_points_are_no_defect() {
    let sq = straight(&[
        (10.0, 10.0),
        (10.0, 10.0),
        (50.0, 10.0),
        (90.0, 10.0),
        (90.0, 90.0),
        (90.0, 90.0),
        (10.0, 90.0),
    ]);
    assert!(is_simple(&sq));
    assert_eq!(split_simple(&sq, 0.25, 0.5).len(), 1);
}

#[test]
fn figure_eight_is_detected_and_split() {
    let f = figure_eight();
    assert!(!is_simple(&f));
    let pieces = split_simple(&f, 0.25, 0.5);
    assert_eq!(pieces.len(), 2, "two lobes");
    let (n, mse, bound) = check_repair(&f, 0.25, 0.5);
    assert_eq!(n, 1);
    assert!(mse <= bound, "mse {mse} > {bound}");
}

#[test]
fn bowtie_touching_and_folds_are_not_simple() {
    // Bowtie: edges cross.
    assert!(!ring_is_simple(&[
        (0.0, 0.0),
        (10.0, 10.0),
        (10.0, 0.0),
        (0.0, 10.0)
    ]));
    // Touch: a vertex lies on a non-neighbouring edge.
    assert!(!ring_is_simple(&[
        (0.0, 0.0),
        (10.0, 0.0),
        (10.0, 10.0),
        (5.0, 0.0),
        (0.0, 10.0)
    ]));
    // A 180° fold (a spike of zero width) with nothing else wrong.
    assert!(!ring_is_simple(&[
        (0.0, 0.0),
        (10.0, 0.0),
        (10.0, 10.0),
        (10.0, 20.0),
        (10.0, 12.0),
        (0.0, 10.0)
    ]));
    // Collinear triangle (zero area) and too few points.
    assert!(!ring_is_simple(&[(0.0, 0.0), (5.0, 0.0), (10.0, 0.0)]));
    assert!(!ring_is_simple(&[(0.0, 0.0), (5.0, 0.0), (5.0, 0.0)]));
    // A sharp but real spike (1° wide) is simple.
    let t = 1f64.to_radians();
    assert!(ring_is_simple(&[
        (0.0, 0.0),
        (10.0, 0.0),
        (10.0 + 40.0 * t.cos(), 40.0 * t.sin()),
        (10.0, 1.0),
        (0.0, 10.0)
    ]));
}

#[test]
fn spike_is_detected_and_removed() {
    // A square whose top-right corner has a zero-width spike folded out and back.
    let s = straight(&[
        (10.0, 10.0),
        (60.0, 10.0),
        (80.0, 10.0),
        (60.0, 10.0),
        (60.0, 60.0),
        (10.0, 60.0),
    ]);
    assert!(!is_simple(&s));
    let pieces = split_simple(&s, 0.25, 0.5);
    assert_eq!(pieces.len(), 1);
    let (n, mse, bound) = check_repair(&s, 0.25, 0.5);
    assert_eq!(n, 1);
    assert!(mse <= bound, "mse {mse} > {bound}");
}

#[test]
fn hole_made_by_an_inner_loop_is_cut_into_simple_pieces() {
    let h = ring_with_hole();
    assert!(!is_simple(&h));
    let pieces = split_simple(&h, 0.25, 0.5);
    assert!(
        pieces.len() >= 2,
        "a ring needs at least two hole-free pieces"
    );
    let (n, mse, bound) = check_repair(&h, 0.25, 0.5);
    assert_eq!(n, 1);
    assert!(mse <= bound, "mse {mse} > {bound}");
    // The hole stays empty: its centre is background.
    let mut after = scene_of(vec![h]);
    make_scene_simple(&mut after, 0.25, 0.5);
    let img = crate::raster::render(&after);
    let c = img.pixel(50, 50);
    assert!(
        c[0] > 0.99 && c[1] > 0.99 && c[2] > 0.99,
        "hole centre {c:?}"
    );
}

#[test]
fn scene_order_is_kept_and_cap_respected() {
    let c = Shape::circle(20.0, 20.0, 10.0, 4, Rgba::BLACK).unwrap();
    let mut s = scene_of(vec![c.clone(), figure_eight(), c.clone()]);
    assert_eq!(make_scene_simple(&mut s, 0.25, 0.5), 1);
    assert_eq!(s.shapes.len(), 4);
    assert_eq!(s.shapes[0], c);
    assert_eq!(s.shapes[3], c);
    // At the cap, only the largest piece fits.
    let mut full = scene_of(vec![c.clone(); MAX_PATHS - 1]);
    full.shapes.push(figure_eight());
    assert_eq!(make_scene_simple(&mut full, 0.25, 0.5), 1);
    assert_eq!(full.shapes.len(), MAX_PATHS);
    full.validate().unwrap();
}

#[test]
fn deterministic() {
    let h = ring_with_hole();
    assert_eq!(split_simple(&h, 0.25, 0.5), split_simple(&h, 0.25, 0.5));
}

/// LIVE-like shapes: circles of 4-8 segments whose points were pushed around at random (as an
/// optimiser does), often into loops and crossings.
#[test]
fn random_deformed_circles_repair_to_simple_pieces() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut broken = 0;
    for case in 0..60 {
        let segs = 4 + (rng.random::<u32>() % 5) as usize;
        let r = 10.0 + 25.0 * rng.random::<f32>();
        let mut c = Shape::circle(50.0, 50.0, r, segs, RED).unwrap();
        let amp = r * (0.3 + 1.2 * rng.random::<f32>());
        for p in &mut c.points {
            p.x = (p.x + amp * (rng.random::<f32>() - 0.5) * 2.0).clamp(0.0, 100.0);
            p.y = (p.y + amp * (rng.random::<f32>() - 0.5) * 2.0).clamp(0.0, 100.0);
        }
        if !is_simple(&c) {
            broken += 1;
        }
        let (_, mse, bound) = check_repair(&c, 0.25, 0.5);
        assert!(mse <= bound, "case {case}: mse {mse} > {bound}");
    }
    assert!(
        broken >= 15,
        "only {broken} of 60 random shapes needed repair"
    );
}

#[test]
fn a_fold_of_a_segment_too_short_to_see_is_dropped_whole() {
    // Along the top edge: to x = 60, a 0.05 px step back, on to 80: a fold 0.05 px long.
    let s = straight(&[
        (10.0, 10.0),
        (60.0, 10.0),
        (59.95, 10.0),
        (80.0, 10.0),
        (80.0, 60.0),
        (10.0, 60.0),
    ]);
    assert!(!is_simple(&s));
    let t = crate::vector::without_tiny_segments(&s);
    assert_eq!(t.num_segments(), s.num_segments() - 1);
    assert!(is_simple(&t));
    // make_simple takes that one piece, the same shape less the step.
    let mut scene = scene_of(vec![s.clone()]);
    assert_eq!(crate::vector::make_simple(&mut scene, 0.5), 1);
    assert_eq!(scene.shapes, vec![t]);
    // A path with no such segment is left as it is.
    let sq = straight(&[(10.0, 10.0), (60.0, 10.0), (60.0, 60.0), (10.0, 60.0)]);
    assert_eq!(crate::vector::without_tiny_segments(&sq), sq);
}
