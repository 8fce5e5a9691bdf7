//! Editability counts of any SVG: how many paths, how many cross themselves, how many cannot be
//! seen, how many are too small or thin to see or edit, and how many colours.
//!
//! # How an SVG is measured
//! The text is parsed with [`crate::svg::parse_usvg`] (bounded by [`crate::svg::SvgLimits`])
//! and every drawn node is taken in paint order as a *layer*: each path and raster image,
//! rendered alone with resvg at the SVG's own size (`width` × `height` in px), times the
//! opacity of its groups. The render of the document is the source-over composite of the
//! layers. (Clip paths, masks, filters and blend modes of enclosing groups are not applied to
//! the single layers: the measure is exact for flat documents such as ours and tracers' output,
//! approximate for others.)
//!
//! The *background* is the first path when its fill covers at least [`BACKGROUND_COVER`] of the
//! canvas (our exporter's `<rect>`, a tracer's canvas-sized first path): it is painted and its
//! colour counted, but it is not one of the [`Editability::paths`].
//!
//! Each path's outline (its data through its transform, curves flattened at
//! [`crate::vector::simple::FLATTEN_TOLERANCE`] px) is split into one ring per subpath (an
//! unclosed subpath is closed, as fill does).

use crate::vector::simple::{FLATTEN_TOLERANCE, ring_is_simple, rings_cross};
use resvg::{tiny_skia, usvg};
use std::collections::BTreeSet;

/// A visible path's change to the render must exceed this in some premultiplied RGBA channel
/// (1 step of 8-bit colour) for a pixel to count as showing it.
pub const VISIBLE_STEP: f32 = 1.0 / 255.0;

/// A path whose visible area (pixels where it changes the render by more than
/// [`VISIBLE_STEP`]) is under this many px² is hidden.
pub const HIDDEN_AREA: f64 = 1.0;

/// A visible path whose visible area is under this many px² is a sliver.
pub const SLIVER_AREA: f64 = 2.0;

/// A visible path whose mean width (`2 · area / perimeter` of its own painted outline) is under
/// this many px is a sliver: a strip thinner than half a pixel cannot be seen as a shape or
/// picked in an editor.
pub const SLIVER_WIDTH: f64 = 0.5;

/// Fraction of the canvas the first path's fill must cover to be the background.
pub const BACKGROUND_COVER: f64 = 0.995;

/// Most layer pixels (sum over layers of their painted bounding boxes) one check may hold.
const MAX_LAYER_PIXELS: u64 = 1 << 25;

/// Editability counts of one SVG (see the module docs for how it is read).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Editability {
    /// Visible paths (`visibility` not hidden; with a fill or a stroke), the background excluded.
    pub paths: usize,
    /// Filled paths whose outline is not valid in shapely's sense: some subpath's ring is not
    /// simple (it crosses or touches itself, folds back 180°, or has no area; see
    /// [`crate::vector::simple::ring_is_simple`]), or two rings of the path meet in more than
    /// one point ([`crate::vector::simple::rings_cross`]; a hole inside its outer ring, even
    /// touching it at one point, is fine).
    pub self_intersecting: usize,
    /// Paths whose removal changes fewer than [`HIDDEN_AREA`] px² of the render by more than
    /// [`VISIBLE_STEP`] (covered by paths above, transparent, or empty).
    pub hidden: usize,
    /// Paths that are not hidden but whose visible area is under [`SLIVER_AREA`] px² or whose
    /// own mean width `2 · area / perimeter` is under [`SLIVER_WIDTH`] px. No path is counted
    /// both hidden and a sliver.
    pub slivers: usize,
    /// Distinct colours (`#rrggbb`, opacity ignored) of the fills and strokes of all visible
    /// paths, the background included; a gradient counts each stop's colour.
    pub colors: usize,
}

