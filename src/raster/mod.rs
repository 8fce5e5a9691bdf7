//! Differentiable CPU rasteriser: exact-area anti-aliasing, nonzero and even-odd fills, strokes,
//! groups as layers (opacity, clip, mask), premultiplied source-over compositing in `f32`, and an
//! exact backward pass.
//!
//! # Model (what is rendered)
//! - Cubic segments are flattened at fixed parameters `t = k/n`; `n` per segment comes from
//!   Wang's formula with a tolerance of [`FLATTEN_TOLERANCE`] px and is fixed within one
//!   forward/backward pair. Polygons are used as they are.
//! - Coverage of a pixel is `min(|A|, 1)` where `A` is the exact integral of the winding number
//!   over the pixel square (box filter). For non-overlapping outlines this is the exact
//!   area coverage and equals the nonzero rule; where an outline overlaps itself it saturates.
//!   An even-odd fill's coverage is the distance from `A` to the nearest even integer (0 where
//!   the winding is even, 1 where odd, exact wherever a pixel is crossed by one edge).
//!   Forward-only renders may ask for [`Antialias::Supersampled`] instead: the share of 16
//!   point samples inside, as resvg's tiny-skia anti-aliases (see `sampled`).
//! - A round-capped, round-joined stroke is the union of one capsule per polyline edge
//!   ([`crate::svg::to_svg`] writes `stroke-linecap="round" stroke-linejoin="round"` so other
//!   renderers agree); butt and square caps and miter (with its limit) and bevel joins are
//!   drawn as SVG draws them, as a union of per-edge pieces (see `stroke`).
//! - Per shape the fill is painted first, then the stroke. `alpha = coverage * colour.a`,
//!   `out = colour.rgb * alpha + below * (1 - alpha)` (premultiplied), over the background.
//!   The colour is the flat one, or a gradient's colour at the pixel centre (`paint`), or a
//!   texture's (`texture`: imported images and patterns, constants for the backward).
//! - A scene's groups ([`crate::scene::Group`]) paint their shapes onto a transparent layer,
//!   composited with `opacity × clip × mask` per pixel (see `layer`), by the group's blend
//!   mode (all sixteen of W3C Compositing Level 1, see `blend`); a flat scene takes the same
//!   path as before, untouched.
//!
//! # Backward
//! [`backward`] is the exact derivative of the forward function above (up to the measure-zero
//! kinks of `min(|A|, 1)`): the compositing is differentiated pixel by pixel top-down, the
//! coverage integral by Reynolds transport along each edge (see `walk`), then the chain rule
//! goes through the stroke outline and the Bernstein weights of the flattening to the control
//! points. Every group of [`Params`] gets gradients, group opacities included (clip and mask
//! content is not a parameter: it is drawn once per pass and held constant). Edge lengths in the
//! stroke normal are smoothed (`sqrt(|d|² + 1e-6)`) so degenerate paths give finite gradients.
//!
//! # Invariants and failure
//! All functions take scenes that passed [`Scene::validate`] and cannot fail on them; on an
//! invalid scene they never panic (non-finite outlines are skipped). Work is split into row
//! bands processed in parallel with rayon; per layer only its bounding box ∩ band is touched,
//! and the tape keeps `5` floats per painted pixel per layer, plus 3 words per pixel an edge of
//! a fill crosses (so the backward pass does not walk the edges again).

// Index loops over small fixed arrays read clearer in numeric code; NaN-aware negated
// comparisons are intentional (a NaN must take the early-out branch).
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

mod blend;
mod composite;
mod engine;
mod geom;
mod grad;
mod layer;
mod paint;
mod real;
mod sampled;
mod stroke;
mod texture;
mod walk;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_blend;
#[cfg(test)]
mod tests_layer;
#[cfg(test)]
mod tests_layer_paint;
#[cfg(test)]
mod tests_paint;
#[cfg(test)]
mod tests_sampled;
#[cfg(test)]
mod tests_stroke;
#[cfg(test)]
mod tests_texture;

use crate::image::Image;
use crate::scene::{ParamGroup, Params, Point, Scene, Shape};
pub(crate) use geom::SceneT;

/// Flattening tolerance in pixels used by [`render`] and [`render_tape`].
pub const FLATTEN_TOLERANCE: f32 = geom::TOLERANCE;

/// Everything [`backward`] needs from the forward pass.
#[derive(Clone, Debug)]
pub struct Tape {
    sc: SceneT<f32>,
    layers: Vec<geom::Layer<f32>>,
    bands: Vec<engine::BandTape<f32>>,
}

impl Tape {
    /// Floats held by the tape (for memory accounting).
    pub fn len_floats(&self) -> usize {
        self.bands
            .iter()
            .map(|b| b.area.len() + b.dst.len() + b.group.len() + 3 * b.pieces.len())
            .sum()
    }

