//! Small image operations used by tracing: resampling, per-pixel error maps, connected
//! components and a chamfer distance transform.

use super::Image;

/// Resamples `src` to `width x height` with an area (box) filter when shrinking and bilinear
/// interpolation when growing. Works on premultiplied values, so edges do not bleed colour.
pub fn resize(src: &Image, width: u32, height: u32) -> Image {
    let (sw, sh) = (src.width as usize, src.height as usize);
    let (dw, dh) = (width.max(1) as usize, height.max(1) as usize);
    if sw == dw && sh == dh {
        return src.clone();
    }
    let mut out = Image::new(dw as u32, dh as u32);
    let sx = sw as f32 / dw as f32;
    let sy = sh as f32 / dh as f32;
    for y in 0..dh {
        for x in 0..dw {
            let mut acc = [0.0f32; 4];
            if sx > 1.0 || sy > 1.0 {
                // Box filter over the source footprint [x0, x1) x [y0, y1).
                let (x0, x1) = (x as f32 * sx, (x + 1) as f32 * sx);
                let (y0, y1) = (y as f32 * sy, (y + 1) as f32 * sy);
                let mut wsum = 0.0f32;
                let mut yy = y0.floor() as usize;
                while (yy as f32) < y1 && yy < sh {
                    let wy = ((yy + 1) as f32).min(y1) - (yy as f32).max(y0);
                    let mut xx = x0.floor() as usize;
                    while (xx as f32) < x1 && xx < sw {
                        let wx = ((xx + 1) as f32).min(x1) - (xx as f32).max(x0);
                        let w = wx * wy;
                        let i = 4 * (yy * sw + xx);
                        for (a, v) in acc.iter_mut().zip(&src.data[i..i + 4]) {
                            *a += w * v;
                        }
                        wsum += w;
                        xx += 1;
                    }
                    yy += 1;
                }
                if wsum > 0.0 {
                    for v in &mut acc {
                        *v /= wsum;
                    }
                }
            } else {
                let fx = ((x as f32 + 0.5) * sx - 0.5).clamp(0.0, (sw - 1) as f32);
                let fy = ((y as f32 + 0.5) * sy - 0.5).clamp(0.0, (sh - 1) as f32);
                let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
                let (x1, y1) = ((x0 + 1).min(sw - 1), (y0 + 1).min(sh - 1));
                let (tx, ty) = (fx - x0 as f32, fy - y0 as f32);
                for (c, a) in acc.iter_mut().enumerate() {
                    let g = |xx: usize, yy: usize| src.data[4 * (yy * sw + xx) + c];
                    let top = g(x0, y0) * (1.0 - tx) + g(x1, y0) * tx;
                    let bot = g(x0, y1) * (1.0 - tx) + g(x1, y1) * tx;
                    *a = top * (1.0 - ty) + bot * ty;
                }
            }
            out.data[4 * (y * dw + x)..4 * (y * dw + x) + 4].copy_from_slice(&acc);
        }
    }
    out
}

/// Per-pixel squared RGB error of `a` against `b`, both composited over white
/// (length `width * height`). Sizes must match; extra pixels of the larger image are ignored.
pub fn error_map(a: &Image, b: &Image) -> Vec<f32> {
    a.data
        .chunks_exact(4)
        .zip(b.data.chunks_exact(4))
        .map(|(p, q)| {
            (0..3)
                .map(|c| {
                    let d = (p[c] + 1.0 - p[3]) - (q[c] + 1.0 - q[3]);
                    d * d
                })
                .sum()
        })
        .collect()
}

/// One connected component of a labelled image.
#[derive(Clone, Debug, PartialEq)]
pub struct Component {
    /// Label in the label map (index into the returned component list).
    pub label: u32,
    /// Number of pixels.
    pub area: usize,
    /// Sum of the per-pixel weights (e.g. error) over the component.
    pub weight: f32,
    /// Pixel inside the component farthest from its boundary (chamfer distance).
    pub interior: (u32, u32),
    /// That distance in pixels: roughly the radius of the largest inscribed disc.
    pub inradius: f32,
}

