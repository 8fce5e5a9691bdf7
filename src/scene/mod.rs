//! The vector scene: a canvas, a background and an ordered list of shapes painted source-over.
//!
//! Every shape is a sequence of segments (cubic Béziers or straight lines) that is either closed
//! (filled, iconography and pixel art) or open (stroked, sketch). Parameters live in the shapes;
//! [`Params`] is the flat view that optimisers work on, split into named [`ParamGroup`]s.
//!
//! # Invariants (checked by [`Scene::validate`] and every constructor)
//! - `width` and `height` are in `1..=MAX_SIDE`.
//! - Every coordinate, colour channel and stroke width is finite.
//! - Colour channels are in `[0, 1]` (straight, non-premultiplied alpha); widths are `>= 0`.
//! - A closed cubic path with `n >= 1` segments has exactly `3n` points (anchor, ctrl, ctrl per
//!   segment; the last segment ends at point 0). An open cubic path with `n >= 1` segments has
//!   `3n + 1` points. A polygon has `n >= 3` vertices and is always closed.
//! - A closed shape has a fill; an open shape has a stroke and no fill.
//! - [`Scene::groups`] obey the invariants of [`group`] (empty for a flat scene).
//! - A fill or stroke painted with a gradient ([`Shape::gradients`]) keeps its flat colour as
//!   the gradient's stand-in; the gradient's own invariants are in [`paint`].

mod group;
pub mod paint;
mod params;
pub mod texture;

pub use group::{BlendMode, Clip, Content, FillRule, Group, Mask, MaskKind};
pub use paint::{Affine, Gradient, GradientGeometry, GradientStop, Gradients, Spread};
pub use params::{ParamGroup, Params, Trainable};
pub use texture::{Texture, TextureEdge, TextureFilter};

use serde::{Deserialize, Serialize};

/// Largest canvas side we accept, in pixels.
pub const MAX_SIDE: u32 = 8192;

/// Most paths (shapes) a run may create or a job may ask for: the one cap that LIVE, the
/// pipeline, the request limits and `Config::validate` all read.
pub const MAX_PATHS: usize = 1024;

/// A 2-D point in canvas pixels (x right, y down).
#[derive(Clone, Copy, Debug, PartialEq, Default, Serialize, Deserialize)]
pub struct Point {
    pub x: f32,
    pub y: f32,
}

impl Point {
    pub const fn new(x: f32, y: f32) -> Self {
        Self { x, y }
    }

    /// The points of `xy`, in order.
    pub fn list(xy: &[(f32, f32)]) -> Vec<Point> {
        xy.iter().map(|&(x, y)| Point::new(x, y)).collect()
    }

    /// The control points of the cubic that is the straight segment from `a` to `b`: its
    /// thirds (how a polygon edge, an SVG `L` and a straightened segment are drawn).
    pub fn line_controls(a: Point, b: Point) -> [Point; 2] {
        let at = |t: f32| Point::new(a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t);
        [at(1.0 / 3.0), at(2.0 / 3.0)]
    }
}

/// Straight-alpha RGBA colour, each channel in `[0, 1]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rgba {
    pub r: f32,
    pub g: f32,
    pub b: f32,
    pub a: f32,
}

impl Rgba {
    pub const WHITE: Rgba = Rgba::new(1.0, 1.0, 1.0, 1.0);
    pub const BLACK: Rgba = Rgba::new(0.0, 0.0, 0.0, 1.0);
    pub const TRANSPARENT: Rgba = Rgba::new(0.0, 0.0, 0.0, 0.0);

    pub const fn new(r: f32, g: f32, b: f32, a: f32) -> Self {
        Self { r, g, b, a }
    }

    pub fn to_array(self) -> [f32; 4] {
        [self.r, self.g, self.b, self.a]
    }

    pub fn from_array(a: [f32; 4]) -> Self {
        Self::new(a[0], a[1], a[2], a[3])
    }

    /// Clamps every channel into `[0, 1]`; NaN becomes 0.
    pub fn clamped(self) -> Self {
        let c = |v: f32| if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
        Self::new(c(self.r), c(self.g), c(self.b), c(self.a))
    }

