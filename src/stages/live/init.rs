//! Component-wise path initialisation: new paths start as small circles at the largest
//! connected regions of high error, coloured from the target there.

use crate::image::Image;
use crate::image::ops::{connected_components, error_map};
use crate::scene::{Rgba, Shape};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;

/// Settings for [`init_paths`].
#[derive(Clone, Debug, PartialEq)]
pub struct InitConfig {
    /// Circle radius in pixels (capped by the region's inscribed radius).
    pub radius: f32,
    /// Cubic segments per circle.
    pub segments: usize,
    /// Per-pixel squared RGB error (sum over channels) above which a pixel is "wrong".
    pub error_threshold: f32,
    /// Squared RGB distance under which neighbouring target pixels belong to the same region.
    pub colour_tolerance: f32,
    /// Regions smaller than this (pixels) are ignored.
    pub min_area: usize,
    /// Grow the circle to the region's inscribed radius (at least `radius`).
    pub fit_region: bool,
}

impl Default for InitConfig {
    fn default() -> Self {
        Self {
            radius: 5.0,
            segments: 4,
            error_threshold: 0.01,
            colour_tolerance: 0.01,
            min_area: 4,
            fit_region: false,
        }
    }
}

/// A region chosen for a new path.
#[derive(Clone, Debug, PartialEq)]
pub struct Seed {
    pub x: f32,
    pub y: f32,
    pub radius: f32,
    pub colour: Rgba,
    /// Pixels in the region.
    pub area: usize,
}

/// Finds up to `k` seeds: connected regions of pixels whose error (render vs target, over
/// white) exceeds the threshold and whose target colours are alike, largest total error first.
/// Each seed sits at the region's most interior pixel (jittered by under half a pixel with
/// `rng`) and carries the region's mean target colour (opaque, over white).
pub fn find_seeds(
    current: &Image,
    target: &Image,
    k: usize,
    cfg: &InitConfig,
    rng: &mut ChaCha8Rng,
) -> Vec<Seed> {
    if k == 0 || current.width != target.width || current.height != target.height {
        return Vec::new();
    }
    let err = error_map(current, target);
    let white: Vec<[f32; 3]> = target
        .data
        .chunks_exact(4)
        .map(|p| [p[0] + 1.0 - p[3], p[1] + 1.0 - p[3], p[2] + 1.0 - p[3]])
        .collect();
    let mask: Vec<bool> = err.iter().map(|&e| e > cfg.error_threshold).collect();
    let tol = cfg.colour_tolerance;
    let (labels, comps) = connected_components(target.width, target.height, &mask, &err, |i, j| {
        let (a, b) = (white[i], white[j]);
        (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2) < tol
    });
    let mut order: Vec<usize> = (0..comps.len())
        .filter(|&c| comps[c].area >= cfg.min_area)
        .collect();
    order.sort_by(|&a, &b| {
        comps[b]
            .weight
            .total_cmp(&comps[a].weight)
            .then(comps[b].area.cmp(&comps[a].area))
            .then(a.cmp(&b))
    });
    order.truncate(k);
    // Mean target colour per chosen component.
    let mut sums = vec![[0.0f64; 3]; comps.len()];
    for (i, &l) in labels.iter().enumerate() {
        if l != crate::image::ops::NO_LABEL {
            for c in 0..3 {
                sums[l as usize][c] += white[i][c] as f64;
            }
        }
    }
    order
        .into_iter()
        .map(|c| {
            let comp = &comps[c];
            let n = comp.area.max(1) as f64;
            let s = sums[c];
            let jx: f32 = rng.random_range(-0.25..0.25);
            let jy: f32 = rng.random_range(-0.25..0.25);
            Seed {
                x: comp.interior.0 as f32 + 0.5 + jx,
                y: comp.interior.1 as f32 + 0.5 + jy,
                radius: if cfg.fit_region {
                    (0.9 * comp.inradius).max(cfg.radius)
                } else {
                    cfg.radius.min(comp.inradius.max(1.0))
                },
                colour: Rgba::new((s[0] / n) as f32, (s[1] / n) as f32, (s[2] / n) as f32, 1.0)
                    .clamped(),
                area: comp.area,
            }
        })
        .collect()
}

/// Circles (closed cubic paths) for [`find_seeds`].
pub fn init_paths(
    current: &Image,
    target: &Image,
    k: usize,
    cfg: &InitConfig,
    rng: &mut ChaCha8Rng,
) -> Vec<Shape> {
    find_seeds(current, target, k, cfg, rng)
        .into_iter()
        .filter_map(|s| Shape::circle(s.x, s.y, s.radius, cfg.segments, s.colour).ok())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// White 64x64 target with a big red square and a small blue one.
    fn target() -> Image {
        let (red, blue) = ([1.0, 0.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0]);
        super::super::tests::white_with_rects(64, &[(8..40, 8..40, red), (48..56, 48..56, blue)])
    }

    #[test]
    fn seeds_land_in_largest_error_regions_with_their_colour() {
        let t = target();
        let blank = Image::filled(64, 64, [1.0, 1.0, 1.0, 1.0]);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let seeds = find_seeds(&blank, &t, 5, &InitConfig::default(), &mut rng);
        assert_eq!(seeds.len(), 2, "two wrong regions");
        let big = &seeds[0];
        assert!((8.0..40.0).contains(&big.x) && (8.0..40.0).contains(&big.y));
        assert!((big.x - 24.0).abs() < 2.0 && (big.y - 24.0).abs() < 2.0);
        assert!(big.colour.r > 0.99 && big.colour.g < 0.01);
        assert_eq!(big.radius, 5.0);
        let small = &seeds[1];
        assert!(small.colour.b > 0.99 && small.colour.r < 0.01);
        assert!((48.0..56.0).contains(&small.x));
        // Once the render matches, nothing is left to seed.
        assert!(find_seeds(&t, &t, 5, &InitConfig::default(), &mut rng).is_empty());
        // k bounds the count; the biggest region comes first.
        let one = find_seeds(&blank, &t, 1, &InitConfig::default(), &mut rng);
        assert_eq!(one.len(), 1);
        assert!(one[0].area > 900);
    }

    #[test]
    fn circles_are_valid_and_deterministic_per_seed() {
        let t = target();
        let blank = Image::filled(64, 64, [1.0, 1.0, 1.0, 1.0]);
        let cfg = InitConfig::default();
        let a = init_paths(&blank, &t, 4, &cfg, &mut ChaCha8Rng::seed_from_u64(7));
        let b = init_paths(&blank, &t, 4, &cfg, &mut ChaCha8Rng::seed_from_u64(7));
        assert_eq!(a, b);
        assert_eq!(a[0].points.len(), 12);
        let c = init_paths(&blank, &t, 4, &cfg, &mut ChaCha8Rng::seed_from_u64(8));
        assert_ne!(a, c, "jitter depends on the seed");
    }
}
