//! Gradient paint: SVG's `linearGradient` and `radialGradient`, resolved into canvas pixels.
//!
//! A shape's fill or stroke is a flat colour ([`super::Shape::fill`], [`super::Stroke::color`])
//! unless [`super::Shape::gradients`] gives it a [`Gradient`]. The flat colour stays beside the
//! gradient as its **stand-in**: the mean of the stop colours, what colour-only code (palettes,
//! colour grouping, recolouring) reads. The rasteriser and the SVG export paint the gradient and
//! ignore the stand-in.
//!
//! # Model
//! A pixel centre `p` (canvas pixels) is mapped into gradient space, `q = transform⁻¹(p)`, and
//! given a parameter `t`:
//! - linear: `t = (q - p1)·(p2 - p1) / |p2 - p1|²` (`t = 1` when `p1 = p2`);
//! - radial (two-point conical, as SVG 2 and tiny-skia): the largest `t` for which `q` lies on the
//!   circle of centre `f + t(c - f)` and radius `fr + t(r - fr) >= 0`; a pixel without such a
//!   `t` is not painted.
//!
//! `t` goes through the spread method (pad clamps to `[0, 1]`, repeat takes the fraction,
//! reflect mirrors every other period), then the colour is interpolated linearly in straight
//! (non-premultiplied) RGBA between the two stops around it; before the first stop and after
//! the last their colours hold. The painted colour replaces the flat colour in the usual
//! compositing (`alpha = coverage * colour.a`).
//!
//! # Invariants (checked by [`Gradient::validate`], part of [`super::Scene::validate`])
//! - At least one stop; offsets are finite, in `[0, 1]` and non-decreasing; stop colours are
//!   valid [`Rgba`]s (the fill or stroke opacity is already multiplied into their alpha).
//! - Every geometry value is finite; a radial gradient has `r > 0` and `fr >= 0`.
//! - `transform` is finite and invertible.
//! - A shape with `gradients.fill` has a fill; with `gradients.stroke`, a stroke.
//!
//! # Parameters
//! [`Gradient::params`] is the flat view the rasteriser's gradients use: the geometry (`x1, y1,
//! x2, y2` or `cx, cy, r, fx, fy, fr`, in gradient space) then `offset, r, g, b, a` per stop.
//! [`scene_gradient_params`] concatenates them over the scene, shape by shape, fill before
//! stroke.

use super::{Point, Rgba, Scene};
use serde::{Deserialize, Serialize};

/// An affine map `x' = a x + c y + e`, `y' = b x + d y + f` (SVG's `matrix(a b c d e f)`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Affine(pub [f32; 6]);

impl Affine {
    pub const IDENTITY: Affine = Affine([1.0, 0.0, 0.0, 1.0, 0.0, 0.0]);

    pub fn apply(&self, p: Point) -> Point {
        let [a, b, c, d, e, f] = self.0;
        Point::new(a * p.x + c * p.y + e, b * p.x + d * p.y + f)
    }

    /// `self ∘ other`: `other` first, then `self`.
    pub fn then_after(&self, other: &Affine) -> Affine {
        let [a, b, c, d, e, f] = self.0;
        let [a2, b2, c2, d2, e2, f2] = other.0;
        Affine([
            a * a2 + c * b2,
            b * a2 + d * b2,
            a * c2 + c * d2,
            b * c2 + d * d2,
            a * e2 + c * f2 + e,
            b * e2 + d * f2 + f,
        ])
    }

    /// The affine map that agrees with `f` at `(0,0)`, `(1,0)` and `(0,1)` (`f` itself when it
    /// is affine).
    pub fn fit(f: impl Fn(&Point) -> Point) -> Affine {
        let o = f(&Point::new(0.0, 0.0));
        let x = f(&Point::new(1.0, 0.0));
        let y = f(&Point::new(0.0, 1.0));
        Affine([x.x - o.x, x.y - o.y, y.x - o.x, y.y - o.y, o.x, o.y])
    }

    /// The inverse map in f64, as `[a b c d e f]`: exact for an invertible map (every valid
    /// scene's); a singular one gives non-finite values.
    pub fn inverse_f64(&self) -> [f64; 6] {
        let [a, b, c, d, e, f] = self.0.map(f64::from);
        let det = a * d - b * c;
        [
            d / det,
            -b / det,
            -c / det,
            a / det,
            (c * f - d * e) / det,
            (b * e - a * f) / det,
        ]
    }

    pub fn det(&self) -> f32 {
        let [a, b, c, d, ..] = self.0;
        a * d - b * c
    }

    pub(crate) fn is_valid(&self) -> bool {
        let det = self.det();
        self.0.iter().all(|v| v.is_finite()) && det.is_finite() && det != 0.0
    }
}

