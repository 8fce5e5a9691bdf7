//! Our rasteriser against resvg: rendering with resvg and the side-by-side picture written when
//! a comparison fails.

use resvg::{tiny_skia, usvg};
use vectorfusion::image::Image;

/// `svg_text` rendered by resvg at its own size, premultiplied RGBA in `[0, 1]`.
pub fn resvg_render(svg_text: &str) -> Image {
    let tree = usvg::Tree::from_str(svg_text, &usvg::Options::default()).unwrap();
    let size = tree.size().to_int_size();
    let mut pm = tiny_skia::Pixmap::new(size.width(), size.height()).unwrap();
    resvg::render(&tree, tiny_skia::Transform::default(), &mut pm.as_mut());
    Image {
        width: size.width(),
        height: size.height(),
        data: pm.data().iter().map(|&b| b as f32 / 255.0).collect(),
    }
}

/// Mean absolute difference over every channel.
pub fn mean_abs_diff(a: &Image, b: &Image) -> f64 {
    assert_eq!((a.width, a.height), (b.width, b.height));
    let s: f64 = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (*x as f64 - *y as f64).abs())
        .sum();
    s / a.data.len() as f64
}

/// The share of pixels whose largest channel difference exceeds `by`.
pub fn share_off_by(a: &Image, b: &Image, by: f32) -> f64 {
    let n = a
        .data
        .chunks_exact(4)
        .zip(b.data.chunks_exact(4))
        .filter(|(p, q)| p.iter().zip(q.iter()).any(|(x, y)| (x - y).abs() > by))
        .count();
    n as f64 / (a.width as f64 * a.height as f64)
}

/// Writes `ours | theirs | 8x amplified difference` to `$CARGO_TARGET_TMPDIR/golden_<name>.png`
/// and returns its path.
pub fn write_triptych(name: &str, ours: &Image, theirs: &Image) -> String {
    let (w, h) = (ours.width, ours.height);
    let mut out = Image::new(3 * w, h);
    for y in 0..h {
        for x in 0..w {
            let (p, q) = (ours.pixel(x, y), theirs.pixel(x, y));
            let row = (y * 3 * w) as usize;
            for c in 0..4 {
                out.data[4 * (row + x as usize) + c] = p[c];
                out.data[4 * (row + (w + x) as usize) + c] = q[c];
            }
            let d = (0..4).map(|c| (p[c] - q[c]).abs()).fold(0.0, f32::max);
            let v = (8.0 * d).min(1.0);
            let i = 4 * (row + (2 * w + x) as usize);
            out.data[i..i + 4].copy_from_slice(&[v, v, v, 1.0]);
        }
    }
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let path = dir.join(format!("golden_{name}.png"));
    out.save_png(&path).unwrap();
    path.display().to_string()
}
