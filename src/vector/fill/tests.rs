use super::*;
use crate::scene::{Params, Rgba, Scene, Shape};

/// The largest per-channel difference of two renders.
fn max_diff(a: &crate::image::Image, b: &crate::image::Image) -> f32 {
    a.data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max)
}

fn scene(kind: FillKind) -> Scene {
    let mut s = Scene::new(48, 40, Rgba::WHITE).unwrap();
    s.shapes
        .push(Shape::circle(20.0, 18.0, 9.0, 4, Rgba::new(0.8, 0.2, 0.1, 1.0)).unwrap());
    s.shapes
        .push(Shape::square(5.0, 6.0, 12.0, Rgba::new(0.1, 0.3, 0.9, 1.0)).unwrap());
    kind.paint_new(&mut s);
    s
}

#[test]
fn flat_equivalent_gradients_render_as_the_flat_fill() {
    let flat = crate::raster::render(&scene(FillKind::Flat));
    for kind in [FillKind::Linear, FillKind::Radial] {
        let s = scene(kind);
        assert!(s.validate().is_ok());
        assert!(s.shapes.iter().all(|sh| sh.gradients.is_some()));
        let img = crate::raster::render(&s);
        let worst = max_diff(&img, &flat);
        assert!(worst < 1e-5, "{kind:?}: {worst}");
        // Painting again adds nothing.
        let mut again = s.clone();
        assert_eq!(kind.paint_new(&mut again), 0);
    }
    assert!(
        scene(FillKind::Flat)
            .shapes
            .iter()
            .all(|s| s.gradients.is_none())
    );
}

#[test]
fn palette_is_refused_with_gradients() {
    assert!(FillKind::Flat.check_with_palette(true).is_ok());
    assert!(FillKind::Linear.check_with_palette(false).is_ok());
    let e = FillKind::Radial.check_with_palette(true).unwrap_err();
    assert!(e.contains("palette"), "{e}");
}

#[test]
fn tidy_folds_uniform_scales_and_keeps_the_render() {
    let mut s = scene(FillKind::Radial);
    // Make the stops differ so the geometry matters.
    if let Some(g) = s.shapes[0].gradients.as_mut().and_then(|g| g.fill.as_mut()) {
        g.stops[1].color = Rgba::new(0.1, 0.9, 0.2, 1.0);
    }
    let mut big = s.scaled_to_width(96);
    big.height = 80;
    let before = crate::raster::render(&big);
    tidy_gradients(&mut big);
    let g = fill_gradient(&big.shapes[0]).unwrap();
    assert_eq!(g.transform, Affine::IDENTITY);
    let after = crate::raster::render(&big);
    let worst = max_diff(&after, &before);
    assert!(worst < 0.02, "{worst}");
}

#[test]
fn restart_keeps_the_parameter_layout() {
    let s = scene(FillKind::Linear);
    let old = fill_gradient(&s.shapes[0]).unwrap();
    let fresh = Shape::circle(30.0, 30.0, 4.0, 4, Rgba::BLACK).unwrap();
    let g = restart_like(old, &fresh);
    assert_eq!(g.num_params(), old.num_params());
    assert!(g.stops.iter().all(|st| st.color == Rgba::BLACK));
    let p = Params::from_scene(&s);
    assert_eq!(p.paint(&s), crate::scene::paint::scene_gradient_params(&s));
}
