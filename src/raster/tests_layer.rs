//! Even-odd fills, and groups (opacity, clip, mask) forward and backward.

use super::tests::{assert_fd, assert_same_image, random_scene, rgba};
use super::*;
use crate::scene::{Clip, Content, FillRule, Group, Mask, MaskKind, Rgba};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

pub(super) fn content(shapes: Vec<Shape>) -> Content {
    Content {
        shapes,
        groups: Vec::new(),
    }
}

pub(super) fn clip(shapes: Vec<Shape>) -> Box<Clip> {
    Box::new(Clip {
        content: content(shapes),
        clip: None,
    })
}

/// Two nested squares wound the same way as one closed polygon (a bridge there and back).
pub(super) fn frame(rule: FillRule) -> Shape {
    let p = |x: f32, y: f32| Point::new(x, y);
    let mut s = Shape::polygon(
        vec![
            p(2.0, 2.0),
            p(14.0, 2.0),
            p(14.0, 14.0),
            p(2.0, 14.0),
            p(2.0, 2.0),
            p(5.0, 5.0),
            p(11.0, 5.0),
            p(11.0, 11.0),
            p(5.0, 11.0),
            p(5.0, 5.0),
        ],
        Rgba::BLACK,
    )
    .unwrap();
    s.fill_rule = rule;
    s
}

fn one(shape: Shape) -> Scene {
    let mut s = Scene::new(16, 16, Rgba::TRANSPARENT).unwrap();
    s.shapes.push(shape);
    s
}

#[test]
fn even_odd_leaves_doubly_wound_areas_empty() {
    let nz = render(&one(frame(FillRule::NonZero)));
    let eo = render(&one(frame(FillRule::EvenOdd)));
    assert_eq!(nz.pixel(8, 8)[3], 1.0, "nonzero fills the inner square");
    assert_eq!(eo.pixel(8, 8)[3], 0.0, "even-odd leaves it empty");
    assert_eq!(eo.pixel(3, 8)[3], 1.0);
    // Half-covered pixels on the inner edge are half covered under both rules.
    let mut half = frame(FillRule::EvenOdd);
    for q in &mut half.points[5..] {
        q.x += 0.5;
    }
    let im = render(&one(half));
    assert!(
        (im.pixel(5, 8)[3] - 0.5).abs() < 1e-5,
        "{:?}",
        im.pixel(5, 8)
    );
    let total: f32 = eo.data.chunks(4).map(|p| p[3]).sum();
    assert!((total - (144.0 - 36.0)).abs() < 1e-3, "{total}");
}

#[test]
fn group_opacity_composites_the_children_as_one_layer() {
    let mut s = Scene::new(16, 16, Rgba::WHITE).unwrap();
    s.shapes
        .push(Shape::square(2.0, 2.0, 8.0, Rgba::new(1.0, 0.0, 0.0, 1.0)).unwrap());
    s.shapes
        .push(Shape::square(6.0, 6.0, 8.0, Rgba::new(0.0, 0.0, 1.0, 1.0)).unwrap());
    s.groups = vec![Group::new(0..2, 0.5)];
    let im = render(&s);
    // The overlap shows the blue square at half strength over white, no red through it.
    let p = im.pixel(8, 8);
    assert!(
        (p[0] - 0.5).abs() < 1e-6 && (p[2] - 1.0).abs() < 1e-6,
        "{p:?}"
    );
    let p = im.pixel(3, 3);
    assert!(
        (p[0] - 1.0).abs() < 1e-6 && (p[1] - 0.5).abs() < 1e-6,
        "{p:?}"
    );
}

