//! Tests of the finish in [`super`]: hidden paths, outlines cut to the canvas.

use super::*;
use crate::scene::{Rgba, Scene, Shape};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// [`drop_hidden`]'s rule with a whole render per trial.
fn drop_hidden_whole(scene: &mut Scene) -> usize {
    remove_by_whole_renders(scene, |img, current| {
        img.data
            .iter()
            .zip(&current.data)
            .all(|(a, b)| (a - b).abs() <= check::VISIBLE_STEP)
    })
}

fn opaque(rng: &mut ChaCha8Rng) -> Rgba {
    Rgba::new(
        rng.random_range(0.0..1.0),
        rng.random_range(0.0..1.0),
        rng.random_range(0.0..1.0),
        1.0,
    )
}

#[test]
fn hidden_paths_go_as_whole_renders_decide() {
    let red = Rgba::new(0.9, 0.1, 0.1, 1.0);
    for seed in 0..6u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut s = Scene::new(96, 80, Rgba::new(1.0, 1.0, 1.0, 1.0)).unwrap();
        // Under a cover: a square painted over later, one of the cover's colour painted on it.
        s.shapes
            .push(Shape::square(20.0, 30.0, 12.0, opaque(&mut rng)).unwrap());
        s.shapes.push(Shape::square(10.0, 20.0, 40.0, red).unwrap());
        s.shapes.push(Shape::square(22.5, 31.5, 8.0, red).unwrap());
        for _ in 0..10 {
            let (x, y) = (rng.random_range(-10.0..90.0), rng.random_range(-10.0..75.0));
            let r = rng.random_range(1.0..20.0);
            let segs = 4;
            s.shapes
                .push(Shape::circle(x, y, r, segs, opaque(&mut rng)).unwrap());
        }
        let (mut a, mut b) = (s.clone(), s.clone());
        let removed = drop_hidden(&mut a);
        assert_eq!(removed, drop_hidden_whole(&mut b), "seed {seed}");
        assert_eq!(a, b, "seed {seed}");
        // At least the two covered squares (and any random circle hidden by chance).
        assert!(removed >= 2, "seed {seed}: {removed}");
        assert_eq!(crate::raster::render(&a), crate::raster::render(&b));
    }
}

#[test]
fn the_finish_leaves_no_outline_past_the_canvas() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut s = Scene::new(64, 48, Rgba::WHITE).unwrap();
    for _ in 0..16 {
        let (x, y) = (rng.random_range(-8.0..72.0), rng.random_range(-8.0..56.0));
        let r = rng.random_range(4.0..16.0);
        s.shapes
            .push(Shape::circle(x, y, r, 4, opaque(&mut rng)).unwrap());
    }
    let past = |s: &Scene| {
        s.shapes
            .iter()
            .filter(|sh| {
                simple::flatten_f64(sh, 0.01)
                    .iter()
                    .any(|p| p.0 < -1e-3 || p.1 < -1e-3 || p.0 > 64.0 + 1e-3 || p.1 > 48.0 + 1e-3)
            })
            .count()
    };
    assert!(past(&s) >= 4, "{}", past(&s));
    let before = crate::raster::render(&s);
    let report = finish_scene(&mut s, &ColorPlan::default(), true);
    assert_eq!(past(&s), 0);
    assert!(report.cut >= 4, "{report:?}");
    let (mean, _) = export::diff(&before, &crate::raster::render(&s));
    assert!(mean < 1.0 / 255.0, "{mean}");
}