    fn is_valid(self) -> bool {
        self.to_array()
            .iter()
            .all(|v| v.is_finite() && (0.0..=1.0).contains(v))
    }
}

/// A stroke: colour, width in pixels, and the shape of its ends and corners (SVG's
/// `stroke-linecap`, `stroke-linejoin`, `stroke-miterlimit`). What optimisation creates is
/// round-capped and round-joined ([`Stroke::round`]): the covered area is then the union of
/// per-segment capsules, see `raster`; imported SVG strokes keep their caps and joins.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stroke {
    pub color: Rgba,
    pub width: f32,
    #[serde(default, skip_serializing_if = "LineCap::is_round")]
    pub cap: LineCap,
    #[serde(default, skip_serializing_if = "LineJoin::is_round")]
    pub join: LineJoin,
    /// Longest miter, in stroke widths, before a miter join is drawn bevelled (`>= 1`).
    #[serde(
        default = "Stroke::default_miter_limit",
        skip_serializing_if = "Stroke::is_default_miter_limit"
    )]
    pub miter_limit: f32,
}

impl Stroke {
    /// SVG's default `stroke-miterlimit`.
    pub const DEFAULT_MITER_LIMIT: f32 = 4.0;

    /// A round-capped, round-joined stroke (what the optimisers create and train).
    pub const fn round(color: Rgba, width: f32) -> Self {
        Stroke {
            color,
            width,
            cap: LineCap::Round,
            join: LineJoin::Round,
            miter_limit: Self::DEFAULT_MITER_LIMIT,
        }
    }

    /// Whether caps and joins are both round (the covered area is a union of capsules).
    pub fn is_round(&self) -> bool {
        self.cap.is_round() && self.join.is_round()
    }

    fn default_miter_limit() -> f32 {
        Self::DEFAULT_MITER_LIMIT
    }

    fn is_default_miter_limit(v: &f32) -> bool {
        *v == Self::DEFAULT_MITER_LIMIT
    }
}

/// How an open stroke ends (SVG `stroke-linecap`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LineCap {
    /// A half disc beyond the end.
    #[default]
    Round,
    /// Flat at the end point.
    Butt,
    /// Flat, half a width beyond the end point.
    Square,
}

impl LineCap {
    pub fn is_round(&self) -> bool {
        *self == LineCap::Round
    }
}

/// How a stroke turns a corner (SVG `stroke-linejoin`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LineJoin {
    #[default]
    Round,
    /// The outer edges extended until they meet (bevelled past the miter limit).
    Miter,
    /// The outer corners joined by a straight edge.
    Bevel,
}

impl LineJoin {
    pub fn is_round(&self) -> bool {
        *self == LineJoin::Round
    }
}

/// What the points of a shape mean.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ShapeKind {
    /// Closed cubic Bézier path: `3n` points.
    ClosedCubic,
    /// Open cubic Bézier path: `3n + 1` points.
    OpenCubic,
    /// Closed polygon of straight edges: `n >= 3` vertices (pixel-art squares are 4-gons).
    Polygon,
}

/// One shape. Build it with [`Shape::closed_cubic`], [`Shape::open_cubic`] or
/// [`Shape::polygon`], which validate the invariants in the module docs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Shape {
    pub kind: ShapeKind,
    pub points: Vec<Point>,
    pub fill: Option<Rgba>,
    pub stroke: Option<Stroke>,
    /// How the fill covers where the outline overlaps itself (SVG `fill-rule`).
    #[serde(default, skip_serializing_if = "FillRule::is_nonzero")]
    pub fill_rule: FillRule,
    /// Gradient paint of the fill and/or stroke (imported SVG); `None` (the common case) paints
    /// the flat colours. With a gradient, `fill` / `stroke.color` is its flat stand-in (the
    /// mean stop colour, see [`paint`]), read by colour-only code and ignored when drawing.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gradients: Option<Box<Gradients>>,
    /// The LIVE stage that added the shape (0: the vtracer start), kept by every edit that
    /// replaces it (splits, merges, scaling); `None` for shapes from anywhere else. The SVG
    /// groups by it on request ([`crate::svg::SvgOptions::group_by_stage`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stage: Option<u16>,
}

