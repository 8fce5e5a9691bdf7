//! Scene ⇄ SVG text, plus the benchmark scene JSON format.
//!
//! # Export ([`to_svg`], in `export.rs`)
//! The best picture per byte, deterministic and exact to the chosen grid
//! ([`SvgOptions::precision`] decimals of [`SvgOptions::units_per_px`] user units per pixel;
//! with `k > 1` units per pixel the `viewBox` is `k` times `width` × `height`, which stay in
//! pixels):
//! - every coordinate is rounded once to an integer number of `10^-precision` units; each path
//!   command then takes the shorter of its absolute and relative form, the relative numbers being
//!   differences of those integers (exact: no error builds up along a path);
//! - numbers without trailing zeros, leading `0` (`.5`), `-0` or unneeded separators (`1-2`,
//!   `.5.5`); repeated command letters dropped (`M0 0 5 5` for `M0 0L5 5`);
//! - a cubic whose control points lie (within half a unit) at 1/3 and 2/3 of its rounded chord is
//!   written as a line, `H`/`V` when axis-aligned; a cubic whose first control point is (after
//!   rounding) the reflection of the previous one's second becomes `S`; a closed outline's last
//!   segment is left to `Z` when it is such a straight line of non-zero length;
//! - colours as `#rgb` when possible else `#rrggbb` (8 bits per channel, as in every SVG
//!   renderer); opacities with `max(3, precision)` decimals; attributes equal to the SVG default
//!   (fill black, opacity 1) left out; shapes that paint nothing (transparent fill, no visible
//!   stroke) left out;
//! - strokes keep their caps, joins and miter limit, written where they differ from SVG's
//!   defaults: what optimisation creates is round-capped and round-joined
//!   (`stroke-linecap="round" stroke-linejoin="round"`), exactly what [`crate::raster`] draws
//!   (a union of capsules), so resvg, browsers and our rasteriser agree. With two or more stroked
//!   paths the shared ones go on one `<g>` around all the shapes, with the stroke width (and, when
//!   every shape is stroked alike, the stroke colour and opacity; when no shape is filled,
//!   `fill="none"`) that they share;
//! - [`SvgOptions::group_by_color`]: runs of consecutive paths with the same fill in one
//!   `<g fill="…">`; [`SvgOptions::ids`]: `id="p<k>"` on paths (shape index + 1) and
//!   `id="c<k>"` on colour groups.
//!
//! The background becomes a full-canvas `<rect>` first when it is not fully transparent.
//! Gradients are written once each in a `<defs>` after it (`export_paint`: user-space
//! coordinates, exact numbers, ids `g1, g2, …` in scene order) and referenced as `url(#gK)`
//! (in a scene with groups, in the order the paths are written, mask content included). A scene
//! with groups is written by `export_groups` (`<g opacity clip-path mask style>`, `<clipPath>` and
//! `<mask>` in `<defs>` with ids `clip<k>`/`mask<k>`); even-odd fills get `fill-rule="evenodd"`.
//! [`crate::vector::export::compact_svg`] picks the coarsest grid (1 px to 1/1000 px, written as
//! integers) that still renders the same.
//!
//! # Import ([`from_svg`], [`import_svg`] with warnings; in `import.rs`)
//! A file's bytes become text by [`encoding`]: UTF-8, UTF-16 by its byte-order mark, or the
//! legacy encoding its XML declaration names.
//! Parsing, CSS/style attributes, `<rect>`/`<circle>`/`<ellipse>`/`<polygon>`/`<line>`, arcs,
//! `<use>`, groups and transforms are normalised by `usvg` (after the guard, which breaks
//! reference cycles and drops entity texts that refer to entities, with a warning each); we then
//! walk its path tree:
//! - every point is mapped through its groups' chained transforms (a root `background-color`
//!   lands on the canvas whatever the viewBox origin); stroke widths are scaled by `sqrt(|det|)`
//!   of that transform;
//! - lines and quadratics are converted to (exactly equivalent) cubics;
//! - **fill**: all subpaths of one `<path>` become ONE [`ShapeKind::ClosedCubic`] shape. Extra
//!   subpaths are joined to the first one by straight "bridge" segments that are walked there and
//!   back, so they cancel in the winding number and holes survive exactly; `fill-rule` is kept
//!   on the shape ([`crate::scene::FillRule`], drawn exactly by the rasteriser).
//! - **stroke**: a path with a single subpath keeps its stroke on the same shape (closed subpath)
//!   or becomes an [`ShapeKind::OpenCubic`] (open subpath, no fill). With several subpaths, each
//!   subpath gets its own stroke shape (closed ones get a transparent fill) painted after the fill.
//!   Caps, joins and the miter limit are kept ([`crate::scene::Stroke`]); a dash pattern (with its
//!   offset) is expanded into one open stroke per dash. Under a transform that is no similarity
//!   (skew, unequal scales) a stroke has no single width: its outline (dashes, caps and joins
//!   included, computed by tiny-skia's stroker in the path's own units) is mapped through the
//!   transform and filled in the stroke's colour.
//! - **groups**: a group (or element) with an opacity below 1, a `clip-path`, a `mask`, a
//!   `mix-blend-mode` or `isolation: isolate` becomes a [`crate::scene::Group`] over the range of
//!   shapes its children became (one shape painting one layer takes a lone opacity itself
//!   instead); `plus-lighter` is drawn as normal with a warning. Clip paths (their children by `clip-rule`, a
//!   `clip-path` on a `<clipPath>` or on its children) and masks (luminance or alpha, a `mask` on
//!   a `<mask>`, the mask region as a clip when it does not cover the canvas) are kept with their
//!   units resolved in canvas pixels; nested `<svg>` and `<symbol>` viewports are the clip paths
//!   usvg gives them. Transforms are chained group by group as resvg draws them.
//! - **gradients**: linear and radial gradients (fill and stroke) become
//!   [`crate::scene::Gradient`]s in canvas pixels, as usvg resolved them (`href` inheritance,
//!   units, stop clamping; see `import_paint`), the flat colour beside them being the mean stop
//!   colour; a stroke drawn as a filled outline keeps its gradient as the outline's fill.
//! - **images and patterns** become [`crate::scene::Texture`]s: an `<image>` its rectangle
//!   filled with its pixels (`import_image`; where it may come from and the bounds on decoding
//!   it in `images`: `data:` URLs, files only beside an SVG file the caller names), an SVG image
//!   its content clipped to its viewport; a pattern on a fill its tile drawn by our rasteriser,
//!   repeated (`import_pattern`; on a stroke its mean colour). They export as image-filled
//!   `<pattern>`s (`export_texture`).
//! - **text** is laid out by usvg with the fonts of [`fonts`] (`VF_FONT_DIRS`, the system's) and
//!   kept as the glyphs' outlines, filled and stroked as the text was.
//!   Text without fonts and filters are ignored, each with a warning naming the element
//!   (`filter on #id ignored …`; at most 16, then a count): the content is drawn as it is,
//!   unfiltered.
//! - if the first shape is a filled rectangle covering the whole canvas (what [`to_svg`] writes
//!   for the background) it becomes the scene background.

