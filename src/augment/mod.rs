//! Differentiable image augmentation for score distillation: a random perspective warp
//! (torchvision's `RandomPerspective`: each corner moves inwards by up to `distortion · half side`,
//! applied with probability `p`) followed by a random (resized) crop.
//!
//! Both are resampling with bilinear taps whose positions do not depend on the image, so one
//! sampled [`Warp`] is an affine map `out = A · in + fill · (1 − A·1)`; [`Warp::vjp`] applies `Aᵀ`
//! exactly. Pixels sampled outside the source take the `fill` colour (white by default, like
//! VectorFusion's `fill=1`).

#![allow(clippy::needless_range_loop)] // index loops read clearest in pixel code

use crate::image::Image;
use rand::{Rng, RngExt};

/// Why an augmentation could not be built or applied.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum AugmentError {
    #[error("image is {got_w}x{got_h}, the warp was sampled for {want_w}x{want_h}")]
    Size {
        got_w: u32,
        got_h: u32,
        want_w: u32,
        want_h: u32,
    },
    #[error("gradient has length {got}, expected {want}")]
    GradLength { got: usize, want: usize },
    #[error("invalid augmentation settings: {0}")]
    Config(String),
}

/// Augmentation settings.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AugmentConfig {
    /// Probability of applying the perspective warp (VectorFusion: 0.7).
    pub perspective_p: f32,
    /// Maximum corner displacement as a fraction of half the side (VectorFusion: 0.5).
    pub distortion: f32,
    /// Width of the output (the encoder's input size) ...
    pub out_size: u32,
    /// ... and its height when it differs (a non-square canvas); `None`: a square output.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub out_height: Option<u32>,
    /// Crop side as a fraction of the input side, drawn uniformly from this range and resized to
    /// `out_size`. `None` = an unresized crop of exactly `out_size` pixels (the input must be at
    /// least that large), e.g. render 600 px and crop 512 px.
    pub crop_scale: Option<(f32, f32)>,
    /// Premultiplied colour for samples outside the source.
    pub fill: [f32; 4],
}

impl AugmentConfig {
    /// VectorFusion's settings for an encoder input of `out_size` px.
    pub fn vectorfusion(out_size: u32) -> Self {
        Self {
            perspective_p: 0.7,
            distortion: 0.5,
            out_size,
            out_height: None,
            crop_scale: None,
            fill: [1.0, 1.0, 1.0, 1.0],
        }
    }

    /// This config with a `width x height` output (the square one when they are equal).
    pub fn with_output(self, width: u32, height: u32) -> Self {
        Self {
            out_size: width,
            out_height: (height != width).then_some(height),
            ..self
        }
    }

    /// `(width, height)` of the output.
    pub fn out_dims(&self) -> (u32, u32) {
        (self.out_size, self.out_height.unwrap_or(self.out_size))
    }

    /// `(width, height)` to render at: [`AugmentConfig::render_size`] for each side.
    pub fn render_dims(&self) -> (u32, u32) {
        let (w, h) = self.out_dims();
        match self.crop_scale {
            None => (
                ((w as f64) * 600.0 / 512.0).round() as u32,
                ((h as f64) * 600.0 / 512.0).round() as u32,
            ),
            Some(_) => (w, h),
        }
    }

    /// Render side to use with this config: `out_size · 600/512` for a plain crop, else
    /// `out_size`.
    pub fn render_size(&self) -> u32 {
        match self.crop_scale {
            None => ((self.out_size as f64) * 600.0 / 512.0).round() as u32,
            Some(_) => self.out_size,
        }
    }
}

/// One sampled augmentation: bilinear taps for every output pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Warp {
    pub in_w: u32,
    pub in_h: u32,
    pub out_w: u32,
    pub out_h: u32,
    /// Input pixel index of each tap (`u32::MAX` = outside, takes the fill colour).
    idx: Vec<[u32; 4]>,
    weight: Vec<[f32; 4]>,
    fill: [f32; 4],
    /// Whether the perspective part was applied.
    pub perspective: bool,
}

const OUTSIDE: u32 = u32::MAX;

/// A 3x3 homography, row-major, mapping `(x, y, 1)`.
pub type Homography = [f64; 9];

/// Maps a point through a homography.
pub fn apply_homography(h: &Homography, x: f64, y: f64) -> (f64, f64) {
    let w = h[6] * x + h[7] * y + h[8];
    (
        (h[0] * x + h[1] * y + h[2]) / w,
        (h[3] * x + h[4] * y + h[5]) / w,
    )
}

