//! Tests of [`super`]: what is cut, the pieces' shapes, and that the picture stays.

use super::*;
use crate::scene::{Point, Rgba};

const RED: Rgba = Rgba::new(0.8, 0.1, 0.1, 1.0);

/// A closed cubic outline of straight segments through `xy`.
fn outline(xy: &[(f32, f32)]) -> Shape {
    let v = Point::list(xy);
    let mut points = Vec::new();
    for i in 0..v.len() {
        let (a, b) = (v[i], v[(i + 1) % v.len()]);
        let [c1, c2] = Point::line_controls(a, b);
        points.extend([a, c1, c2]);
    }
    Shape::closed_cubic(points, RED).unwrap()
}

fn scene(w: u32, h: u32, shapes: Vec<Shape>) -> Scene {
    let mut s = Scene::new(w, h, Rgba::WHITE).unwrap();
    s.shapes = shapes;
    s
}

/// Whether the outline (not its handles) lies on the `w × h` canvas.
fn on_canvas(s: &Shape, w: f32, h: f32) -> bool {
    let e = 1e-3;
    flatten_f64(s, 0.01)
        .iter()
        .all(|p| (-e..=w as f64 + e).contains(&p.0) && (-e..=h as f64 + e).contains(&p.1))
}

fn area(s: &Shape) -> f64 {
    ring_area(&flatten_f64(s, 0.01)).abs()
}

/// Cuts `s` to its canvas and checks what every cut must hold: every outline on the canvas,
/// every piece simple, the render the same: but for the flattening of the cut curves (the
/// rasteriser flattens a cubic split in two along other points) and a piece under
/// `MIN_PIECE_AREA` dropped (at most that share of a pixel). Returns the scene after.
fn cut_checked(mut s: Scene) -> Scene {
    let before = crate::raster::render(&s);
    cut_scene_to_canvas(&mut s);
    let (w, h) = (s.width as f32, s.height as f32);
    for sh in &s.shapes {
        assert!(on_canvas(sh, w, h), "{:?}", sh.points);
        assert!(is_simple(sh));
    }
    let (mean, max) = super::super::export::diff(&before, &crate::raster::render(&s));
    assert!(
        mean < 1e-4 && max < MIN_PIECE_AREA,
        "render changed: mean {mean} max {max}"
    );
    s
}

#[test]
fn a_circle_past_an_edge_keeps_its_arc_and_gains_the_edge() {
    let c = Shape::circle(28.0, 16.0, 8.0, 4, RED).unwrap();
    let s = cut_checked(scene(32, 32, vec![c.clone()]));
    assert_eq!(s.shapes.len(), 1);
    // The part on the canvas: the circle's left 5/8 (a segment of the disk).
    let full = area(&c);
    let got = area(&s.shapes[0]);
    let r: f64 = 8.0;
    let d: f64 = 4.0; // the edge lies 4 px right of the centre
    let cap = r * r * (d / r).acos() - d * (r * r - d * d).sqrt();
    assert!(
        (got - (full - cap)).abs() < 0.05 * full,
        "{got} vs {}",
        full - cap
    );
    // Points on the right edge: the cut runs along x = 32.
    assert!(s.shapes[0].points.iter().any(|p| p.x == 32.0));
}

#[test]
fn a_corner_is_walked_round() {
    // A square over the top-right corner: what is left is the corner's square.
    let sq = outline(&[(24.0, -8.0), (40.0, -8.0), (40.0, 8.0), (24.0, 8.0)]);
    let s = cut_checked(scene(32, 32, vec![sq]));
    assert_eq!(s.shapes.len(), 1);
    assert!((area(&s.shapes[0]) - 64.0).abs() < 1e-3);
    assert!(s.shapes[0].points.contains(&Point::new(32.0, 0.0)));
}

#[test]
fn an_arch_leaves_two_legs_in_paint_order() {
    // Π: the bar above the canvas, the legs on it; both orientations give the same pieces.
    let xy = [
        (2.0, -5.0),
        (8.0, -5.0),
        (8.0, 6.0),
        (6.0, 6.0),
        (6.0, -2.0),
        (4.0, -2.0),
        (4.0, 6.0),
        (2.0, 6.0),
    ];
    let mut rev = xy;
    rev.reverse();
    for pts in [xy, rev] {
        let under = Shape::square(0.0, 0.0, 3.0, Rgba::BLACK).unwrap();
        let over = Shape::square(5.0, 5.0, 4.0, Rgba::BLACK).unwrap();
        let s = cut_checked(scene(10, 10, vec![under, outline(&pts), over]));
        assert_eq!(s.shapes.len(), 4);
        let areas: Vec<f64> = s.shapes[1..3].iter().map(area).collect();
        assert!(areas.iter().all(|a| (a - 12.0).abs() < 1e-3), "{areas:?}");
        assert_eq!(s.shapes[0].fill, Some(Rgba::BLACK));
        assert_eq!(s.shapes[3].fill, Some(Rgba::BLACK));
    }
}

