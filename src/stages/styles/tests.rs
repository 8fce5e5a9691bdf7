use super::*;
use crate::scene::{Point, ShapeKind, Stroke};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

#[test]
fn init_scenes_follow_the_paper() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let icon = Style::Iconography.init_scene(512, 64, &mut rng).unwrap();
    assert_eq!(icon.shapes.len(), 64);
    for s in &icon.shapes {
        assert_eq!(s.num_segments(), 4);
        assert!(s.is_closed());
        let a = s.fill.unwrap().a;
        assert!((0.7..=1.0).contains(&a));
        let (lo, hi) = s.control_bounds();
        assert!((hi.x - lo.x - 40.0).abs() < 1.0, "radius 20 at 512 px");
    }
    let px = Style::PixelArt.init_scene(64, 0, &mut rng).unwrap();
    assert_eq!(px.shapes.len(), 1024);
    assert_eq!(px.shapes[33].points[0], Point::new(2.0, 2.0));
    let sk = Style::Sketch.init_scene(512, 16, &mut rng).unwrap();
    assert_eq!(sk.shapes.len(), 16);
    for s in &sk.shapes {
        assert_eq!(s.num_segments(), 5);
        let st = s.stroke.unwrap();
        assert_eq!((st.color, st.width), (Rgba::BLACK, 6.0));
    }
    for sc in [&icon, &px, &sk] {
        assert!(sc.validate().is_ok());
    }
}

#[test]
fn low_poly_scenes_are_opaque_polygons_with_few_vertices() {
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let sc = Style::LowPoly.init_scene(256, 20, &mut rng).unwrap();
    assert_eq!(sc.shapes.len(), 20);
    for s in &sc.shapes {
        assert_eq!(s.kind, ShapeKind::Polygon);
        assert_eq!(s.points.len(), 3);
        assert_eq!(s.fill.unwrap().a, 1.0);
        assert!(s.stroke.is_none());
    }
    sc.validate().unwrap();
    let spec = Style::LowPoly.spec();
    assert!(spec.opaque_fills() && spec.prune_weak() && !spec.reinit_faint_paths());
    let t = spec.trainable();
    assert!(t.points && t.fill && t.background && !t.stroke && !t.width);
    // A trace (closed 4-segment cubics, translucent) becomes opaque quadrilaterals through
    // the segment end points.
    let mut traced = Scene::new(64, 64, Rgba::WHITE).unwrap();
    let c = Shape::circle(20.0, 30.0, 8.0, 4, Rgba::new(0.2, 0.4, 0.6, 0.5)).unwrap();
    traced.shapes.push(c.clone());
    let lp = spec.restyle_trace(traced, 64).unwrap();
    assert_eq!(lp.shapes.len(), 1);
    let q = &lp.shapes[0];
    assert_eq!(q.kind, ShapeKind::Polygon);
    assert_eq!(
        q.points,
        vec![c.points[0], c.points[3], c.points[6], c.points[9]]
    );
    assert_eq!(q.fill.unwrap(), Rgba::new(0.2, 0.4, 0.6, 1.0));
}

#[test]
fn painting_scenes_are_coloured_strokes_with_trainable_width() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let sc = Style::Painting.init_scene(512, 12, &mut rng).unwrap();
    assert_eq!(sc.shapes.len(), 12);
    let mut widths = Vec::new();
    for s in &sc.shapes {
        assert_eq!(s.kind, ShapeKind::OpenCubic);
        assert!(s.fill.is_none());
        let st = s.stroke.unwrap();
        assert_eq!(st.color.a, 1.0);
        assert!((6.0..=18.0).contains(&st.width), "{}", st.width);
        widths.push(st.width);
    }
    assert!(
        widths.iter().any(|w| (w - widths[0]).abs() > 1e-3),
        "widths vary"
    );
    sc.validate().unwrap();
    let t = Style::Painting.trainable();
    assert!(t.points && t.stroke && t.width && !t.fill);
    // Traced outlines become strokes in their fill colour.
    let mut traced = Scene::new(64, 64, Rgba::WHITE).unwrap();
    traced
        .shapes
        .push(Shape::circle(20.0, 30.0, 8.0, 4, Rgba::new(0.9, 0.1, 0.1, 0.8)).unwrap());
    let p = Style::Painting.spec().restyle_trace(traced, 64).unwrap();
    let Stroke { color, width, .. } = p.shapes[0].stroke.unwrap();
    assert_eq!(color, Rgba::new(0.9, 0.1, 0.1, 1.0));
    assert_eq!(width, 2.0 * Style::stroke_width(64));
    assert_eq!(Style::Painting.spec().min_shapes(7), 7);
}