/// Why a scene or shape is not valid.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SceneError {
    #[error("canvas size {0}x{1} is out of range (1..={MAX_SIDE})")]
    CanvasSize(u32, u32),
    #[error("shape {shape}: {reason}")]
    Shape { shape: usize, reason: String },
    #[error("background colour must have finite channels in [0, 1]")]
    Background,
    #[error("{0}")]
    Group(String),
    #[error("parameter vector for group {group:?} has length {got}, expected {expected}")]
    ParamLength {
        group: ParamGroup,
        got: usize,
        expected: usize,
    },
}

impl Shape {
    /// A closed cubic outline through `points` painted as this shape is (fill, stroke, fill rule,
    /// gradients) and from its stage: a piece of this shape, as the vector stage splits it.
    pub fn closed_cubic_like(&self, points: Vec<Point>) -> Shape {
        Shape {
            kind: ShapeKind::ClosedCubic,
            points,
            fill: self.fill,
            stroke: self.stroke,
            fill_rule: self.fill_rule,
            gradients: self.gradients.clone(),
            stage: self.stage,
        }
    }

    /// The shape with every control point moved by `f` and its stroke width multiplied by
    /// `stroke_k` (kind and paint kept): the one way geometry is rescaled or placed. `f` must be
    /// affine; gradients move with the shape.
    pub fn mapped(&self, f: impl Fn(&Point) -> Point, stroke_k: f32) -> Shape {
        let gradients = self.gradients.as_ref().map(|g| {
            let m = Affine::fit(&f);
            Box::new(Gradients {
                fill: g.fill.as_ref().map(|g| g.mapped(&m)),
                stroke: g.stroke.as_ref().map(|g| g.mapped(&m)),
                texture: g.texture.as_ref().map(|t| Box::new(t.mapped(&m))),
            })
        });
        Shape {
            kind: self.kind,
            points: self.points.iter().map(f).collect(),
            fill: self.fill,
            stroke: self.stroke.map(|st| Stroke {
                width: st.width * stroke_k,
                ..st
            }),
            fill_rule: self.fill_rule,
            gradients,
            stage: self.stage,
        }
    }

    /// The shape with these parts, if it is valid.
    fn checked(
        kind: ShapeKind,
        points: Vec<Point>,
        fill: Option<Rgba>,
        stroke: Option<Stroke>,
    ) -> Result<Self, SceneError> {
        let s = Shape {
            kind,
            points,
            fill,
            stroke,
            fill_rule: FillRule::NonZero,
            gradients: None,
            stage: None,
        };
        s.validate(0)?;
        Ok(s)
    }

    /// A closed, filled cubic path. `points.len()` must be a positive multiple of 3.
    pub fn closed_cubic(points: Vec<Point>, fill: Rgba) -> Result<Self, SceneError> {
        Self::checked(ShapeKind::ClosedCubic, points, Some(fill), None)
    }

    /// An open, stroked cubic path. `points.len()` must be `3n + 1` with `n >= 1`.
    pub fn open_cubic(points: Vec<Point>, stroke: Stroke) -> Result<Self, SceneError> {
        Self::checked(ShapeKind::OpenCubic, points, None, Some(stroke))
    }

    /// A closed, filled polygon with at least 3 vertices.
    pub fn polygon(points: Vec<Point>, fill: Rgba) -> Result<Self, SceneError> {
        Self::checked(ShapeKind::Polygon, points, Some(fill), None)
    }

    /// An axis-aligned square (pixel-art cell) as a 4-gon.
    pub fn square(x: f32, y: f32, side: f32, fill: Rgba) -> Result<Self, SceneError> {
        Self::polygon(
            Point::list(&[(x, y), (x + side, y), (x + side, y + side), (x, y + side)]),
            fill,
        )
    }

