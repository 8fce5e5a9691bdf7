//! Pruning: drop paths whose removal barely changes the render, and find faint or tiny paths.

use crate::image::{Image, mse_rgb_over_white, sq_err_rgb_over_white};
use crate::losses::{outline, polygon_area};
use crate::scene::Scene;

/// Removes, one at a time from the top of the stack down, every path whose removal changes the
/// render by less than `tolerance` (mean squared RGB difference over white). Returns the indices
/// (in the original scene) of the removed paths, ascending.
///
/// A flat scene's trials render only the row bands a path can change
/// ([`crate::raster::render_rows`]); the pixels elsewhere are equal and add nothing to the
/// difference, so every decision is the whole render's.
pub fn prune_paths(scene: &mut Scene, tolerance: f64) -> Vec<usize> {
    let mut current = crate::raster::render(scene);
    let pixels = 3.0 * current.len_pixels() as f64;
    let row = 4 * scene.width as usize;
    // Top-down, path `i` is tried after only paths above it went: the rows below stay valid.
    let rows = crate::raster::shape_rows(scene);
    let mut alive: Vec<usize> = (0..scene.shapes.len()).collect();
    let mut removed = Vec::new();
    let mut i = scene.shapes.len();
    while i > 0 {
        i -= 1;
        let (trial, start, img) = crate::vector::without_shape(scene, i, rows[i].clone());
        let at = start as usize * row;
        let was = &mut current.data[at..at + img.len()];
        if sq_err_rgb_over_white(&img, was) / pixels < tolerance {
            was.copy_from_slice(&img);
            *scene = trial;
            removed.push(alive.remove(i));
        }
    }
    removed.sort_unstable();
    removed
}

/// Removes the paths whose removal costs least (MSE against `target`, over white) until
/// `bytes(scene)` is at most `max` or one path is left (an empty picture is no answer: the path
/// whose removal would cost most stays, even over the budget). Each round ranks every path once
/// and removes as many of the cheapest as the excess asks for at the scene's mean bytes per
/// path (at least one). Returns how many paths were removed.
pub fn trim_to_bytes(
    scene: &mut Scene,
    target: &Image,
    max: usize,
    bytes: impl Fn(&Scene) -> usize,
) -> usize {
    let mut removed = 0;
    loop {
        let size = bytes(scene);
        let n = scene.shapes.len();
        if size <= max || n <= 1 {
            return removed;
        }
        let mut cost: Vec<(f64, usize)> = (0..n)
            .map(|i| {
                let mut trial = scene.clone();
                trial.shapes.remove(i);
                let m = mse_rgb_over_white(&crate::raster::render(&trial), target);
                (m, i)
            })
            .collect();
        cost.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let per_path = (size / n).max(1);
        let k = (size - max).div_ceil(per_path).clamp(1, n - 1);
        let mut drop: Vec<usize> = cost[..k].iter().map(|c| c.1).collect();
        drop.sort_unstable();
        for &i in drop.iter().rev() {
            scene.shapes.remove(i);
        }
        removed += k;
    }
}

