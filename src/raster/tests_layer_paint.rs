//! Gradient paint inside groups: clipped, masked and faded gradients forward and backward,
//! gradient-painted mask content, and the fused pass on such scenes.

use super::tests::{assert_fd, assert_same_image, separate_and_fused};
use super::tests_layer::{clip, content};
use super::tests_paint::{fd_check_paint, linear, radial, scene, with};
use super::*;
use crate::scene::{Group, Mask, MaskKind, Rgba, Spread};

/// The gradient test scene (a linear fill, a radial fill and stroke, a linear open stroke)
/// with its first two shapes in a clipped group at opacity 0.6 and the third under a luminance
/// mask whose content is itself gradient-painted.
fn grouped(spread: Spread) -> Scene {
    let mut s = scene(spread);
    let mut g = Group::new(0..2, 0.6);
    g.clip = Some(clip(vec![
        Shape::circle(11.0, 10.0, 8.2, 5, Rgba::BLACK).unwrap(),
    ]));
    let disc = Shape::circle(12.0, 13.0, 9.0, 4, Rgba::WHITE).unwrap();
    let mut m = Group::new(2..3, 0.9);
    m.mask = Some(Box::new(Mask {
        kind: MaskKind::Luminance,
        content: content(vec![with(disc, Some(radial(spread, 0.0)), None)]),
        mask: None,
    }));
    s.groups = vec![g, m];
    s.validate().unwrap();
    s
}

#[test]
fn gradients_in_groups_match_finite_differences() {
    let s = grouped(Spread::Pad);
    // Points, flat colours, widths, background and both opacities.
    assert_fd(&s, 61);
    let (checked, bad) = fd_check_paint(&s, 62);
    assert_eq!(
        checked,
        crate::scene::paint::scene_gradient_params(&s).len()
    );
    assert!(bad.len() * 50 <= checked, "{}", bad.join("\n"));
    let (_, tape) = render_tape(&s);
    let d = vec![1.0f32; 4 * (s.width * s.height) as usize];
    let (g, gp) = backward_with_gradients(&s, &tape, &d);
    assert!(g.get(ParamGroup::Opacity).iter().all(|v| *v != 0.0));
    assert!(gp.iter().filter(|v| **v != 0.0).count() * 2 > gp.len());
}

#[test]
fn a_gradient_painted_mask_fades_its_group() {
    // A white square under a luminance mask of a black-to-white linear gradient: the group's
    // alpha follows the gradient's luminance from left to right.
    let mut s = Scene::new(32, 8, Rgba::TRANSPARENT).unwrap();
    s.shapes
        .push(Shape::square(0.0, 0.0, 32.0, Rgba::WHITE).unwrap());
    let mut ramp = linear(0.0, 0.0, 32.0, 0.0, Spread::Pad);
    ramp.stops = vec![
        crate::scene::GradientStop {
            offset: 0.0,
            color: Rgba::BLACK,
        },
        crate::scene::GradientStop {
            offset: 1.0,
            color: Rgba::WHITE,
        },
    ];
    let cover = Shape::square(0.0, 0.0, 32.0, Rgba::BLACK).unwrap();
    let mut g = Group::new(0..1, 1.0);
    g.mask = Some(Box::new(Mask {
        kind: MaskKind::Luminance,
        content: content(vec![with(cover, Some(ramp), None)]),
        mask: None,
    }));
    s.groups = vec![g];
    let im = render(&s);
    for x in [2u32, 9, 16, 23, 30] {
        let want = (x as f32 + 0.5) / 32.0;
        let a = im.pixel(x, 4)[3];
        assert!(
            (a - want).abs() < 2e-3,
            "x {x}: alpha {a}, luminance {want}"
        );
    }
}

#[test]
fn a_clip_draws_its_content_opaque_whatever_its_paint() {
    // A clip shape's gradient (here half transparent) does not matter: clips are coverage.
    let mut s = scene(Spread::Pad);
    let mut g = Group::new(0..3, 1.0);
    let square = || Shape::square(4.0, 3.0, 12.0, Rgba::BLACK).unwrap();
    g.clip = Some(clip(vec![square()]));
    s.groups = vec![g.clone()];
    let plain = render(&s);
    let ramp = linear(4.0, 3.0, 16.0, 15.0, Spread::Pad);
    g.clip = Some(clip(vec![with(square(), Some(ramp), None)]));
    s.groups = vec![g];
    assert_same_image(&plain, &render(&s));
}

#[test]
fn fused_loss_pass_matches_render_then_backward_with_groups_and_gradients() {
    for (seed, spread, width) in [(0u64, Spread::Pad, 24u32), (1, Spread::Reflect, 72)] {
        let s = grouped(spread).scaled_to_width(width);
        let [(want_loss, want, want_paint), (loss, got, paint)] =
            separate_and_fused(&s, seed + 300);
        assert_eq!(got, want, "seed {seed}: the same gradients, bit for bit");
        assert!(got.get(ParamGroup::Opacity).iter().all(|v| *v != 0.0));
        let rel = (loss - want_loss).abs() / want_loss.abs();
        assert!(rel < 1e-6, "seed {seed}: loss {loss} vs {want_loss}");
        // The gradient parameters' gradients, from the same fused pass.
        assert_eq!(paint, want_paint, "seed {seed}: gradient parameters");
        assert!(paint.iter().any(|v| *v != 0.0));
    }
}
