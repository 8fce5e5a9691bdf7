//! Scene → vector PDF (PDF 1.4, one page): every path stays a path, so a designer's tool opens
//! it as editable vectors, as it opens the SVG.
//!
//! The page has the SVG's size at CSS resolution (96 px = 72 pt, so 1 px = 0.75 pt); the content
//! stream flips y once (`cm`) and then draws in canvas pixels, in scene order: the background as
//! a full-page rectangle when it is not transparent, then each shape's fill (by its fill rule, as
//! the rasteriser and the SVG) and stroke (its caps, joins and miter limit; round by default).
//! Opacities go through one `ExtGState` per distinct alpha (`/ca` for fills, `/CA` for strokes).
//! A textured fill (an imported image or pattern) is a tiling pattern whose cell is the texture
//! (an RGB image with its alpha as a soft mask, deflated), placed by the texture's transform:
//! the texels repeat as in the SVG export, and an image's shape covers just its one tile. A
//! gradient fill or stroke is a shading pattern (axial or radial, its stops a stitching function,
//! extended past both ends as `pad`), placed by the gradient's transform; a `repeat` or `reflect`
//! gradient spans the periods the shape covers (a radial one grows its circles over them). Stop
//! opacities, which a shading cannot carry, are a soft mask of the same gradient painting them
//! as greys. A group is a form XObject painted with its opacity, blend mode, clip and mask
//! (`groups`); a pattern drawn inside a form is placed in canvas pixels, the form's space, not
//! the page's. The page and every form name one resources dictionary, the last object.
//!
//! Invariant: the output is a complete PDF whose cross-reference offsets are exact; writing
//! cannot fail for a valid [`Scene`] (non-finite numbers are written as `0`).

mod groups;
mod paint;

use crate::scene::{
    BlendMode, FillRule, Gradient, Group, LineCap, LineJoin, Point, Rgba, Scene, Shape, ShapeKind,
    Texture,
};
use groups::blend_name;
use paint::{Channel, gradient_object, t_range, texture_objects};
use std::fmt::Write as _;

/// PDF points per canvas pixel (CSS: 96 px per inch, PDF: 72 pt per inch).
pub const PT_PER_PX: f32 = 0.75;

/// `v` with at most 4 decimals, no trailing zeros, `0` for non-finite values.
fn num(out: &mut String, v: f32) {
    let v = if v.is_finite() { v } else { 0.0 };
    let mut s = format!("{v:.4}");
    if s.contains('.') {
        while s.ends_with('0') {
            s.pop();
        }
        if s.ends_with('.') {
            s.pop();
        }
    }
    if s == "-0" {
        s = "0".into();
    }
    out.push_str(&s);
}

/// Numbers separated by spaces, then the operator and a newline.
fn op(out: &mut String, nums: &[f32], operator: &str) {
    for v in nums {
        num(out, *v);
        out.push(' ');
    }
    out.push_str(operator);
    out.push('\n');
}

/// Numbers separated by spaces (as [`num`] writes each).
fn nums(values: impl IntoIterator<Item = f32>) -> String {
    let mut out = String::new();
    for (i, v) in values.into_iter().enumerate() {
        if i > 0 {
            out.push(' ');
        }
        num(&mut out, v);
    }
    out
}

/// The path of `shape` (construction operators only: `m`, `c`, `l`, `h`).
fn path(out: &mut String, shape: &Shape) {
    let p = &shape.points;
    let Some(first) = p.first() else { return };
    op(out, &[first.x, first.y], "m");
    match shape.kind {
        ShapeKind::Polygon => {
            for q in &p[1..] {
                op(out, &[q.x, q.y], "l");
            }
            out.push_str("h\n");
        }
        ShapeKind::ClosedCubic | ShapeKind::OpenCubic => {
            let closed = shape.kind == ShapeKind::ClosedCubic;
            // 3n points closed (the last segment ends at the first point), 3n + 1 open.
            let n = if closed {
                p.len() / 3
            } else {
                (p.len() - 1) / 3
            };
            for i in 0..n {
                let at = |k: usize| -> Point { p[(3 * i + k) % p.len()] };
                let (c1, c2, e) = (at(1), at(2), at(3));
                op(out, &[c1.x, c1.y, c2.x, c2.y, e.x, e.y], "c");
            }
            if closed {
                out.push_str("h\n");
            }
        }
    }
}

fn color(out: &mut String, c: Rgba, operator: &str) {
    op(out, &[c.r, c.g, c.b], operator);
}