/// Why an SVG could not be checked.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CheckError {
    #[error("cannot parse SVG: {0}")]
    Parse(String),
    #[error("SVG size {0}x{1} is out of range (1..={max} px a side)", max = crate::scene::MAX_SIDE)]
    Size(f32, f32),
    #[error("SVG paints {0} layer pixels; at most {MAX_LAYER_PIXELS} can be checked")]
    TooLarge(u64),
}

/// The editability counts of `scene` as written by our exporter: the same measure as
/// [`check_svg`] on [`crate::svg::to_svg`] with default options. An exported scene always
/// parses; if it did not, the counts would be all zero.
pub fn check(scene: &crate::scene::Scene) -> Editability {
    check_svg(&crate::svg::to_svg(scene, &Default::default())).unwrap_or_default()
}

/// One layer: a path or image rendered alone, cropped to its painted pixels.
struct Layer {
    /// Crop `[x0, y0, x1, y1)` in canvas pixels (empty when nothing was painted).
    rect: [usize; 4],
    /// Premultiplied RGBA of the crop, row-major.
    rgba: Vec<u8>,
    /// The render below this layer over the crop, premultiplied RGBA (filled in pass 1).
    below: Vec<u8>,
    /// For paths: own area (px²) and perimeter (px); `None` for images.
    path: Option<(f64, f64)>,
}

/// The editability counts of any SVG text (see [`Editability`] for each count).
pub fn check_svg(svg: &str) -> Result<Editability, CheckError> {
    let tree = crate::svg::parse_usvg(svg).map_err(|e| CheckError::Parse(e.to_string()))?;
    let size = tree.size();
    let (fw, fh) = (size.width(), size.height());
    let (w, h) = (fw.ceil(), fh.ceil());
    let max = crate::scene::MAX_SIDE as f32;
    if !(w >= 1.0 && h >= 1.0 && w <= max && h <= max) {
        return Err(CheckError::Size(fw, fh));
    }
    let (w, h) = (w as u32, h as u32);
    let mut walk = Walk {
        w,
        h,
        pixmap: tiny_skia::Pixmap::new(w, h).ok_or(CheckError::Size(fw, fh))?,
        mask: tiny_skia::Mask::new(w, h).ok_or(CheckError::Size(fw, fh))?,
        layers: Vec::new(),
        colors: BTreeSet::new(),
        counts: Editability::default(),
        background_seen: false,
        layer_pixels: 0,
    };
    walk.group(tree.root(), 1.0)?;
    let mut counts = walk.counts.clone();
    counts.colors = walk.colors.len();
    let (hidden, slivers) = visibility(&mut walk.layers, w as usize, h as usize);
    counts.hidden = hidden;
    counts.slivers = slivers;
    Ok(counts)
}

/// How many filled paths of `svg` have an outline that meets itself: [`check_svg`]'s
/// `self_intersecting` count (the same rings, the same test), without rendering anything.
pub fn self_intersecting_svg(svg: &str) -> Result<usize, CheckError> {
    fn walk(g: &usvg::Group, n: &mut usize) {
        for node in g.children() {
            match node {
                usvg::Node::Group(child) => walk(child, n),
                usvg::Node::Path(p) if p.is_visible() && p.fill().is_some() => {
                    *n += usize::from(!rings_valid(&rings_of(p.data(), p.abs_transform())));
                }
                usvg::Node::Text(t) => walk(t.flattened(), n),
                _ => {}
            }
        }
    }
    let tree = crate::svg::parse_usvg(svg).map_err(|e| CheckError::Parse(e.to_string()))?;
    let mut n = 0;
    walk(tree.root(), &mut n);
    Ok(n)
}

struct Walk {
    w: u32,
    h: u32,
    pixmap: tiny_skia::Pixmap,
    mask: tiny_skia::Mask,
    layers: Vec<Layer>,
    colors: BTreeSet<String>,
    counts: Editability,
    background_seen: bool,
    layer_pixels: u64,
}

