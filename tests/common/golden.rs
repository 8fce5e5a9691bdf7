//! Our render against resvg's: the comparison and the triptych (ours | resvg | 8x amplified
//! difference) written to `$CARGO_TARGET_TMPDIR/golden_<name>.png` on failure.
#![allow(dead_code)]

use resvg::{tiny_skia, usvg};
use vectorfusion::image::Image;

/// How different two renders may be.
pub struct Tolerance {
    /// Largest mean absolute difference over all channels (0..1 units).
    pub mean: f64,
    /// A pixel whose channels differ by more than this differs "a lot".
    pub large: f32,
    /// Largest share of pixels that differ a lot.
    pub max_share: f64,
}

impl Tolerance {
    /// Our own exports: anti-aliasing differences between two correct rasterisers stay below
    /// 128/255 (the largest are on 1 px diagonal strokes, which tiny-skia draws as lighter
    /// hairlines, up to 0.45); at most 0.05 % of the pixels may differ that much, so a missing
    /// thin stroke (a few dozen pixels, well inside the mean tolerance) still fails.
    pub const GOLDEN: Tolerance = Tolerance {
        mean: 1.5 / 255.0,
        large: 128.0 / 255.0,
        max_share: 0.0005,
    };
    /// resvg's test-suite harness (`scripts/resvg_suite.py`): mean at most 1.5/255 and at most
    /// 1 % of the pixels off by more than 16/255.
    pub const SUITE: Tolerance = Tolerance {
        mean: 1.5 / 255.0,
        large: 16.0 / 255.0,
        max_share: 0.01,
    };
}

/// resvg's render of `svg_text` at its own size (premultiplied RGBA in 0..1).
pub fn resvg_render(svg_text: &str) -> Image {
    resvg_render_with(svg_text, &usvg::Options::default())
}

/// [`resvg_render`] with these options (e.g. a font database).
pub fn resvg_render_with(svg_text: &str, opts: &usvg::Options) -> Image {
    let tree = usvg::Tree::from_str(svg_text, opts).unwrap();
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

/// The share of pixels whose largest channel difference exceeds `large`.
pub fn share_off_by(a: &Image, b: &Image, large: f32) -> f64 {
    let n = a
        .data
        .chunks_exact(4)
        .zip(b.data.chunks_exact(4))
        .filter(|(p, q)| p.iter().zip(q.iter()).any(|(x, y)| (x - y).abs() > large))
        .count();
    n as f64 / (a.width as f64 * a.height as f64)
}

/// Fails (with a triptych) when the mean difference or the share of very different pixels is
/// over `tol`; returns the mean.
pub fn compare(name: &str, ours: &Image, theirs: &Image, tol: &Tolerance) -> f64 {
    let d = mean_abs_diff(ours, theirs);
    let share = share_off_by(ours, theirs, tol.large);
    let large = tol.large * 255.0;
    eprintln!(
        "{name}: mean abs diff {:.3}/255, {:.3}% of pixels differ by more than {large}/255",
        d * 255.0,
        share * 100.0
    );
    if d > tol.mean || share > tol.max_share {
        let p = write_triptych(name, ours, theirs);
        panic!(
            "{name}: mean abs diff {:.3}/255 (at most {:.1}/255), {:.3}% of pixels differ by more \
             than {large}/255 (at most {:.2}%), diff image at {p}",
            d * 255.0,
            tol.mean * 255.0,
            share * 100.0,
            tol.max_share * 100.0
        );
    }
    d
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
