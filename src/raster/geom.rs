//! Scene → outline polygons ("layers"), and the chain rule back from outline vertices to scene
//! parameters.
//!
//! - Cubic segments are flattened at fixed parameters `t = k/n` (`n` from Wang's formula on the
//!   control points, fixed per call), so every polyline vertex is a fixed Bernstein combination
//!   of four control points. Polygons are used as they are.
//! - A fill layer is the closed polyline of a closed shape.
//! - A stroke layer keeps the polyline and half-width; its coverage comes from the distance to
//!   the polyline (see `stroke`).

use super::Antialias;
use super::layer::GroupT;
use super::paint::PaintT;
use super::real::Real;
use super::stroke::Style;
use super::texture::TextureT;
use crate::scene::{FillRule, Rgba, Scene, ShapeKind, Stroke};

/// Flattening tolerance in pixels (max distance between curve and polyline, approximately).
pub(crate) const TOLERANCE: f32 = 0.05;
/// Most polyline pieces per cubic segment.
const MAX_PIECES: u32 = 128;

/// Wang's formula: pieces needed to flatten one cubic within `tol` pixels.
pub(crate) fn pieces_for(seg: [[f32; 2]; 4], tol: f32) -> u32 {
    let dd = |a: [f32; 2], b: [f32; 2], c: [f32; 2]| {
        let x = a[0] - 2.0 * b[0] + c[0];
        let y = a[1] - 2.0 * b[1] + c[1];
        (x * x + y * y).sqrt()
    };
    let m = dd(seg[0], seg[1], seg[2]).max(dd(seg[1], seg[2], seg[3]));
    let n = (0.75 * m / tol.max(1e-4)).sqrt().ceil();
    if n.is_finite() {
        (n as u32).clamp(1, MAX_PIECES)
    } else {
        1
    }
}

/// A shape's parameters in the working precision.
#[derive(Clone, Debug)]
pub(crate) struct ShapeT<T> {
    pub kind: ShapeKind,
    pub pts: Vec<[T; 2]>,
    pub fill: Option<[T; 4]>,
    pub stroke: Option<([T; 4], T)>,
    /// The stroke's caps and joins (round when there is no stroke).
    pub style: Style,
    /// Pieces per segment (fixed for the step).
    pub pieces: Vec<u32>,
    /// Whether the fill uses the even-odd rule.
    pub even_odd: bool,
    /// Indices into [`SceneT::paints`] of the fill's and the stroke's gradient.
    pub fill_paint: Option<usize>,
    pub stroke_paint: Option<usize>,
    /// Index into [`SceneT::textures`] of the fill's texture.
    pub fill_texture: Option<usize>,
}

/// A scene's parameters in the working precision, plus the fixed flattening plan.
#[derive(Clone, Debug)]
pub(crate) struct SceneT<T> {
    pub width: u32,
    pub height: u32,
    pub bg: [T; 4],
    pub shapes: Vec<ShapeT<T>>,
    /// The scene's groups, with their clip and mask drawn (see `layer`).
    pub groups: Vec<GroupT<T>>,
    /// Every gradient, shape by shape, fill before stroke (the parameter order of
    /// [`crate::scene::paint::scene_gradient_params`]).
    pub paints: Vec<PaintT<T>>,
    /// Every fill texture, shape by shape (constants, see `texture`).
    pub textures: Vec<TextureT<T>>,
    /// How edges are anti-aliased: [`Antialias::Exact`] for every pass that has a backward.
    pub aa: Antialias,
}

fn seg_f32(kind: ShapeKind, p: &[[f32; 2]], i: usize) -> [[f32; 2]; 4] {
    let n = p.len();
    match kind {
        ShapeKind::ClosedCubic => [p[3 * i], p[3 * i + 1], p[3 * i + 2], p[(3 * i + 3) % n]],
        ShapeKind::OpenCubic => [p[3 * i], p[3 * i + 1], p[3 * i + 2], p[3 * i + 3]],
        ShapeKind::Polygon => [p[i], p[i], p[(i + 1) % n], p[(i + 1) % n]],
    }
}

impl<T: Real> SceneT<T> {
    pub fn from_scene(scene: &Scene, tol: f32) -> Self {
        Self::from_scene_aa(scene, tol, Antialias::Exact)
    }

