//! The canvas of a text run: what a caller asks for (an [`Aspect`], or a `width` and `height`:
//! [`CanvasRequest`]) and what the plan resolves it to ([`CanvasPlan`]): the SVG's canvas and
//! the shape the model samples, traces and distils at.
//!
//! Stable Diffusion samples at the canvas's aspect: its shorter side is the preset's size and
//! its longer side is rounded to a multiple of what the model's autoencoder and UNet need
//! ([`SampleShape::Multiple`]). A model that only draws squares (the embedded `vf-icon`, a
//! pixel-space prior, the analytic test teacher) and the pixel-art style draw their square.
//! At the end the scene is scaled uniformly to fit the canvas and centred on it; the canvas
//! around it is the scene's background. No request means the square canvas of earlier
//! releases (no [`CanvasPlan`] at all, the same SVG byte for byte).

use super::SpecError;
use crate::scene::{Point, Scene, Shape};
use serde::{Deserialize, Serialize};

/// Smallest canvas side a caller may ask for (px).
pub const MIN_CANVAS_SIDE: u32 = 64;
/// The longer side of a sample is at most this many times its shorter side (a longer canvas
/// gets a sample of this ratio, centred on it).
pub const MAX_SAMPLE_RATIO: u32 = 4;

/// A named aspect ratio, width:height.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Aspect {
    #[serde(rename = "1:1")]
    Square,
    #[serde(rename = "4:3")]
    Landscape4x3,
    #[serde(rename = "3:4")]
    Portrait3x4,
    #[serde(rename = "16:9")]
    Wide16x9,
    #[serde(rename = "9:16")]
    Tall9x16,
    #[serde(rename = "3:2")]
    Landscape3x2,
    #[serde(rename = "2:3")]
    Portrait2x3,
}

impl Aspect {
    pub const ALL: &[Aspect] = &[
        Aspect::Square,
        Aspect::Landscape4x3,
        Aspect::Portrait3x4,
        Aspect::Wide16x9,
        Aspect::Tall9x16,
        Aspect::Landscape3x2,
        Aspect::Portrait2x3,
    ];

    /// `(width, height)` in lowest terms.
    pub fn ratio(self) -> (u32, u32) {
        match self {
            Aspect::Square => (1, 1),
            Aspect::Landscape4x3 => (4, 3),
            Aspect::Portrait3x4 => (3, 4),
            Aspect::Wide16x9 => (16, 9),
            Aspect::Tall9x16 => (9, 16),
            Aspect::Landscape3x2 => (3, 2),
            Aspect::Portrait2x3 => (2, 3),
        }
    }

    /// `"16:9"`.
    pub fn as_str(self) -> String {
        let (w, h) = self.ratio();
        format!("{w}:{h}")
    }
}

impl std::str::FromStr for Aspect {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let s = s.trim();
        Aspect::ALL
            .iter()
            .copied()
            .find(|a| a.as_str() == s)
            .ok_or_else(|| {
                let names: Vec<String> = Aspect::ALL.iter().map(|a| a.as_str()).collect();
                format!(
                    "unknown aspect {s:?} (expected one of {})",
                    names.join(", ")
                )
            })
    }
}

/// The canvas a caller asks for: an aspect, or a width and a height (not both); nothing is
/// the square canvas of the preset's size.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct CanvasRequest {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aspect: Option<Aspect>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height: Option<u32>,
}

impl CanvasRequest {
    pub fn is_empty(&self) -> bool {
        *self == CanvasRequest::default()
    }

    /// The request's own checks (sides within `MIN_CANVAS_SIDE..=max_side`, an aspect or a
    /// width and a height, not both); `Err` names the field. Returns the canvas asked for.
    pub fn check(&self, max_side: u32) -> Result<Option<CanvasShape>, SpecError> {
        let given = match (self.aspect, self.width, self.height) {
            (None, None, None) => return Ok(None),
            (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
                let field = if self.width.is_some() {
                    "width"
                } else {
                    "height"
                };
                return Err(SpecError::new(
                    field,
                    "give either aspect or width and height, not both",
                ));
            }
            (Some(a), None, None) => return Ok(Some(CanvasShape::Aspect(a))),
            (None, Some(_), None) => {
                return Err(SpecError::new("height", "is required with width"));
            }
            (None, None, Some(_)) => {
                return Err(SpecError::new("width", "is required with height"));
            }
            (None, Some(w), Some(h)) => (w, h),
        };
        for (field, v) in [("width", given.0), ("height", given.1)] {
            if !(MIN_CANVAS_SIDE..=max_side).contains(&v) {
                return Err(SpecError::new(
                    field,
                    format!("must be between {MIN_CANVAS_SIDE} and {max_side}, got {v}"),
                ));
            }
        }
        Ok(Some(CanvasShape::Size(given.0, given.1)))
    }
}

/// A checked canvas request.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CanvasShape {
    Aspect(Aspect),
    Size(u32, u32),
}

/// What shapes a model samples at.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleShape {
    /// Squares only (the embedded model, pixel-space priors, the analytic test teacher).
    Square,
    /// Any width and height that are multiples of this (px): the autoencoder's downsampling
    /// times the UNet's (64 for Stable Diffusion 1.x/2.x: 8 × 8).
    Multiple(u32),
}

