//! The target's border: its mean colour starts the background, its mean opacity tells a
//! transparent background (`--background auto`).

use crate::image::Image;
use crate::scene::Rgba;

/// Mean over the image border of each pixel's RGB over white and its opacity.
fn border_mean(img: &Image) -> [f64; 4] {
    let (w, h) = (img.width, img.height);
    let mut s = [0.0f64; 4];
    let mut n = 0.0f64;
    for y in 0..h {
        for x in 0..w {
            if x == 0 || y == 0 || x + 1 == w || y + 1 == h {
                let p = img.pixel(x, y);
                for c in 0..3 {
                    s[c] += (p[c] + 1.0 - p[3]) as f64;
                }
                s[3] += p[3] as f64;
                n += 1.0;
            }
        }
    }
    s.map(|v| v / n.max(1.0))
}

/// Mean opacity of the image border: a transparent border means a transparent background.
pub(super) fn border_alpha(img: &Image) -> f32 {
    border_mean(img)[3] as f32
}

/// Mean colour of the image border (over white): the starting background.
pub(super) fn border_colour(img: &Image) -> Rgba {
    let m = border_mean(img);
    Rgba::new(m[0] as f32, m[1] as f32, m[2] as f32, 1.0).clamped()
}