/// Label value for pixels outside every component.
pub const NO_LABEL: u32 = u32::MAX;

/// 4-connected components of the pixels where `mask` is true, where neighbours also join only
/// if `same(i, j)` holds for their pixel indices (e.g. similar target colour). Returns the label
/// map (`NO_LABEL` outside the mask) and the components in label order.
pub fn connected_components(
    width: u32,
    height: u32,
    mask: &[bool],
    weights: &[f32],
    same: impl Fn(usize, usize) -> bool,
) -> (Vec<u32>, Vec<Component>) {
    let (w, h) = (width as usize, height as usize);
    let n = w * h;
    let mut labels = vec![NO_LABEL; n];
    let mut comps = Vec::new();
    let mut stack = Vec::new();
    for start in 0..n.min(mask.len()) {
        if !mask[start] || labels[start] != NO_LABEL {
            continue;
        }
        let label = comps.len() as u32;
        labels[start] = label;
        stack.push(start);
        let (mut area, mut weight) = (0usize, 0.0f32);
        while let Some(i) = stack.pop() {
            area += 1;
            weight += weights.get(i).copied().unwrap_or(0.0);
            let (x, y) = (i % w, i / w);
            let mut visit = |j: usize| {
                if mask[j] && labels[j] == NO_LABEL && same(i, j) {
                    labels[j] = label;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - w);
            }
            if y + 1 < h {
                visit(i + w);
            }
        }
        comps.push(Component {
            label,
            area,
            weight,
            interior: ((start % w) as u32, (start / w) as u32),
            inradius: 0.0,
        });
    }
    // Interior points: chamfer distance to the nearest pixel with another label.
    let dist = distance_to_label_boundary(width, height, &labels);
    for (i, &l) in labels.iter().enumerate() {
        if l != NO_LABEL {
            let c = &mut comps[l as usize];
            if dist[i] > c.inradius {
                c.inradius = dist[i];
                c.interior = ((i % w) as u32, (i / w) as u32);
            }
        }
    }
    (labels, comps)
}

/// Chamfer (3-4) distance in pixels from every pixel to the nearest pixel whose label differs
/// from its own (the image border counts as a boundary). Boundary pixels get distance 0.5.
pub fn distance_to_label_boundary(width: u32, height: u32, labels: &[u32]) -> Vec<f32> {
    let (w, h) = (width as usize, height as usize);
    let inf = f32::INFINITY;
    let mut d = vec![inf; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let l = labels[i];
            let edge = x == 0
                || y == 0
                || x + 1 == w
                || y + 1 == h
                || labels[i - 1] != l
                || labels[i + 1] != l
                || labels[i - w] != l
                || labels[i + w] != l;
            if edge {
                d[i] = 0.5;
            }
        }
    }
    chamfer(w, h, &mut d);
    d
}

/// Unsigned distance from every pixel centre to the nearest of the given polylines, capped at
/// `cap` (pixels farther than `cap` get `cap`). Exact point-to-segment distances, computed only
/// within `cap` of each segment.
pub fn distance_to_polylines(
    width: u32,
    height: u32,
    polylines: &[Vec<(f32, f32)>],
    closed: bool,
    cap: f32,
) -> Vec<f32> {
    let (w, h) = (width as usize, height as usize);
    let mut d = vec![cap; w * h];
    for line in polylines {
        let m = line.len();
        if m == 0 {
            continue;
        }
        let segs = if closed {
            m
        } else {
            m.saturating_sub(1).max(1)
        };
        for k in 0..segs {
            let a = line[k];
            let b = line[(k + 1) % m];
            let x0 = (a.0.min(b.0) - cap).floor().max(0.0) as usize;
            let x1 = ((a.0.max(b.0) + cap).ceil().max(0.0) as usize).min(w);
            let y0 = (a.1.min(b.1) - cap).floor().max(0.0) as usize;
            let y1 = ((a.1.max(b.1) + cap).ceil().max(0.0) as usize).min(h);
            let (ex, ey) = (b.0 - a.0, b.1 - a.1);
            let len2 = ex * ex + ey * ey;
            for y in y0..y1 {
                for x in x0..x1 {
                    let (px, py) = (x as f32 + 0.5 - a.0, y as f32 + 0.5 - a.1);
                    let t = if len2 > 0.0 {
                        ((px * ex + py * ey) / len2).clamp(0.0, 1.0)
                    } else {
                        0.0
                    };
                    let (qx, qy) = (px - t * ex, py - t * ey);
                    let dist = (qx * qx + qy * qy).sqrt();
                    let cell = &mut d[y * w + x];
                    if dist < *cell {
                        *cell = dist;
                    }
                }
            }
        }
    }
    d
}

