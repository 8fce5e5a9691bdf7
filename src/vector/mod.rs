//! The vector stage's finish: what every SVG we write passes through before it leaves a run.
//!
//! | file | job |
//! |---|---|
//! | [`lobes`] | exact repair of a looping outline: cut it where it meets itself into lobes |
//! | [`canvas`] | outlines reaching past the canvas cut to it, their own cubics joined along its edge |
//! | [`simple`] | simple outlines: find paths that cross themselves or fold into spikes, split them into simple pieces |
//! | [`check`] | editability counts of any SVG (self-intersecting, hidden, slivers, colours) |
//! | [`export`] | compact, exact SVG text (fewest decimals within a render tolerance) |
//! | [`palette`] | a small palette: k-means of the target, user palettes, snapping fills |
//! | [`straight`] | near-straight segments made straight, so that they are written as lines |

pub mod canvas;
pub mod cells;
pub mod check;
pub mod export;
pub mod fill;
pub mod lobes;
pub mod merge;
pub mod palette;
pub mod simple;
pub mod straight;

use crate::scene::{Point, Rgba, Scene, Shape, ShapeKind};
use palette::{Background, ColorPlan};
use serde::{Deserialize, Serialize};

/// The vector options of a request, in user terms, as the API and the command line take them
/// (field names are the job fields).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct VectorOptions {
    #[serde(flatten)]
    pub colors: ColorPlan,
    /// Vectorize runs: stop adding paths once the PSNR (dB) reaches this.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_psnr: Option<f64>,
    /// Vectorize runs: the SVG at most this many bytes (one path always stays).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_bytes: Option<usize>,
    /// What the trace (and SDS) paint fills with; `flat` is left out of the JSON.
    #[serde(default, skip_serializing_if = "fill::FillKind::is_flat")]
    pub fill: fill::FillKind,
}

/// Smallest `max_bytes` accepted: an SVG's header and one small path.
pub const MIN_BYTES: usize = 256;
/// Largest `max_bytes` accepted (16 MiB).
pub const MAX_BYTES: usize = 16 << 20;

/// A stop rule outside its range (the message follows the option's name).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum StopRuleError {
    #[error("must be above 0 and at most 100 (dB), got {0}")]
    TargetPsnr(f64),
    #[error("must be between {MIN_BYTES} and {MAX_BYTES}, got {0}")]
    MaxBytes(usize),
}

/// `target_psnr` is in `(0, 100]` dB.
pub fn check_target_psnr(v: f64) -> Result<f64, StopRuleError> {
    if v.is_finite() && v > 0.0 && v <= 100.0 {
        Ok(v)
    } else {
        Err(StopRuleError::TargetPsnr(v))
    }
}

/// `max_bytes` is in `MIN_BYTES..=MAX_BYTES`.
pub fn check_max_bytes(v: usize) -> Result<usize, StopRuleError> {
    if (MIN_BYTES..=MAX_BYTES).contains(&v) {
        Ok(v)
    } else {
        Err(StopRuleError::MaxBytes(v))
    }
}

impl VectorOptions {
    /// Checks every option; the error names the field.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        self.colors
            .validate()
            .map_err(|(f, e)| (f, e.to_string()))?;
        if let Some(v) = self.target_psnr {
            check_target_psnr(v).map_err(|e| ("target_psnr", e.to_string()))?;
        }
        if let Some(v) = self.max_bytes {
            check_max_bytes(v).map_err(|e| ("max_bytes", e.to_string()))?;
        }
        let palette = self.colors.colors.is_some() || self.colors.palette.is_some();
        self.fill
            .check_with_palette(palette)
            .map_err(|e| ("fill", e))?;
        Ok(())
    }
}

/// Curve-fitting tolerance (px) when a looping path is split into simple pieces.
pub const SIMPLE_TOLERANCE: f32 = 0.1;
/// Pieces of a split path below this area (px²) are dropped.
pub const SIMPLE_MIN_AREA: f32 = 0.5;

