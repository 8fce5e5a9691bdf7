//! Texture fills: sampling (bilinear, nearest, pad, repeat) and the finite-difference check of
//! a path drawn over and under an image (the texels are constants; every shape parameter,
//! the textured shape's own outline included, gets its gradient).

use super::tests::fd_check;
use super::*;
use crate::scene::{Affine, Gradients, Rgba, Stroke, Texture, TextureEdge, TextureFilter};

/// A 2×2 texture (red, green / blue, half-transparent white) scaled by `k` and moved to `at`.
fn texture(k: f32, at: (f32, f32), edge: TextureEdge, filter: TextureFilter) -> Texture {
    Texture {
        width: 2,
        height: 2,
        pixels: vec![
            255, 0, 0, 255, 0, 255, 0, 255, 0, 0, 255, 255, 128, 128, 128, 128,
        ],
        transform: Affine([k, 0.0, 0.0, k, at.0, at.1]),
        edge,
        filter,
    }
}

fn textured(mut s: Shape, t: Texture) -> Shape {
    s.fill = Some(t.mean_color());
    s.gradients = Some(Box::new(Gradients {
        fill: None,
        stroke: None,
        texture: Some(Box::new(t)),
    }));
    s
}

fn pixel(img: &crate::image::Image, x: u32, y: u32) -> [f32; 4] {
    let i = 4 * (y * img.width + x) as usize;
    [
        img.data[i],
        img.data[i + 1],
        img.data[i + 2],
        img.data[i + 3],
    ]
}

#[test]
fn nearest_and_bilinear_sampling_with_pad_and_repeat() {
    let mut s = Scene::new(8, 8, Rgba::TRANSPARENT).unwrap();
    let rect = Shape::square(0.0, 0.0, 8.0, Rgba::BLACK).unwrap();
    s.shapes.push(textured(
        rect.clone(),
        texture(2.0, (0.0, 0.0), TextureEdge::Pad, TextureFilter::Nearest),
    ));
    s.validate().unwrap();
    let img = render(&s);
    assert_eq!(pixel(&img, 0, 0), [1.0, 0.0, 0.0, 1.0]);
    assert_eq!(pixel(&img, 3, 0), [0.0, 1.0, 0.0, 1.0]);
    // Pad: the last texel continues.
    assert_eq!(pixel(&img, 7, 0), [0.0, 1.0, 0.0, 1.0]);
    let w = pixel(&img, 7, 7);
    assert!(
        (w[3] - 128.0 / 255.0).abs() < 1e-3 && (w[0] - w[3]).abs() < 1e-3,
        "{w:?}"
    );
    // Repeat: the tile starts again at x = 4.
    s.shapes[0] = textured(
        rect.clone(),
        texture(2.0, (0.0, 0.0), TextureEdge::Repeat, TextureFilter::Nearest),
    );
    assert_eq!(pixel(&render(&s), 4, 0), [1.0, 0.0, 0.0, 1.0]);
    // Bilinear: halfway between the red and green texel centres (x = 1 and 3, pixel 2's
    // centre at 2.5 is 3/4 of the way).
    s.shapes[0] = textured(
        rect,
        texture(2.0, (0.0, 0.0), TextureEdge::Pad, TextureFilter::Bilinear),
    );
    let p = pixel(&render(&s), 2, 0);
    assert!(
        (p[0] - 0.25).abs() < 1e-3 && (p[1] - 0.75).abs() < 1e-3,
        "{p:?}"
    );
}

#[test]
fn finite_differences_over_and_under_an_image() {
    let mut s = Scene::new(16, 14, Rgba::new(0.9, 0.9, 0.8, 1.0)).unwrap();
    s.shapes
        .push(Shape::circle(5.2, 6.1, 4.3, 4, Rgba::new(0.2, 0.4, 0.9, 0.8)).unwrap());
    let img = Shape::circle(8.3, 7.1, 5.6, 4, Rgba::BLACK).unwrap();
    s.shapes.push(textured(
        img,
        texture(3.1, (2.3, 1.7), TextureEdge::Pad, TextureFilter::Bicubic),
    ));
    let line = Shape::open_cubic(
        Point::list(&[(1.0, 12.0), (6.0, 3.0), (10.0, 13.0), (12.6, 4.2)]),
        Stroke::round(Rgba::new(0.9, 0.1, 0.1, 0.7), 2.0),
    )
    .unwrap();
    s.shapes.push(line);
    let (checked, bad) = fd_check(&s, 5);
    assert!(checked > 30, "{checked}");
    assert!(bad.is_empty(), "{bad:#?}");
}

#[test]
fn a_texture_drawn_one_to_one_is_not_resampled() {
    // Moved by half a pixel, not scaled: each pixel shows the texel under its centre (crisp),
    // not a mix, although the texture asks for bicubic sampling.
    let mut s = Scene::new(4, 2, Rgba::TRANSPARENT).unwrap();
    let rect = Shape::square(0.0, 0.0, 4.0, Rgba::BLACK).unwrap();
    s.shapes.push(textured(
        rect.clone(),
        texture(1.0, (0.5, 0.0), TextureEdge::Repeat, TextureFilter::Bicubic),
    ));
    let img = render(&s);
    // Pixel 1's centre 1.5 is texel 1.0: green; pixel 0's centre 0.5 is texel 0.0: red.
    assert_eq!(pixel(&img, 0, 0), [1.0, 0.0, 0.0, 1.0]);
    assert_eq!(pixel(&img, 1, 0), [0.0, 1.0, 0.0, 1.0]);
    // Scaled, the same texture is blended.
    s.shapes[0] = textured(
        rect,
        texture(1.5, (0.5, 0.0), TextureEdge::Repeat, TextureFilter::Bicubic),
    );
    let p = pixel(&render(&s), 1, 0);
    assert!(p[0] > 0.05 && p[1] > 0.05, "{p:?}");
}

#[test]
fn bicubic_keeps_a_flat_texture_flat_and_overshoots_no_colour() {
    // The Mitchell weights sum to one: a one-colour texture, however placed, samples to its
    // colour; across a hard red/green edge the filter's negative lobes would dip below zero and
    // rise above one, which the clamp keeps in range.
    let flat = Texture {
        width: 3,
        height: 2,
        pixels: [51u8, 102, 153, 204].repeat(6),
        transform: Affine([2.7, 0.4, -0.3, 1.9, 0.35, 0.8]),
        edge: TextureEdge::Repeat,
        filter: TextureFilter::Bicubic,
    };
    let mut s = Scene::new(9, 7, Rgba::TRANSPARENT).unwrap();
    let rect = Shape::square(0.0, 0.0, 9.0, Rgba::BLACK).unwrap();
    s.shapes.push(textured(rect.clone(), flat));
    let img = render(&s);
    for y in 0..7 {
        for x in 0..7 {
            let p = pixel(&img, x, y);
            let want = [0.2, 0.4, 0.6, 0.8]; // premultiplied
            assert!(
                p.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-5),
                "({x}, {y}): {p:?}"
            );
        }
    }
    s.shapes[0] = textured(
        rect,
        texture(2.5, (0.3, 0.0), TextureEdge::Pad, TextureFilter::Bicubic),
    );
    let img = render(&s);
    let mut between = false;
    for x in 0..9 {
        let p = pixel(&img, x, 0);
        assert!(p.iter().all(|v| (0.0..=1.0).contains(v)), "{x}: {p:?}");
        between |= p[0] > 0.1 && p[1] > 0.1;
    }
    assert!(between, "the red/green edge is filtered");
}