#[test]
fn clips_and_masks_multiply_the_layer() {
    let mut s = Scene::new(16, 16, Rgba::TRANSPARENT).unwrap();
    s.shapes
        .push(Shape::square(0.0, 0.0, 16.0, Rgba::BLACK).unwrap());
    let mut g = Group::new(0..1, 1.0);
    // Clip: the left half, intersected with (nested clip) the top half.
    g.clip = Some(clip(vec![
        Shape::square(0.0, 0.0, 8.0, Rgba::BLACK).unwrap(),
    ]));
    g.clip.as_mut().unwrap().content.shapes[0].points[1].x = 8.0;
    let mut c = g.clip.take().unwrap();
    c.clip = Some(clip(vec![
        Shape::polygon(
            Point::list(&[(0.0, 0.0), (16.0, 0.0), (16.0, 8.0), (0.0, 8.0)]),
            Rgba::BLACK,
        )
        .unwrap(),
    ]));
    g.clip = Some(c);
    s.groups = vec![g.clone()];
    let im = render(&s);
    assert_eq!(im.pixel(2, 2)[3], 1.0);
    assert_eq!(im.pixel(12, 2)[3], 0.0, "outside the clip");
    assert_eq!(im.pixel(2, 12)[3], 0.0, "outside the nested clip");
    // A luminance mask of 50 % grey, and an alpha mask of half-transparent black.
    for (kind, colour) in [
        (MaskKind::Luminance, Rgba::new(0.5, 0.5, 0.5, 1.0)),
        (MaskKind::Alpha, Rgba::new(0.0, 0.0, 0.0, 0.5)),
    ] {
        let mut g = Group::new(0..1, 1.0);
        g.mask = Some(Box::new(Mask {
            kind,
            content: content(vec![Shape::square(0.0, 0.0, 16.0, colour).unwrap()]),
            mask: None,
        }));
        s.groups = vec![g];
        let a = render(&s).pixel(5, 5)[3];
        assert!((a - 0.5).abs() < 1e-3, "{kind:?}: {a}");
    }
}

/// The random scene of the gradient tests with nested groups, clips, masks and even-odd fills.
fn layered_scene(seed: u64) -> Scene {
    let mut s = random_scene(seed);
    let mut rng = ChaCha8Rng::seed_from_u64(seed + 50);
    s.shapes[0].fill_rule = FillRule::EvenOdd;
    s.shapes[2].fill_rule = FillRule::EvenOdd;
    let mut outer = Group::new(0..8, 0.7);
    let mut mask = content(vec![
        Shape::circle(12.0, 10.0, 9.0, 4, Rgba::new(0.9, 0.8, 0.7, 0.9)).unwrap(),
    ]);
    mask.groups = vec![Group::new(0..1, 0.8)];
    outer.mask = Some(Box::new(Mask {
        kind: MaskKind::Luminance,
        content: mask,
        mask: None,
    }));
    let mut clipped = Group::new(1..4, 0.6);
    let mut eo = frame(FillRule::EvenOdd);
    eo.points.iter_mut().for_each(|p| p.x += 4.3);
    clipped.clip = Some(Box::new(Clip {
        content: content(vec![
            eo,
            Shape::circle(6.0, 6.0, 5.5, 4, Rgba::BLACK).unwrap(),
        ]),
        clip: Some(clip(vec![
            Shape::circle(10.0, 9.0, 8.5, 5, Rgba::BLACK).unwrap(),
        ])),
    }));
    let mut alpha = Group::new(2..3, 0.8);
    alpha.mask = Some(Box::new(Mask {
        kind: MaskKind::Alpha,
        content: content(vec![
            Shape::circle(12.0, 9.0, 7.0, 3, rgba(&mut rng)).unwrap(),
        ]),
        mask: None,
    }));
    s.groups = vec![outer, clipped, alpha, Group::new(5..8, 0.5)];
    s.validate().unwrap();
    s
}

#[test]
fn layered_gradients_match_finite_differences() {
    for seed in 0..3 {
        let s = layered_scene(seed);
        assert_fd(&s, 200 + seed);
        // Every group's opacity was checked, and it matters.
        let (_, tape) = render_tape(&s);
        let d = vec![1.0f32; 4 * (s.width * s.height) as usize];
        let g = backward(&s, &tape, &d);
        assert_eq!(g.get(ParamGroup::Opacity).len(), 4);
        assert!(
            g.get(ParamGroup::Opacity).iter().all(|v| *v != 0.0),
            "{g:?}"
        );
    }
}

#[test]
fn layered_render_matches_the_flat_one_for_neutral_groups() {
    // Opacity-1 groups without clip or mask draw exactly what the flat scene draws.
    let flat = random_scene(3);
    let mut grouped = flat.clone();
    grouped.groups = vec![Group::new(0..8, 1.0), Group::new(1..3, 1.0)];
    assert_same_image(&render(&flat), &render(&grouped));
}
