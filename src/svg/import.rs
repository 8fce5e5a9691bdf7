//! SVG text → [`Scene`] (the walk over usvg's tree that [`super`]'s module docs describe).

use super::SvgError;
use super::images::{ImageLimits, Images};
use super::import_paint::{Painted, gradients, painted};
use super::walk::{Mode, Walk};
use crate::scene::{
    Content, FillRule, Gradient, LineCap, LineJoin, MAX_SIDE, Point, Rgba, Scene, Shape, ShapeKind,
    Stroke,
};
use resvg::usvg;
use std::sync::Arc;

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
        let [c1, c2] = Point::line_controls(a, b);
        [c1, c2, b]
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
}

/// The subpaths of `data` mapped through `ts` (the user space of the path's parent group).
fn subpaths(data: &usvg::tiny_skia_path::Path, ts: usvg::Transform) -> Vec<SubPath> {
    let map = |p: usvg::tiny_skia_path::Point| {
        let mut q = p;
        ts.map_point(&mut q);
        Point::new(q.x, q.y)
    };
    let mut out: Vec<SubPath> = Vec::new();
    let mut cur: Option<SubPath> = None;
    use usvg::tiny_skia_path::PathSegment as S;
    for seg in data.segments() {
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
    // A subpath of zero length is one zero-length segment (SVG caps it as such), however many
    // segments it was written with.
    for s in &mut out {
        if s.segs.iter().flatten().all(|p| *p == s.start) {
            s.segs.truncate(1);
        }
    }
    let finite = |p: &Point| p.x.is_finite() && p.y.is_finite();
    out.retain(|s| finite(&s.start) && s.segs.iter().flatten().all(finite));
    out
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

/// The shapes that draw `p` (in user space `ts`, its opacity times `opacity`), added to
/// `shapes`.
pub(super) fn path_shapes(
    p: &usvg::Path,
    ts: usvg::Transform,
    opacity: f32,
    shapes: &mut Vec<Shape>,
) {
    let subs = subpaths(p.data(), ts);
    if subs.is_empty() {
        return;
    }
    let fill = p
        .fill()
        .map(|f| painted(f.paint(), f.opacity().get() * opacity, ts));
    let stroke = p
        .stroke()
        .map_or(StrokeDraw::Nothing, |s| stroke_draw(p, s, ts, opacity));
    // `paint-order: stroke`: the fill shape is moved after the stroke shapes.
    let stroke_first = p.paint_order() == usvg::PaintOrder::StrokeAndFill
        && fill.is_some()
        && !matches!(stroke, StrokeDraw::Nothing);
    let first = shapes.len();
    if let Some(f) = fill {
        // A single closed outline keeps its (undashed) stroke on the filled shape.
        let on_fill = match &stroke {
            StrokeDraw::Strokes(st, sg, None)
                if subs.len() == 1 && subs[0].closed && !stroke_first =>
            {
                Some((*st, sg.clone()))
            }
            _ => None,
        };
        let (st, sg) = on_fill.clone().unzip();
        shapes.push(Shape {
            kind: ShapeKind::ClosedCubic,
            points: closed_points(&subs),
            fill: Some(f.color),
            stroke: st,
            fill_rule: fill_rule(p),
            gradients: with_texture(gradients(f.gradient, sg.flatten()), f.texture),
            stage: None,
        });
        if on_fill.is_some() {
            return;
        }
    }
    match stroke {
        StrokeDraw::Nothing => {}
        StrokeDraw::Strokes(st, sg, dashes) => {
            for s in dashes.as_ref().unwrap_or(&subs) {
                shapes.push(stroke_shape(s, st, sg.clone()));
            }
        }
        StrokeDraw::Outline(paint, outline) => shapes.push(Shape {
            kind: ShapeKind::ClosedCubic,
            points: closed_points(&outline),
            fill: Some(paint.color),
            stroke: None,
            fill_rule: FillRule::NonZero,
            gradients: with_texture(gradients(paint.gradient, None), paint.texture),
            stage: None,
        }),
    }
    if stroke_first {
        shapes[first..].rotate_left(1);
    }
}

/// One subpath stroked: open, or closed with a transparent fill.
fn stroke_shape(s: &SubPath, st: Stroke, gradient: Option<Gradient>) -> Shape {
    if !s.closed {
        return Shape {
            kind: ShapeKind::OpenCubic,
            points: open_points(s),
            fill: None,
            stroke: Some(st),
            fill_rule: FillRule::NonZero,
            gradients: gradients(None, gradient),
            stage: None,
        };
    }
    let mut pts = Vec::new();
    let mut a = s.start;
    for seg in s.closed_segments() {
        pts.extend_from_slice(&[a, seg[0], seg[1]]);
        a = seg[2];
    }
    Shape {
        kind: ShapeKind::ClosedCubic,
        points: pts,
        fill: Some(Rgba::TRANSPARENT),
        stroke: Some(st),
        fill_rule: FillRule::NonZero,
        gradients: gradients(None, gradient),
        stage: None,
    }
}

/// How a path's stroke is drawn.
enum StrokeDraw {
    Nothing,
    /// As strokes of the scene (with the stroke's gradient): along the path's subpaths, or
    /// along these dashes.
    Strokes(Stroke, Option<Gradient>, Option<Vec<SubPath>>),
    /// Under a transform that is no similarity (skew, unequal scales) a stroke of one width
    /// cannot be drawn, nor a stroke painted with a pattern: its outline (computed in the
    /// path's own units, dashes, caps and joins included) is filled in this paint instead.
    Outline(Painted, Vec<SubPath>),
}

fn stroke_draw(p: &usvg::Path, s: &usvg::Stroke, ts: usvg::Transform, opacity: f32) -> StrokeDraw {
    let paint = painted(s.paint(), s.opacity().get() * opacity, ts);
    let scale = (ts.sx * ts.sy - ts.kx * ts.ky).abs().sqrt();
    let width = s.width().get() * scale;
    if !(width.is_finite() && width > 0.0) {
        return StrokeDraw::Nothing;
    }
    // Dashes and outlines are flattened finely enough for the canvas.
    let res = scale.max(1.0);
    let dashed = s
        .dasharray()
        .and_then(|a| usvg::tiny_skia_path::StrokeDash::new(a.to_vec(), s.dashoffset()))
        .map(|d| p.data().dash(&d, res));
    // A pattern (a texture, which strokes do not take) paints the stroke's outline as a fill.
    if !is_similarity(ts) || paint.texture.is_some() {
        let mut outline_stroke = s.to_tiny_skia();
        outline_stroke.dash = None;
        let data = match &dashed {
            Some(Some(d)) => d,
            Some(None) => return StrokeDraw::Nothing,
            None => p.data(),
        };
        return match data.stroke(&outline_stroke, res) {
            Some(o) => StrokeDraw::Outline(paint, subpaths(&o, ts)),
            None => StrokeDraw::Nothing,
        };
    }
    let st = Stroke {
        color: paint.color,
        width,
        cap: match s.linecap() {
            usvg::LineCap::Butt => LineCap::Butt,
            usvg::LineCap::Round => LineCap::Round,
            usvg::LineCap::Square => LineCap::Square,
        },
        join: match s.linejoin() {
            usvg::LineJoin::Miter | usvg::LineJoin::MiterClip => LineJoin::Miter,
            usvg::LineJoin::Round => LineJoin::Round,
            usvg::LineJoin::Bevel => LineJoin::Bevel,
        },
        miter_limit: s.miterlimit().get().max(1.0),
    };
    match dashed {
        // A dash pattern that draws nothing.
        Some(None) => StrokeDraw::Nothing,
        Some(Some(d)) => StrokeDraw::Strokes(st, paint.gradient, Some(subpaths(&d, ts))),
        None => StrokeDraw::Strokes(st, paint.gradient, None),
    }
}

/// Whether `ts` keeps angles and scales every direction alike (so a stroke keeps one width).
fn is_similarity(ts: usvg::Transform) -> bool {
    let (c0, c1) = ((ts.sx, ts.ky), (ts.kx, ts.sy));
    let (l0, l1) = (c0.0 * c0.0 + c0.1 * c0.1, c1.0 * c1.0 + c1.1 * c1.1);
    let dot = c0.0 * c1.0 + c0.1 * c1.1;
    let tol = 1e-4 * l0.max(l1);
    (l0 - l1).abs() <= tol && dot.abs() <= tol
}

/// The fill rule of `p`'s fill (a clip path's children carry their `clip-rule` there).
fn fill_rule(p: &usvg::Path) -> FillRule {
    match p.fill().map(|f| f.rule()) {
        Some(usvg::FillRule::EvenOdd) => FillRule::EvenOdd,
        _ => FillRule::NonZero,
    }
}

/// The area `p` adds to a clip path (in user space `ts`): its outline filled by its clip rule,
/// whatever its paint.
pub(super) fn clip_shape(p: &usvg::Path, ts: usvg::Transform, shapes: &mut Vec<Shape>) {
    clip_path_shape(p.data(), ts, fill_rule(p), shapes);
}

/// The clip shape of outline `data` in user space `ts`, filled by `rule`.
pub(super) fn clip_path_shape(
    data: &usvg::tiny_skia_path::Path,
    ts: usvg::Transform,
    rule: FillRule,
    shapes: &mut Vec<Shape>,
) {
    let subs = subpaths(data, ts);
    if subs.is_empty() {
        return;
    }
    shapes.push(Shape {
        kind: ShapeKind::ClosedCubic,
        points: closed_points(&subs),
        fill: Some(Rgba::BLACK),
        stroke: None,
        fill_rule: rule,
        gradients: None,
        stage: None,
    });
}

/// An imported SVG: the scene and what the import could not keep as drawn (dropped links,
/// ignored filters), one sentence each.
#[derive(Clone, Debug, PartialEq)]
pub struct SvgImport {
    pub scene: Scene,
    pub warnings: Vec<String>,
}

/// Parses SVG text into a scene (see the module docs for what is kept). Bad SVG gives an error,
/// never a panic.
pub fn from_svg(text: &str) -> Result<Scene, SvgError> {
    import_svg(text).map(|i| i.scene)
}

/// [`from_svg`], with the import's warnings. Reads no file: an `<image>` naming one is dropped
/// with a warning.
pub fn import_svg(text: &str) -> Result<SvgImport, SvgError> {
    import_svg_in(text, None, ImageLimits::DEFAULT)
}

/// [`import_svg`] for an SVG file in `base_dir`: its `<image>`s may name files there (relative
/// paths); `limits` bound every image (see `images`).
pub fn import_svg_in(
    text: &str,
    base_dir: Option<&std::path::Path>,
    limits: ImageLimits,
) -> Result<SvgImport, SvgError> {
    import_svg_with_fonts(text, base_dir, limits, super::fonts::database())
}

/// [`import_svg_in`] with these fonts instead of the process's ([`super::fonts::database`]).
pub fn import_svg_with_fonts(
    text: &str,
    base_dir: Option<&std::path::Path>,
    limits: ImageLimits,
    fonts: Arc<usvg::fontdb::Database>,
) -> Result<SvgImport, SvgError> {
    let images = Arc::new(Images::new(base_dir, limits, fonts));
    let parsed = images.parse(text, 0).map_err(SvgError::Parse)?;
    let tree = parsed.tree;
    let size = tree.size();
    let (fw, fh) = (size.width(), size.height());
    let (w, h) = (fw.round(), fh.round());
    if !(1.0..=MAX_SIDE as f32).contains(&w) || !(1.0..=MAX_SIDE as f32).contains(&h) {
        return Err(SvgError::Size(fw, fh));
    }
    let mut walk = Walk::new((w, h), Arc::clone(&images));
    for w in parsed.warnings.into_iter().chain(images.take_warnings()) {
        walk.warn(w);
    }
    for w in super::import_paint::dangling_paint_warnings(text) {
        walk.warn(w);
    }
    let mut content = Content::default();
    walk.group(
        tree.root(),
        usvg::Transform::identity(),
        Mode::Draw,
        &mut content,
    );
    walk.text_warnings(text);
    let warnings = walk.finish();
    let Content {
        mut shapes,
        mut groups,
    } = content;
    let mut background = Rgba::TRANSPARENT;
    if let Some(first) = shapes.first()
        && is_canvas_rect(first, w, h)
        && let Some(f) = first.fill
        && groups.iter().all(|g| g.start > 0)
    {
        background = f;
        shapes.remove(0);
        for g in &mut groups {
            g.start -= 1;
            g.end -= 1;
        }
    }
    let scene = Scene {
        width: w as u32,
        height: h as u32,
        background,
        shapes,
        groups,
    };
    scene.validate()?;
    Ok(SvgImport { scene, warnings })
}

/// `g` with the fill texture `t`, if there is one.
fn with_texture(
    g: Option<Box<crate::scene::Gradients>>,
    t: Option<Box<crate::scene::Texture>>,
) -> Option<Box<crate::scene::Gradients>> {
    let Some(t) = t else {
        return g;
    };
    let mut g = g.unwrap_or_default();
    g.texture = Some(t);
    Some(g)
}

fn is_canvas_rect(s: &Shape, w: f32, h: f32) -> bool {
    if s.stroke.is_some()
        || s.gradients.is_some()
        || s.kind != ShapeKind::ClosedCubic
        || s.points.len() != 12
    {
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
#[path = "import_tests.rs"]
mod tests;