/// Replaces every closed path whose outline meets itself by simple pieces, in place (same
/// place in the paint order): without its segments too short to see when that is enough
/// ([`without_tiny_segments`]: a fold back and forth), else its lobes, cut exactly out of its outline
/// ([`lobes::split_lobes`]); a lobe that is still not simple (a cusp or a fold without a
/// crossing) by the union repair ([`simple::split_simple`]). Pieces under `min_area` px² are
/// dropped. Returns how many paths were repaired. The scene never grows past `MAX_PATHS`.
pub fn make_simple(scene: &mut Scene, min_area: f32) -> usize {
    let mut repaired = 0;
    let mut budget = crate::scene::MAX_PATHS;
    let mut pieces = Vec::with_capacity(scene.shapes.len());
    for s in &scene.shapes {
        let mut out = Vec::new();
        if simple::is_simple(s) {
            out.push(s.clone());
        } else {
            repaired += 1;
            // A spike of a segment too short to see (a fold back and forth) is dropped first.
            let s = without_tiny_segments(s);
            if simple::is_simple(&s) {
                out.push(s);
            } else {
                for l in lobes::split_lobes(&s, min_area) {
                    if simple::is_simple(&l) {
                        out.push(l);
                    } else {
                        out.extend(simple::split_simple(&l, SIMPLE_TOLERANCE, min_area));
                    }
                }
            }
        }
        out.truncate(budget);
        budget -= out.len();
        pieces.push(out);
    }
    // Groups stay on the pieces of their shapes.
    scene.replace_shapes(pieces);
    repaired
}

/// Segments whose control points all lie within this of their start (px) are dropped by
/// [`without_tiny_segments`].
pub const TINY_SEGMENT: f32 = 0.125;

/// A closed cubic path without its segments shorter than [`TINY_SEGMENT`] (all four points
/// within it of the segment's start), each next segment starting where the last kept one ends;
/// the path itself when it has no such segment, when fewer than two would be left, or when it
/// is not a closed cubic.
pub fn without_tiny_segments(shape: &Shape) -> Shape {
    let n = shape.num_segments();
    if shape.kind != ShapeKind::ClosedCubic || n < 3 {
        return shape.clone();
    }
    let tiny = |seg: &[Point; 4]| {
        seg.iter()
            .all(|p| (p.x - seg[0].x).hypot(p.y - seg[0].y) < TINY_SEGMENT)
    };
    let kept: Vec<[Point; 4]> = (0..n)
        .map(|i| shape.segment(i))
        .filter(|seg| !tiny(seg))
        .collect();
    if kept.len() == n || kept.len() < 2 {
        return shape.clone();
    }
    let mut points = Vec::with_capacity(3 * kept.len());
    for (j, seg) in kept.iter().enumerate() {
        // Each segment starts where the previous kept one ended; the last one closes at the
        // first one's start.
        points.push(if j == 0 { seg[0] } else { kept[j - 1][3] });
        points.extend([seg[1], seg[2]]);
    }
    let mut out = shape.clone();
    out.points = points;
    out
}

/// Removes the paths a designer would find hidden or too small to see or edit, by the
/// measure of [`check`]: visible area under [`check::SLIVER_AREA`] px², or a mean width
/// (2·area/perimeter) under [`check::SLIVER_WIDTH`] px, in px of the output canvas, which is
/// `scale` times the scene's. Returns how many.
pub fn drop_unseen(scene: &mut Scene, scale: f32) -> usize {
    let vis = palette::visibility(scene, None);
    let k2 = (scale * scale) as f64;
    let before = scene.shapes.len();
    let keep: Vec<bool> = scene
        .shapes
        .iter()
        .zip(&vis)
        .map(|(sh, v)| {
            let ring = simple::flatten(sh, 0.1);
            let area = crate::losses::polygon_area(&ring).abs() as f64;
            let perim: f64 = (0..ring.len())
                .map(|i| {
                    let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
                    ((a.0 - b.0) as f64).hypot((a.1 - b.1) as f64)
                })
                .sum();
            let wide = !sh.is_closed()
                || perim <= 0.0
                || 2.0 * area / perim * scale as f64 >= check::SLIVER_WIDTH;
            v.area as f64 * k2 >= check::SLIVER_AREA && wide
        })
        .collect();
    let pieces = (scene.shapes.iter().zip(keep))
        .map(|(sh, k)| if k { vec![sh.clone()] } else { Vec::new() })
        .collect();
    scene.replace_shapes(pieces);
    before - scene.shapes.len()
}

