//! Scene ⇄ SVG text, plus the benchmark scene JSON format.
//!
//! # Export ([`to_svg`], in `export.rs`)
//! The best picture per byte, deterministic and exact to the chosen decimals
//! ([`SvgOptions::precision`]):
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
//! - strokes are round-capped and round-joined (`stroke-linecap="round"
//!   stroke-linejoin="round"`), which is exactly what [`crate::raster`] draws (a union of
//!   capsules), so resvg, browsers and our rasteriser agree. With two or more stroked paths these
//!   go on one `<g>` around all the shapes, with the stroke width (and, when every shape is
//!   stroked alike, the stroke colour and opacity; when no shape is filled, `fill="none"`) that
//!   they share;
//! - [`SvgOptions::group_by_color`]: runs of consecutive paths with the same fill in one
//!   `<g fill="…">`; [`SvgOptions::ids`]: `id="p<k>"` on paths (shape index + 1) and
//!   `id="c<k>"` on colour groups.
//!
//! The background becomes a full-canvas `<rect>` first when it is not fully transparent.
//! [`crate::vector::export::compact_svg`] picks the fewest decimals that still render the same.
//!
//! # Import ([`from_svg`])
//! Parsing, CSS/style attributes, `<rect>`/`<circle>`/`<ellipse>`/`<polygon>`/`<line>`, arcs,
//! `<use>`, groups and transforms are normalised by `usvg`; we then walk its path tree:
//! - every point is mapped through the path's absolute transform; stroke widths are scaled by
//!   `sqrt(|det|)` of that transform;
//! - lines and quadratics are converted to (exactly equivalent) cubics;
//! - **fill**: all subpaths of one `<path>` become ONE [`ShapeKind::ClosedCubic`] shape. Extra
//!   subpaths are joined to the first one by straight "bridge" segments that are walked there and
//!   back, so they cancel in the winding number and holes survive exactly under the nonzero rule.
//!   For `fill-rule="evenodd"` subpaths are re-oriented by nesting depth (odd depth reversed)
//!   first, which reproduces even-odd for properly nested outlines (the usual case: glyphs,
//!   donuts); self-overlapping even-odd paths are approximated by nonzero.
//! - **stroke**: a path with a single subpath keeps its stroke on the same shape (closed subpath)
//!   or becomes an [`ShapeKind::OpenCubic`] (open subpath, no fill). With several subpaths, each
//!   subpath gets its own stroke shape (closed ones get a transparent fill) painted after the fill.
//!   Dashes, caps and joins other than round are drawn round.
//! - gradients and patterns are replaced by the average colour of their stops (patterns: grey);
//!   group opacity is multiplied into the shape opacities (exact unless children overlap);
//!   images, text without fonts, clip paths, masks and filters are ignored.
//! - if the first shape is a filled rectangle covering the whole canvas (what [`to_svg`] writes
//!   for the background) it becomes the scene background.

mod export;
mod file;
mod guard;
mod path_data;
mod profile;

pub use export::{MAX_PRECISION, SvgOptions, to_svg, with_metadata, written_color};

pub use file::{SCENE_FILE_MAX_BYTES, load_scene, read_text_capped, scene_from_json};
pub use guard::{SvgLimits, SvgRejected};
pub use profile::{ProfileViolation, check_safe_output};

use crate::scene::{MAX_SIDE, Point, Rgba, Scene, SceneError, Shape, ShapeKind, Stroke};
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
    use resvg::tiny_skia;
    let tree = parse_usvg(svg)?;
    let size = tree.size();
    let scale = (max_side / size.width().max(size.height())).min(1.0);
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

/// One subpath as cubic segments `[p1, p2, p3]` after a start point.
#[derive(Clone, Debug)]
struct SubPath {
    start: Point,
    segs: Vec<[Point; 3]>,
    closed: bool,
}

impl SubPath {
    fn end(&self) -> Point {
        self.segs.last().map_or(self.start, |s| s[2])
    }

    fn line(a: Point, b: Point) -> [Point; 3] {
        let l = |t: f32| Point::new(a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t);
        [l(1.0 / 3.0), l(2.0 / 3.0), b]
    }