/// The canvas of a text run, resolved once.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct CanvasPlan {
    /// The SVG's canvas (its viewBox), px.
    pub width: u32,
    pub height: u32,
    /// The image the model samples, LIVE traces and SDS distils, px (the canvas's aspect
    /// rounded to what the model needs; a square for models that draw squares only).
    pub sample_width: u32,
    pub sample_height: u32,
}

fn gcd(a: u32, b: u32) -> u32 {
    if b == 0 { a } else { gcd(b, a % b) }
}

/// The canvas `shape` resolves to for a model sampling `sample` shapes at `size` px (the
/// preset's side: the shorter side of the sample, whose longer side is at most
/// [`MAX_SAMPLE_RATIO`] times it).
pub fn resolve_canvas(shape: CanvasShape, size: u32, sample: SampleShape) -> CanvasPlan {
    let (width, height) = match shape {
        CanvasShape::Size(w, h) => (w, h),
        CanvasShape::Aspect(a) => {
            // The smallest canvas of exactly this aspect whose shorter side is at least `size`.
            let (aw, ah) = a.ratio();
            let k = size.div_ceil(aw.min(ah));
            (k * aw, k * ah)
        }
    };
    let (sample_width, sample_height) = match sample {
        SampleShape::Square => (size, size),
        SampleShape::Multiple(m) => {
            let q = gcd(size, m.max(1));
            let (long, short) = (width.max(height) as f64, width.min(height) as f64);
            let longer = ((size as f64 * long / short / q as f64).round() as u32 * q)
                .clamp(size, MAX_SAMPLE_RATIO * size);
            if width >= height {
                (longer, size)
            } else {
                (size, longer)
            }
        }
    };
    CanvasPlan {
        width,
        height,
        sample_width,
        sample_height,
    }
}

/// `p` scaled by `(sx, sy)` then moved by `(dx, dy)`.
fn map_point(p: &Point, s: (f32, f32), d: (f32, f32)) -> Point {
    Point::new(p.x * s.0 + d.0, p.y * s.1 + d.1)
}

/// `shape` scaled by `s` (stroke widths by the geometric mean) and moved by `d`.
pub fn map_shape(shape: &Shape, s: (f32, f32), d: (f32, f32)) -> Shape {
    shape.mapped(|p| map_point(p, s, d), (s.0 * s.1).sqrt())
}

/// `scene`'s shapes scaled by `s` and moved by `d`, on a `width x height` canvas.
fn mapped(scene: &Scene, (width, height): (u32, u32), s: (f32, f32), d: (f32, f32)) -> Scene {
    Scene {
        width,
        height,
        background: scene.background,
        shapes: scene.shapes.iter().map(|sh| map_shape(sh, s, d)).collect(),
    }
}

/// `scene` stretched to `width x height` (a random start drawn on a square, fitted to a
/// non-square sample).
pub fn stretched(scene: &Scene, width: u32, height: u32) -> Scene {
    let s = (
        width as f32 / scene.width as f32,
        height as f32 / scene.height as f32,
    );
    mapped(scene, (width, height), s, (0.0, 0.0))
}

/// `scene` scaled uniformly to fit a `width x height` canvas and centred on it; the rest of
/// the canvas is the scene's background. A scene of the canvas's size is returned as it is.
pub fn placed(scene: &Scene, width: u32, height: u32) -> Scene {
    if scene.width == width && scene.height == height {
        return scene.clone();
    }
    let k = (width as f32 / scene.width as f32).min(height as f32 / scene.height as f32);
    let d = (
        (width as f32 - scene.width as f32 * k) / 2.0,
        (height as f32 - scene.height as f32 * k) / 2.0,
    );
    mapped(scene, (width, height), (k, k), d)
}