/// Indices of paths that are faint (fill opacity below `min_opacity`) or tiny (outline area
/// below `min_area` square pixels): candidates for re-initialisation.
pub fn weak_paths(scene: &Scene, min_opacity: f32, min_area: f32) -> Vec<usize> {
    scene
        .shapes
        .iter()
        .enumerate()
        .filter(|(_, s)| {
            let faint = s.fill.is_none_or(|f| f.a < min_opacity);
            let area = polygon_area(&outline(s, 8)).abs();
            faint || area < min_area
        })
        .map(|(i, _)| i)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Rgba, Shape};

    /// Coverage-free "renderer" for the test: paints each square's bounding box.
    fn boxes(scene: &Scene) -> Image {
        let mut im = Image::filled(scene.width, scene.height, [1.0, 1.0, 1.0, 1.0]);
        for s in &scene.shapes {
            let (lo, hi) = s.control_bounds();
            let f = s.fill.unwrap_or(Rgba::TRANSPARENT);
            for y in lo.y.max(0.0) as u32..(hi.y as u32).min(scene.height) {
                for x in lo.x.max(0.0) as u32..(hi.x as u32).min(scene.width) {
                    let i = 4 * (y * scene.width + x) as usize;
                    for c in 0..3 {
                        let v = [f.r, f.g, f.b][c];
                        im.data[i + c] = im.data[i + c] * (1.0 - f.a) + v * f.a;
                    }
                }
            }
        }
        im
    }

    #[test]
    fn prune_removes_hidden_and_invisible_paths_only() {
        let mut scene = Scene::new(32, 32, Rgba::WHITE).unwrap();
        let red = Rgba::new(1.0, 0.0, 0.0, 1.0);
        // 0: hidden under 2; 1: visible; 2: covers 0; 3: white on white.
        scene
            .shapes
            .push(Shape::square(4.0, 4.0, 4.0, Rgba::BLACK).unwrap());
        scene
            .shapes
            .push(Shape::square(20.0, 20.0, 8.0, red).unwrap());
        scene
            .shapes
            .push(Shape::square(2.0, 2.0, 10.0, red).unwrap());
        scene
            .shapes
            .push(Shape::square(14.0, 2.0, 6.0, Rgba::WHITE).unwrap());
        let before = crate::raster::render(&scene);
        let removed = prune_paths(&mut scene, 1e-6);
        assert_eq!(removed, vec![0, 3]);
        assert_eq!(scene.shapes.len(), 2);
        assert!(mse_rgb_over_white(&crate::raster::render(&scene), &before) < 1e-6);
        // A large tolerance removes everything small enough.
        let mut s2 = scene.clone();
        let removed = prune_paths(&mut s2, 1.0);
        assert_eq!(removed.len(), 2);
    }

    /// [`prune_paths`]'s rule with a whole render per trial.
    fn prune_whole(scene: &mut Scene, tolerance: f64) -> usize {
        crate::vector::remove_by_whole_renders(scene, |img, current| {
            mse_rgb_over_white(img, current) < tolerance
        })
    }

    #[test]
    fn pruning_decides_as_whole_renders_do() {
        use rand::{RngExt, SeedableRng};
        for seed in 0..6u64 {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let mut s = Scene::new(96, 80, Rgba::WHITE).unwrap();
            for _ in 0..16 {
                let (x, y) = (rng.random_range(-10.0..90.0), rng.random_range(-10.0..75.0));
                let c = Rgba::new(rng.random(), rng.random(), rng.random(), 1.0);
                let r = rng.random_range(0.5..20.0);
                s.shapes.push(Shape::circle(x, y, r, 4, c).unwrap());
            }
            for tol in [1e-6, 2e-5, 1e-3] {
                let (mut a, mut b) = (s.clone(), s.clone());
                let removed = prune_paths(&mut a, tol);
                assert_eq!(
                    removed.len(),
                    prune_whole(&mut b, tol),
                    "seed {seed} tol {tol}"
                );
                assert_eq!(a, b, "seed {seed} tol {tol}");
                assert!(
                    tol < 1e-3 || !removed.is_empty(),
                    "seed {seed}: nothing pruned"
                );
            }
        }
    }

    #[test]
    fn trim_keeps_the_most_valuable_path_when_none_fits() {
        let mut scene = Scene::new(32, 32, Rgba::WHITE).unwrap();
        scene
            .shapes
            .push(Shape::square(2.0, 2.0, 4.0, Rgba::BLACK).unwrap());
        scene
            .shapes
            .push(Shape::square(10.0, 10.0, 16.0, Rgba::BLACK).unwrap());
        scene
            .shapes
            .push(Shape::square(20.0, 2.0, 6.0, Rgba::BLACK).unwrap());
        let target = boxes(&scene);
        let bytes = |s: &Scene| 100 * s.shapes.len();
        // Within budget: nothing goes; two fit: the smallest square goes.
        assert_eq!(trim_to_bytes(&mut scene.clone(), &target, 300, bytes), 0);
        let mut s = scene.clone();
        assert_eq!(trim_to_bytes(&mut s, &target, 200, bytes), 1);
        assert_eq!(s.shapes.len(), 2);
        // No path fits: the largest square stays.
        let mut s = scene.clone();
        assert_eq!(trim_to_bytes(&mut s, &target, 10, bytes), 2);
        assert_eq!(s.shapes.len(), 1);
        assert_eq!(s.shapes[0].control_bounds().0.x, 10.0);
    }

    #[test]
    fn weak_paths_finds_faint_and_tiny() {
        let mut scene = Scene::new(64, 64, Rgba::WHITE).unwrap();
        scene
            .shapes
            .push(Shape::circle(20.0, 20.0, 10.0, 4, Rgba::BLACK).unwrap());
        scene
            .shapes
            .push(Shape::circle(40.0, 40.0, 10.0, 4, Rgba::new(0.0, 0.0, 0.0, 0.01)).unwrap());
        scene
            .shapes
            .push(Shape::circle(10.0, 50.0, 3.0, 4, Rgba::BLACK).unwrap());
        assert_eq!(weak_paths(&scene, 0.05, 64.0), vec![1, 2]);
    }
}