impl Walk {
    fn group(&mut self, g: &usvg::Group, opacity: f32) -> Result<(), CheckError> {
        let opacity = opacity * g.opacity().get();
        for node in g.children() {
            match node {
                usvg::Node::Group(child) => self.group(child, opacity)?,
                usvg::Node::Path(p) => {
                    if p.is_visible() && (p.fill().is_some() || p.stroke().is_some()) {
                        self.path(node, p, opacity)?;
                    }
                }
                usvg::Node::Image(_) => {
                    self.render_layer(node, opacity, None)?;
                }
                usvg::Node::Text(t) => self.group(t.flattened(), opacity)?,
            }
        }
        Ok(())
    }

    fn path(&mut self, node: &usvg::Node, p: &usvg::Path, opacity: f32) -> Result<(), CheckError> {
        let ts = p.abs_transform();
        let rings = rings_of(p.data(), ts);
        // Own painted area: coverage of the fill and the stroke outline.
        self.mask.clear();
        if let Some(f) = p.fill() {
            let rule = match f.rule() {
                usvg::FillRule::NonZero => tiny_skia::FillRule::Winding,
                usvg::FillRule::EvenOdd => tiny_skia::FillRule::EvenOdd,
            };
            self.mask.fill_path(p.data(), rule, true, ts);
        }
        let scale = (ts.sx * ts.sy - ts.kx * ts.ky).abs().sqrt().max(1e-6);
        if let Some(s) = p.stroke()
            && let Some(outline) = p.data().stroke(&s.to_tiny_skia(), scale)
        {
            self.mask
                .fill_path(&outline, tiny_skia::FillRule::Winding, true, ts);
        }
        let area = self.mask.data().iter().map(|&v| v as f64).sum::<f64>() / 255.0;
        let lengths: f64 = rings.iter().map(|r| ring_length(r)).sum();
        let perimeter = if p.fill().is_some() {
            lengths
        } else {
            2.0 * lengths
        };
        let is_background = !self.background_seen
            && self.counts.paths == 0
            && p.fill().is_some()
            && area >= BACKGROUND_COVER * (self.w as f64 * self.h as f64);
        self.background_seen = true;
        if let Some(f) = p.fill() {
            add_colors(&mut self.colors, f.paint());
        }
        if let Some(s) = p.stroke() {
            add_colors(&mut self.colors, s.paint());
        }
        if is_background {
            return self.render_layer(node, opacity, None);
        }
        self.counts.paths += 1;
        if p.fill().is_some() && !rings_valid(&rings) {
            self.counts.self_intersecting += 1;
        }
        self.render_layer(node, opacity, Some((area, perimeter)))
    }

    /// Renders `node` alone at its place on the canvas, keeps the painted crop.
    fn render_layer(
        &mut self,
        node: &usvg::Node,
        opacity: f32,
        path: Option<(f64, f64)>,
    ) -> Result<(), CheckError> {
        self.pixmap.fill(tiny_skia::Color::TRANSPARENT);
        if let Some(bbox) = node.abs_layer_bounding_box() {
            // resvg::render_node shifts by the layer box; undo that so the node lands where
            // the whole document would paint it.
            let ts = node_parent_transform(node).pre_translate(bbox.x(), bbox.y());
            let _ = resvg::render_node(node, ts, &mut self.pixmap.as_mut());
        }
        let (w, h) = (self.w as usize, self.h as usize);
        let data = self.pixmap.data();
        let (mut x0, mut y0, mut x1, mut y1) = (w, h, 0usize, 0usize);
        for y in 0..h {
            let row = &data[4 * y * w..4 * (y + 1) * w];
            for x in 0..w {
                if row[4 * x + 3] != 0 {
                    x0 = x0.min(x);
                    x1 = x1.max(x + 1);
                    y0 = y0.min(y);
                    y1 = y1.max(y + 1);
                }
            }
        }
        let rect = if x1 > x0 && y1 > y0 {
            [x0, y0, x1, y1]
        } else {
            [0, 0, 0, 0]
        };
        let n = ((rect[2] - rect[0]) * (rect[3] - rect[1])) as u64;
        self.layer_pixels += n;
        if self.layer_pixels > MAX_LAYER_PIXELS {
            return Err(CheckError::TooLarge(self.layer_pixels));
        }
        let mut rgba = Vec::with_capacity(4 * n as usize);
        let op = opacity.clamp(0.0, 1.0);
        for y in rect[1]..rect[3] {
            for &v in &data[4 * (y * w + rect[0])..4 * (y * w + rect[2])] {
                rgba.push(if op < 1.0 {
                    (v as f32 * op).round() as u8
                } else {
                    v
                });
            }
        }
        self.layers.push(Layer {
            rect,
            rgba,
            below: Vec::new(),
            path,
        });
        Ok(())
    }
}

