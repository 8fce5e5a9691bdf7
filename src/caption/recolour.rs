//! Recolouring toward a caption's colour: every pixel (or fill) of the picture's largest hue
//! family moves into the named family, keeping its lightness structure (hue rotation for
//! colours; desaturation and a lightness map for black, grey and white).

use super::colour::{ColourName, Hue, Shade, dominant, family, hsl_to_rgb, rgb_to_hsl};
use crate::image::Image;
use crate::scene::{Rgba, Scene};

/// Saturation given to pixels that had no hue of their own (grey, black) when they are coloured.
const SATURATION_FROM_GREY: f32 = 0.7;
/// Least saturation of a recoloured pixel, so that a dull source still reads as the colour.
const MIN_SATURATION: f32 = 0.45;
/// How far a pixel's hue may stay off the new family's centre (degrees): shading within a
/// family survives, at half its spread.
const MAX_HUE_OFFSET: f32 = 10.0;

/// The signed difference `a - b` of two angles, in `(-180, 180]`.
fn angle_diff(a: f32, b: f32) -> f32 {
    let d = (a - b).rem_euclid(360.0);
    if d > 180.0 { d - 360.0 } else { d }
}

/// The lightness range in which a pixel of `hue` still reads as that family ([`family`]).
fn lightness_range(hue: Hue) -> (f32, f32) {
    match hue {
        Hue::Brown => (0.12, 0.33),
        Hue::Orange => (0.45, 0.7),
        Hue::Red => (0.2, 0.66),
        Hue::Yellow => (0.45, 0.75),
        Hue::Pink => (0.45, 0.82),
        _ => (0.18, 0.75),
    }
}

/// Where one straight RGB colour of family `from` goes when `from` is recoloured to `to`.
pub fn recolour_rgb(rgb: [f32; 3], from: Hue, to: ColourName) -> [f32; 3] {
    let (h, s, l) = rgb_to_hsl(rgb[0], rgb[1], rgb[2]);
    let l = match to.shade {
        Some(Shade::Dark) => l * 0.7,
        Some(Shade::Light) => l + (1.0 - l) * 0.35,
        None => l,
    };
    let (h2, s2, l2) = match (to.hue, to.hue.centre()) {
        (Hue::Black, _) => (h, s * 0.15, (l * 0.3).min(0.1)),
        (Hue::Grey, _) => (h, 0.0, 0.3 + 0.35 * l),
        (Hue::White, _) => (h, s * 0.1, 0.9 + 0.08 * l),
        (hue, Some(centre)) => {
            let offset = from.centre().map_or(0.0, |c| {
                (angle_diff(h, c) * 0.5).clamp(-MAX_HUE_OFFSET, MAX_HUE_OFFSET)
            });
            let (s2, l2) = if from.is_achromatic() {
                (SATURATION_FROM_GREY, 0.3 + 0.4 * l)
            } else {
                (s.max(MIN_SATURATION), l)
            };
            let (lo, hi) = lightness_range(hue);
            (centre + offset, s2, l2.clamp(lo, hi))
        }
        (_, None) => (h, s, l),
    };
    let (r, g, b) = hsl_to_rgb(h2, s2, l2);
    [r, g, b]
}

/// The family to move into `to`'s in a picture whose largest drawn family is `largest`: none
/// when it already is `to`'s, and none for white (the page: a white thing on it is drawn by its
/// outline and shading, which recolouring would erase).
fn to_move(largest: Option<Hue>, to: ColourName) -> Option<Hue> {
    largest.filter(|&d| d != to.hue && to.hue != Hue::White)
}

/// Recolours `img` (premultiplied RGBA) toward `to`: the pixels of its largest drawn family
/// move into `to`'s. Returns the family moved; `None` when the picture already is `to`'s
/// family, `to` is white or nothing is drawn, and then `img` is unchanged.
pub fn recolour_image(img: &mut Image, to: ColourName) -> Option<Hue> {
    let from = to_move(dominant(img), to)?;
    for px in img.data.chunks_exact_mut(4) {
        let a = px[3];
        if a <= 1e-6 {
            continue;
        }
        let straight = [px[0] / a, px[1] / a, px[2] / a].map(|c| c.clamp(0.0, 1.0));
        let over = |c: f32| (c * a + 1.0 - a).clamp(0.0, 1.0);
        if family(over(straight[0]), over(straight[1]), over(straight[2])) != from {
            continue;
        }
        let new = recolour_rgb(straight, from, to);
        for (c, v) in px.iter_mut().zip(new) {
            *c = v * a;
        }
    }
    Some(from)
}

