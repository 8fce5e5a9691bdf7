//! SSIM (Wang, Bovik, Sheikh & Simoncelli 2004) of two images composited over white.
//!
//! The conventions are scikit-image's `structural_similarity(a, b, channel_axis=2,
//! gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=1.0)`:
//! an 11×11 Gaussian window (σ = 1.5, normalised to sum 1), K1 = 0.01, K2 = 0.03 with a data
//! range of 1, population (not sample) variances, and the SSIM map averaged over the pixels at
//! least 5 px from every edge (the window never leaves the image). Each of R, G, B (over white:
//! `c + 1 - a` of the premultiplied channel) gets its own SSIM, and the result is their mean.
//! The test checks a value computed with scikit-image 0.26.

use super::Image;

/// Gaussian σ of the window, in pixels.
const SIGMA: f64 = 1.5;
/// Half-width of the window: scikit-image's `int(3.5 * σ + 0.5)` = 5, an 11×11 window.
const RADIUS: usize = 5;
const C1: f64 = 0.01 * 0.01;
const C2: f64 = 0.03 * 0.03;

/// Mean SSIM over R, G and B of `a` and `b` composited over white (1 for identical images).
/// NaN when the sizes differ or a side is shorter than the 11-pixel window.
pub fn ssim_over_white(a: &Image, b: &Image) -> f64 {
    let (w, h) = (a.width as usize, a.height as usize);
    let win = 2 * RADIUS + 1;
    if a.width != b.width || a.height != b.height || w < win || h < win {
        return f64::NAN;
    }
    let kernel = gaussian_kernel();
    let mut total = 0.0;
    for c in 0..3 {
        let x = over_white_plane(a, c);
        let y = over_white_plane(b, c);
        let xx: Vec<f64> = x.iter().map(|v| v * v).collect();
        let yy: Vec<f64> = y.iter().map(|v| v * v).collect();
        let xy: Vec<f64> = x.iter().zip(&y).map(|(p, q)| p * q).collect();
        let mx = filter_valid(&x, w, h, &kernel);
        let my = filter_valid(&y, w, h, &kernel);
        let mxx = filter_valid(&xx, w, h, &kernel);
        let myy = filter_valid(&yy, w, h, &kernel);
        let mxy = filter_valid(&xy, w, h, &kernel);
        let n = mx.len();
        let mut sum = 0.0;
        for i in 0..n {
            let (ux, uy) = (mx[i], my[i]);
            let vx = mxx[i] - ux * ux;
            let vy = myy[i] - uy * uy;
            let cov = mxy[i] - ux * uy;
            sum += ((2.0 * ux * uy + C1) * (2.0 * cov + C2))
                / ((ux * ux + uy * uy + C1) * (vx + vy + C2));
        }
        total += sum / n as f64;
    }
    total / 3.0
}

/// The normalised 1-D Gaussian of the window.
fn gaussian_kernel() -> [f64; 2 * RADIUS + 1] {
    let mut k = [0.0; 2 * RADIUS + 1];
    for (i, v) in k.iter_mut().enumerate() {
        let d = i as f64 - RADIUS as f64;
        *v = (-0.5 * d * d / (SIGMA * SIGMA)).exp();
    }
    let s: f64 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= s);
    k
}

/// Channel `c` of `im` over white, row-major.
fn over_white_plane(im: &Image, c: usize) -> Vec<f64> {
    im.data
        .chunks_exact(4)
        .map(|p| p[c] as f64 + 1.0 - p[3] as f64)
        .collect()
}

/// Separable filtering of a `w × h` plane, keeping only the `(w - 2r) × (h - 2r)` outputs whose
/// window lies inside the plane.
fn filter_valid(plane: &[f64], w: usize, h: usize, k: &[f64]) -> Vec<f64> {
    let ow = w - 2 * RADIUS;
    let oh = h - 2 * RADIUS;
    let mut rows = vec![0.0; ow * h];
    for y in 0..h {
        let src = &plane[y * w..(y + 1) * w];
        for x in 0..ow {
            rows[y * ow + x] = k.iter().zip(&src[x..]).map(|(a, b)| a * b).sum();
        }
    }
    let mut out = vec![0.0; ow * oh];
    for y in 0..oh {
        for x in 0..ow {
            out[y * ow + x] = k
                .iter()
                .enumerate()
                .map(|(j, kv)| kv * rows[(y + j) * ow + x])
                .sum();
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The test pair, built the same way in the Python snippet of `known_value`.
    fn pair() -> (Image, Image) {
        let (w, h) = (40u32, 32u32);
        let mut a = Image::new(w, h);
        let mut b = Image::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let (xf, yf) = (x as f64, y as f64);
                let alpha = if x < 8 { 0.5 } else { 1.0 };
                let ra = ((x * 7 + y * 3) % 17) as f64 / 16.0;
                let ga = ((x * x + y) % 13) as f64 / 12.0;
                let ba = (xf + yf) / 70.0;
                let rb = (ra + 0.1 * (0.5 * xf).sin()).clamp(0.0, 1.0);
                let gb = 0.8 * ga;
                let bb = ((x * 5 + y * 11) % 23) as f64 / 22.0;
                let i = 4 * (y * w + x) as usize;
                for (c, v) in [ra, ga, ba].into_iter().enumerate() {
                    a.data[i + c] = (v * alpha) as f32;
                }
                a.data[i + 3] = alpha as f32;
                for (c, v) in [rb, gb, bb].into_iter().enumerate() {
                    b.data[i + c] = v as f32;
                }
                b.data[i + 3] = 1.0;
            }
        }
        (a, b)
    }

    #[test]
    fn identical_images_score_one() {
        let (a, _) = pair();
        assert!((ssim_over_white(&a, &a) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn size_mismatch_and_tiny_images_are_nan() {
        let (a, _) = pair();
        assert!(ssim_over_white(&a, &Image::new(40, 31)).is_nan());
        let t = Image::new(10, 40);
        assert!(ssim_over_white(&t, &t).is_nan());
    }

    /// Against scikit-image 0.26.0 (numpy float64), built from the same f32 values:
    ///
    /// ```python
    /// import numpy as np
    /// from skimage.metrics import structural_similarity
    /// w, h = 40, 32
    /// A = np.zeros((h, w, 3)); B = np.zeros((h, w, 3))
    /// for y in range(h):
    ///     for x in range(w):
    ///         al = 0.5 if x < 8 else 1.0
    ///         ra = ((x*7 + y*3) % 17) / 16; ga = ((x*x + y) % 13) / 12; ba = (x + y) / 70
    ///         rb = min(max(ra + 0.1*np.sin(0.5*x), 0), 1); gb = 0.8*ga; bb = ((x*5 + y*11) % 23) / 22
    ///         f = lambda v: float(np.float32(v))
    ///         A[y, x] = [f(v*al) + 1 - f(al) for v in (ra, ga, ba)]
    ///         B[y, x] = [f(v) for v in (rb, gb, bb)]
    /// structural_similarity(A, B, channel_axis=2, gaussian_weights=True, sigma=1.5,
    ///                       use_sample_covariance=False, data_range=1.0)
    /// ```
    #[test]
    fn known_value() {
        let (a, b) = pair();
        let s = ssim_over_white(&a, &b);
        let want = SKIMAGE_VALUE;
        assert!((s - want).abs() < 1e-9, "ssim {s} vs scikit-image {want}");
        // Symmetric.
        assert!((ssim_over_white(&b, &a) - s).abs() < 1e-12);
    }

    const SKIMAGE_VALUE: f64 = 0.628_524_642_086_297_7;
}