    /// Adds the closing straight segment if the subpath does not end at its start.
    fn closed_segments(&self) -> Vec<[Point; 3]> {
        let mut segs = self.segs.clone();
        let e = self.end();
        if e != self.start || segs.is_empty() {
            segs.push(Self::line(e, self.start));
        }
        segs
    }

    fn reversed(&self) -> SubPath {
        let segs = self.closed_segments();
        let mut out = Vec::with_capacity(segs.len());
        let mut anchors = vec![self.start];
        anchors.extend(segs.iter().map(|s| s[2]));
        for i in (0..segs.len()).rev() {
            out.push([segs[i][1], segs[i][0], anchors[i]]);
        }
        SubPath {
            start: self.start,
            segs: out,
            closed: true,
        }
    }

    /// Signed area of the anchor + control polygon (orientation estimate).
    fn signed_area(&self) -> f32 {
        let mut pts = vec![self.start];
        for s in self.closed_segments() {
            pts.extend_from_slice(&s);
        }
        let mut a = 0.0;
        for i in 0..pts.len() {
            let (p, q) = (pts[i], pts[(i + 1) % pts.len()]);
            a += p.x * q.y - q.x * p.y;
        }
        a * 0.5
    }

    fn polygon(&self) -> Vec<Point> {
        let mut pts = vec![self.start];
        for s in self.closed_segments() {
            pts.extend_from_slice(&s);
        }
        pts
    }
}

fn point_in_polygon(p: Point, poly: &[Point]) -> bool {
    let mut inside = false;
    let n = poly.len();
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        if (a.y > p.y) != (b.y > p.y) {
            let x = a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x);
            if p.x < x {
                inside = !inside;
            }
        }
    }
    inside
}

fn subpaths(path: &usvg::Path) -> Vec<SubPath> {
    let ts = path.abs_transform();
    let map = |p: usvg::tiny_skia_path::Point| {
        let mut q = p;
        ts.map_point(&mut q);
        Point::new(q.x, q.y)
    };
    let mut out: Vec<SubPath> = Vec::new();
    let mut cur: Option<SubPath> = None;
    use usvg::tiny_skia_path::PathSegment as S;
    for seg in path.data().segments() {
        match seg {
            S::MoveTo(p) => {
                if let Some(c) = cur.take() {
                    out.push(c);
                }
                cur = Some(SubPath {
                    start: map(p),
                    segs: Vec::new(),
                    closed: false,
                });
            }
            S::LineTo(p) => {
                if let Some(c) = cur.as_mut() {
                    let a = c.end();
                    c.segs.push(SubPath::line(a, map(p)));
                }
            }
            S::QuadTo(p1, p2) => {
                if let Some(c) = cur.as_mut() {
                    let a = c.end();
                    let (q, b) = (map(p1), map(p2));
                    let k = 2.0 / 3.0;
                    let c1 = Point::new(a.x + k * (q.x - a.x), a.y + k * (q.y - a.y));
                    let c2 = Point::new(b.x + k * (q.x - b.x), b.y + k * (q.y - b.y));
                    c.segs.push([c1, c2, b]);
                }
            }
            S::CubicTo(p1, p2, p3) => {
                if let Some(c) = cur.as_mut() {
                    c.segs.push([map(p1), map(p2), map(p3)]);
                }
            }
            S::Close => {
                if let Some(mut c) = cur.take() {
                    c.closed = true;
                    let start = c.start;
                    out.push(c);
                    // A segment after Z without MoveTo starts again at the subpath start.
                    cur = Some(SubPath {
                        start,
                        segs: Vec::new(),
                        closed: false,
                    });
                }
            }
        }
    }
    if let Some(c) = cur.take() {
        out.push(c);
    }
    out.retain(|s| !s.segs.is_empty());
    let finite = |p: &Point| p.x.is_finite() && p.y.is_finite();
    out.retain(|s| finite(&s.start) && s.segs.iter().flatten().all(finite));
    out
}

