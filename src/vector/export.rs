//! Compact SVG text: the fewest decimals that still render like the scene.
//!
//! [`compact_svg`] writes the scene with [`crate::svg::to_svg`] at 0, 1, 2 and 3 decimals, reads
//! each back with [`crate::svg::from_svg`], renders it with [`crate::raster::render`] at the
//! scene's size and keeps the first whose render is within [`Tolerance`] of the reference.
//!
//! The reference is the scene at full (f32) precision with its colours as the SVG holds them
//! (8-bit RGB, opacity to 1/1000: [`crate::svg::written_color`]), so the choice is about
//! coordinates and stroke widths only; colour rounding is the same at every precision.
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

/// Most decimals [`compact_svg`] tries.
pub const MAX_DECIMALS: u8 = 3;

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
    /// The decimals used (`0..=MAX_DECIMALS`).
    pub precision: u8,
    /// Mean absolute difference of its render from the reference (0..=1 scale).
    pub mean_abs: f64,
    /// Largest absolute difference of its render from the reference (0..=1 scale).
    pub max_abs: f64,
    /// Whether it is within the tolerance. `false` only when even [`MAX_DECIMALS`] decimals are
    /// not (then `svg` is written with `MAX_DECIMALS`), e.g. for shapes too thin to survive
    /// rounding or a scene the importer reads back differently.
    pub within: bool,
}

/// The scene written with the fewest decimals (0..=3) whose render stays within
/// [`Tolerance::default`] of the scene's own render; `opts.precision` is ignored, the other
/// options are kept. See the module docs.
pub fn compact_svg(scene: &Scene, opts: &SvgOptions) -> CompactSvg {
    compact_svg_within(scene, opts, Tolerance::default())
}

/// [`compact_svg`] with another tolerance.
pub fn compact_svg_within(scene: &Scene, opts: &SvgOptions, tol: Tolerance) -> CompactSvg {
    let reference = crate::raster::render(&colors_as_written(scene));
    let mut last = None;
    for precision in 0..=MAX_DECIMALS {
        let o = SvgOptions { precision, ..*opts };
        let svg = to_svg(scene, &o);
        let (mean_abs, max_abs) = match from_svg(&svg) {
            Ok(back) if (back.width, back.height) == (scene.width, scene.height) => {
                diff(&reference, &crate::raster::render(&back))
            }
            _ => (f64::INFINITY, f64::INFINITY),
        };
        let within = mean_abs <= tol.mean_abs && max_abs <= tol.max_abs;
        let out = CompactSvg {
            svg,
            precision,
            mean_abs,
            max_abs,
            within,
        };
        if within {
            return out;
        }
        last = Some(out);
    }
    last.unwrap_or_else(|| CompactSvg {
        svg: to_svg(scene, opts),
        precision: opts.precision,
        mean_abs: f64::INFINITY,
        max_abs: f64::INFINITY,
        within: false,
    })
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
pub(super) fn diff(a: &Image, b: &Image) -> (f64, f64) {
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
                vec![
                    Point::new(30.0 + o, 6.0),
                    Point::new(60.0, 12.0 + o),
                    Point::new(44.0 + o, 58.0 - o),
                ],
                Rgba::new(0.1, 0.3, 0.9, 0.8),
            )
            .unwrap(),
        );
        s.shapes.push(
            Shape::open_cubic(
                vec![
                    Point::new(4.0, 50.0 + o),
                    Point::new(20.0 + o, 36.0),
                    Point::new(36.0, 62.0 - o),
                    Point::new(60.0 - o, 44.0),
                ],
                Stroke::round(Rgba::BLACK, 2.0),
            )
            .unwrap(),
        );
        s
    }

    #[test]
    fn integer_scenes_need_no_decimals_and_fractional_ones_do() {
        // The circle's control points are not integers; make every point one.
        let mut int = scene(0.0);
        for sh in &mut int.shapes {
            for p in &mut sh.points {
                *p = Point::new(p.x.round(), p.y.round());
            }
        }
        let c = compact_svg(&int, &SvgOptions::default());
        assert_eq!(c.precision, 0, "{c:?}");
        assert!(c.within && c.max_abs < 1e-4, "{c:?}");

        let frac = scene(0.237);
        let c = compact_svg(&frac, &SvgOptions::default());
        assert!(c.precision >= 1 && c.within, "{c:?}");
        let tol = Tolerance::default();
        assert!(c.mean_abs <= tol.mean_abs && c.max_abs <= tol.max_abs);
        // Check the claim independently: the text it returns renders within the tolerance.
        let back = from_svg(&c.svg).unwrap();
        let (mean, max) = diff(
            &crate::raster::render(&colors_as_written(&frac)),
            &crate::raster::render(&back),
        );
        assert!(mean <= tol.mean_abs && max <= tol.max_abs, "{mean} {max}");
        // One decimal fewer is out of tolerance (that is why it was not chosen).
        let fewer = to_svg(
            &frac,
            &SvgOptions {
                precision: c.precision - 1,
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
        assert_eq!(grouped.precision, c.precision);
    }
}