    /// The scene with its clips and masks drawn by anti-aliasing `aa` (which the forward pass
    /// then uses too).
    pub fn from_scene_aa(scene: &Scene, tol: f32, aa: Antialias) -> Self {
        let c4 = |c: crate::scene::Rgba| c.to_array().map(T::of);
        let mut paints = Vec::new();
        let mut add = |g: Option<&crate::scene::Gradient>| {
            g.map(|g| {
                paints.push(PaintT::of(g));
                paints.len() - 1
            })
        };
        let mut textures = Vec::new();
        let shapes =
            scene
                .shapes
                .iter()
                .map(|s| {
                    let p32: Vec<[f32; 2]> = s.points.iter().map(|p| [p.x, p.y]).collect();
                    let nseg = s.num_segments();
                    let pieces = (0..nseg)
                        .map(|i| match s.kind {
                            ShapeKind::Polygon => 1,
                            k => pieces_for(seg_f32(k, &p32, i), tol),
                        })
                        .collect();
                    ShapeT {
                        kind: s.kind,
                        pts: p32.iter().map(|p| [T::of(p[0]), T::of(p[1])]).collect(),
                        fill: s.fill.map(c4),
                        stroke: s.stroke.map(|st| (c4(st.color), T::of(st.width))),
                        style: Style::of(&s.stroke.unwrap_or(Stroke::round(Rgba::BLACK, 0.0))),
                        pieces,
                        even_odd: s.fill_rule == FillRule::EvenOdd,
                        fill_paint: add(s.gradients.as_ref().and_then(|g| g.fill.as_ref())),
                        stroke_paint: add(s.gradients.as_ref().and_then(|g| g.stroke.as_ref())),
                        fill_texture: s.gradients.as_ref().and_then(|g| g.texture.as_ref()).map(
                            |t| {
                                textures.push(TextureT::of(t));
                                textures.len() - 1
                            },
                        ),
                    }
                })
                .collect();
        SceneT {
            width: scene.width,
            height: scene.height,
            bg: c4(scene.background),
            shapes,
            groups: super::layer::groups_t(scene, tol, aa),
            aa,
            paints,
            textures,
        }
    }
}

/// Point indices and weights whose combination gives the vertex at `t` of segment `i`.
#[inline]
fn weights<T: Real>(kind: ShapeKind, n: usize, i: usize, t: T) -> [(usize, T); 4] {
    let one = T::one();
    let u = one - t;
    match kind {
        ShapeKind::Polygon => [(i, u), ((i + 1) % n, t), (i, T::zero()), (i, T::zero())],
        _ => {
            let three = T::c(3.0);
            let w = [u * u * u, three * t * u * u, three * t * t * u, t * t * t];
            let idx = |j: usize| {
                if kind == ShapeKind::ClosedCubic {
                    (3 * i + j) % n
                } else {
                    3 * i + j
                }
            };
            [
                (idx(0), w[0]),
                (idx(1), w[1]),
                (idx(2), w[2]),
                (idx(3), w[3]),
            ]
        }
    }
}

/// Visits every polyline vertex of a shape as (segment, t).
fn for_each_vertex<T: Real>(s: &ShapeT<T>, mut f: impl FnMut(usize, T)) {
    let nseg = s.pieces.len();
    for (i, &k) in s.pieces.iter().enumerate() {
        let kt = T::c(k as f64);
        for j in 0..k {
            f(i, T::c(j as f64) / kt);
        }
    }
    if s.kind == ShapeKind::OpenCubic && nseg > 0 {
        f(nseg - 1, T::one());
    }
}

/// The polyline of a shape (closed: last vertex connects to the first).
pub(crate) fn polyline<T: Real>(s: &ShapeT<T>) -> Vec<[T; 2]> {
    let n = s.pts.len();
    let mut out = Vec::with_capacity(s.pieces.iter().sum::<u32>() as usize + 1);
    for_each_vertex(s, |i, t| {
        let mut v = [T::zero(); 2];
        for (k, w) in weights(s.kind, n, i, t) {
            v[0] += w * s.pts[k][0];
            v[1] += w * s.pts[k][1];
        }
        out.push(v);
    });
    out
}