fn paint_color(paint: &usvg::Paint, opacity: f32) -> Rgba {
    let c8 = |c: usvg::Color| {
        [
            c.red as f32 / 255.0,
            c.green as f32 / 255.0,
            c.blue as f32 / 255.0,
        ]
    };
    let avg = |stops: &[usvg::Stop]| {
        if stops.is_empty() {
            return ([0.0; 3], 1.0);
        }
        let mut s = [0.0f32; 4];
        for st in stops {
            let c = c8(st.color());
            s[0] += c[0];
            s[1] += c[1];
            s[2] += c[2];
            s[3] += st.opacity().get();
        }
        let n = stops.len() as f32;
        ([s[0] / n, s[1] / n, s[2] / n], s[3] / n)
    };
    let (rgb, a) = match paint {
        usvg::Paint::Color(c) => (c8(*c), 1.0),
        usvg::Paint::LinearGradient(g) => avg(g.stops()),
        usvg::Paint::RadialGradient(g) => avg(g.stops()),
        usvg::Paint::Pattern(_) => ([0.5; 3], 1.0),
    };
    Rgba::new(rgb[0], rgb[1], rgb[2], a * opacity).clamped()
}

fn closed_points(subs: &[SubPath]) -> Vec<Point> {
    // Points of a closed cubic path: anchor, ctrl, ctrl per segment.
    let mut pts = Vec::new();
    let push_loop = |pts: &mut Vec<Point>, s: &SubPath| {
        let mut a = s.start;
        for seg in s.closed_segments() {
            pts.extend_from_slice(&[a, seg[0], seg[1]]);
            a = seg[2];
        }
    };
    let first = subs[0].start;
    push_loop(&mut pts, &subs[0]);
    for s in &subs[1..] {
        // Bridge first → s.start, the loop of s, and back: the bridges cancel in the winding.
        let [c1, c2, _] = SubPath::line(first, s.start);
        pts.extend_from_slice(&[first, c1, c2]);
        push_loop(&mut pts, s);
        let [c1, c2, _] = SubPath::line(s.start, first);
        pts.extend_from_slice(&[s.start, c1, c2]);
    }
    pts
}

fn open_points(s: &SubPath) -> Vec<Point> {
    let mut pts = vec![s.start];
    for seg in &s.segs {
        pts.extend_from_slice(seg);
    }
    pts
}

fn walk_group(g: &usvg::Group, opacity: f32, shapes: &mut Vec<Shape>) {
    let opacity = opacity * g.opacity().get();
    for node in g.children() {
        match node {
            usvg::Node::Group(child) => walk_group(child, opacity, shapes),
            usvg::Node::Path(p) => {
                if p.is_visible() {
                    path_shapes(p, opacity, shapes);
                }
            }
            usvg::Node::Image(_) => {}
            usvg::Node::Text(t) => walk_group(t.flattened(), opacity, shapes),
        }
    }
}

fn path_shapes(p: &usvg::Path, opacity: f32, shapes: &mut Vec<Shape>) {
    let mut subs = subpaths(p);
    if subs.is_empty() {
        return;
    }
    let fill = p
        .fill()
        .map(|f| paint_color(f.paint(), f.opacity().get() * opacity));
    let stroke = p.stroke().and_then(|s| {
        let ts = p.abs_transform();
        let scale = (ts.sx * ts.sy - ts.kx * ts.ky).abs().sqrt();
        let width = s.width().get() * scale;
        (width.is_finite() && width > 0.0).then(|| Stroke {
            color: paint_color(s.paint(), s.opacity().get() * opacity),
            width,
        })
    });
    if let Some(f) = fill {
        if fill_is_evenodd(p) && subs.len() > 1 {
            orient_even_odd(&mut subs);
        }
        let single_closed = subs.len() == 1 && subs[0].closed;
        shapes.push(Shape {
            kind: ShapeKind::ClosedCubic,
            points: closed_points(&subs),
            fill: Some(f),
            stroke: if single_closed { stroke } else { None },
        });
        if single_closed {
            return;
        }
    }
    if let Some(st) = stroke {
        for s in &subs {
            if s.closed {
                let mut pts = Vec::new();
                let mut a = s.start;
                for seg in s.closed_segments() {
                    pts.extend_from_slice(&[a, seg[0], seg[1]]);
                    a = seg[2];
                }
                shapes.push(Shape {
                    kind: ShapeKind::ClosedCubic,
                    points: pts,
                    fill: Some(Rgba::TRANSPARENT),
                    stroke: Some(st),
                });
            } else {
                shapes.push(Shape {
                    kind: ShapeKind::OpenCubic,
                    points: open_points(s),
                    fill: None,
                    stroke: Some(st),
                });
            }
        }
    }
}

