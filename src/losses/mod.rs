//! Losses with analytic gradients: (weighted) L2 on RGB over white, LIVE's unsigned-distance
//! (UDF) weighting, and LIVE's self-intersection ("Xing") loss on cubic segments.
//!
//! Image losses return the gradient with respect to the rendered **premultiplied RGBA** image
//! (what `raster::backward` takes); the Xing loss adds its gradient into a [`Params`] in the
//! `Points` group. Every gradient here is checked against finite differences in the tests.

use crate::image::Image;
use crate::scene::{ParamGroup, Params, Point, Scene, ShapeKind};

/// Why a loss could not be computed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum LossError {
    #[error("image sizes differ: {0}x{1} vs {2}x{3}")]
    SizeMismatch(u32, u32, u32, u32),
    #[error("weight map has {got} entries, expected {expected}")]
    WeightLength { got: usize, expected: usize },
}

fn check_sizes(render: &Image, target: &Image) -> Result<(), LossError> {
    if render.width != target.width
        || render.height != target.height
        || render.data.len() != target.data.len()
    {
        return Err(LossError::SizeMismatch(
            render.width,
            render.height,
            target.width,
            target.height,
        ));
    }
    Ok(())
}

/// `sum_i w_i * sum_c (over_white(render)_ic - over_white(target)_ic)^2`, with its gradient
/// with respect to the premultiplied RGBA values of `render` (length `4 * w * h`).
pub fn weighted_l2(
    render: &Image,
    target: &Image,
    weights: &[f32],
) -> Result<(f64, Vec<f32>), LossError> {
    let mut grad = Vec::new();
    let loss = weighted_l2_into(render, target, weights, &mut grad)?;
    Ok((loss, grad))
}

/// [`weighted_l2`] writing the gradient into `grad` (resized to `4 * w * h`), so an
/// optimisation loop reuses one buffer.
pub fn weighted_l2_into(
    render: &Image,
    target: &Image,
    weights: &[f32],
    grad: &mut Vec<f32>,
) -> Result<f64, LossError> {
    check_sizes(render, target)?;
    let n = render.len_pixels();
    if weights.len() != n {
        return Err(LossError::WeightLength {
            got: weights.len(),
            expected: n,
        });
    }
    grad.clear();
    grad.resize(4 * n, 0.0);
    Ok(weighted_l2_slices(
        &render.data,
        &target.data,
        weights,
        grad,
    ))
}

/// [`weighted_l2_into`] on raw slices of equal pixel count (premultiplied RGBA `render` and
/// `target`, one weight per pixel), writing the gradient into `grad` (same length as
/// `render`): the per-band loss of [`crate::raster::render_loss_backward`]. Extra elements of
/// the longer slice are ignored.
pub fn weighted_l2_slices(
    render: &[f32],
    target: &[f32],
    weights: &[f32],
    grad: &mut [f32],
) -> f64 {
    /// Pixels summed in `f32` before the running total takes them in `f64`.
    const BLOCK: usize = 64;
    let mut loss = 0.0f64;
    for (((p, q), g), w) in render
        .chunks(4 * BLOCK)
        .zip(target.chunks(4 * BLOCK))
        .zip(grad.chunks_mut(4 * BLOCK))
        .zip(weights.chunks(BLOCK))
    {
        let mut block = 0.0f32;
        for (((p, q), g), &w) in p
            .chunks_exact(4)
            .zip(q.chunks_exact(4))
            .zip(g.chunks_exact_mut(4))
            .zip(w)
        {
            block += w * l2_pixel(p, q, w, g);
        }
        loss += block as f64;
    }
    loss
}

/// The gradient of [`weighted_l2_slices`] alone (the same values bit for bit), without the
/// loss: the serial sum is what bounds the loss's speed, and most optimisation steps do not
/// need its value.
pub fn weighted_l2_grad_slices(render: &[f32], target: &[f32], weights: &[f32], grad: &mut [f32]) {
    for (((p, q), g), &w) in render
        .chunks_exact(4)
        .zip(target.chunks_exact(4))
        .zip(grad.chunks_exact_mut(4))
        .zip(weights)
    {
        l2_pixel(p, q, w, g);
    }
}

/// One pixel of [`weighted_l2_slices`]: writes its gradient into `g` and returns its unweighted
/// squared error.
#[inline(always)]
fn l2_pixel(p: &[f32], q: &[f32], w: f32, g: &mut [f32]) -> f32 {
    let mut s = 0.0f32;
    let mut da = 0.0f32;
    for c in 0..3 {
        let d = (p[c] - p[3]) - (q[c] - q[3]);
        s += d * d;
        g[c] = 2.0 * w * d;
        da -= 2.0 * w * d;
    }
    g[3] = da;
    s
}