/// The transform resvg's `render_node` must be given so that `node` is drawn with its own
/// absolute transform (paths and images carry it; groups are never passed here).
fn node_parent_transform(node: &usvg::Node) -> tiny_skia::Transform {
    match node {
        usvg::Node::Path(p) => p.abs_transform(),
        usvg::Node::Image(i) => i.abs_transform(),
        usvg::Node::Group(g) => g.abs_transform(),
        usvg::Node::Text(t) => t.abs_transform(),
    }
}

fn add_colors(set: &mut BTreeSet<String>, paint: &usvg::Paint) {
    let hex = |c: usvg::Color| format!("#{:02x}{:02x}{:02x}", c.red, c.green, c.blue);
    match paint {
        usvg::Paint::Color(c) => {
            set.insert(hex(*c));
        }
        usvg::Paint::LinearGradient(g) => {
            set.extend(g.stops().iter().map(|s| hex(s.color())));
        }
        usvg::Paint::RadialGradient(g) => {
            set.extend(g.stops().iter().map(|s| hex(s.color())));
        }
        usvg::Paint::Pattern(_) => {}
    }
}

/// One ring per subpath of `data` through `ts`, curves flattened at [`FLATTEN_TOLERANCE`] px;
/// subpaths with fewer than 2 points are dropped.
fn rings_of(data: &tiny_skia::Path, ts: tiny_skia::Transform) -> Vec<Vec<(f64, f64)>> {
    let map = |p: tiny_skia::Point| {
        kurbo::Point::new(
            (ts.sx * p.x + ts.kx * p.y + ts.tx) as f64,
            (ts.ky * p.x + ts.sy * p.y + ts.ty) as f64,
        )
    };
    let mut bez = kurbo::BezPath::new();
    let mut open = false;
    for seg in data.segments() {
        match seg {
            tiny_skia::PathSegment::MoveTo(p) => {
                bez.move_to(map(p));
                open = true;
            }
            tiny_skia::PathSegment::LineTo(p) if open => bez.line_to(map(p)),
            tiny_skia::PathSegment::QuadTo(a, p) if open => bez.quad_to(map(a), map(p)),
            tiny_skia::PathSegment::CubicTo(a, b, p) if open => {
                bez.curve_to(map(a), map(b), map(p))
            }
            tiny_skia::PathSegment::Close if open => {
                bez.close_path();
                open = false;
            }
            _ => {}
        }
    }
    let mut rings: Vec<Vec<(f64, f64)>> = Vec::new();
    kurbo::flatten(bez, FLATTEN_TOLERANCE as f64, |el| match el {
        kurbo::PathEl::MoveTo(p) => rings.push(vec![(p.x, p.y)]),
        kurbo::PathEl::LineTo(p) => {
            if let Some(r) = rings.last_mut() {
                r.push((p.x, p.y));
            }
        }
        _ => {}
    });
    for r in &mut rings {
        if r.len() > 1 && r.first() == r.last() {
            r.pop();
        }
    }
    rings.retain(|r| r.len() >= 2);
    rings
}