fn fill_is_evenodd(p: &usvg::Path) -> bool {
    p.fill()
        .is_some_and(|f| f.rule() == usvg::FillRule::EvenOdd)
}

/// Orients every subpath so that its winding contribution alternates with nesting depth.
fn orient_even_odd(subs: &mut [SubPath]) {
    let polys: Vec<Vec<Point>> = subs.iter().map(SubPath::polygon).collect();
    let reference = subs[0].signed_area().signum();
    for i in 0..subs.len() {
        let probe = subs[i].start;
        let depth = (0..subs.len())
            .filter(|&j| j != i && point_in_polygon(probe, &polys[j]))
            .count();
        let want = if depth % 2 == 0 {
            reference
        } else {
            -reference
        };
        if subs[i].signed_area().signum() != want {
            subs[i] = subs[i].reversed();
        }
    }
}

/// Parses untrusted SVG text with usvg. This is the only place the crate parses SVG: it checks
/// [`SvgLimits::DEFAULT`] before any geometry work ([`guard`]), never reads files and never decodes
/// embedded images (`<image href="/dev/zero">` must not be followed), so every caller — HTTP
/// submissions, previews, the worker, evaluation, tracing — is bounded on hostile input.
pub fn parse_usvg(text: &str) -> Result<usvg::Tree, SvgRejected> {
    let opts = usvg::Options {
        image_href_resolver: usvg::ImageHrefResolver {
            resolve_data: Box::new(|_, _, _| None),
            resolve_string: Box::new(|_, _| None),
        },
        ..usvg::Options::default()
    };
    guard::parse(text, &SvgLimits::DEFAULT, &opts)
}

/// Parses SVG text into a scene (see the module docs for what is kept). Bad SVG gives an error,
/// never a panic.
pub fn from_svg(text: &str) -> Result<Scene, SvgError> {
    let tree = parse_usvg(text).map_err(SvgError::Parse)?;
    let size = tree.size();
    let (fw, fh) = (size.width(), size.height());
    let (w, h) = (fw.round(), fh.round());
    if !(1.0..=MAX_SIDE as f32).contains(&w) || !(1.0..=MAX_SIDE as f32).contains(&h) {
        return Err(SvgError::Size(fw, fh));
    }
    let mut shapes = Vec::new();
    walk_group(tree.root(), 1.0, &mut shapes);
    let mut background = Rgba::TRANSPARENT;
    if let Some(first) = shapes.first()
        && is_canvas_rect(first, w, h)
        && let Some(f) = first.fill
    {
        background = f;
        shapes.remove(0);
    }
    let scene = Scene {
        width: w as u32,
        height: h as u32,
        background,
        shapes,
    };
    scene.validate()?;
    Ok(scene)
}

fn is_canvas_rect(s: &Shape, w: f32, h: f32) -> bool {
    if s.stroke.is_some() || s.kind != ShapeKind::ClosedCubic || s.points.len() != 12 {
        return false;
    }
    // Four straight segments along the canvas border.
    let corners = [
        Point::new(0.0, 0.0),
        Point::new(w, 0.0),
        Point::new(w, h),
        Point::new(0.0, h),
    ];
    let near = |a: Point, b: Point| (a.x - b.x).abs() < 1e-3 && (a.y - b.y).abs() < 1e-3;
    let anchors: Vec<Point> = (0..4).map(|i| s.points[3 * i]).collect();
    let straight = (0..4).all(|i| {
        let seg = s.segment(i);
        let l = SubPath::line(seg[0], seg[3]);
        near(l[0], seg[1]) && near(l[1], seg[2])
    });
    straight && corners.iter().all(|c| anchors.iter().any(|a| near(*a, *c)))
}

#[cfg(test)]
mod tests;
