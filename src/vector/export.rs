//! Compact SVG text: the coarsest coordinate grid that still renders like the scene.
//!
//! [`compact_svg`] writes the scene with [`crate::svg::to_svg`] on each grid of [`GRIDS`] in
//! turn, from 1 px down to 1/1000 px, reads each back with [`crate::svg::from_svg`], renders it
//! with [`crate::raster::render`] at the scene's size and keeps the first whose render is within
//! [`Tolerance`] of the reference. A grid of `1/k` px is written as integers in a `viewBox` `k`
//! times the pixel size ([`SvgOptions::units_per_px`]; `width` and `height` stay in pixels):
//! `1234` instead of `12.34`, one character less per number than decimals on the same grid, and
//! grids of 1/2, 1/4, 1/5, 1/20, 1/50 px between the powers of ten that decimals cannot write.
//!
//! The reference is the scene at full (f32) precision with its colours as the SVG holds them
//! (8-bit RGB, opacity to 1/1000: [`crate::svg::written_color`]), so the choice is about
//! coordinates and stroke widths only; colour rounding is the same on every grid.
//!
//! # Tolerance
//! Both over the premultiplied RGBA values (0..=1, all four channels of every pixel):
//! - mean absolute difference at most 0.5/255: on average under half an 8-bit step;
//! - largest absolute difference at most 8/255: a single channel may move more, because a
//!   rounded coordinate shifts an anti-aliased edge (a 0.05 px shift of a black-on-white edge
//!   changes its pixels by up to 13/255), but no pixel changes visibly. Requiring the maximum
//!   under 0.5/255 would ask for 3 decimals on almost every curved scene.

use crate::image::Image;
use crate::scene::Scene;
use crate::svg::{SvgOptions, from_svg, to_svg, written_color};

/// Decimals of the opacities [`compact_svg`] writes (as [`crate::svg::written_color`] at this
/// precision).
pub const MAX_DECIMALS: u8 = 3;

/// The grids [`compact_svg`] tries, coarsest first, as user units per pixel (a grid of `1/k` px).
pub const GRIDS: [u32; 11] = [1, 2, 4, 5, 10, 20, 25, 50, 100, 200, 1000];

/// How close the re-imported render must stay to the reference (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tolerance {
    /// Largest mean absolute difference per channel value (0..=1 scale).
    pub mean_abs: f64,
    /// Largest absolute difference of any channel value (0..=1 scale).
    pub max_abs: f64,
}

impl Default for Tolerance {
    fn default() -> Self {
        Tolerance {
            mean_abs: 0.5 / 255.0,
            max_abs: 8.0 / 255.0,
        }
    }
}

/// What [`compact_svg`] chose.
#[derive(Clone, Debug, PartialEq)]
pub struct CompactSvg {
    /// The SVG document.
    pub svg: String,
    /// User units per pixel: coordinates lie on a grid of `1/units_per_px` px, written as
    /// integers (one of [`GRIDS`]).
    pub units_per_px: u32,
    /// Mean absolute difference of its render from the reference (0..=1 scale).
    pub mean_abs: f64,
    /// Largest absolute difference of its render from the reference (0..=1 scale).
    pub max_abs: f64,
    /// Whether it is within the tolerance (and accepted, see [`compact_svg_checked`]). `false` only when even the finest grid is not (then
    /// `svg` is written on it), e.g. for shapes too thin to survive rounding or a scene the
    /// importer reads back differently.
    pub within: bool,
}

/// The scene written on the coarsest grid of [`GRIDS`] whose render stays within
/// [`Tolerance::default`] of the scene's own render; `opts.precision` and `opts.units_per_px`
/// are ignored, the other options are kept. See the module docs.
pub fn compact_svg(scene: &Scene, opts: &SvgOptions) -> CompactSvg {
    compact_svg_within(scene, opts, Tolerance::default())
}

/// [`compact_svg`] with another tolerance.
pub fn compact_svg_within(scene: &Scene, opts: &SvgOptions, tol: Tolerance) -> CompactSvg {
    compact_svg_checked(scene, opts, tol, |_, _| true)
}