#[test]
fn around_the_canvas_is_the_canvas_and_off_it_is_nothing() {
    let around = Shape::circle(16.0, 16.0, 40.0, 4, RED).unwrap();
    let off = Shape::circle(60.0, 16.0, 8.0, 4, RED).unwrap();
    let pieces = cut_to_canvas(&around, 32, 32).unwrap();
    assert_eq!(pieces.len(), 1);
    assert!((area(&pieces[0]) - 1024.0).abs() < 1e-3);
    assert_eq!(cut_to_canvas(&off, 32, 32), Some(Vec::new()));
    cut_checked(scene(32, 32, vec![around]));
}

#[test]
fn what_lies_on_the_canvas_or_is_not_cut_stays() {
    // Handles past the edge, the curve itself on the canvas.
    let bulge = Shape::closed_cubic(
        Point::list(&[
            (4.0, 4.0),
            (4.0, 4.0),
            (40.0, 10.0),
            (28.0, 28.0),
            (28.0, 28.0),
            (4.0, 28.0),
        ]),
        RED,
    )
    .unwrap();
    assert!(bulge.control_bounds().1.x > 32.0);
    assert_eq!(cut_to_canvas(&bulge, 32, 32), None);
    // Stroked outlines keep their geometry (the stroke would show along the cut), and so do
    // textured ones (a piece each would write the pixels again).
    let mut stroked = Shape::circle(30.0, 16.0, 8.0, 4, RED).unwrap();
    stroked.stroke = Some(crate::scene::Stroke::round(Rgba::BLACK, 1.0));
    assert_eq!(cut_to_canvas(&stroked, 32, 32), None);
    let mut textured = Shape::circle(30.0, 16.0, 8.0, 4, RED).unwrap();
    textured.gradients = Some(Box::new(crate::scene::Gradients {
        texture: Some(Box::new(crate::scene::Texture {
            width: 1,
            height: 1,
            pixels: vec![200, 20, 20, 255],
            transform: crate::scene::Affine([32.0, 0.0, 0.0, 32.0, 0.0, 0.0]),
            edge: Default::default(),
            filter: crate::scene::TextureFilter::Nearest,
        })),
        ..Default::default()
    }));
    assert_eq!(cut_to_canvas(&textured, 32, 32), None);
    let inside = Shape::circle(16.0, 16.0, 8.0, 4, RED).unwrap();
    assert_eq!(cut_to_canvas(&inside, 32, 32), None);
}

#[test]
fn random_circles_round_the_edges_are_cut_exactly() {
    for seed in 0..8 {
        random_circles(seed);
    }
}

fn random_circles(seed: u64) {
    use rand::{RngExt, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut shapes = Vec::new();
    for _ in 0..40 {
        let (x, y) = (rng.random_range(-10.0..74.0), rng.random_range(-10.0..74.0));
        let r = rng.random_range(3.0..20.0);
        let c = Rgba::new(rng.random(), rng.random(), rng.random(), 1.0);
        let mut sh = Shape::circle(x, y, r, 4, c).unwrap();
        // Wobble the control points so the outlines are not all circles.
        for p in &mut sh.points {
            p.x += rng.random_range(-2.0..2.0);
            p.y += rng.random_range(-2.0..2.0);
        }
        if is_simple(&sh) {
            shapes.push(sh);
        }
    }
    let n = shapes.len();
    let s = scene(64, 64, shapes);
    let past = s
        .shapes
        .iter()
        .filter(|sh| !on_canvas(sh, 64.0, 64.0))
        .count();
    assert!(past > 10, "{past} of {n} reach past an edge");
    let s = cut_checked(s);
    assert!(s.shapes.iter().all(|sh| on_canvas(sh, 64.0, 64.0)));
}

#[test]
fn a_gradient_fill_is_kept_by_every_piece_and_paints_as_before() {
    use crate::scene::{Affine, Gradient, GradientGeometry, GradientStop, Gradients, Spread};
    let stop = |offset, color| GradientStop { offset, color };
    let paint = Gradient {
        geometry: GradientGeometry::Linear {
            x1: 4.0,
            y1: 2.0,
            x2: 30.0,
            y2: 28.0,
        },
        transform: Affine([1.1, 0.3, -0.2, 0.9, 1.5, -2.0]),
        spread: Spread::Reflect,
        stops: vec![
            stop(0.1, Rgba::new(1.0, 0.6, 0.0, 1.0)),
            stop(0.8, Rgba::new(0.1, 0.2, 0.9, 0.7)),
        ],
    };
    // A U whose bottom bar lies below the canvas: its legs are two pieces on it.
    let mut u = outline(&[
        (4.0, 2.0),
        (10.0, 2.0),
        (10.0, 34.0),
        (22.0, 34.0),
        (22.0, 2.0),
        (28.0, 2.0),
        (28.0, 40.0),
        (4.0, 40.0),
    ]);
    u.gradients = Some(Box::new(Gradients {
        fill: Some(paint.clone()),
        ..Default::default()
    }));
    let s = cut_checked(scene(32, 32, vec![u]));
    assert_eq!(s.shapes.len(), 2);
    for sh in &s.shapes {
        assert_eq!(
            sh.gradients.as_ref().and_then(|g| g.fill.as_ref()),
            Some(&paint)
        );
    }
}