    /// A circle-like closed path of `segments` cubic segments (the LIVE / VectorFusion init).
    pub fn circle(
        cx: f32,
        cy: f32,
        radius: f32,
        segments: usize,
        fill: Rgba,
    ) -> Result<Self, SceneError> {
        let n = segments.max(1);
        let step = std::f32::consts::TAU / n as f32;
        // Handle length for a circular arc of angle `step`.
        let k = 4.0 / 3.0 * (step / 4.0).tan() * radius;
        let mut pts = Vec::with_capacity(3 * n);
        for i in 0..n {
            let a0 = i as f32 * step;
            let a1 = a0 + step;
            let (s0, c0) = a0.sin_cos();
            let (s1, c1) = a1.sin_cos();
            pts.push(Point::new(cx + radius * c0, cy + radius * s0));
            pts.push(Point::new(
                cx + radius * c0 - k * s0,
                cy + radius * s0 + k * c0,
            ));
            pts.push(Point::new(
                cx + radius * c1 + k * s1,
                cy + radius * s1 - k * c1,
            ));
        }
        Self::closed_cubic(pts, fill)
    }

    /// Number of segments (cubic or straight) in the outline.
    pub fn num_segments(&self) -> usize {
        match self.kind {
            ShapeKind::ClosedCubic => self.points.len() / 3,
            ShapeKind::OpenCubic => self.points.len().saturating_sub(1) / 3,
            ShapeKind::Polygon => self.points.len(),
        }
    }

    /// Whether the outline is closed (filled).
    pub fn is_closed(&self) -> bool {
        !matches!(self.kind, ShapeKind::OpenCubic)
    }

    /// The `i`-th cubic segment's four control points (closed/open cubic shapes), or the
    /// straight edge as a degenerate cubic with handles at 1/3 and 2/3 (polygons).
    pub fn segment(&self, i: usize) -> [Point; 4] {
        let p = &self.points;
        let n = p.len();
        match self.kind {
            ShapeKind::ClosedCubic => [p[3 * i], p[3 * i + 1], p[3 * i + 2], p[(3 * i + 3) % n]],
            ShapeKind::OpenCubic => [p[3 * i], p[3 * i + 1], p[3 * i + 2], p[3 * i + 3]],
            ShapeKind::Polygon => {
                let a = p[i];
                let b = p[(i + 1) % n];
                let [c1, c2] = Point::line_controls(a, b);
                [a, c1, c2, b]
            }
        }
    }

    /// Axis-aligned bounds of the control polygon (contains the curve), ignoring stroke width.
    pub fn control_bounds(&self) -> (Point, Point) {
        let mut lo = Point::new(f32::INFINITY, f32::INFINITY);
        let mut hi = Point::new(f32::NEG_INFINITY, f32::NEG_INFINITY);
        for p in &self.points {
            lo.x = lo.x.min(p.x);
            lo.y = lo.y.min(p.y);
            hi.x = hi.x.max(p.x);
            hi.y = hi.y.max(p.y);
        }
        (lo, hi)
    }

    pub(crate) fn validate(&self, index: usize) -> Result<(), SceneError> {
        let err = |reason: String| SceneError::Shape {
            shape: index,
            reason,
        };
        let n = self.points.len();
        match self.kind {
            ShapeKind::ClosedCubic if n == 0 || !n.is_multiple_of(3) => {
                return Err(err(format!(
                    "closed cubic path needs a positive multiple of 3 points, got {n}"
                )));
            }
            ShapeKind::OpenCubic if n < 4 || !(n - 1).is_multiple_of(3) => {
                return Err(err(format!(
                    "open cubic path needs 3n+1 points (n >= 1), got {n}"
                )));
            }
            ShapeKind::Polygon if n < 3 => {
                return Err(err(format!("polygon needs at least 3 vertices, got {n}")));
            }
            _ => {}
        }
        if let Some(i) = self
            .points
            .iter()
            .position(|p| !p.x.is_finite() || !p.y.is_finite())
        {
            return Err(err(format!("point {i} is not finite")));
        }
        match (self.is_closed(), self.fill, self.stroke) {
            (true, None, _) => return Err(err("closed shape needs a fill".into())),
            (false, Some(_), _) => return Err(err("open shape cannot have a fill".into())),
            (false, _, None) => return Err(err("open shape needs a stroke".into())),
            _ => {}
        }
        if let Some(f) = self.fill
            && !f.is_valid()
        {
            return Err(err("fill colour must be finite and in [0, 1]".into()));
        }
        if let Some(s) = self.stroke {
            if !s.color.is_valid() {
                return Err(err("stroke colour must be finite and in [0, 1]".into()));
            }
            if !s.width.is_finite() || s.width < 0.0 {
                return Err(err(format!(
                    "stroke width must be finite and >= 0, got {}",
                    s.width
                )));
            }
            if !(s.miter_limit >= 1.0 && s.miter_limit.is_finite()) {
                return Err(err(format!(
                    "stroke miter limit must be finite and >= 1, got {}",
                    s.miter_limit
                )));
            }
        }
        self.validate_gradients().map_err(err)
    }