/// Mean squared error over RGB composited over white (the quantity behind `image::psnr`),
/// with its gradient.
pub fn l2(render: &Image, target: &Image) -> Result<(f64, Vec<f32>), LossError> {
    let n = render.len_pixels().max(1);
    let w = vec![1.0 / (3.0 * n as f32); render.len_pixels()];
    weighted_l2(render, target, &w)
}

/// LIVE's unsigned-distance weights: `w_i = relu(tau - d_i) / sum_j relu(tau - d_j)` where `d_i`
/// is the distance from pixel `i` to the nearest of the given outlines. The weights sum to 1
/// (all zero if no pixel lies within `tau`). They are constants of the optimisation step (LIVE
/// does not differentiate through them).
pub fn udf_weights(width: u32, height: u32, outlines: &[Vec<(f32, f32)>], tau: f32) -> Vec<f32> {
    let d = crate::image::ops::distance_to_polylines(width, height, outlines, true, tau);
    let mut w: Vec<f32> = d.iter().map(|&v| (tau - v).max(0.0)).collect();
    let s: f64 = w.iter().map(|&v| v as f64).sum();
    if s > 0.0 {
        for v in &mut w {
            *v = (*v as f64 / s) as f32;
        }
    }
    w
}

/// Flattens a closed or open shape's outline into a polyline, `pieces` straight pieces per cubic
/// segment (uniform in the curve parameter).
pub fn outline(shape: &crate::scene::Shape, pieces: usize) -> Vec<(f32, f32)> {
    let pieces = pieces.max(1);
    let mut out = Vec::with_capacity(shape.num_segments() * pieces + 1);
    for i in 0..shape.num_segments() {
        let [p0, p1, p2, p3] = shape.segment(i);
        for k in 0..pieces {
            let t = k as f32 / pieces as f32;
            out.push(cubic_at(p0, p1, p2, p3, t));
        }
    }
    if !shape.is_closed() && shape.num_segments() > 0 {
        let [.., p3] = shape.segment(shape.num_segments() - 1);
        out.push((p3.x, p3.y));
    }
    out
}

fn cubic_at(p0: Point, p1: Point, p2: Point, p3: Point, t: f32) -> (f32, f32) {
    let u = 1.0 - t;
    let (a, b, c, d) = (u * u * u, 3.0 * u * u * t, 3.0 * u * t * t, t * t * t);
    (
        a * p0.x + b * p1.x + c * p2.x + d * p3.x,
        a * p0.y + b * p1.y + c * p2.y + d * p3.y,
    )
}

/// Signed area of a closed polyline (shoelace), positive for clockwise in y-down coordinates.
pub fn polygon_area(poly: &[(f32, f32)]) -> f32 {
    let n = poly.len();
    if n < 3 {
        return 0.0;
    }
    let mut s = 0.0f32;
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        s += a.0 * b.1 - b.0 * a.1;
    }
    0.5 * s
}

const XING_EPS: f32 = 1e-6;

/// LIVE's self-intersection loss for one cubic segment `A, B, C, D`:
/// `D1 * relu(-D2) + (1 - D1) * relu(D2)` with `D1 = [AB x BC >= 0]` (held constant) and
/// `D2 = (AB x CD) / (|AB| |CD|)`. Returns the loss and its gradient with respect to the four
/// points. It is zero when the end handles turn the same way as the control polygon.
pub fn xing_segment(seg: [Point; 4]) -> (f32, [Point; 4]) {
    let [a, b, c, d] = seg;
    let u = (b.x - a.x, b.y - a.y);
    let m = (c.x - b.x, c.y - b.y);
    let v = (d.x - c.x, d.y - c.y);
    let d1 = u.0 * m.1 - u.1 * m.0 >= 0.0;
    let nu = (u.0 * u.0 + u.1 * u.1).sqrt() + XING_EPS;
    let nv = (v.0 * v.0 + v.1 * v.1).sqrt() + XING_EPS;
    let s = u.0 * v.1 - u.1 * v.0;
    let d2 = s / (nu * nv);
    // loss = relu(sign * d2) with sign = -1 when D1, +1 otherwise.
    let sign = if d1 { -1.0 } else { 1.0 };
    let z = sign * d2;
    let zero = [Point::default(); 4];
    if z <= 0.0 {
        return (0.0, zero);
    }
    // d(d2)/du and d(d2)/dv. |u| includes eps: d|u|/du = u / (|u| - eps).
    let ru = nu - XING_EPS;
    let rv = nv - XING_EPS;
    let inv = 1.0 / (nu * nv);
    let (du_nu, dv_nv) = if ru > 0.0 && rv > 0.0 {
        ((u.0 / ru, u.1 / ru), (v.0 / rv, v.1 / rv))
    } else {
        ((0.0, 0.0), (0.0, 0.0))
    };
    let gu = (
        v.1 * inv - d2 / nu * du_nu.0,
        -v.0 * inv - d2 / nu * du_nu.1,
    );
    let gv = (
        -u.1 * inv - d2 / nv * dv_nv.0,
        u.0 * inv - d2 / nv * dv_nv.1,
    );
    let (gu, gv) = ((sign * gu.0, sign * gu.1), (sign * gv.0, sign * gv.1));
    (
        z,
        [
            Point::new(-gu.0, -gu.1),
            Point::new(gu.0, gu.1),
            Point::new(-gv.0, -gv.1),
            Point::new(gv.0, gv.1),
        ],
    )
}

