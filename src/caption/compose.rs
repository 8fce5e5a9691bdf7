//! Two pictures in one: the start of a two-object caption ("a cat wearing a hat") drawn from one
//! icon per object by a fixed layout rule of the relation between them.

use super::Relation;
use crate::image::Image;
use crate::image::ops::resize;

/// Where one object goes on the canvas: its side as a share of the canvas side and its centre
/// as shares of the canvas.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Place {
    scale: f32,
    cx: f32,
    cy: f32,
}

/// The layout of `relation`: where the first and the second object go, drawn in that order
/// (the later one on top).
fn layout(relation: Relation) -> [(usize, Place); 2] {
    let p = |scale, cx, cy| Place { scale, cx, cy };
    match relation {
        // The wearer large and low, what it wears smaller on its top.
        Relation::Wearing => [(0, p(0.8, 0.5, 0.6)), (1, p(0.5, 0.5, 0.22))],
        // The mount large and low, the rider smaller above it.
        Relation::Riding => [(1, p(0.8, 0.5, 0.62)), (0, p(0.5, 0.5, 0.3))],
        Relation::Beside => [(0, p(0.56, 0.29, 0.5)), (1, p(0.56, 0.71, 0.5))],
    }
}

/// How much of a pixel (straight RGB over white) is ink rather than page: 0 for white, 1 from
/// a little below white on.
fn ink(r: f32, g: f32, b: f32) -> f32 {
    ((1.0 - r.min(g).min(b)) / 0.12).clamp(0.0, 1.0)
}

/// Pastes the ink of `src` (opaque over white) onto `dst` at `place`.
fn paste(dst: &mut Image, src: &Image, place: Place) {
    let side = ((dst.width.min(dst.height) as f32) * place.scale)
        .round()
        .max(1.0) as u32;
    let small = resize(src, side, side);
    let x0 = (place.cx * dst.width as f32 - side as f32 / 2.0).round() as i64;
    let y0 = (place.cy * dst.height as f32 - side as f32 / 2.0).round() as i64;
    for y in 0..side {
        for x in 0..side {
            let (dx, dy) = (x0 + i64::from(x), y0 + i64::from(y));
            if dx < 0 || dy < 0 || dx >= i64::from(dst.width) || dy >= i64::from(dst.height) {
                continue;
            }
            let s = 4 * (y * side + x) as usize;
            let a = small.data[s + 3];
            // Over white, then as ink.
            let over = |c: f32| (c + 1.0 - a).clamp(0.0, 1.0);
            let rgb = [
                over(small.data[s]),
                over(small.data[s + 1]),
                over(small.data[s + 2]),
            ];
            let k = ink(rgb[0], rgb[1], rgb[2]);
            let d = 4 * (dy as usize * dst.width as usize + dx as usize);
            for (out, v) in dst.data[d..d + 3].iter_mut().zip(rgb) {
                *out = *out * (1.0 - k) + v * k;
            }
            dst.data[d + 3] = 1.0;
        }
    }
}

/// The start of a two-object caption: `first` and `second` (opaque pictures of the same size)
/// laid out on a white canvas of that size as `relation` says.
pub fn compose(first: &Image, second: &Image, relation: Relation) -> Image {
    let (w, h) = (first.width, first.height);
    let mut out = Image {
        width: w,
        height: h,
        data: vec![1.0; 4 * (w * h) as usize],
    };
    for (which, place) in layout(relation) {
        paste(&mut out, if which == 0 { first } else { second }, place);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn filled(side: u32, rgb: [f32; 3]) -> Image {
        let mut img = Image::new(side, side);
        for px in img.data.chunks_exact_mut(4) {
            px.copy_from_slice(&[rgb[0], rgb[1], rgb[2], 1.0]);
        }
        img
    }

    fn at(img: &Image, x: u32, y: u32) -> [f32; 3] {
        let i = 4 * (y * img.width + x) as usize;
        [img.data[i], img.data[i + 1], img.data[i + 2]]
    }

    #[test]
    fn side_by_side_keeps_both_objects() {
        let red = filled(32, [1.0, 0.0, 0.0]);
        let blue = filled(32, [0.0, 0.0, 1.0]);
        let out = compose(&red, &blue, Relation::Beside);
        assert_eq!(at(&out, 8, 16), [1.0, 0.0, 0.0]);
        assert_eq!(at(&out, 24, 16), [0.0, 0.0, 1.0]);
        assert_eq!(at(&out, 16, 1), [1.0, 1.0, 1.0]);
    }

    #[test]
    fn what_is_worn_goes_on_top() {
        let cat = filled(32, [0.5, 0.5, 0.5]);
        let hat = filled(32, [0.0, 0.0, 1.0]);
        let out = compose(&cat, &hat, Relation::Wearing);
        // The hat above, the wearer below.
        assert_eq!(at(&out, 16, 6), [0.0, 0.0, 1.0]);
        assert_eq!(at(&out, 16, 26), [0.5, 0.5, 0.5]);
        let out = compose(&cat, &hat, Relation::Riding);
        // The rider (first) above the mount.
        assert_eq!(at(&out, 16, 9), [0.5, 0.5, 0.5]);
        assert_eq!(at(&out, 16, 28), [0.0, 0.0, 1.0]);
    }
}