/// What a pattern `/P{i}` paints.
enum Paint<'a> {
    /// A texture, and what of its texels' colours it paints.
    Texture(&'a Texture, Channel),
    /// A gradient, the range of its parameter `t` the shape covers, and what of its stops'
    /// colours it paints.
    Gradient(&'a Gradient, [f32; 2], Channel),
}

impl Paint<'_> {
    /// How many objects it takes (the pattern last).
    fn objects(&self) -> usize {
        match self {
            Paint::Texture(..) => 3,
            Paint::Gradient(..) => 1,
        }
    }
}

/// A graphics state `/G{i}` (an `ExtGState`).
#[derive(Clone, Copy, PartialEq)]
enum State {
    /// The alpha of fills (`/ca`) and strokes (`/CA`).
    Alpha(f32),
    /// A group's opacity and blend mode.
    Group(f32, BlendMode),
    /// A soft mask: form `/X{form}` read by its luminosity or by its alpha.
    SoftMask { luminosity: bool, form: usize },
}

/// How shapes are drawn: as they are, or as a clip's coverage (opaque white fills, the colour
/// and the strokes ignored, as the rasteriser draws a clip).
#[derive(Clone, Copy, PartialEq)]
enum Mode {
    Paint,
    Clip,
}

/// The document being written: what the page's content and its forms name.
struct Doc<'a> {
    states: Vec<State>,
    /// Each pattern and whether it is drawn in the page's content (its matrix then takes the
    /// page's flip) or in a form, whose space is canvas pixels.
    paints: Vec<(Paint<'a>, bool)>,
    /// The content streams of the forms `/X{i}` (canvas pixels; isolated transparency groups).
    forms: Vec<String>,
    /// Whether what is drawn now goes into the page's content rather than a form.
    on_page: bool,
    /// The canvas: width and height in pixels.
    size: (f32, f32),
    /// What colours are drawn as now (their luminance inside a luminance mask).
    channel: Channel,
}

impl<'a> Doc<'a> {
    /// The name of graphics state `s`, adding it if new.
    fn state(&mut self, s: State) -> String {
        let i = match self.states.iter().position(|x| *x == s) {
            Some(i) => i,
            None => {
                self.states.push(s);
                self.states.len() - 1
            }
        };
        format!("/G{i}")
    }

    /// Adds a pattern; its index.
    fn paint(&mut self, p: Paint<'a>) -> usize {
        self.paints.push((p, self.on_page));
        self.paints.len() - 1
    }

    /// Adds a form with this content; its index.
    fn form(&mut self, content: String) -> usize {
        self.forms.push(content);
        self.forms.len() - 1
    }

    /// Shapes `range` of `shapes`, in order, each run that a group of `groups` (sorted, nested
    /// or disjoint, all inside `range`) covers as that group.
    fn draw(
        &mut self,
        out: &mut String,
        shapes: &'a [Shape],
        groups: &'a [Group],
        range: std::ops::Range<usize>,
        mode: Mode,
    ) {
        let (mut i, mut next) = (range.start, 0);
        while i < range.end {
            match groups.get(next).filter(|g| g.start == i) {
                Some(g) => {
                    // The groups inside it follow it in the list.
                    let inner = groups[next + 1..]
                        .iter()
                        .take_while(|h| h.start < g.end)
                        .count();
                    self.group(out, shapes, g, &groups[next + 1..next + 1 + inner], mode);
                    next += 1 + inner;
                    i = g.end;
                }
                None => {
                    match mode {
                        Mode::Paint => self.shape(out, &shapes[i]),
                        Mode::Clip => {
                            out.push_str("q 1 g\n");
                            path(out, &shapes[i]);
                            let _ = writeln!(out, "{} Q", fill_op(&shapes[i]));
                        }
                    }
                    i += 1;
                }
            }
        }
    }