/// Sum of [`xing_segment`] over every cubic segment of the cubic shapes of `scene` whose index
/// is in `shapes`, times `weight`. Adds `weight * gradient` into `grad`'s `Points` group (which
/// must have `scene`'s layout) and returns the weighted loss.
pub fn xing_loss(
    scene: &Scene,
    shapes: std::ops::Range<usize>,
    weight: f32,
    grad: &mut Params,
) -> f64 {
    let mut total = 0.0f64;
    let g = grad.get_mut(ParamGroup::Points);
    let mut offset = Params::point_offset(scene, shapes.start.min(scene.shapes.len()));
    for sh in scene.shapes.iter().take(shapes.end).skip(shapes.start) {
        let n = sh.points.len();
        if matches!(sh.kind, ShapeKind::ClosedCubic | ShapeKind::OpenCubic) {
            for i in 0..sh.num_segments() {
                let (l, gs) = xing_segment(sh.segment(i));
                if l == 0.0 {
                    continue;
                }
                total += (weight * l) as f64;
                for (k, gp) in gs.iter().enumerate() {
                    let idx = (3 * i + k) % n;
                    if let Some(slot) = g.get_mut(offset + 2 * idx..offset + 2 * idx + 2) {
                        slot[0] += weight * gp.x;
                        slot[1] += weight * gp.y;
                    }
                }
            }
        }
        offset += 2 * n;
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Rgba, Shape};

    #[test]
    fn the_gradient_alone_equals_the_losss_gradient_bit_for_bit() {
        let (a, b) = (rng_image(13, 7, 3), rng_image(13, 7, 4));
        let w: Vec<f32> = (0..13 * 7).map(|i| 0.01 + (i % 7) as f32 * 0.1).collect();
        let (mut g1, mut g2) = (vec![0.0; a.data.len()], vec![1.0; a.data.len()]);
        let loss = weighted_l2_slices(&a.data, &b.data, &w, &mut g1);
        weighted_l2_grad_slices(&a.data, &b.data, &w, &mut g2);
        assert!(loss > 0.0);
        assert!(g1.iter().any(|v| *v != 0.0));
        assert!(g1.iter().zip(&g2).all(|(x, y)| x.to_bits() == y.to_bits()));
    }

    fn rng_image(w: u32, h: u32, seed: u32) -> Image {
        let mut im = Image::new(w, h);
        let mut s = seed.wrapping_mul(2654435761).wrapping_add(1);
        for px in im.data.chunks_exact_mut(4) {
            let mut next = || {
                s ^= s << 13;
                s ^= s >> 17;
                s ^= s << 5;
                (s % 1000) as f32 / 1000.0
            };
            let a = next();
            px[3] = a;
            for v in px.iter_mut().take(3) {
                *v = next() * a;
            }
        }
        im
    }

    #[test]
    fn l2_matches_psnr_and_fd_gradient() {
        let r = rng_image(5, 4, 1);
        let t = rng_image(5, 4, 2);
        let (loss, grad) = l2(&r, &t).unwrap();
        let mse = crate::image::mse_rgb_over_white(&r, &t);
        assert!((loss - mse).abs() < 1e-6 * mse.max(1.0));
        let h = 1e-3f32;
        for k in [0usize, 3, 7, 22, 79] {
            let mut rp = r.clone();
            rp.data[k] += h;
            let mut rm = r.clone();
            rm.data[k] -= h;
            let fd = (l2(&rp, &t).unwrap().0 - l2(&rm, &t).unwrap().0) / (2.0 * h as f64);
            assert!(
                (fd - grad[k] as f64).abs() < 1e-4,
                "k={k} fd={fd} an={}",
                grad[k]
            );
        }
    }

    #[test]
    fn weighted_l2_rejects_bad_inputs() {
        let r = rng_image(5, 4, 1);
        let t = rng_image(4, 5, 2);
        assert!(matches!(
            l2(&r, &t),
            Err(LossError::SizeMismatch(5, 4, 4, 5))
        ));
        assert!(matches!(
            weighted_l2(&r, &r, &[1.0; 3]),
            Err(LossError::WeightLength { .. })
        ));
    }

    #[test]
    fn udf_weights_focus_on_the_outline() {
        let circle = Shape::circle(16.0, 16.0, 6.0, 4, Rgba::BLACK).unwrap();
        let w = udf_weights(32, 32, &[outline(&circle, 8)], 4.0);
        let s: f32 = w.iter().sum();
        assert!((s - 1.0).abs() < 1e-4);
        // On the outline (x = 22) beats the centre and far corners (zero).
        let on = w[16 * 32 + 21];
        assert!(on > 0.0);
        assert_eq!(w[16 * 32 + 16], 0.0);
        assert_eq!(w[0], 0.0);
    }

    #[test]
    fn xing_is_zero_for_a_circle_and_positive_for_a_twisted_segment() {
        let c = Shape::circle(10.0, 10.0, 5.0, 4, Rgba::BLACK).unwrap();
        for i in 0..4 {
            assert_eq!(xing_segment(c.segment(i)).0, 0.0);
        }
        // Handles crossing each other: a loop.
        let twisted = [
            Point::new(0.0, 0.0),
            Point::new(10.0, 10.0),
            Point::new(10.0, 0.0),
            Point::new(0.0, 10.0),
        ];
        let (l, _) = xing_segment(twisted);
        assert!(l > 0.5, "loss {l}");
    }

    #[test]
    fn xing_gradient_matches_finite_differences() {
        let segs = [
            [
                Point::new(0.0, 0.0),
                Point::new(10.0, 10.0),
                Point::new(10.0, 0.0),
                Point::new(0.0, 10.0),
            ],
            [
                Point::new(1.0, 2.0),
                Point::new(4.0, -3.0),
                Point::new(7.0, 5.0),
                Point::new(3.0, 1.0),
            ],
            [
                Point::new(0.0, 0.0),
                Point::new(5.0, 1.0),
                Point::new(3.0, 6.0),
                Point::new(9.0, -2.0),
            ],
        ];
        let mut checked = 0;
        for seg in segs {
            let (l, g) = xing_segment(seg);
            if l == 0.0 {
                continue;
            }
            checked += 1;
            let h = 1e-3f32;
            for k in 0..4 {
                for axis in 0..2 {
                    let bump = |delta: f32| {
                        let mut s = seg;
                        if axis == 0 {
                            s[k].x += delta;
                        } else {
                            s[k].y += delta;
                        }
                        xing_segment(s).0 as f64
                    };
                    let fd = (bump(h) - bump(-h)) / (2.0 * h as f64);
                    let an = if axis == 0 { g[k].x } else { g[k].y } as f64;
                    assert!((fd - an).abs() < 2e-3, "k={k} axis={axis} fd={fd} an={an}");
                }
            }
        }
        assert!(checked >= 2, "need non-trivial segments, got {checked}");
    }

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn xing_loss_scatters_into_scene_layout() {
        let mut scene = Scene::new(32, 32, Rgba::WHITE).unwrap();
        scene
            .shapes
            .push(Shape::circle(5.0, 5.0, 3.0, 4, Rgba::BLACK).unwrap());
        let twisted = Point::list(&[
            (0.0, 0.0),
            (10.0, 10.0),
            (10.0, 0.0),
            (0.0, 10.0),
            (-3.0, 12.0),
            (-5.0, 2.0),
        ]);
        scene
            .shapes
            .push(Shape::closed_cubic(twisted, Rgba::BLACK).unwrap());
        let mut g = Params::zeros_like(&scene);
        let l = xing_loss(&scene, 0..2, 0.5, &mut g);
        assert!(l > 0.0);
        let pts = g.get(ParamGroup::Points);
        assert!(pts[..24].iter().all(|v| *v == 0.0), "circle has no loss");
        assert!(pts[24..].iter().any(|v| *v != 0.0));
        // Finite differences over the whole-scene function.
        let h = 1e-3f32;
        for k in 24..36 {
            let eval = |delta: f32| {
                let mut s = scene.clone();
                let mut p = Params::from_scene(&s);
                p.get_mut(ParamGroup::Points)[k] += delta;
                p.write_to(&mut s).unwrap();
                xing_loss(&s, 0..2, 0.5, &mut Params::zeros_like(&s))
            };
            let fd = (eval(h) - eval(-h)) / (2.0 * h as f64);
            assert!(
                (fd - pts[k] as f64).abs() < 2e-3,
                "k={k} fd={fd} an={}",
                pts[k]
            );
        }
        // Only the requested range contributes.
        let mut g2 = Params::zeros_like(&scene);
        assert_eq!(xing_loss(&scene, 0..1, 0.5, &mut g2), 0.0);
    }
}
