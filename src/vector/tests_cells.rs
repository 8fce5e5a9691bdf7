//! Tests of [`super`]: pixel-art cells become one simple outline per region, the picture
//! stays, and scenes that are not a grid of cells are left alone.

use super::*;
use crate::vector::check::check;
use crate::vector::export::diff;
use rand::{RngExt, SeedableRng};

const RED: Rgba = Rgba::new(0.8, 0.1, 0.1, 1.0);
const BLUE: Rgba = Rgba::new(0.1, 0.2, 0.9, 1.0);
const PALETTE: [Rgba; 4] = [
    RED,
    BLUE,
    Rgba::new(0.95, 0.85, 0.2, 1.0),
    Rgba::new(0.2, 0.7, 0.3, 0.6),
];

/// A `n × n` grid of `cell` px squares, colour `colour(x, y)` each (`None`: no cell there),
/// drawn row by row as the pixel-art style draws it.
fn grid(n: i32, cell: f32, colour: impl Fn(i32, i32) -> Option<Rgba>) -> Scene {
    let side = (n as f32 * cell).ceil() as u32;
    let mut s = Scene::new(side, side, Rgba::WHITE).unwrap();
    for y in 0..n {
        for x in 0..n {
            if let Some(c) = colour(x, y) {
                let sq = Shape::square(x as f32 * cell, y as f32 * cell, cell, c).unwrap();
                s.shapes.push(sq);
            }
        }
    }
    s
}

/// Merges `s` and checks that the render stays within `max` (0..=1) and that every outline is
/// simple; returns the merged scene.
fn merged_within(mut s: Scene, max: f64) -> Scene {
    let before = crate::raster::render(&s);
    let n = s.shapes.len();
    let removed = merge_cells(&mut s);
    assert_eq!(n - removed, s.shapes.len());
    let (mean, worst) = diff(&before, &crate::raster::render(&s));
    assert!(worst <= max, "mean {mean} max {worst}");
    let ed = check(&s);
    assert_eq!(ed.self_intersecting, 0, "{ed:?}");
    s
}

#[test]
fn random_pixel_art_becomes_one_outline_per_region_and_draws_the_same() {
    for seed in 0..6 {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        // Blobs: each cell repeats its left or upper neighbour's colour most of the time.
        let n = 16;
        let mut colours = vec![0usize; (n * n) as usize];
        for y in 0..n {
            for x in 0..n {
                let i = (y * n + x) as usize;
                colours[i] = match rng.random_range(0..10) {
                    0..4 if x > 0 => colours[i - 1],
                    4..8 if y > 0 => colours[i - n as usize],
                    _ => rng.random_range(0..PALETTE.len()),
                };
            }
        }
        let s = grid(n, 4.0, |x, y| Some(PALETTE[colours[(y * n + x) as usize]]));
        let cells = s.shapes.len();
        // On whole pixels, separate squares and merged outlines draw alike (to f32 rounding).
        let m = merged_within(s, 1e-5);
        assert!(
            m.shapes.len() * 3 < cells,
            "seed {seed}: {} of {cells}",
            m.shapes.len()
        );
        assert!(m.shapes.iter().all(|s| s.kind == ShapeKind::Polygon));
    }
}

#[test]
fn two_colour_noise_with_corners_and_holes_everywhere_stays_simple_and_the_same() {
    for seed in 0..8 {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(100 + seed);
        let n = 12;
        let bits: Vec<bool> = (0..n * n).map(|_| rng.random_bool(0.5)).collect();
        let s = grid(n, 2.0, |x, y| {
            Some(if bits[(y * n + x) as usize] {
                RED
            } else {
                BLUE
            })
        });
        merged_within(s, 1e-5);
    }
}