    fn validate_gradients(&self) -> Result<(), String> {
        let Some(g) = self.gradients.as_deref() else {
            return Ok(());
        };
        if let Some(f) = &g.fill {
            if self.fill.is_none() {
                return Err("fill gradient on a shape without a fill".into());
            }
            f.validate().map_err(|e| format!("fill {e}"))?;
        }
        if let Some(s) = &g.stroke {
            if self.stroke.is_none() {
                return Err("stroke gradient on a shape without a stroke".into());
            }
            s.validate().map_err(|e| format!("stroke {e}"))?;
        }
        texture::validate_on(g, self.fill.is_some())
    }
}

/// A canvas with a background and shapes painted in order (first is bottom).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Scene {
    pub width: u32,
    pub height: u32,
    pub background: Rgba,
    pub shapes: Vec<Shape>,
    /// Layers over ranges of `shapes` (opacity, clip, mask); empty for a flat scene.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub groups: Vec<Group>,
}

impl Scene {
    /// An empty scene; fails if the canvas size or background is out of range.
    pub fn new(width: u32, height: u32, background: Rgba) -> Result<Self, SceneError> {
        let s = Scene {
            width,
            height,
            background,
            shapes: Vec::new(),
            groups: Vec::new(),
        };
        s.validate()?;
        Ok(s)
    }

    /// Checks every invariant listed in the module docs.
    pub fn validate(&self) -> Result<(), SceneError> {
        if self.width == 0 || self.height == 0 || self.width > MAX_SIDE || self.height > MAX_SIDE {
            return Err(SceneError::CanvasSize(self.width, self.height));
        }
        if !self.background.is_valid() {
            return Err(SceneError::Background);
        }
        for (i, s) in self.shapes.iter().enumerate() {
            s.validate(i)?;
        }
        group::validate_groups(&self.groups, self.shapes.len())
    }

    /// Uniformly scales geometry (points and stroke widths) and the canvas to `new_width`
    /// pixels wide; the height keeps the aspect ratio (rounded, at least 1).
    pub fn scaled_to_width(&self, new_width: u32) -> Scene {
        let s = new_width as f32 / self.width as f32;
        let height = ((self.height as f32 * s).round() as u32).max(1);
        let f = |p: &Point| Point::new(p.x * s, p.y * s);
        Scene {
            width: new_width,
            height,
            background: self.background,
            shapes: self.shapes.iter().map(|sh| sh.mapped(f, s)).collect(),
            groups: self.groups.iter().map(|g| g.mapped(&f, s)).collect(),
        }
    }

    /// The scene `k` times larger: canvas, geometry and stroke widths (the user units of an
    /// SVG whose `viewBox` is `k` times its size in pixels). A shape's gradient that had no
    /// transform of its own takes the scale into its geometry, on a grid of 1/1000 user unit
    /// (so a coordinate on the pixel grid stays a short number), instead of a transform.
    pub fn scaled_by(&self, k: u32) -> Scene {
        let s = k as f32;
        let f = |p: &Point| Point::new(p.x * s, p.y * s);
        let mut shapes: Vec<Shape> = self.shapes.iter().map(|sh| sh.mapped(f, s)).collect();
        for g in shapes
            .iter_mut()
            .filter_map(|sh| sh.gradients.as_deref_mut())
            .flat_map(|gs| [gs.fill.as_mut(), gs.stroke.as_mut()])
            .flatten()
        {
            g.fold_uniform_transform();
            if g.transform == Affine::IDENTITY {
                g.round_geometry(1000.0);
            }
        }
        Scene {
            width: self.width.saturating_mul(k),
            height: self.height.saturating_mul(k),
            background: self.background,
            shapes,
            groups: self.groups.iter().map(|g| g.mapped(&f, s)).collect(),
        }
    }