    /// One shape's fill, then its stroke.
    fn shape(&mut self, out: &mut String, shape: &'a Shape) {
        let g = shape.gradients.as_deref();
        let fill_op = fill_op(shape);
        if let (Some(t), Some(_)) = (g.and_then(|g| g.texture.as_deref()), shape.fill) {
            let _ = writeln!(
                out,
                "q /Pattern cs /P{} scn",
                self.paint(Paint::Texture(t, self.channel))
            );
            path(out, shape);
            let _ = writeln!(out, "{fill_op} Q");
        } else if let (Some(gr), Some(_)) = (g.and_then(|g| g.fill.as_ref()), shape.fill) {
            self.gradient_paint(out, gr, shape, "cs", "scn");
            path(out, shape);
            let _ = writeln!(out, "{fill_op} Q");
        } else if let Some(f) = shape.fill.filter(|f| f.a > 0.0) {
            let _ = writeln!(out, "q {} gs", self.state(State::Alpha(f.a)));
            color(out, self.channel.map(f), "rg");
            path(out, shape);
            let _ = writeln!(out, "{fill_op} Q");
        }
        let Some(s) = shape.stroke.filter(|s| s.width > 0.0) else {
            return;
        };
        // PDF paints a zero-length subpath's cap only when round (ISO 32000-1, 8.5.3.2); SVG
        // draws a square cap as a square along the x axis, as the rasteriser does: filled here.
        let dot = shape
            .points
            .first()
            .filter(|&&p0| s.cap == LineCap::Square && shape.points.iter().all(|p| *p == p0))
            .copied();
        let (space, set, rgb) = if dot.is_some() {
            ("cs", "scn", "rg")
        } else {
            ("CS", "SCN", "RG")
        };
        if let Some(gr) = g.and_then(|g| g.stroke.as_ref()) {
            self.gradient_paint(out, gr, shape, space, set);
        } else if s.color.a > 0.0 {
            let _ = writeln!(out, "q {} gs", self.state(State::Alpha(s.color.a)));
            color(out, self.channel.map(s.color), rgb);
        } else {
            return;
        }
        if let Some(c) = dot {
            let r = s.width / 2.0;
            op(out, &[c.x - r, c.y - r, s.width, s.width], "re");
            out.push_str("f Q\n");
            return;
        }
        op(out, &[s.width], "w");
        // The page draws round caps and joins (what the optimisers make); others are set here.
        if s.cap != LineCap::Round {
            out.push_str(if s.cap == LineCap::Butt {
                "0 J\n"
            } else {
                "2 J\n"
            });
        }
        match s.join {
            LineJoin::Round => {}
            LineJoin::Miter => {
                out.push_str("0 j\n");
                op(out, &[s.miter_limit], "M");
            }
            LineJoin::Bevel => out.push_str("2 j\n"),
        }
        path(out, shape);
        out.push_str("S Q\n");
    }

    /// Opens a graphics state painting with gradient `gr` on `shape` as the next pattern,
    /// through `space` and `set` (`cs`/`scn` for fills, `CS`/`SCN` for strokes). A shading has
    /// no alpha: stops of one alpha are that alpha's state; stops of several are a luminosity
    /// soft mask of the same gradient painting their alphas as greys over the canvas.
    fn gradient_paint(
        &mut self,
        out: &mut String,
        gr: &'a Gradient,
        shape: &Shape,
        space: &str,
        set: &str,
    ) {
        let range = t_range(gr, shape);
        let p = self.paint(Paint::Gradient(gr, range, self.channel));
        let alpha = gr.stops.first().map_or(1.0, |s| s.color.a);
        let gs = if gr.stops.iter().all(|s| s.color.a == alpha) {
            self.state(State::Alpha(alpha))
        } else {
            let on_page = std::mem::replace(&mut self.on_page, false);
            let a = self.paint(Paint::Gradient(gr, range, Channel::Alpha));
            self.on_page = on_page;
            let mut body = format!("q /Pattern cs /P{a} scn\n");
            op(&mut body, &[0.0, 0.0, self.size.0, self.size.1], "re");
            body.push_str("f Q\n");
            let form = self.form(body);
            self.state(State::SoftMask {
                luminosity: true,
                form,
            })
        };
        let _ = writeln!(out, "q {gs} gs /Pattern {space} /P{p} {set}");
    }
}

fn fill_op(shape: &Shape) -> &'static str {
    match shape.fill_rule {
        FillRule::NonZero => "f",
        FillRule::EvenOdd => "f*",
    }
}

/// The page's content stream and the document it names.
fn content(scene: &Scene) -> (String, Doc<'_>) {
    let (w, h) = (scene.width as f32, scene.height as f32);
    let mut out = String::new();
    let mut doc = Doc {
        states: Vec::new(),
        paints: Vec::new(),
        forms: Vec::new(),
        on_page: true,
        size: (w, h),
        channel: Channel::Colour,
    };
    // Canvas pixels, y down, onto the page in points, y up.
    op(
        &mut out,
        &[PT_PER_PX, 0.0, 0.0, -PT_PER_PX, 0.0, h * PT_PER_PX],
        "cm",
    );
    out.push_str("1 J 1 j\n");
    if scene.background.a > 0.0 {
        let _ = writeln!(out, "q {} gs", doc.state(State::Alpha(scene.background.a)));
        color(&mut out, scene.background, "rg");
        op(&mut out, &[0.0, 0.0, w, h], "re");
        out.push_str("f Q\n");
    }
    let n = scene.shapes.len();
    doc.draw(&mut out, &scene.shapes, &scene.groups, 0..n, Mode::Paint);
    (out, doc)
}

