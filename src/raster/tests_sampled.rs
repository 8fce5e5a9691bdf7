//! Supersampled anti-aliasing: coverage is the share of 16 sample points inside, counted as a
//! brute-force point-in-polygon test counts them.
use super::*;
use crate::scene::{FillRule, Rgba};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Winding number of the closed polygon `poly` around `(x, y)`.
fn winding(poly: &[[f32; 2]], x: f32, y: f32) -> i32 {
    let mut w = 0;
    for (i, a) in poly.iter().enumerate() {
        let b = poly[(i + 1) % poly.len()];
        let side = (b[0] - a[0]) * (y - a[1]) - (x - a[0]) * (b[1] - a[1]);
        if a[1] <= y && b[1] > y && side > 0.0 {
            w += 1;
        } else if a[1] > y && b[1] <= y && side < 0.0 {
            w -= 1;
        }
    }
    w
}

/// Whether segment `a`–`b` meets the pixel square at `(px, py)` (Liang–Barsky clipping).
fn meets(a: [f32; 2], b: [f32; 2], px: f32, py: f32) -> bool {
    let (mut t0, mut t1) = (0.0f32, 1.0f32);
    for c in 0..2 {
        let (lo, hi) = if c == 0 {
            (px, px + 1.0)
        } else {
            (py, py + 1.0)
        };
        let d = b[c] - a[c];
        if d == 0.0 {
            if a[c] < lo || a[c] > hi {
                return false;
            }
            continue;
        }
        let (ta, tb) = ((lo - a[c]) / d, (hi - a[c]) / d);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    t0 <= t1
}

#[test]
fn supersampled_coverage_is_the_share_of_sixteen_samples_inside() {
    for (seed, rule) in [
        (1, FillRule::NonZero),
        (2, FillRule::EvenOdd),
        (3, FillRule::NonZero),
    ] {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        // A self-intersecting star: winding numbers 0, 1 and 2.
        let poly: Vec<[f32; 2]> = (0..7)
            .map(|k| {
                let a = k as f32 * 3.0 * std::f32::consts::TAU / 7.0 + rng.random_range(0.0..0.3);
                let r = rng.random_range(7.0..9.5);
                [10.3 + r * a.cos(), 10.1 + r * a.sin()]
            })
            .collect();
        let points = poly.iter().map(|p| Point::new(p[0], p[1])).collect();
        let mut shape = Shape::polygon(points, Rgba::new(0.0, 0.0, 0.0, 1.0)).unwrap();
        shape.fill_rule = rule;
        let mut scene = Scene::new(21, 21, Rgba::TRANSPARENT).unwrap();
        scene.shapes.push(shape);
        let im = render_with(&scene, Antialias::Supersampled);
        for py in 0..21u32 {
            for px in 0..21u32 {
                // Samples at the sub-cell centres, a tie on an edge counted as Skia counts it.
                let mut inside = 0;
                for (i, j) in (0..4).flat_map(|i| (0..4).map(move |j| (i, j))) {
                    let x = px as f32 + (j as f32 + 0.5) / 4.0 - 1.0 / 256.0;
                    let y = py as f32 + (i as f32 + 0.5) / 4.0 - 1.0 / 256.0;
                    let w = winding(&poly, x, y);
                    inside += match rule {
                        FillRule::NonZero => w != 0,
                        FillRule::EvenOdd => w % 2 != 0,
                    } as u32;
                }
                let want = inside as f32 / 16.0;
                let got = im.pixel(px, py)[3];
                // Where two edges meet in the pixel (a vertex, a crossing), a sub-cell they
                // both cross may have its centre on its smaller part: a sample off there.
                let edges = (0..poly.len())
                    .filter(|&i| meets(poly[i], poly[(i + 1) % poly.len()], px as f32, py as f32))
                    .count();
                let tol = if edges >= 2 { 2.0 / 16.0 + 1e-5 } else { 1e-5 };
                assert!(
                    (got - want).abs() <= tol,
                    "seed {seed} pixel ({px}, {py}): {got} vs {want} samples inside"
                );
            }
        }
    }
}

#[test]
fn an_edge_between_quarter_pixels_is_drawn_on_the_nearer_one() {
    // Samples sit at k/4 + 1/8: a left edge at x = 2.3 leaves 2.375, 2.625 and 2.875 inside
    // (exact coverage: 0.7).
    let mut scene = Scene::new(8, 8, Rgba::TRANSPARENT).unwrap();
    scene
        .shapes
        .push(Shape::square(2.3, 2.0, 4.0, Rgba::new(0.0, 0.0, 0.0, 1.0)).unwrap());
    let exact = render(&scene);
    let sampled = render_with(&scene, Antialias::Supersampled);
    assert!((exact.pixel(2, 3)[3] - 0.7).abs() < 1e-5);
    assert!((sampled.pixel(2, 3)[3] - 0.75).abs() < 1e-6);
    // The right edge at 6.3 covers the sample at 6.125 only.
    assert!((sampled.pixel(6, 3)[3] - 0.25).abs() < 1e-6);
    assert_eq!(sampled.pixel(4, 4)[3], 1.0);
    // A sample exactly on an edge: inside on the right edge, outside on the left one.
    let mut tie = Scene::new(8, 8, Rgba::TRANSPARENT).unwrap();
    tie.shapes
        .push(Shape::square(1.875, 1.0, 3.75, Rgba::new(0.0, 0.0, 0.0, 1.0)).unwrap());
    let t = render_with(&tie, Antialias::Supersampled);
    assert!((t.pixel(1, 2)[3] - 0.0).abs() < 1e-6, "{:?}", t.pixel(1, 2));
    assert!(
        (t.pixel(5, 2)[3] - 0.75).abs() < 1e-6,
        "{:?}",
        t.pixel(5, 2)
    );
}

#[test]
fn the_backward_pass_keeps_exact_coverage() {
    // render_tape (optimisation) is exact whatever a forward-only render used.
    let scene = super::tests::random_scene(5);
    let (img, _) = render_tape(&scene);
    assert_eq!(img.data, render(&scene).data);
    assert_ne!(img.data, render_with(&scene, Antialias::Supersampled).data);
}