/// The homography that maps each `from[i]` onto `to[i]` (4 point pairs), or `None` when the
/// points are degenerate.
pub fn homography(from: [(f64, f64); 4], to: [(f64, f64); 4]) -> Option<Homography> {
    // Unknowns h0..h7 (h8 = 1): for each pair two rows.
    let mut a = [[0.0f64; 9]; 8];
    for i in 0..4 {
        let (x, y) = from[i];
        let (u, v) = to[i];
        a[2 * i] = [x, y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y, u];
        a[2 * i + 1] = [0.0, 0.0, 0.0, x, y, 1.0, -v * x, -v * y, v];
    }
    // Gaussian elimination with partial pivoting on the 8x8 system (last column = rhs).
    for col in 0..8 {
        let piv = (col..8).max_by(|&r, &s| a[r][col].abs().total_cmp(&a[s][col].abs()))?;
        if a[piv][col].abs() < 1e-12 {
            return None;
        }
        a.swap(col, piv);
        for r in 0..8 {
            if r != col {
                let f = a[r][col] / a[col][col];
                for c in col..9 {
                    a[r][c] -= f * a[col][c];
                }
            }
        }
    }
    let mut h = [0.0; 9];
    for i in 0..8 {
        h[i] = a[i][8] / a[i][i];
    }
    h[8] = 1.0;
    h.iter().all(|v| v.is_finite()).then_some(h)
}