/// How `t` outside `[0, 1]` is mapped back (SVG `spreadMethod`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Spread {
    #[default]
    Pad,
    Reflect,
    Repeat,
}

/// The gradient's geometry in gradient space.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum GradientGeometry {
    Linear {
        x1: f32,
        y1: f32,
        x2: f32,
        y2: f32,
    },
    /// End circle `(cx, cy, r)`, focal (start) circle `(fx, fy, fr)`.
    Radial {
        cx: f32,
        cy: f32,
        r: f32,
        fx: f32,
        fy: f32,
        fr: f32,
    },
}

impl GradientGeometry {
    /// The geometry values in parameter order.
    pub fn values(&self) -> Vec<f32> {
        match *self {
            Self::Linear { x1, y1, x2, y2 } => vec![x1, y1, x2, y2],
            Self::Radial {
                cx,
                cy,
                r,
                fx,
                fy,
                fr,
            } => vec![cx, cy, r, fx, fy, fr],
        }
    }

    /// The SVG attribute of each of [`Self::values`].
    pub fn names(&self) -> &'static [&'static str] {
        match self {
            Self::Linear { .. } => &["x1", "y1", "x2", "y2"],
            Self::Radial { .. } => &["cx", "cy", "r", "fx", "fy", "fr"],
        }
    }

    /// Where the parameter `t` starts (0) and ends (1): a linear gradient's axis ends
    /// `[x, y, 0]`, a radial one's focal and end circles `[x, y, r]`.
    pub fn ends(&self) -> [[f32; 3]; 2] {
        match *self {
            Self::Linear { x1, y1, x2, y2 } => [[x1, y1, 0.0], [x2, y2, 0.0]],
            Self::Radial { .. } => {
                let v = self.values();
                [[v[3], v[4], v[5]], [v[0], v[1], v[2]]]
            }
        }
    }

    /// The same kind of geometry with these values (radii kept valid).
    fn with_values(&self, v: &[f32]) -> Self {
        match self {
            Self::Linear { .. } => Self::Linear {
                x1: v[0],
                y1: v[1],
                x2: v[2],
                y2: v[3],
            },
            Self::Radial { .. } => Self::Radial {
                cx: v[0],
                cy: v[1],
                r: v[2].max(1e-6),
                fx: v[3],
                fy: v[4],
                fr: v[5].max(0.0),
            },
        }
    }
}

/// One colour stop.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GradientStop {
    pub offset: f32,
    pub color: Rgba,
}

/// A linear or radial gradient (see the module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Gradient {
    pub geometry: GradientGeometry,
    /// Gradient space → canvas pixels.
    pub transform: Affine,
    #[serde(default)]
    pub spread: Spread,
    pub stops: Vec<GradientStop>,
}

/// The paints of one shape beyond its flat colours: gradients, or a fill texture.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Gradients {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fill: Option<Gradient>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stroke: Option<Gradient>,
    /// A sampled raster painting the fill instead ([`super::texture`]; no fill gradient then).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture: Option<Box<super::Texture>>,
}

impl Gradients {
    /// Both paints, fill first (the parameter order).
    pub fn iter(&self) -> impl Iterator<Item = &Gradient> {
        self.fill.iter().chain(self.stroke.iter())
    }

    fn iter_mut(&mut self) -> impl Iterator<Item = &mut Gradient> {
        self.fill.iter_mut().chain(self.stroke.iter_mut())
    }
}

impl Gradient {
    /// The mean stop colour: the flat stand-in kept beside the gradient.
    pub fn mean_color(&self) -> Rgba {
        let n = self.stops.len().max(1) as f32;
        let mut s = [0.0f32; 4];
        for st in &self.stops {
            for (acc, v) in s.iter_mut().zip(st.color.to_array()) {
                *acc += v / n;
            }
        }
        Rgba::from_array(s).clamped()
    }

    /// The gradient moved with its shape: `m` (canvas → new canvas) after its transform.
    pub fn mapped(&self, m: &Affine) -> Gradient {
        Gradient {
            transform: m.then_after(&self.transform),
            ..self.clone()
        }
    }

    /// Folds a transform `x' = s x + e, y' = s y + f` (`s > 0`) into the geometry (points map,
    /// radii scale; the transform becomes the identity): the same gradient, written without a
    /// `gradientTransform`. Any other transform stays as it is.
    pub fn fold_uniform_transform(&mut self) {
        let [a, b, c, d, e, f] = self.transform.0;
        if !(b == 0.0 && c == 0.0 && a == d && a > 0.0) {
            return;
        }
        let mut v = self.params();
        // Linear: x1 y1 x2 y2; radial: cx cy r fx fy fr (points at 0, 3; radii at 2, 5).
        let (points, radii): (&[usize], &[usize]) = match self.geometry {
            GradientGeometry::Linear { .. } => (&[0, 2], &[]),
            GradientGeometry::Radial { .. } => (&[0, 3], &[2, 5]),
        };
        for &k in points {
            v[k] = a * v[k] + e;
            v[k + 1] = d * v[k + 1] + f;
        }
        for &k in radii {
            v[k] *= a;
        }
        self.set_params(&v);
        self.transform = Affine::IDENTITY;
    }