#[test]
fn a_ring_fills_its_hole_and_the_region_inside_is_painted_after_it() {
    // A blue ring around a red 2×2 centre, on 6×6 cells.
    let s = grid(6, 4.0, |x, y| {
        Some(if (2..4).contains(&x) && (2..4).contains(&y) {
            RED
        } else {
            BLUE
        })
    });
    let m = merged_within(s, 1e-6);
    assert_eq!(m.shapes.len(), 2);
    assert_eq!(m.shapes[0].fill, Some(BLUE));
    assert_eq!(m.shapes[0].points.len(), 4, "the ring's outer square");
    assert_eq!(m.shapes[1].fill, Some(RED));
}

#[test]
fn a_region_touching_itself_at_a_corner_is_written_as_simple_outlines() {
    // Red cells on a diagonal touch only at corners; a red L joined to them through cells
    // that make one region that touches itself at (2, 2).
    let red = [
        (0, 0),
        (1, 0),
        (1, 1),
        (2, 2),
        (3, 2),
        (3, 1),
        (3, 0),
        (2, 0),
    ];
    let s = grid(4, 4.0, |x, y| {
        Some(if red.contains(&(x, y)) { RED } else { BLUE })
    });
    merged_within(s, 1e-6);
}

#[test]
fn a_hole_nothing_opaque_hides_makes_its_region_rectangles() {
    // A blue ring around an empty place: filling its outline would paint the hole. Top row,
    // the two sides, bottom row.
    let s = grid(3, 4.0, |x, y| (x != 1 || y != 1).then_some(BLUE));
    let m = merged_within(s, 1e-6);
    assert_eq!(m.shapes.len(), 4);
    // Around a translucent cell the same: the ring's fill would show through it.
    let glass = Rgba::new(0.2, 0.7, 0.3, 0.6);
    let s = grid(5, 4.0, |x, y| {
        Some(if (x, y) == (2, 2) { glass } else { BLUE })
    });
    let m = merged_within(s, 1e-5);
    // Rows 0-1 whole, row 2 left and right of the glass, rows 3-4 whole; and the glass.
    assert_eq!(m.shapes.len(), 5);
}

#[test]
fn off_pixel_cells_lose_their_seams_and_nothing_else() {
    // 3.3 px cells: squares of one colour side by side leave seams where their anti-aliased
    // edges meet; the merged outline draws as one square of the whole grid would.
    let s = grid(8, 3.3, |_, _| Some(RED));
    let mut whole = s.clone();
    whole.shapes = vec![Shape::square(0.0, 0.0, 8.0 * 3.3, RED).unwrap()];
    let seams = diff(&crate::raster::render(&s), &crate::raster::render(&whole)).1;
    assert!(seams > 0.1, "{seams}");
    let m = merged_within(s, 1.0);
    assert_eq!(m.shapes.len(), 1);
    let left = diff(&crate::raster::render(&m), &crate::raster::render(&whole)).1;
    assert!(left < 1e-6, "{left}");
}

#[test]
fn scenes_that_are_not_a_grid_of_cells_are_left_alone() {
    let mut circles = Scene::new(32, 32, Rgba::WHITE).unwrap();
    circles.shapes = vec![
        Shape::circle(10.0, 10.0, 5.0, 4, RED).unwrap(),
        Shape::circle(14.0, 10.0, 5.0, 4, RED).unwrap(),
    ];
    let mut mixed = grid(4, 4.0, |_, _| Some(RED));
    mixed
        .shapes
        .push(Shape::circle(8.0, 8.0, 3.0, 4, BLUE).unwrap());
    let mut unaligned = grid(2, 4.0, |_, _| Some(RED));
    unaligned.shapes[1] = Shape::square(4.5, 0.0, 4.0, RED).unwrap();
    let mut stacked = grid(2, 4.0, |_, _| Some(RED));
    stacked
        .shapes
        .push(Shape::square(0.0, 0.0, 4.0, BLUE).unwrap());
    for mut s in [circles, mixed, unaligned, stacked] {
        let before = s.clone();
        assert_eq!(merge_cells(&mut s), 0);
        assert_eq!(s, before);
    }
}