/// Keeps every shape of `scene` inside its canvas: control points past an edge are moved onto
/// it (a shape reaching out of the sample is folded onto its edge, where a canvas of the
/// sample's size cut it off), and shapes left without area (all outside one edge) are dropped.
/// Before a sample is placed on a larger canvas, which would show what lay past its edges.
pub fn kept_inside(scene: &mut Scene) {
    let (w, h) = (scene.width as f32, scene.height as f32);
    scene.shapes.retain_mut(|sh| {
        for p in &mut sh.points {
            *p = Point::new(p.x.clamp(0.0, w), p.y.clamp(0.0, h));
        }
        let (lo, hi) = sh.control_bounds();
        hi.x > lo.x && hi.y > lo.y
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    fn aspect(a: Aspect, size: u32, sample: SampleShape) -> CanvasPlan {
        resolve_canvas(CanvasShape::Aspect(a), size, sample)
    }

    #[test]
    fn aspects_give_exact_canvases_and_rounded_samples() {
        let p = aspect(Aspect::Wide16x9, 256, SampleShape::Multiple(64));
        assert_eq!((p.width, p.height), (464, 261));
        assert_eq!(p.width * 9, p.height * 16);
        // 256 · 16/9 = 455 → 448, a multiple of 64.
        assert_eq!((p.sample_width, p.sample_height), (448, 256));
        let p = aspect(Aspect::Tall9x16, 64, SampleShape::Multiple(4));
        assert_eq!((p.width, p.height), (72, 128));
        assert_eq!((p.sample_width, p.sample_height), (64, 112));
        let p = aspect(Aspect::Wide16x9, 64, SampleShape::Square);
        assert_eq!((p.width, p.height), (128, 72));
        assert_eq!((p.sample_width, p.sample_height), (64, 64));
        let p = aspect(Aspect::Square, 64, SampleShape::Multiple(64));
        assert_eq!(
            (p.width, p.height, p.sample_width, p.sample_height),
            (64, 64, 64, 64)
        );
        // A 32 px draft on a 64-multiple model rounds to multiples of 32.
        let p = aspect(Aspect::Landscape3x2, 32, SampleShape::Multiple(64));
        assert_eq!((p.sample_width, p.sample_height), (64, 32));
        for a in Aspect::ALL {
            assert_eq!(a.as_str().parse::<Aspect>().unwrap(), *a);
            let json = serde_json::to_value(a).unwrap();
            assert_eq!(json, serde_json::Value::String(a.as_str()));
        }
        assert!("5:4".parse::<Aspect>().is_err());
    }

    #[test]
    fn sizes_are_checked_and_named() {
        let req = |aspect, width, height| CanvasRequest {
            aspect,
            width,
            height,
        };
        let err = |r: CanvasRequest| r.check(2048).unwrap_err().field;
        assert_eq!(req(None, None, None).check(2048), Ok(None));
        assert_eq!(
            err(req(Some(Aspect::Square), Some(100), Some(100))),
            "width"
        );
        assert_eq!(err(req(Some(Aspect::Square), None, Some(100))), "height");
        assert_eq!(err(req(None, Some(100), None)), "height");
        assert_eq!(err(req(None, None, Some(100))), "width");
        assert_eq!(err(req(None, Some(63), Some(100))), "width");
        assert_eq!(err(req(None, Some(100), Some(2049))), "height");
        // A canvas longer than 4:1 gets a 4:1 sample, centred on it.
        let long = req(None, Some(2048), Some(64))
            .check(2048)
            .unwrap()
            .unwrap();
        let p = resolve_canvas(long, 64, SampleShape::Multiple(8));
        assert_eq!(
            (p.width, p.height, p.sample_width, p.sample_height),
            (2048, 64, 256, 64)
        );
        assert_eq!(
            req(None, Some(1920), Some(1080)).check(2048),
            Ok(Some(CanvasShape::Size(1920, 1080)))
        );
        assert_eq!(
            req(None, Some(100), Some(400))
                .check(2048)
                .map(|s| s.is_some()),
            Ok(true)
        );
    }

    #[test]
    fn placed_centres_a_square_on_a_wide_canvas() {
        let mut scene = Scene::new(64, 64, crate::scene::Rgba::WHITE).unwrap();
        scene
            .shapes
            .push(Shape::square(0.0, 0.0, 64.0, crate::scene::Rgba::BLACK).unwrap());
        let out = placed(&scene, 128, 72);
        assert_eq!((out.width, out.height), (128, 72));
        let xs: Vec<f32> = out.shapes[0].points.iter().map(|p| p.x).collect();
        let ys: Vec<f32> = out.shapes[0].points.iter().map(|p| p.y).collect();
        let (x0, x1) = (
            xs.iter().cloned().fold(f32::MAX, f32::min),
            xs.iter().cloned().fold(f32::MIN, f32::max),
        );
        let (y0, y1) = (
            ys.iter().cloned().fold(f32::MAX, f32::min),
            ys.iter().cloned().fold(f32::MIN, f32::max),
        );
        assert!(
            (x0 - 28.0).abs() < 1e-4 && (x1 - 100.0).abs() < 1e-4,
            "{x0} {x1}"
        );
        assert!(y0.abs() < 1e-4 && (y1 - 72.0).abs() < 1e-4, "{y0} {y1}");
        assert_eq!(placed(&scene, 64, 64), scene);
        // Past the sample's edges: folded onto them, or dropped when wholly outside.
        let mut wide = scene.clone();
        wide.shapes
            .push(Shape::square(-10.0, 10.0, 30.0, crate::scene::Rgba::BLACK).unwrap());
        wide.shapes
            .push(Shape::square(70.0, 10.0, 30.0, crate::scene::Rgba::BLACK).unwrap());
        kept_inside(&mut wide);
        assert_eq!(wide.shapes.len(), 2);
        assert_eq!(wide.shapes[0], scene.shapes[0]);
        assert!(
            wide.shapes[1]
                .points
                .iter()
                .all(|p| p.x >= 0.0 && p.x <= 20.0)
        );
        let s = stretched(&scene, 128, 64);
        assert_eq!((s.width, s.height), (128, 64));
        assert!(
            s.shapes[0]
                .points
                .iter()
                .any(|p| (p.x - 128.0).abs() < 1e-4)
        );
    }
}