    /// Rounds the geometry (points and radii) to a grid of `1 / per_unit`.
    pub fn round_geometry(&mut self, per_unit: f32) {
        let mut v = self.params();
        for x in &mut v[..self.geometry.values().len()] {
            *x = (*x * per_unit).round() / per_unit;
        }
        self.set_params(&v);
    }

    /// Number of scalars in [`Gradient::params`].
    pub fn num_params(&self) -> usize {
        self.geometry.values().len() + 5 * self.stops.len()
    }

    /// Geometry, then `offset, r, g, b, a` per stop.
    pub fn params(&self) -> Vec<f32> {
        let mut v = self.geometry.values();
        for s in &self.stops {
            v.push(s.offset);
            v.extend_from_slice(&s.color.to_array());
        }
        v
    }

    /// Reads [`Gradient::params`] back, keeping the invariants: colours and offsets clamped
    /// into `[0, 1]`, offsets made non-decreasing, radii positive. Non-finite values are
    /// ignored (the old value stays).
    pub fn set_params(&mut self, v: &[f32]) {
        let old = self.params();
        let v: Vec<f32> = v
            .iter()
            .zip(&old)
            .map(|(n, o)| if n.is_finite() { *n } else { *o })
            .collect();
        let ng = self.geometry.values().len();
        self.geometry = self.geometry.with_values(&v[..ng]);
        let mut lo = 0.0f32;
        for (s, p) in self.stops.iter_mut().zip(v[ng..].chunks_exact(5)) {
            s.offset = p[0].clamp(lo, 1.0);
            lo = s.offset;
            s.color = Rgba::new(p[1], p[2], p[3], p[4]).clamped();
        }
    }

    /// Checks the invariants in the module docs.
    pub fn validate(&self) -> Result<(), String> {
        if self.stops.is_empty() {
            return Err("gradient needs at least one stop".into());
        }
        let mut lo = 0.0f32;
        for (i, s) in self.stops.iter().enumerate() {
            if !(s.offset >= lo && s.offset <= 1.0) {
                return Err(format!(
                    "gradient stop {i}: offset {} must be in [0, 1] and non-decreasing",
                    s.offset
                ));
            }
            lo = s.offset;
            if !s.color.is_valid() {
                return Err(format!(
                    "gradient stop {i}: colour must be finite and in [0, 1]"
                ));
            }
        }
        if !self.geometry.values().iter().all(|v| v.is_finite()) {
            return Err("gradient geometry must be finite".into());
        }
        if let GradientGeometry::Radial { r, fr, .. } = self.geometry
            && !(r > 0.0 && fr >= 0.0)
        {
            return Err(format!(
                "radial gradient needs r > 0 and fr >= 0, got {r}, {fr}"
            ));
        }
        if !self.transform.is_valid() {
            return Err("gradient transform must be finite and invertible".into());
        }
        Ok(())
    }
}

/// Every gradient parameter of the scene (see the module docs for the order).
pub fn scene_gradient_params(scene: &Scene) -> Vec<f32> {
    scene
        .shapes
        .iter()
        .filter_map(|s| s.gradients.as_deref())
        .flat_map(|g| g.iter().flat_map(Gradient::params).collect::<Vec<_>>())
        .collect()
}

/// Writes [`scene_gradient_params`]-ordered values back (see [`Gradient::set_params`]); the
/// flat stand-ins follow their gradients. Fails when the length does not match.
pub fn write_scene_gradient_params(scene: &mut Scene, v: &[f32]) -> Result<(), String> {
    let want = scene_gradient_params(scene).len();
    if v.len() != want {
        return Err(format!("{} gradient parameters, expected {want}", v.len()));
    }
    let mut k = 0;
    for sh in &mut scene.shapes {
        let Some(gs) = sh.gradients.as_deref_mut() else {
            continue;
        };
        for g in gs.iter_mut() {
            let n = g.num_params();
            g.set_params(&v[k..k + n]);
            k += n;
        }
        if let (Some(g), Some(f)) = (&gs.fill, &mut sh.fill) {
            *f = g.mean_color();
        }
        if let (Some(g), Some(s)) = (&gs.stroke, &mut sh.stroke) {
            s.color = g.mean_color();
        }
    }
    Ok(())
}