impl Warp {
    /// Samples a random perspective (with probability `perspective_p`) and crop for an input of
    /// `in_w x in_h` pixels.
    pub fn sample<R: Rng>(
        cfg: &AugmentConfig,
        in_w: u32,
        in_h: u32,
        rng: &mut R,
    ) -> Result<Warp, AugmentError> {
        let (out, out_h) = cfg.out_dims();
        if out == 0 || out_h == 0 || in_w == 0 || in_h == 0 {
            return Err(AugmentError::Config("sizes must be positive".into()));
        }
        if !(0.0..=1.0).contains(&cfg.perspective_p) || !(0.0..1.0).contains(&cfg.distortion) {
            return Err(AugmentError::Config(
                "perspective_p must be in [0,1] and distortion in [0,1)".into(),
            ));
        }
        let (w, h) = (in_w as f64, in_h as f64);
        let apply_persp = cfg.perspective_p > 0.0 && rng.random::<f32>() < cfg.perspective_p;
        // `inv` maps a point of the warped image back to the source image.
        let inv = if apply_persp {
            let (dx, dy) = (
                cfg.distortion as f64 * w / 2.0,
                cfg.distortion as f64 * h / 2.0,
            );
            let mut r = || rng.random::<f64>();
            let start = [(0.0, 0.0), (w, 0.0), (w, h), (0.0, h)];
            let end = [
                (r() * dx, r() * dy),
                (w - r() * dx, r() * dy),
                (w - r() * dx, h - r() * dy),
                (r() * dx, h - r() * dy),
            ];
            homography(end, start)
                .ok_or_else(|| AugmentError::Config("degenerate perspective".into()))?
        } else {
            [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        };
        let (cw, ch) = match cfg.crop_scale {
            None => {
                if out > in_w || out_h > in_h {
                    return Err(AugmentError::Config(format!(
                        "crop of {out}x{out_h} px does not fit in a {in_w}x{in_h} render"
                    )));
                }
                (out as f64, out_h as f64)
            }
            Some((lo, hi)) => {
                if !(lo > 0.0 && lo <= hi && hi <= 1.0) {
                    return Err(AugmentError::Config(format!(
                        "crop scale range ({lo}, {hi}) must satisfy 0 < lo <= hi <= 1"
                    )));
                }
                let s = lo as f64 + (hi - lo) as f64 * rng.random::<f64>();
                (w * s, h * s)
            }
        };
        let x0 = (w - cw) * rng.random::<f64>();
        let y0 = (h - ch) * rng.random::<f64>();
        let (x0, y0) = if cfg.crop_scale.is_none() {
            (x0.floor(), y0.floor())
        } else {
            (x0, y0)
        };
        Ok(Self::build(
            in_w,
            in_h,
            out,
            out_h,
            &inv,
            x0,
            y0,
            cw,
            ch,
            cfg.fill,
            apply_persp,
        ))
    }

    /// A warp from an explicit source-from-warped homography and crop rectangle.
    #[allow(clippy::too_many_arguments)]
    pub fn build(
        in_w: u32,
        in_h: u32,
        out_w: u32,
        out_h: u32,
        inv: &Homography,
        x0: f64,
        y0: f64,
        cw: f64,
        ch: f64,
        fill: [f32; 4],
        perspective: bool,
    ) -> Warp {
        let n = out_w as usize * out_h as usize;
        let mut idx = Vec::with_capacity(n);
        let mut weight = Vec::with_capacity(n);
        let (sx_scale, sy_scale) = (cw / out_w as f64, ch / out_h as f64);
        for y in 0..out_h {
            for x in 0..out_w {
                let qx = x0 + (x as f64 + 0.5) * sx_scale;
                let qy = y0 + (y as f64 + 0.5) * sy_scale;
                let (sx, sy) = apply_homography(inv, qx, qy);
                let (px, py) = (sx - 0.5, sy - 0.5);
                let (fx, fy) = (px.floor(), py.floor());
                let (tx, ty) = ((px - fx) as f32, (py - fy) as f32);
                let mut ids = [OUTSIDE; 4];
                let ws = [
                    (1.0 - tx) * (1.0 - ty),
                    tx * (1.0 - ty),
                    (1.0 - tx) * ty,
                    tx * ty,
                ];
                let finite = px.is_finite() && py.is_finite();
                for (k, (ox, oy)) in [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().enumerate() {
                    let (ix, iy) = (fx + ox as f64, fy + oy as f64);
                    if finite && ix >= 0.0 && iy >= 0.0 && ix < in_w as f64 && iy < in_h as f64 {
                        ids[k] = iy as u32 * in_w + ix as u32;
                    }
                }
                idx.push(ids);
                weight.push(if finite { ws } else { [1.0, 0.0, 0.0, 0.0] });
            }
        }
        Warp {
            in_w,
            in_h,
            out_w,
            out_h,
            idx,
            weight,
            fill,
            perspective,
        }
    }

    /// Applies the warp.
    pub fn apply(&self, image: &Image) -> Result<Image, AugmentError> {
        if image.width != self.in_w
            || image.height != self.in_h
            || image.data.len() != 4 * (self.in_w * self.in_h) as usize
        {
            return Err(AugmentError::Size {
                got_w: image.width,
                got_h: image.height,
                want_w: self.in_w,
                want_h: self.in_h,
            });
        }
        let mut out = Image::new(self.out_w, self.out_h);
        for (o, (ids, ws)) in out
            .data
            .chunks_exact_mut(4)
            .zip(self.idx.iter().zip(&self.weight))
        {
            for (&i, &w) in ids.iter().zip(ws) {
                if i == OUTSIDE {
                    for c in 0..4 {
                        o[c] += w * self.fill[c];
                    }
                } else {
                    let p = &image.data[4 * i as usize..4 * i as usize + 4];
                    for c in 0..4 {
                        o[c] += w * p[c];
                    }
                }
            }
        }
        Ok(out)
    }

    /// Vector-Jacobian product: dL/d(input data) from dL/d(output data).
    pub fn vjp(&self, d_out: &[f32]) -> Result<Vec<f32>, AugmentError> {
        let want = 4 * (self.out_w * self.out_h) as usize;
        if d_out.len() != want {
            return Err(AugmentError::GradLength {
                got: d_out.len(),
                want,
            });
        }
        let mut d_in = vec![0.0f32; 4 * (self.in_w * self.in_h) as usize];
        for (g, (ids, ws)) in d_out.chunks_exact(4).zip(self.idx.iter().zip(&self.weight)) {
            for (&i, &w) in ids.iter().zip(ws) {
                if i != OUTSIDE {
                    let d = &mut d_in[4 * i as usize..4 * i as usize + 4];
                    for c in 0..4 {
                        d[c] += w * g[c];
                    }
                }
            }
        }
        Ok(d_in)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn random_image(rng: &mut ChaCha8Rng, w: u32, h: u32) -> Image {
        let mut im = Image::new(w, h);
        for v in &mut im.data {
            *v = rng.random::<f32>();
        }
        im
    }

    #[test]
    fn homography_maps_corners() {
        let from = [(0.0, 0.0), (10.0, 0.0), (10.0, 8.0), (0.0, 8.0)];
        let to = [(1.0, 2.0), (9.0, 0.5), (8.0, 7.0), (2.0, 8.0)];
        let h = homography(from, to).unwrap();
        for (f, t) in from.iter().zip(&to) {
            let (x, y) = apply_homography(&h, f.0, f.1);
            assert!((x - t.0).abs() < 1e-9 && (y - t.1).abs() < 1e-9);
        }
        assert!(homography(from, [(0.0, 0.0); 4]).is_none());
    }

    #[test]
    fn identity_crop_copies_pixels() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let im = random_image(&mut rng, 12, 10);
        let cfg = AugmentConfig {
            perspective_p: 0.0,
            out_size: 6,
            ..AugmentConfig::vectorfusion(6)
        };
        let w = Warp::sample(&cfg, 12, 10, &mut rng).unwrap();
        let out = w.apply(&im).unwrap();
        // Find the offset: a pure crop copies an exact window.
        let found = (0..=6).any(|x0| {
            (0..=4).any(|y0| {
                (0..6).all(|y| {
                    (0..6).all(|x| {
                        (0..4).all(|c| {
                            (out.data[4 * (y * 6 + x) + c]
                                - im.data[4 * ((y + y0) * 12 + x + x0) + c])
                                .abs()
                                < 1e-6
                        })
                    })
                })
            })
        });
        assert!(found);
    }

    #[test]
    fn vjp_matches_finite_differences_and_adjoint() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let cfg = AugmentConfig {
            perspective_p: 1.0,
            crop_scale: Some((0.7, 0.9)),
            ..AugmentConfig::vectorfusion(9)
        };
        for _ in 0..4 {
            let im = random_image(&mut rng, 13, 11);
            let w = Warp::sample(&cfg, 13, 11, &mut rng).unwrap();
            assert!(w.perspective);
            let g = random_image(&mut rng, 9, 9).data;
            let d_in = w.vjp(&g).unwrap();
            let loss = |im: &Image| -> f64 {
                let o = w.apply(im).unwrap();
                o.data.iter().zip(&g).map(|(a, b)| (a * b) as f64).sum()
            };
            for i in (0..im.data.len()).step_by(7) {
                let fd = crate::image::central_difference(&im, i, 1e-2, loss);
                assert!(
                    (fd - d_in[i] as f64).abs() < 2e-3,
                    "i={i} fd={fd} {}",
                    d_in[i]
                );
            }
            // Adjoint identity on the linear part (fill = 0).
            let w0 = Warp {
                fill: [0.0; 4],
                ..w
            };
            let x = random_image(&mut rng, 13, 11);
            let lhs: f64 = w0
                .apply(&x)
                .unwrap()
                .data
                .iter()
                .zip(&g)
                .map(|(a, b)| (a * b) as f64)
                .sum();
            let rhs: f64 = x
                .data
                .iter()
                .zip(&w0.vjp(&g).unwrap())
                .map(|(a, b)| (a * b) as f64)
                .sum();
            assert!((lhs - rhs).abs() < 1e-3 * lhs.abs().max(1.0));
        }
    }

    #[test]
    fn perspective_keeps_a_constant_image_and_fills_outside() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let cfg = AugmentConfig {
            perspective_p: 1.0,
            fill: [0.0, 0.0, 0.0, 0.0],
            crop_scale: Some((1.0, 1.0)),
            ..AugmentConfig::vectorfusion(32)
        };
        let im = Image::filled(32, 32, [0.5, 0.5, 0.5, 1.0]);
        let w = Warp::sample(&cfg, 32, 32, &mut rng).unwrap();
        let out = w.apply(&im).unwrap();
        // The warped quad lies inside the frame, so corners are (partly) fill and the centre is
        // the source colour.
        assert!((out.pixel(16, 16)[3] - 1.0).abs() < 1e-5);
        assert!(out.data.iter().all(|v| (-1e-6..=1.0 + 1e-6).contains(v)));
        let corner_alpha = [(0, 0), (31, 0), (0, 31), (31, 31)]
            .iter()
            .map(|&(x, y)| out.pixel(x, y)[3])
            .fold(0.0f32, f32::max);
        assert!(corner_alpha < 1.0);
    }