/// Recolours `scene` toward `to`: when its render's largest drawn family is another, every
/// fill and stroke of that family moves into `to`'s (alpha kept). Returns the family moved.
pub fn recolour_scene(scene: &mut Scene, to: ColourName) -> Option<Hue> {
    if to.hue == Hue::White {
        return None;
    }
    let from = to_move(dominant(&crate::raster::render(scene)), to)?;
    let moved = |c: Rgba| -> Rgba {
        if family(c.r, c.g, c.b) != from {
            return c;
        }
        let [r, g, b] = recolour_rgb([c.r, c.g, c.b], from, to);
        Rgba::new(r, g, b, c.a)
    };
    for shape in &mut scene.shapes {
        if let Some(f) = shape.fill {
            shape.fill = Some(moved(f));
        }
        if let Some(s) = shape.stroke.as_mut() {
            s.color = moved(s.color);
        }
    }
    Some(from)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::caption::colour::dominant;

    fn name(hue: Hue) -> ColourName {
        ColourName { hue, shade: None }
    }

    /// A 16 px picture: a red disc with a darker red shadow half, on white.
    fn red_icon() -> Image {
        let mut img = Image::new(16, 16);
        for y in 0..16u32 {
            for x in 0..16u32 {
                let (dx, dy) = (x as f32 - 7.5, y as f32 - 7.5);
                let rgb = if dx * dx + dy * dy > 36.0 {
                    [1.0, 1.0, 1.0]
                } else if y < 8 {
                    [0.9, 0.15, 0.1]
                } else {
                    [0.55, 0.05, 0.05]
                };
                let i = 4 * (y * 16 + x) as usize;
                img.data[i..i + 4].copy_from_slice(&[rgb[0], rgb[1], rgb[2], 1.0]);
            }
        }
        img
    }

    fn lightness(img: &Image, x: u32, y: u32) -> f32 {
        let i = 4 * (y * img.width + x) as usize;
        rgb_to_hsl(img.data[i], img.data[i + 1], img.data[i + 2]).2
    }

    #[test]
    fn a_red_start_becomes_blue_with_its_shading() {
        let mut img = red_icon();
        assert_eq!(dominant(&img), Some(Hue::Red));
        let (light, dark) = (lightness(&img, 7, 4), lightness(&img, 7, 11));
        assert_eq!(recolour_image(&mut img, name(Hue::Blue)), Some(Hue::Red));
        assert_eq!(dominant(&img), Some(Hue::Blue));
        // Lightness kept: both halves as light as before, the shadow still darker.
        let (light2, dark2) = (lightness(&img, 7, 4), lightness(&img, 7, 11));
        assert!((light - light2).abs() < 0.02, "{light} -> {light2}");
        assert!((dark - dark2).abs() < 0.02, "{dark} -> {dark2}");
        // The page stays white.
        assert_eq!(&img.data[..4], &[1.0, 1.0, 1.0, 1.0]);
    }

    #[test]
    fn every_family_can_be_reached_and_the_target_is_left_alone() {
        for hue in Hue::ALL.into_iter().filter(|&h| h != Hue::White) {
            let mut img = red_icon();
            let moved = recolour_image(&mut img, name(hue));
            assert_eq!(dominant(&img), Some(hue), "{hue:?}");
            assert_eq!(moved, (hue != Hue::Red).then_some(Hue::Red));
        }
        // The target family, and white (the page), leave the picture as it is.
        for hue in [Hue::Red, Hue::White] {
            let mut img = red_icon();
            let before = img.clone();
            assert_eq!(recolour_image(&mut img, name(hue)), None);
            assert_eq!(img, before);
        }
    }

    #[test]
    fn grey_becomes_a_colour_and_shades_shift_lightness() {
        let grey = [0.5, 0.5, 0.5];
        let [r, g, b] = recolour_rgb(grey, Hue::Grey, name(Hue::Green));
        assert_eq!(family(r, g, b), Hue::Green);
        let dark = ColourName {
            hue: Hue::Blue,
            shade: Some(Shade::Dark),
        };
        let light = ColourName {
            hue: Hue::Blue,
            shade: Some(Shade::Light),
        };
        let red = [0.9, 0.15, 0.1];
        let ld = rgb_to_hsl_l(recolour_rgb(red, Hue::Red, dark));
        let ll = rgb_to_hsl_l(recolour_rgb(red, Hue::Red, light));
        assert!(ld < ll, "{ld} {ll}");
    }

    fn rgb_to_hsl_l(c: [f32; 3]) -> f32 {
        rgb_to_hsl(c[0], c[1], c[2]).2
    }
}