    fn matches(&self, scene: &Scene) -> bool {
        self.sc.width == scene.width
            && self.sc.height == scene.height
            && self.sc.shapes.len() == scene.shapes.len()
            && self.sc.groups.len() == scene.groups.len()
            && self.sc.shapes.iter().zip(&scene.shapes).all(|(a, b)| {
                a.pts.len() == b.points.len()
                    && a.fill.is_some() == b.fill.is_some()
                    && a.stroke.is_some() == b.stroke.is_some()
            })
            && self.sc.paints.iter().map(|p| p.num_params()).sum::<usize>()
                == crate::scene::paint::scene_gradient_params(scene).len()
    }
}

pub(crate) fn render_t<T: real::Real>(sc: &SceneT<T>) -> Vec<T> {
    let ls = geom::layers(sc);
    engine::forward(sc, &ls, false, Vec::new()).0
}

/// Band buffers of dropped tapes, reused by the next [`render_tape`] (saves allocating and
/// page-faulting tens of MB per optimisation step). Bounded by [`POOL_MAX`] band buffers.
static POOL: std::sync::Mutex<Vec<engine::BandTape<f32>>> = std::sync::Mutex::new(Vec::new());
const POOL_MAX: usize = 64;
const POOL_BAND_MAX_FLOATS: usize = 16 << 20;

impl Drop for Tape {
    fn drop(&mut self) {
        recycle(std::mem::take(&mut self.bands));
    }
}

/// Returns band buffers to [`POOL`] for the next render with a tape.
fn recycle(bands: Vec<engine::BandTape<f32>>) {
    if let Ok(mut pool) = POOL.lock()
        && pool.len() < POOL_MAX
    {
        let room = POOL_MAX - pool.len();
        // Do not keep the buffers of unusually large renders alive.
        pool.extend(
            bands
                .into_iter()
                .filter(|b| {
                    b.area.capacity()
                        + b.dst.capacity()
                        + b.group.capacity()
                        + b.img.capacity()
                        + b.grad.capacity()
                        <= POOL_BAND_MAX_FLOATS
                })
                .take(room),
        );
    }
}

fn take_pooled(n: usize) -> Vec<engine::BandTape<f32>> {
    match POOL.lock() {
        Ok(mut pool) => {
            let k = pool.len().saturating_sub(n);
            pool.split_off(k)
        }
        Err(_) => Vec::new(),
    }
}

/// Renders `scene` to a premultiplied RGBA image of the scene's size.
pub fn render(scene: &Scene) -> Image {
    render_with(scene, Antialias::Exact)
}

/// How the forward pass anti-aliases edges.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Antialias {
    /// Exact area coverage (a box filter): the differentiable model, and the default.
    #[default]
    Exact,
    /// The share of 16 point samples per pixel on a 4 × 4 grid, as tiny-skia (resvg) and
    /// Skia's CPU rasteriser anti-alias (see `sampled`): forward only, for pixel-for-pixel
    /// comparisons with them. Passes with a backward always use [`Antialias::Exact`].
    Supersampled,
}

/// [`render`] with anti-aliasing `aa`.
pub fn render_with(scene: &Scene, aa: Antialias) -> Image {
    // Sampling a quarter pixel apart, the curves are flattened four times as finely.
    let tol = match aa {
        Antialias::Exact => FLATTEN_TOLERANCE,
        Antialias::Supersampled => FLATTEN_TOLERANCE / 4.0,
    };
    let sc = SceneT::<f32>::from_scene_aa(scene, tol, aa);
    Image {
        width: scene.width,
        height: scene.height,
        data: render_t(&sc),
    }
}

/// Per shape, the rows of the canvas its fill and stroke can paint (their pixel bounds; empty
/// where a shape paints nothing on the canvas). Removing shape `i` changes no pixel outside
/// its rows.
pub fn shape_rows(scene: &Scene) -> Vec<std::ops::Range<u32>> {
    let sc = SceneT::<f32>::from_scene(scene, FLATTEN_TOLERANCE);
    let mut rows = vec![0..0; scene.shapes.len()];
    for l in geom::layers(&sc) {
        let [_, y0, _, y1] = l.bbox;
        let (y0, y1) = (y0.max(0) as u32, y1.max(0) as u32);
        if y0 >= y1 {
            continue;
        }
        if let Some(r) = rows.get_mut(l.shape) {
            *r = if r.start >= r.end {
                y0..y1
            } else {
                r.start.min(y0)..r.end.max(y1)
            };
        }
    }
    rows
}

/// Part of [`render`]'s image: every row band of the full render that meets `rows`, computed as
/// the full render computes it, so its pixels are [`render`]'s bit for bit. Returns the first
/// row computed and the premultiplied RGBA of the computed rows (full width, whole bands); no
/// pixels when `rows` is empty or off the canvas.
pub fn render_rows(scene: &Scene, rows: std::ops::Range<u32>) -> (u32, Vec<f32>) {
    if rows.is_empty() {
        return (0, Vec::new());
    }
    let sc = SceneT::<f32>::from_scene(scene, FLATTEN_TOLERANCE);
    let ls = geom::layers(&sc);
    let clamp = |v: u32| v.min(scene.height) as i32;
    let (first, data) = engine::forward_rows(&sc, &ls, clamp(rows.start)..clamp(rows.end));
    (first as u32, data)
}

