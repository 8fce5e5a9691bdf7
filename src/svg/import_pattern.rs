//! `<pattern>` paint → a repeating [`Texture`]: the pattern's tile is imported by the same walk
//! (usvg has resolved `href` inheritance of attributes and children, `patternUnits`,
//! `patternContentUnits`, `viewBox` and `preserveAspectRatio`) and drawn by our own rasteriser
//! at the resolution the tile has on the canvas (as resvg does: the tile's size times the scale
//! of the path's transform and `patternTransform`, rounded to whole pixels), then sampled with
//! [`TextureEdge::Repeat`]. The content overflowing the tile is cut (`overflow` is ignored, as
//! in resvg). Patterns inside pattern tiles nest [`MAX_DEPTH`] deep (each drawn at its tile's
//! resolution, which includes the [`drawn_at`] factor once); deeper ones paint nothing. Tiles
//! are anti-aliased as the scene will be ([`DrawnAt::antialias`]).

use super::images::{ImageLimits, Images};
use super::walk::{Mode, Walk};
use crate::raster::Antialias;
use crate::scene::{Affine, Content, Rgba, Scene, Texture, TextureEdge, TextureFilter};
use resvg::usvg;
use std::cell::Cell;
use std::sync::Arc;
use usvg::Transform;

/// Patterns inside pattern tiles inside …, at most this deep.
pub const MAX_DEPTH: u32 = 4;
/// Largest tile side and tile area, in pixels.
const MAX_TILE_SIDE: f32 = 2048.0;
const MAX_TILE_PIXELS: f32 = 1024.0 * 1024.0;

/// How an imported scene will be drawn, so that its pattern tiles are drawn alike.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DrawnAt {
    /// Device pixels per canvas pixel (`render --size`): a tile drawn at the canvas's own
    /// resolution and magnified would be blurred. Clamped to `(0, 16]` (1 when not finite).
    pub resolution: f32,
    pub antialias: Antialias,
}

impl DrawnAt {
    /// The canvas's own resolution, exact coverage: how every pass that optimises draws.
    pub const CANVAS: DrawnAt = DrawnAt {
        resolution: 1.0,
        antialias: Antialias::Exact,
    };
}

thread_local! {
    static DEPTH: Cell<u32> = const { Cell::new(0) };
    /// How the imported scene will be drawn (see [`drawn_at`]).
    static DRAWN_AT: Cell<DrawnAt> = const { Cell::new(DrawnAt::CANVAS) };
}

/// Runs `f` (an import on this thread) with pattern tiles drawn as `d` says.
pub fn drawn_at<R>(d: DrawnAt, f: impl FnOnce() -> R) -> R {
    let resolution = if d.resolution.is_finite() && d.resolution > 0.0 {
        d.resolution.min(16.0)
    } else {
        1.0
    };
    let old = DRAWN_AT.with(|c| c.replace(DrawnAt { resolution, ..d }));
    let out = f();
    DRAWN_AT.with(|c| c.set(old));
    out
}

/// The texture that paints `p` at `opacity` on a path in user space `ts`; `None` when the tile
/// is empty, degenerate or nested too deep.
pub(super) fn texture(p: &usvg::Pattern, ts: Transform, opacity: f32) -> Option<Texture> {
    let depth = DEPTH.with(Cell::get);
    if depth >= MAX_DEPTH {
        return None;
    }
    DEPTH.with(|d| d.set(depth + 1));
    let t = tile(p, ts, opacity);
    DEPTH.with(|d| d.set(depth));
    t
}

fn tile(p: &usvg::Pattern, ts: Transform, opacity: f32) -> Option<Texture> {
    let m = ts.pre_concat(p.transform());
    let rect = p.rect();
    let (mut sx, mut sy) = m.get_scale();
    let drawn = DRAWN_AT.with(Cell::get);
    (sx, sy) = (sx * drawn.resolution, sy * drawn.resolution);
    // Keep the tile within its bounds, at one scale for both axes.
    let (w, h) = (rect.width() * sx, rect.height() * sy);
    let k = (MAX_TILE_SIDE / w.max(h))
        .min((MAX_TILE_PIXELS / (w * h)).sqrt())
        .min(1.0);
    if !(k.is_finite() && k > 0.0) {
        return None;
    }
    (sx, sy) = (sx * k, sy * k);
    let tw = (rect.width() * sx).round();
    let th = (rect.height() * sy).round();
    if !(tw >= 1.0 && th >= 1.0) {
        return None;
    }
    let images = Images::new(None, ImageLimits::DEFAULT, super::fonts::database());
    let mut walk = Walk::new((tw, th), Arc::new(images));
    let mut content = Content::default();
    // The tile is drawn at device resolution already: patterns inside it take no more.
    let inner = DrawnAt {
        resolution: 1.0,
        ..drawn
    };
    drawn_at(inner, || {
        walk.group(
            p.root(),
            Transform::from_scale(sx, sy),
            Mode::Draw,
            &mut content,
        )
    });
    let scene = Scene {
        width: tw as u32,
        height: th as u32,
        background: Rgba::TRANSPARENT,
        shapes: content.shapes,
        groups: content.groups,
    };
    scene.validate().ok()?;
    let img = crate::raster::render_with(&scene, drawn.antialias);
    let q = |v: f32| (v * opacity * 255.0).round().clamp(0.0, 255.0) as u8;
    let to_canvas = m
        .pre_translate(rect.x(), rect.y())
        .pre_scale(1.0 / sx, 1.0 / sy);
    let t = Texture {
        width: scene.width,
        height: scene.height,
        pixels: img.data.iter().map(|v| q(*v)).collect(),
        transform: Affine([
            to_canvas.sx,
            to_canvas.ky,
            to_canvas.kx,
            to_canvas.sy,
            to_canvas.tx,
            to_canvas.ty,
        ]),
        edge: TextureEdge::Repeat,
        filter: TextureFilter::Bicubic,
    };
    t.validate().ok().map(|()| t)
}