/// [`compact_svg_within`] where a grid also needs `accept` to hold for its text and the scene
/// read back from it (e.g. that rounding made no outline meet itself).
pub fn compact_svg_checked(
    scene: &Scene,
    opts: &SvgOptions,
    tol: Tolerance,
    accept: impl Fn(&str, &Scene) -> bool,
) -> CompactSvg {
    let reference = crate::raster::render(&colors_as_written(scene));
    let attempt = |units_per_px: u32| {
        let o = SvgOptions {
            precision: 0,
            units_per_px,
            ..*opts
        };
        let svg = to_svg(scene, &o);
        let (mean_abs, max_abs, accepted) = match from_svg(&svg) {
            Ok(back) if (back.width, back.height) == (scene.width, scene.height) => {
                let (mean, max) = diff(&reference, &crate::raster::render(&back));
                (mean, max, accept(&svg, &back))
            }
            _ => (f64::INFINITY, f64::INFINITY, false),
        };
        CompactSvg {
            svg,
            units_per_px,
            mean_abs,
            max_abs,
            within: mean_abs <= tol.mean_abs && max_abs <= tol.max_abs && accepted,
        }
    };
    // A finer grid stays closer to the scene, so the first grid within is found by bisection
    // (four tries of eleven); the grid before the one returned was tried and is not within.
    let (mut lo, mut hi) = (0, GRIDS.len());
    let mut best: Option<CompactSvg> = None;
    while lo < hi {
        let mid = (lo + hi) / 2;
        let c = attempt(GRIDS[mid]);
        if c.within {
            hi = mid;
            best = Some(c);
        } else {
            lo = mid + 1;
        }
    }
    // None within: the finest grid, marked as not within.
    best.unwrap_or_else(|| attempt(GRIDS[GRIDS.len() - 1]))
}

/// `scene` with every colour as the SVG holds it.
fn colors_as_written(scene: &Scene) -> Scene {
    let mut s = scene.clone();
    let c = |c| written_color(c, MAX_DECIMALS);
    s.background = c(s.background);
    for sh in &mut s.shapes {
        sh.fill = sh.fill.map(c);
        if let Some(st) = sh.stroke.as_mut() {
            st.color = c(st.color);
        }
    }
    s
}