    #[test]
    fn probability_and_errors() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let cfg = AugmentConfig::vectorfusion(16);
        let n = (0..400)
            .filter(|_| Warp::sample(&cfg, 19, 19, &mut rng).unwrap().perspective)
            .count();
        assert!((230..330).contains(&n), "{n}");
        assert!(Warp::sample(&cfg, 10, 10, &mut rng).is_err());
        let w = Warp::sample(&cfg, 19, 19, &mut rng).unwrap();
        assert!(w.apply(&Image::new(3, 3)).is_err());
        assert!(w.vjp(&[0.0; 5]).is_err());
        assert_eq!(cfg.render_size(), 19);
    }

    #[test]
    fn non_square_outputs_crop_a_non_square_render() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let cfg = AugmentConfig::vectorfusion(32).with_output(32, 18);
        assert_eq!(cfg.out_dims(), (32, 18));
        assert_eq!(cfg.render_dims(), (38, 21));
        assert_eq!(
            AugmentConfig::vectorfusion(16)
                .with_output(16, 16)
                .out_height,
            None
        );
        for _ in 0..8 {
            let w = Warp::sample(&cfg, 38, 21, &mut rng).unwrap();
            assert_eq!((w.out_w, w.out_h), (32, 18));
            let out = w
                .apply(&Image::filled(38, 21, [0.5, 0.5, 0.5, 1.0]))
                .unwrap();
            assert_eq!((out.width, out.height), (32, 18));
        }
        assert!(Warp::sample(&cfg, 38, 17, &mut rng).is_err());
    }
}
