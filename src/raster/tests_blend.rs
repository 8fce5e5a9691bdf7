//! Groups with blend modes: forward against the per-pixel formula, backward against finite
//! differences (colours, opacities, points, background).

use super::tests::{assert_fd, random_scene};
use super::*;
use crate::scene::{BlendMode, Group, Rgba};

fn blended(mode: BlendMode, range: std::ops::Range<usize>, opacity: f32) -> Group {
    let mut g = Group::new(range, opacity);
    g.blend = mode;
    g
}

/// Two squares `(x, y, side, colour)` on a 16 px canvas, the second in a multiply group.
fn multiplied(bg: Rgba, a: (f32, f32, f32, Rgba), b: (f32, f32, f32, Rgba)) -> Scene {
    let mut s = Scene::new(16, 16, bg).unwrap();
    for (x, y, side, c) in [a, b] {
        s.shapes.push(Shape::square(x, y, side, c).unwrap());
    }
    s.groups = vec![blended(BlendMode::Multiply, 1..2, 1.0)];
    s
}

#[test]
fn multiply_of_two_opaque_squares_multiplies_their_colours() {
    let mut s = multiplied(
        Rgba::TRANSPARENT,
        (0.0, 0.0, 10.0, Rgba::new(0.5, 1.0, 0.2, 1.0)),
        (5.0, 5.0, 10.0, Rgba::new(0.4, 0.5, 1.0, 1.0)),
    );
    let im = render(&s);
    let p = im.pixel(7, 7);
    for (c, want) in [0.2, 0.5, 0.2, 1.0].into_iter().enumerate() {
        assert!((p[c] - want).abs() < 1e-6, "{p:?}");
    }
    // Over transparency the source is drawn as it is; under no source the backdrop stays.
    assert!((im.pixel(12, 12)[0] - 0.4).abs() < 1e-6);
    assert!((im.pixel(2, 2)[0] - 0.5).abs() < 1e-6);
    // With half opacity: half-way between the backdrop and the product.
    s.groups[0].opacity = 0.5;
    let p = render(&s).pixel(7, 7);
    assert!(
        (p[0] - 0.35).abs() < 1e-6 && (p[2] - 0.2).abs() < 1e-6,
        "{p:?}"
    );
}

#[test]
fn an_isolated_group_blends_its_children_with_transparency_only() {
    // A multiply group inside an isolated group sees no backdrop: drawn as normal.
    let mut s = multiplied(
        Rgba::WHITE,
        (0.0, 0.0, 16.0, Rgba::new(0.0, 0.5, 0.0, 1.0)),
        (4.0, 4.0, 8.0, Rgba::new(1.0, 1.0, 0.0, 1.0)),
    );
    assert!(
        (render(&s).pixel(8, 8)[0]).abs() < 1e-6,
        "multiplied with green"
    );
    s.groups.insert(0, Group::new(1..2, 1.0));
    assert!((render(&s).pixel(8, 8)[0] - 1.0).abs() < 1e-6, "isolated");
}

#[test]
fn blended_gradients_match_finite_differences() {
    use BlendMode::*;
    let modes = [
        [Multiply, Screen, Overlay],
        [Darken, Lighten, ColorDodge],
        [ColorBurn, HardLight, SoftLight],
        [Difference, Exclusion, Hue],
        [Saturation, Color, Luminosity],
    ];
    for (seed, m) in modes.into_iter().enumerate() {
        let mut s = random_scene(seed as u64);
        s.groups = vec![
            blended(m[0], 2..8, 0.8),
            blended(m[1], 3..5, 0.7),
            blended(m[2], 6..7, 0.9),
        ];
        s.validate().unwrap();
        assert_fd(&s, 300 + seed as u64);
        let (_, tape) = render_tape(&s);
        let d = vec![1.0f32; 4 * (s.width * s.height) as usize];
        let g = backward(&s, &tape, &d);
        assert!(
            g.get(ParamGroup::Opacity).iter().all(|v| *v != 0.0),
            "{m:?}: {:?}",
            g.get(ParamGroup::Opacity)
        );
    }
}