pub mod encoding;
mod export;
mod export_groups;
mod export_paint;
mod export_texture;
mod file;
pub mod fonts;
mod guard;
mod images;
mod import;
mod import_image;
mod import_paint;
mod import_pattern;
mod path_data;
mod profile;
mod walk;

pub use export::{MAX_PRECISION, SvgOptions, to_svg, with_metadata, written_color};

pub use file::{
    SCENE_FILE_MAX_BYTES, load_import, load_import_at, load_scene, read_text_capped,
    scene_from_json,
};
pub use guard::{Parsed, SvgLimits, SvgRejected};
pub use images::ImageLimits;
pub use import::{SvgImport, from_svg, import_svg, import_svg_in, import_svg_with_fonts};
pub use import_pattern::DrawnAt;
pub use profile::{ProfileViolation, check_safe_output};

use crate::scene::{MAX_SIDE, SceneError};
use resvg::usvg;

/// Why an SVG (or scene JSON) could not be turned into a scene.
#[derive(Debug, thiserror::Error)]
pub enum SvgError {
    #[error("cannot parse SVG: {0}")]
    Parse(#[from] SvgRejected),
    #[error("SVG canvas size {0}x{1} is out of range (1..={MAX_SIDE} px)")]
    Size(f32, f32),
    #[error("cannot parse scene JSON: {0}")]
    Json(String),
    #[error("imported scene is invalid: {0}")]
    Invalid(#[from] SceneError),
    #[error("{path} is larger than {max} bytes")]
    TooLarge { path: String, max: u64 },
    #[error("I/O error on {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("{path} is not SVG text: {source}")]
    Text {
        path: String,
        source: encoding::TextError,
    },
}

/// Why SVG text could not be rendered to pixels.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The text passed a bound of [`SvgLimits`] or does not parse.
    #[error("{0}")]
    Rejected(#[from] SvgRejected),
    #[error("SVG has no size")]
    NoSize,
    #[error("SVG aspect ratio {width}x{height} is too extreme to render at {side} px")]
    TooExtreme { width: f32, height: f32, side: u32 },
    #[error("cannot allocate a {width}x{height} pixmap")]
    Pixmap { width: u32, height: u32 },
    #[error("cannot encode PNG: {0}")]
    Png(String),
}

/// A blank `width × height` pixmap to render into.
pub fn pixmap(width: u32, height: u32) -> Result<resvg::tiny_skia::Pixmap, RenderError> {
    resvg::tiny_skia::Pixmap::new(width, height).ok_or(RenderError::Pixmap { width, height })
}

/// Renders `svg` to PNG with resvg at its own size, scaled down so the longest side is at most
/// `max_side` (the service's `result.png`, the command line's `-o out.png`).
pub fn render_png(svg: &str, max_side: f32) -> Result<Vec<u8>, RenderError> {
    render_png_scaled(svg, |longer| (max_side / longer).min(1.0))
}

/// Renders `svg` to PNG with resvg scaled (up or down) so its longest side is `side` px (the
/// service's `result.png?size=N`).
pub fn render_png_at(svg: &str, side: u32) -> Result<Vec<u8>, RenderError> {
    render_png_scaled(svg, |longer| side as f32 / longer)
}

/// Renders `svg` to PNG at the scale `scale(its longest side)` gives.
fn render_png_scaled(svg: &str, scale: impl Fn(f32) -> f32) -> Result<Vec<u8>, RenderError> {
    use resvg::tiny_skia;
    // A written SVG carries its textures as embedded PNGs (`data:` URLs): decode those, within
    // the image limits and never from a file, so the picture shows them.
    let images = images::Images::new(None, ImageLimits::DEFAULT, fonts::database());
    let tree = images.parse(svg, 0)?.tree;
    let size = tree.size();
    let scale = scale(size.width().max(size.height()));
    let w = (size.width() * scale).ceil().max(1.0) as u32;
    let h = (size.height() * scale).ceil().max(1.0) as u32;
    let mut pixmap = pixmap(w, h)?;
    resvg::render(
        &tree,
        tiny_skia::Transform::from_scale(scale, scale),
        &mut pixmap.as_mut(),
    );
    pixmap
        .encode_png()
        .map_err(|e| RenderError::Png(e.to_string()))
}

/// Parses untrusted SVG text with usvg. It checks [`SvgLimits::DEFAULT`] before any geometry
/// work ([`guard`]), never reads files and never decodes embedded images (`<image
/// href="/dev/zero">` must not be followed), so every caller — HTTP submissions, the worker,
/// evaluation, tracing — is bounded on hostile input. The import ([`import_svg`]) and the PNG
/// renders ([`render_png`]) are the other parses: the same guard, with the image sources and
/// bounds of `images` (for the renders `data:` URLs only, never a file).
pub fn parse_usvg(text: &str) -> Result<usvg::Tree, SvgRejected> {
    parse_usvg_repaired(text).map(|p| p.tree)
}

/// [`parse_usvg`], with the repairs the guard made (dropped entity texts, broken reference
/// cycles) as warnings.
pub fn parse_usvg_repaired(text: &str) -> Result<Parsed, SvgRejected> {
    let opts = usvg::Options {
        image_href_resolver: usvg::ImageHrefResolver {
            resolve_data: Box::new(|_, _, _| None),
            resolve_string: Box::new(|_, _| None),
        },
        fontdb: fonts::database(),
        ..usvg::Options::default()
    };
    guard::parse_repaired(text, &SvgLimits::DEFAULT, &opts)
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_gradient;