    /// Removes shape `i` (if there is one), keeping every group on the shapes it had; a group
    /// left without shapes is dropped.
    pub fn remove_shape(&mut self, i: usize) {
        if i >= self.shapes.len() {
            return;
        }
        self.shapes.remove(i);
        for g in &mut self.groups {
            g.start -= (g.start > i) as usize;
            g.end -= (g.end > i) as usize;
        }
        self.groups.retain(|g| g.start < g.end);
    }

    /// Total number of control points over all shapes.
    pub fn num_points(&self) -> usize {
        self.shapes.iter().map(|s| s.points.len()).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constructors_enforce_point_counts() {
        let p = Point::new(0.0, 0.0);
        assert!(Shape::closed_cubic(vec![p; 6], Rgba::BLACK).is_ok());
        assert!(Shape::closed_cubic(vec![p; 5], Rgba::BLACK).is_err());
        assert!(Shape::closed_cubic(vec![], Rgba::BLACK).is_err());
        let st = Stroke::round(Rgba::BLACK, 2.0);
        assert!(Shape::open_cubic(vec![p; 7], st).is_ok());
        assert!(Shape::open_cubic(vec![p; 6], st).is_err());
        assert!(Shape::polygon(vec![p; 2], Rgba::BLACK).is_err());
    }

    #[test]
    fn rejects_non_finite_and_out_of_range() {
        let bad = vec![Point::new(f32::NAN, 0.0); 3];
        assert!(Shape::closed_cubic(bad, Rgba::BLACK).is_err());
        let p = vec![Point::default(); 3];
        assert!(Shape::closed_cubic(p, Rgba::new(1.5, 0.0, 0.0, 1.0)).is_err());
        assert!(Scene::new(0, 10, Rgba::WHITE).is_err());
        assert!(Scene::new(10, MAX_SIDE + 1, Rgba::WHITE).is_err());
    }

    #[test]
    fn removing_a_shape_keeps_the_groups_on_theirs() {
        let mut s = Scene::new(8, 8, Rgba::WHITE).unwrap();
        for i in 0..4 {
            s.shapes
                .push(Shape::square(i as f32, 0.0, 1.0, Rgba::BLACK).unwrap());
        }
        s.groups = vec![
            Group::new(0..3, 0.5),
            Group::new(1..2, 0.5),
            Group::new(3..4, 1.0),
        ];
        s.validate().unwrap();
        s.remove_shape(1);
        assert_eq!(s.groups, vec![Group::new(0..2, 0.5), Group::new(2..3, 1.0)]);
        assert_eq!(s.validate(), Ok(()));
        assert_eq!(s.shapes[1].points[0].x, 2.0);
    }

    #[test]
    fn circle_points_lie_on_radius() {
        let c = Shape::circle(10.0, 20.0, 5.0, 4, Rgba::BLACK).unwrap();
        assert_eq!(c.points.len(), 12);
        for i in 0..4 {
            let a = c.points[3 * i];
            let d = ((a.x - 10.0).powi(2) + (a.y - 20.0).powi(2)).sqrt();
            assert!((d - 5.0).abs() < 1e-4);
        }
        // Midpoint of each segment is on the circle within the cubic approximation error.
        for i in 0..4 {
            let [p0, p1, p2, p3] = c.segment(i);
            let mx = (p0.x + 3.0 * p1.x + 3.0 * p2.x + p3.x) / 8.0;
            let my = (p0.y + 3.0 * p1.y + 3.0 * p2.y + p3.y) / 8.0;
            let d = ((mx - 10.0).powi(2) + (my - 20.0).powi(2)).sqrt();
            assert!((d - 5.0).abs() < 0.01, "midpoint radius {d}");
        }
    }
}