fn ring_length(r: &[(f64, f64)]) -> f64 {
    let n = r.len();
    (0..n)
        .map(|i| {
            let (a, b) = (r[i], r[(i + 1) % n]);
            (a.0 - b.0).hypot(a.1 - b.1)
        })
        .sum()
}

/// Every ring simple and no two rings meeting in more than one point.
fn rings_valid(rings: &[Vec<(f64, f64)>]) -> bool {
    if !rings.iter().all(|r| ring_is_simple(r)) {
        return false;
    }
    let boxes: Vec<[f64; 4]> = rings
        .iter()
        .map(|r| {
            r.iter().fold(
                [
                    f64::INFINITY,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    f64::NEG_INFINITY,
                ],
                |b, p| [b[0].min(p.0), b[1].min(p.1), b[2].max(p.0), b[3].max(p.1)],
            )
        })
        .collect();
    let e = 1e-2;
    for i in 0..rings.len() {
        for j in i + 1..rings.len() {
            let (a, b) = (boxes[i], boxes[j]);
            if a[0] > b[2] + e || b[0] > a[2] + e || a[1] > b[3] + e || b[1] > a[3] + e {
                continue;
            }
            if rings_cross(&rings[i], &rings[j]) {
                return false;
            }
        }
    }
    true
}

/// Counts (hidden, slivers) among the path layers: pass 1 composites the layers bottom-up and
/// keeps, per layer, the render below it over its crop; pass 2 runs top-down with the
/// transmittance of everything above.
fn visibility(layers: &mut [Layer], w: usize, h: usize) -> (usize, usize) {
    let mut canvas = vec![0f32; 4 * w * h];
    for l in layers.iter_mut() {
        let [x0, y0, x1, y1] = l.rect;
        let cw = x1 - x0;
        l.below = Vec::with_capacity(l.rgba.len());
        for y in y0..y1 {
            for x in x0..x1 {
                let c = &mut canvas[4 * (y * w + x)..4 * (y * w + x) + 4];
                let s = &l.rgba[4 * ((y - y0) * cw + (x - x0))..][..4];
                l.below.extend(
                    c.iter()
                        .map(|v| (v * 255.0).round().clamp(0.0, 255.0) as u8),
                );
                let sa = s[3] as f32 / 255.0;
                for k in 0..4 {
                    c[k] = s[k] as f32 / 255.0 + (1.0 - sa) * c[k];
                }
            }
        }
    }
    drop(canvas);
    let mut trans = vec![1f32; w * h];
    let (mut hidden, mut slivers) = (0, 0);
    for l in layers.iter().rev() {
        let [x0, y0, x1, y1] = l.rect;
        let cw = x1 - x0;
        let mut visible = 0usize;
        for y in y0..y1 {
            for x in x0..x1 {
                let i = (y - y0) * cw + (x - x0);
                let s = &l.rgba[4 * i..4 * i + 4];
                let b = &l.below[4 * i..4 * i + 4];
                let sa = s[3] as f32 / 255.0;
                let t = &mut trans[y * w + x];
                let diff = (0..4)
                    .map(|k| (s[k] as f32 / 255.0 - sa * b[k] as f32 / 255.0).abs())
                    .fold(0.0f32, f32::max);
                if diff * *t > VISIBLE_STEP {
                    visible += 1;
                }
                *t *= 1.0 - sa;
            }
        }
        if let Some((area, perimeter)) = l.path {
            let visible = visible as f64;
            let mean_width = if perimeter > 0.0 {
                2.0 * area / perimeter
            } else {
                0.0
            };
            if visible < HIDDEN_AREA {
                hidden += 1;
            } else if visible < SLIVER_AREA || mean_width < SLIVER_WIDTH {
                slivers += 1;
            }
        }
    }
    (hidden, slivers)
}

#[cfg(test)]
#[path = "tests_check.rs"]
mod tests;