/// Renders `scene` and records what [`backward`] needs.
pub fn render_tape(scene: &Scene) -> (Image, Tape) {
    let sc = SceneT::<f32>::from_scene(scene, FLATTEN_TOLERANCE);
    let layers = geom::layers(&sc);
    let recycled = take_pooled(engine::bands(scene.height).len());
    let (data, bands) = engine::forward(&sc, &layers, true, recycled);
    let img = Image {
        width: scene.width,
        height: scene.height,
        data,
    };
    (img, Tape { sc, layers, bands })
}

/// Gradients of a scalar loss with respect to every scene parameter, given
/// `d_image = dL/d(output premultiplied RGBA)` (length `4 * width * height`). The result has
/// the layout of [`Params::from_scene`]. If `tape` was not recorded for a scene of the same
/// structure, or `d_image` has the wrong length, all gradients are zero (and a warning is
/// logged) rather than a panic.
pub fn backward(scene: &Scene, tape: &Tape, d_image: &[f32]) -> Params {
    backward_with_gradients(scene, tape, d_image).0
}

/// [`backward`], plus the gradients of every gradient paint's parameters in the order of
/// [`crate::scene::paint::scene_gradient_params`] (geometry, stop offsets, stop colours; the
/// [`Params`] hold them too, split into its two paint groups). A fill or stroke painted with a
/// gradient gets zero gradient for its flat stand-in colour.
pub fn backward_with_gradients(scene: &Scene, tape: &Tape, d_image: &[f32]) -> (Params, Vec<f32>) {
    let mut out = Params::zeros_like(scene);
    let n = 4 * scene.width as usize * scene.height as usize;
    if !tape.matches(scene) || d_image.len() != n {
        tracing::warn!("raster::backward: tape or d_image does not match the scene");
        let np = crate::scene::paint::scene_gradient_params(scene).len();
        return (out, vec![0.0; np]);
    }
    let g = engine::backward(&tape.sc, &tape.layers, &tape.bands, d_image);
    write_grad(&mut out, &g, scene);
    (out, g.paint)
}

/// A per-pixel loss on the rendered image, for [`render_loss_backward`]: called once per band
/// of rows with the band's pixel range (indices `y0 * width .. y1 * width`), its premultiplied
/// RGBA and a zeroed buffer of the same length, it writes dL/d(premultiplied RGBA) into the
/// buffer and returns the band's share of the loss.
pub type BandLoss<'a> = dyn Fn(std::ops::Range<usize>, &[f32], &mut [f32]) -> f64 + Sync + 'a;

/// One optimisation step's forward and backward in a single parallel pass over the row bands:
/// each band is painted, `loss` gives its gradient, and the band's backward runs at once (the
/// loss runs in parallel, and the pass waits on its threads once instead of twice). The
/// gradients equal [`backward`]'s given the same per-pixel loss gradient; the loss is the sum
/// of the bands' shares in band order. Returns the loss and the gradients in the layout of
/// [`Params::from_scene`].
pub fn render_loss_backward(scene: &Scene, loss: &BandLoss<'_>) -> (f64, Params) {
    let sc = SceneT::<f32>::from_scene(scene, FLATTEN_TOLERANCE);
    let layers = geom::layers(&sc);
    let recycled = take_pooled(engine::bands(scene.height).len());
    let (value, g, bands) = engine::forward_backward(&sc, &layers, recycled, loss);
    recycle(bands);
    let mut out = Params::zeros_like(scene);
    write_grad(&mut out, &g, scene);
    (value, out)
}

fn write_grad(out: &mut Params, g: &grad::GradT<f32>, scene: &Scene) {
    out.get_mut(ParamGroup::Points).copy_from_slice(&g.points);
    out.get_mut(ParamGroup::Fill).copy_from_slice(&g.fill);
    out.get_mut(ParamGroup::Stroke).copy_from_slice(&g.stroke);
    out.get_mut(ParamGroup::Width).copy_from_slice(&g.width);
    out.get_mut(ParamGroup::Background).copy_from_slice(&g.bg);
    out.get_mut(ParamGroup::Opacity).copy_from_slice(&g.opacity);
    out.set_paint(scene, &g.paint);
}

/// The polyline(s) of a shape's outline at `tolerance_px` (closed outlines do not repeat their
/// first vertex). These are the exact vertices the rasteriser fills.
pub fn flatten_shape(shape: &Shape, tolerance_px: f32) -> Vec<Vec<Point>> {
    let sc = Scene {
        width: 1,
        height: 1,
        background: crate::scene::Rgba::TRANSPARENT,
        shapes: vec![Shape {
            gradients: None,
            ..shape.clone()
        }],
        groups: Vec::new(),
    };
    let t = SceneT::<f32>::from_scene(&sc, tolerance_px);
    t.shapes
        .iter()
        .filter(|s| !s.pieces.is_empty())
        .map(|s| {
            geom::polyline(s)
                .into_iter()
                .map(|v| Point::new(v[0], v[1]))
                .collect()
        })
        .collect()
}