#[test]
fn schedules_and_masks() {
    let s = Style::Iconography.schedules(2000);
    assert!((s.points.lr(0) - 0.02).abs() < 1e-7);
    assert!((s.points.lr(500) - 0.2).abs() < 1e-6);
    assert!((s.points.lr(2000) - 0.05).abs() < 1e-6);
    assert!((s.fill.lr(500) - 0.01).abs() < 1e-6);
    assert!((s.background.lr(500) - 0.001).abs() < 1e-6);
    let p = Style::PixelArt.schedules(3000);
    assert!((p.fill.lr(0) - 1e-5).abs() < 1e-9);
    assert!((p.fill.lr(1000) - 1e-4).abs() < 1e-9);
    assert!((p.fill.lr(2500) - 1e-4).abs() < 1e-9);
    assert!(!Style::PixelArt.trainable().points);
    assert!(Style::Sketch.trainable().points && !Style::Sketch.trainable().fill);
}

#[test]
fn one_canonical_spelling_and_the_aliases() {
    assert_eq!(
        Style::PixelArt.prompt("a cat."),
        "a cat. pixel art. trending on artstation"
    );
    for (text, style) in [
        ("pixel-art", Style::PixelArt),
        ("pixel_art", Style::PixelArt),
        ("Pixel Art", Style::PixelArt),
        ("icon", Style::Iconography),
        ("line", Style::Sketch),
        ("low-poly", Style::LowPoly),
        ("low_poly", Style::LowPoly),
        ("painting", Style::Painting),
    ] {
        assert_eq!(text.parse::<Style>().unwrap(), style, "{text}");
    }
    let err = "oil".parse::<Style>().unwrap_err();
    assert!(
        err.contains("low_poly") && err.contains("painting"),
        "{err}"
    );
    for s in Style::ALL {
        assert_eq!(s.to_string().parse::<Style>().unwrap(), s);
        let json = serde_json::to_value(s).unwrap();
        assert_eq!(json, serde_json::Value::String(s.as_str().into()));
        assert_eq!(serde_json::from_value::<Style>(json).unwrap(), s);
    }
    // The API (serde) takes the canonical names only: one value per style in its spec.
    for (alias, style) in Style::ALIASES {
        assert_eq!(alias.parse::<Style>().unwrap(), style, "{alias}");
        let json = serde_json::Value::String(alias.into());
        assert!(serde_json::from_value::<Style>(json).is_err(), "{alias}");
    }
    assert!(serde_json::from_str::<Style>("\"pixel-art\"").is_err());
}

#[test]
fn pixelation_takes_cell_medians() {
    let mut im = Image::filled(64, 64, [1.0, 1.0, 1.0, 1.0]);
    // Cell (1, 0) is 2x2 px: three red pixels and one blue → median red.
    for (x, y, c) in [
        (2, 0, [1.0, 0.0, 0.0, 1.0]),
        (3, 0, [1.0, 0.0, 0.0, 1.0]),
        (2, 1, [1.0, 0.0, 0.0, 1.0]),
        (3, 1, [0.0, 0.0, 1.0, 1.0]),
    ] {
        im.data[4 * (y * 64 + x)..4 * (y * 64 + x) + 4].copy_from_slice(&c);
    }
    let sc = pixelate_l1(&im, 64).unwrap();
    assert_eq!(sc.shapes[1].fill.unwrap(), Rgba::new(1.0, 0.0, 0.0, 1.0));
    assert_eq!(sc.shapes[0].fill.unwrap(), Rgba::WHITE);
}