/// A stream object: `dict` (without `/Length`) and the bytes, then the end-of-line that
/// `endstream` follows (not counted in the length).
fn stream_object(dict: &str, data: &[u8]) -> Vec<u8> {
    let sep = if dict.is_empty() { "" } else { " " };
    let mut o = format!("<< {dict}{sep}/Length {} >>\nstream\n", data.len()).into_bytes();
    o.extend_from_slice(data);
    o.extend_from_slice(b"\nendstream");
    o
}

/// `scene` as a one-page vector PDF (see the module docs).
pub fn to_pdf(scene: &Scene) -> Vec<u8> {
    let (stream, doc) = content(scene);
    let (w, h) = (scene.width as f32, scene.height as f32);
    let page_h = h * PT_PER_PX;
    let media = nums([w * PT_PER_PX, page_h]);
    // Objects 1–5 as below, then each paint's objects from 6 on (its pattern last), then the
    // forms.
    let mut patterns = String::new();
    let mut firsts = Vec::with_capacity(doc.paints.len());
    let mut next = 6;
    for (i, (p, _)) in doc.paints.iter().enumerate() {
        firsts.push(next);
        next += p.objects();
        let _ = write!(patterns, "/P{i} {} 0 R ", next - 1);
    }
    let first_form = next;
    let mut states = String::new();
    for (i, s) in doc.states.iter().enumerate() {
        let _ = write!(states, "/G{i} << /Type /ExtGState");
        match *s {
            State::Alpha(a) => {
                let _ = write!(states, " /ca {0} /CA {0}", nums([a]));
            }
            State::Group(a, blend) => {
                let _ = write!(
                    states,
                    " /ca {0} /CA {0} /BM /{1}",
                    nums([a]),
                    blend_name(blend)
                );
            }
            State::SoftMask { luminosity, form } => {
                let kind = if luminosity { "Luminosity" } else { "Alpha" };
                let _ = write!(
                    states,
                    " /SMask << /Type /Mask /S /{kind} /G {} 0 R >>",
                    first_form + form
                );
            }
        }
        states.push_str(" >> ");
    }
    let mut resources = format!("/ExtGState << {states}>> /Pattern << {patterns}>>");
    if !doc.forms.is_empty() {
        resources.push_str(" /XObject << ");
        for i in 0..doc.forms.len() {
            let _ = write!(resources, "/X{i} {} 0 R ", first_form + i);
        }
        resources.push_str(">>");
    }
    // One resources dictionary, the last object, for the page and every form.
    let res = first_form + doc.forms.len();
    let mut objects: Vec<Vec<u8>> = vec![
        b"<< /Type /Catalog /Pages 2 0 R >>".to_vec(),
        b"<< /Type /Pages /Kids [3 0 R] /Count 1 >>".to_vec(),
        format!(
            "<< /Type /Page /Parent 2 0 R /MediaBox [0 0 {media}] \
             /Resources {res} 0 R /Contents 4 0 R >>"
        )
        .into_bytes(),
        stream_object("", stream.as_bytes()),
        b"<< /Producer (vectorfusion) >>".to_vec(),
    ];
    for ((p, on_page), first) in doc.paints.iter().zip(firsts) {
        let flip = on_page.then_some(page_h);
        match p {
            Paint::Texture(t, channel) => objects.extend(texture_objects(t, first, flip, *channel)),
            Paint::Gradient(g, range, channel) => {
                objects.push(gradient_object(g, *range, flip, *channel))
            }
        }
    }
    let bbox = nums([0.0, 0.0, w, h]);
    for body in &doc.forms {
        objects.push(stream_object(
            &format!(
                "/Type /XObject /Subtype /Form /BBox [{bbox}] \
                 /Group << /S /Transparency /I true /CS /DeviceRGB >> /Resources {res} 0 R"
            ),
            body.as_bytes(),
        ));
    }
    objects.push(format!("<< {resources} >>").into_bytes());
    let mut pdf = b"%PDF-1.4\n%\xe2\xe3\xcf\xd3\n".to_vec();
    let mut offsets = Vec::with_capacity(objects.len());
    for (i, body) in objects.iter().enumerate() {
        offsets.push(pdf.len());
        pdf.extend_from_slice(format!("{} 0 obj\n", i + 1).as_bytes());
        pdf.extend_from_slice(body);
        pdf.extend_from_slice(b"\nendobj\n");
    }
    let xref = pdf.len();
    let mut table = format!("xref\n0 {}\n0000000000 65535 f \n", objects.len() + 1);
    for o in &offsets {
        let _ = writeln!(table, "{o:010} 00000 n ");
    }
    let _ = write!(
        table,
        "trailer\n<< /Size {} /Root 1 0 R /Info 5 0 R >>\nstartxref\n{xref}\n%%EOF\n",
        objects.len() + 1
    );
    pdf.extend_from_slice(table.as_bytes());
    pdf
}

#[cfg(test)]
mod tests;