/// Mean and largest absolute difference over all channel values of two same-size images.
pub fn diff(a: &Image, b: &Image) -> (f64, f64) {
    if a.data.len() != b.data.len() || a.data.is_empty() {
        return (f64::INFINITY, f64::INFINITY);
    }
    let (mut sum, mut max) = (0.0f64, 0.0f64);
    for (x, y) in a.data.iter().zip(&b.data) {
        let d = (*x as f64 - *y as f64).abs();
        sum += d;
        max = max.max(d);
    }
    (sum / a.data.len() as f64, max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Point, Rgba, Shape, Stroke};

    fn scene(offset: f32) -> Scene {
        let mut s = Scene::new(64, 64, Rgba::WHITE).unwrap();
        let o = offset;
        s.shapes.push(
            Shape::circle(24.0 + o, 28.0 + o, 14.0, 4, Rgba::new(0.8, 0.1, 0.1, 1.0)).unwrap(),
        );
        s.shapes.push(
            Shape::polygon(
                Point::list(&[(30.0 + o, 6.0), (60.0, 12.0 + o), (44.0 + o, 58.0 - o)]),
                Rgba::new(0.1, 0.3, 0.9, 0.8),
            )
            .unwrap(),
        );
        s.shapes.push(
            Shape::open_cubic(
                Point::list(&[
                    (4.0, 50.0 + o),
                    (20.0 + o, 36.0),
                    (36.0, 62.0 - o),
                    (60.0 - o, 44.0),
                ]),
                Stroke::round(Rgba::BLACK, 2.0),
            )
            .unwrap(),
        );
        s
    }

    #[test]
    fn integer_scenes_stay_in_pixels_and_fractional_ones_get_a_finer_grid() {
        // The circle's control points are not integers; make every point one.
        let mut int = scene(0.0);
        for sh in &mut int.shapes {
            for p in &mut sh.points {
                *p = Point::new(p.x.round(), p.y.round());
            }
        }
        let c = compact_svg(&int, &SvgOptions::default());
        assert_eq!(c.units_per_px, 1, "{c:?}");
        assert!(c.svg.contains(r#"viewBox="0 0 64 64""#), "{}", c.svg);
        assert!(c.within && c.max_abs < 1e-4, "{c:?}");

        let frac = scene(0.237);
        let c = compact_svg(&frac, &SvgOptions::default());
        assert!(c.units_per_px > 1 && c.within, "{c:?}");
        // Pixels outside, user units inside; integers only.
        let k = c.units_per_px;
        let head = format!(
            r#"width="64" height="64" viewBox="0 0 {} {}""#,
            64 * k,
            64 * k
        );
        assert!(c.svg.contains(&head), "{}", c.svg);
        for d in c.svg.split(r#" d=""#).skip(1) {
            let d = &d[..d.find('"').unwrap()];
            assert!(!d.contains('.'), "{d}");
        }
        let tol = Tolerance::default();
        assert!(c.mean_abs <= tol.mean_abs && c.max_abs <= tol.max_abs);
        // Check the claim independently: the text it returns renders within the tolerance.
        let back = from_svg(&c.svg).unwrap();
        let (mean, max) = diff(
            &crate::raster::render(&colors_as_written(&frac)),
            &crate::raster::render(&back),
        );
        assert!(mean <= tol.mean_abs && max <= tol.max_abs, "{mean} {max}");
        // The next coarser grid is out of tolerance (that is why it was not chosen).
        let i = GRIDS.iter().position(|&g| g == k).unwrap();
        let fewer = to_svg(
            &frac,
            &SvgOptions {
                precision: 0,
                units_per_px: GRIDS[i - 1],
                ..Default::default()
            },
        );
        let (mean, max) = diff(
            &crate::raster::render(&colors_as_written(&frac)),
            &crate::raster::render(&from_svg(&fewer).unwrap()),
        );
        assert!(mean > tol.mean_abs || max > tol.max_abs, "{mean} {max}");
        // Options other than the precision are kept.
        let grouped = compact_svg(
            &frac,
            &SvgOptions {
                ids: true,
                ..Default::default()
            },
        );
        assert!(grouped.svg.contains(r#"id="p1""#));
        assert_eq!(grouped.units_per_px, c.units_per_px);
    }

    #[test]
    fn gradients_on_a_finer_grid_take_the_scale_into_their_numbers() {
        use crate::scene::{Affine, Gradient, GradientGeometry, GradientStop, Gradients, Spread};
        let mut s = scene(0.237);
        let stop = |offset, color| GradientStop { offset, color };
        s.shapes[0].gradients = Some(Box::new(Gradients {
            fill: Some(Gradient {
                geometry: GradientGeometry::Linear {
                    x1: 10.5,
                    y1: 14.0,
                    x2: 38.5,
                    y2: 42.2,
                },
                transform: Affine::IDENTITY,
                spread: Spread::Pad,
                stops: vec![
                    stop(0.0, Rgba::new(1.0, 0.5, 0.0, 1.0)),
                    stop(0.25, Rgba::new(0.0, 0.2, 0.8, 1.0)),
                ],
            }),
            ..Default::default()
        }));
        let c = compact_svg(&s, &SvgOptions::default());
        let k = c.units_per_px;
        assert!(k > 1 && c.within, "{c:?}");
        // No `gradientTransform` for the viewBox's scale: the geometry is in user units, as
        // short as the grid allows; the default offset 0 is left out, the other has no
        // leading zero.
        assert!(!c.svg.contains("gradientTransform"), "{}", c.svg);
        let x1 = format!(r#"x1="{}""#, 10.5 * k as f32);
        assert!(c.svg.contains(&x1), "{x1} {}", c.svg);
        assert!(
            c.svg.contains(r##"<stop stop-color="#ff8000"/>"##),
            "{}",
            c.svg
        );
        assert!(c.svg.contains(r#"<stop offset=".25""#), "{}", c.svg);
        // It reads back as the same gradient, k times larger.
        let back = from_svg(&c.svg).unwrap();
        let g = back.shapes[0]
            .gradients
            .as_ref()
            .unwrap()
            .fill
            .as_ref()
            .unwrap();
        let GradientGeometry::Linear { x1, y2, .. } = g.geometry else {
            panic!("{g:?}");
        };
        assert_eq!((x1, y2), (10.5 * k as f32, 42.2 * k as f32));
    }
}