/// The SVG text of a finished scene: the coarsest coordinate grid whose render stays within
/// [`export::Tolerance`] (see [`export::compact_svg`]) and on which no outline that was simple
/// meets itself, grouped by colour or LIVE stage with stable ids when `colors.group` says so.
/// Should even the finest grid make an outline meet itself, the text is read back, and while any
/// outline does, those are made simple again ([`make_simple`]) at the rounded coordinates and
/// the scene is written anew (three rounds at most).
pub fn write_svg(scene: &Scene, colors: &ColorPlan) -> String {
    let opts = colors.group.svg_options();
    let tol = export::Tolerance::default();
    // A grid that makes a simple outline meet itself is passed over for a finer one.
    let write = |s: &Scene| {
        let all_simple = s.shapes.iter().all(simple::is_simple);
        let stays_simple = |text: &str, back: &Scene| {
            !all_simple || (back.shapes.iter().all(simple::is_simple) && outlines_simple(text))
        };
        let c = export::compact_svg_checked(s, &opts, tol, stays_simple);
        (c.svg, c.within && all_simple)
    };
    let (mut text, checked) = write(scene);
    // A grid within the tolerance was accepted with every outline read back simple: the text
    // is what the loop below would keep.
    if checked {
        return text;
    }
    for _ in 0..3 {
        let Ok(mut back) = crate::svg::from_svg(&text) else {
            break;
        };
        if back.shapes.iter().all(simple::is_simple) && outlines_simple(&text) {
            break;
        }
        make_simple(&mut back, SIMPLE_MIN_AREA);
        text = write(&back).0;
    }
    text
}

/// Whether no outline of `svg` meets itself by the editability check's own test
/// ([`check::self_intersecting_svg`]: its flattening of the text as written).
fn outlines_simple(svg: &str) -> bool {
    check::self_intersecting_svg(svg) == Ok(0)
}

/// Removes, from the top of the paint order down, every path whose removal changes no pixel of
/// the render by more than [`check::VISIBLE_STEP`] (a path hidden under others, or painted
/// over a region of its own colour). Returns how many.
///
/// A flat scene's trial renders cover only the rows the path can paint
/// ([`crate::raster::render_rows`], the same pixels as a whole render): nothing else changes.
pub fn drop_hidden(scene: &mut Scene) -> usize {
    let step = check::VISIBLE_STEP;
    let mut current = crate::raster::render(scene).data;
    let row = 4 * scene.width as usize;
    // Going down the paint order, path `i` is tried after only paths above it were removed:
    // the rows of the paths below it do not change.
    let rows = crate::raster::shape_rows(scene);
    let mut removed = 0;
    let mut i = scene.shapes.len();
    while i > 0 {
        i -= 1;
        let (trial, start, img) = without_shape(scene, i, rows[i].clone());
        let at = start as usize * row;
        let unchanged = img
            .iter()
            .zip(&current[at..at + img.len()])
            .all(|(a, b)| (a - b).abs() <= step);
        if unchanged {
            *scene = trial;
            current[at..at + img.len()].copy_from_slice(&img);
            removed += 1;
        }
    }
    removed
}

/// `scene` without shape `i`, and the rows of its render that removing the shape can change,
/// given the shape's `rows` ([`crate::raster::shape_rows`]; see [`changed_rows`]).
pub(crate) fn without_shape(
    scene: &Scene,
    i: usize,
    rows: std::ops::Range<u32>,
) -> (Scene, u32, Vec<f32>) {
    let mut trial = scene.clone();
    trial.remove_shape(i);
    let (start, img) = changed_rows(scene, &trial, rows);
    (trial, start, img)
}