/// Adds polyline-vertex gradients into control-point gradients (`2 * pts.len()` scalars).
pub(crate) fn polyline_backward<T: Real>(s: &ShapeT<T>, dv: &[[T; 2]], dpts: &mut [T]) {
    let n = s.pts.len();
    let mut idx = 0;
    for_each_vertex(s, |i, t| {
        let g = dv[idx];
        idx += 1;
        for (k, w) in weights(s.kind, n, i, t) {
            dpts[2 * k] += w * g[0];
            dpts[2 * k + 1] += w * g[1];
        }
    });
}

/// What a layer paints.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum LayerKind {
    Fill,
    Stroke,
}

/// One painted layer: closed contours filled (nonzero or even-odd), then composited.
#[derive(Clone, Debug)]
pub(crate) struct Layer<T> {
    pub shape: usize,
    pub kind: LayerKind,
    /// Straight RGBA.
    pub color: [T; 4],
    /// The gradient painted instead of `color` (index into [`SceneT::paints`]).
    pub paint: Option<usize>,
    /// The texture painted instead of `color` (index into [`SceneT::textures`]).
    pub texture: Option<usize>,
    pub verts: Vec<[T; 2]>,
    /// `(start, len)` of each closed contour in `verts`.
    pub contours: Vec<(u32, u32)>,
    /// Pixel bounds `[x0, y0, x1, y1)` clipped to the canvas; empty when `x0 >= x1 || y0 >= y1`.
    pub bbox: [i32; 4],
    /// Polyline of a stroke layer (empty for fills), whether it is closed, and the half-width.
    pub poly: Vec<[T; 2]>,
    pub closed: bool,
    pub radius: T,
    pub style: Style,
    /// Whether a fill layer uses the even-odd rule.
    pub even_odd: bool,
}

fn bbox<T: Real>(verts: &[[T; 2]], pad: f32, w: u32, h: u32) -> [i32; 4] {
    let mut lo = [f32::INFINITY; 2];
    let mut hi = [f32::NEG_INFINITY; 2];
    for v in verts {
        for c in 0..2 {
            let x = v[c].as_f32();
            lo[c] = lo[c].min(x - pad);
            hi[c] = hi[c].max(x + pad);
        }
    }
    if !(lo[0].is_finite() && lo[1].is_finite() && hi[0].is_finite() && hi[1].is_finite()) {
        return [0, 0, 0, 0];
    }
    let x0 = lo[0].floor().clamp(0.0, w as f32) as i32;
    let y0 = lo[1].floor().clamp(0.0, h as f32) as i32;
    let x1 = hi[0].ceil().clamp(0.0, w as f32) as i32;
    let y1 = hi[1].ceil().clamp(0.0, h as f32) as i32;
    [x0, y0, x1, y1]
}

/// Builds the layers of a scene in paint order (per shape: fill, then stroke).
pub(crate) fn layers<T: Real>(sc: &SceneT<T>) -> Vec<Layer<T>> {
    let mut out = Vec::with_capacity(sc.shapes.len());
    for (si, s) in sc.shapes.iter().enumerate() {
        if s.pts.is_empty() || s.pieces.is_empty() {
            continue;
        }
        let poly = polyline(s);
        let closed = s.kind != ShapeKind::OpenCubic;
        if let Some(c) = s.fill
            && closed
        {
            let bb = bbox(&poly, 0.0, sc.width, sc.height);
            out.push(Layer {
                shape: si,
                kind: LayerKind::Fill,
                color: c,
                paint: s.fill_paint,
                texture: s.fill_texture,
                contours: vec![(0, poly.len() as u32)],
                verts: poly.clone(),
                bbox: bb,
                poly: Vec::new(),
                closed,
                radius: T::zero(),
                style: s.style,
                even_odd: s.even_odd,
            });
        }
        if let Some((c, w)) = s.stroke {
            let r = T::c(0.5) * w.max(T::zero());
            let bb = bbox(
                &poly,
                r.as_f32() * s.style.reach() + 1.0,
                sc.width,
                sc.height,
            );
            out.push(Layer {
                shape: si,
                kind: LayerKind::Stroke,
                color: c,
                paint: s.stroke_paint,
                texture: None,
                verts: Vec::new(),
                contours: Vec::new(),
                bbox: bb,
                poly,
                closed,
                radius: r,
                style: s.style,
                even_odd: false,
            });
        }
    }
    out
}