fn chamfer(w: usize, h: usize, d: &mut [f32]) {
    const A: f32 = 1.0;
    const B: f32 = std::f32::consts::SQRT_2;
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let mut v = d[i];
            if x > 0 {
                v = v.min(d[i - 1] + A);
            }
            if y > 0 {
                v = v.min(d[i - w] + A);
                if x > 0 {
                    v = v.min(d[i - w - 1] + B);
                }
                if x + 1 < w {
                    v = v.min(d[i - w + 1] + B);
                }
            }
            d[i] = v;
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let i = y * w + x;
            let mut v = d[i];
            if x + 1 < w {
                v = v.min(d[i + 1] + A);
            }
            if y + 1 < h {
                v = v.min(d[i + w] + A);
                if x + 1 < w {
                    v = v.min(d[i + w + 1] + B);
                }
                if x > 0 {
                    v = v.min(d[i + w - 1] + B);
                }
            }
            d[i] = v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resize_preserves_flat_colour_and_averages() {
        let im = Image::filled(10, 6, [0.2, 0.4, 0.6, 1.0]);
        for (w, h) in [(5, 3), (20, 12), (7, 7)] {
            let r = resize(&im, w, h);
            assert_eq!((r.width, r.height), (w, h));
            for px in r.data.chunks_exact(4) {
                assert!((px[1] - 0.4).abs() < 1e-5);
            }
        }
        // 2x2 -> 1x1 is the mean.
        let mut im = Image::new(2, 2);
        im.data[0] = 1.0;
        let r = resize(&im, 1, 1);
        assert!((r.data[0] - 0.25).abs() < 1e-6);
    }

    #[test]
    fn components_split_by_mask_and_similarity() {
        // 6x3: left block (x<2) and right block (x>3) masked, middle not.
        let (w, h) = (6u32, 3u32);
        let mask: Vec<bool> = (0..18).map(|i| !(2..4).contains(&(i % 6))).collect();
        let weights = vec![1.0; 18];
        let (labels, comps) = connected_components(w, h, &mask, &weights, |_, _| true);
        assert_eq!(comps.len(), 2);
        assert_eq!(comps[0].area, 6);
        assert_eq!(labels[2], NO_LABEL);
        // Similarity splits every pixel when nothing is similar.
        let (_, comps) = connected_components(w, h, &mask, &weights, |_, _| false);
        assert_eq!(comps.len(), 12);
    }

    #[test]
    fn interior_point_is_centre_of_a_disc() {
        let (w, h) = (41u32, 41u32);
        let mask: Vec<bool> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32 - 20.0, (i / w) as f32 - 20.0);
                x * x + y * y <= 100.0
            })
            .collect();
        let (_, comps) = connected_components(w, h, &mask, &vec![0.0; mask.len()], |_, _| true);
        let main = comps.iter().max_by_key(|c| c.area).unwrap();
        let (x, y) = main.interior;
        assert!((x as i32 - 20).abs() <= 1 && (y as i32 - 20).abs() <= 1);
        assert!(
            main.inradius > 8.0 && main.inradius < 12.0,
            "{}",
            main.inradius
        );
    }

    #[test]
    fn polyline_distance_is_exact_near_and_capped_far() {
        let d = distance_to_polylines(20, 20, &[vec![(0.0, 10.0), (20.0, 10.0)]], false, 5.0);
        assert!((d[10 * 20 + 3] - 0.5).abs() < 1e-5);
        assert!((d[13 * 20 + 3] - 3.5).abs() < 1e-5);
        assert_eq!(d[0], 5.0);
    }
}