/// The render of `trial`, an edit of `before` that changes no pixel outside `rows`, where it
/// can differ: the first row and the pixels of [`crate::raster::render_rows`] when `before` is
/// flat, else row 0 and the whole render.
pub(crate) fn changed_rows(
    before: &Scene,
    trial: &Scene,
    rows: std::ops::Range<u32>,
) -> (u32, Vec<f32>) {
    if before.groups.is_empty() {
        crate::raster::render_rows(trial, rows)
    } else {
        (0, crate::raster::render(trial).data)
    }
}

/// What [`finish_scene`] did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FinishReport {
    /// Paths split into simple pieces.
    pub split: usize,
    /// Paths dropped as hidden or too small to see.
    pub dropped: usize,
    /// Paths merged into a touching path of the same fill ([`merge`]), or pixel-art cells
    /// merged into the outline of their region ([`cells`]).
    #[serde(default)]
    pub merged: usize,
    /// Paths cut to the canvas ([`canvas`]).
    #[serde(default)]
    pub cut: usize,
    /// Distinct fills left.
    pub colors: usize,
}

/// The finish of a run without a target image (after score distillation): looping outlines
/// split into simple pieces, paths reaching past the canvas cut to it ([`canvas`]), hidden
/// paths dropped, with `drop_small` paths too small to see (not for styles whose cells are
/// meant to be one pixel: pixel art, strokes), fills reduced as `colors` says (a user palette:
/// each fill to its nearest entry; a colour cap: k-means of the fills weighted by what they
/// show; otherwise near-equal fills merged, then the fewest colours whose render stays within
/// [`palette::FEWEST_COLOURS_PSNR`] dB: [`palette::fewest_colours`]), touching paths of one
/// fill merged ([`merge`]; with `drop_small` only), near-straight segments made straight
/// ([`straight`]), and the background set.
pub fn finish_scene(scene: &mut Scene, colors: &ColorPlan, drop_small: bool) -> FinishReport {
    let split = make_simple(scene, SIMPLE_MIN_AREA);
    let cut = canvas::cut_scene_to_canvas(scene);
    let mut dropped = drop_hidden(scene);
    if drop_small {
        dropped += drop_unseen(scene, 1.0);
    }
    let pal = colors.resolve(|k| palette::palette_of_fills(scene, k));
    match &pal {
        Some(p) => {
            palette::choose_fills(scene, None, p);
        }
        None => {
            palette::merge_similar(scene, palette::MERGE_DISTANCE);
            if let Some(p) = palette::fewest_colours(scene, palette::FEWEST_COLOURS_PSNR) {
                palette::choose_fills(scene, None, &p);
            }
        }
    }
    // Strokes stay as they are drawn; pixel cells become one outline per region of a colour.
    let merged = if drop_small {
        merge::merge_touching(scene, merge::MergeTolerance::default())
    } else {
        cells::merge_cells(scene)
    };
    // Last, so that no choice above sees the (sub-pixel) change; outlines stay simple.
    straight::straighten(scene, straight::STRAIGHT_TOLERANCE);
    match colors.background {
        Background::Transparent => scene.background = Rgba::TRANSPARENT,
        Background::Color(c) => scene.background = c.to_rgba(),
        Background::Auto => {
            if let Some(p) = &pal {
                palette::snap_background(scene, p);
            }
        }
    }
    FinishReport {
        split,
        dropped,
        merged,
        cut,
        colors: palette::distinct_fills(scene),
    }
}

/// Removes shapes from the top of the stack down with a whole render per trial, keeping each
/// removal `keep(new render, current render)` accepts; returns how many went. The reference
/// that the row-band trials of [`drop_hidden`] and the `auto` pruning are tested against.
#[cfg(test)]
pub(crate) fn remove_by_whole_renders(
    scene: &mut Scene,
    keep: impl Fn(&crate::image::Image, &crate::image::Image) -> bool,
) -> usize {
    let mut current = crate::raster::render(scene);
    let mut removed = 0;
    for i in (0..scene.shapes.len()).rev() {
        let mut trial = scene.clone();
        trial.remove_shape(i);
        let img = crate::raster::render(&trial);
        if keep(&img, &current) {
            *scene = trial;
            current = img;
            removed += 1;
        }
    }
    removed
}

#[cfg(test)]
#[path = "tests_finish.rs"]
mod tests;
