//! Scene → vector PDF (PDF 1.4, one page): every path stays a path, so a designer's tool opens
//! it as editable vectors, as it opens the SVG.
//!
//! The page has the SVG's size at CSS resolution (96 px = 72 pt, so 1 px = 0.75 pt); the content
//! stream flips y once (`cm`) and then draws in canvas pixels, in scene order: the background as
//! a full-page rectangle when it is not transparent, then each shape's fill (by its fill rule, as
//! the rasteriser and the SVG) and stroke (round caps and joins, as the rasteriser draws them).
//! Opacities go through one `ExtGState` per distinct alpha (`/ca` for fills, `/CA` for strokes).
//! A textured fill (an imported image or pattern) is a tiling pattern whose cell is the texture
//! (an RGB image with its alpha as a soft mask, deflated), placed by the texture's transform:
//! the texels repeat as in the SVG export, and an image's shape covers just its one tile. A
//! gradient fill or stroke is a shading pattern (axial or radial, its stops a stitching function,
//! extended past both ends as `pad`), placed by the gradient's transform; a linear `repeat` or
//! `reflect` gradient spans the periods the shape covers. Stop opacities are drawn as their mean
//! (PDF shadings carry no alpha); a radial `repeat` or `reflect` is drawn as `pad`.
//!
//! Invariant: the output is a complete PDF whose cross-reference offsets are exact; writing
//! cannot fail for a valid [`Scene`] (non-finite numbers are written as `0`).

use crate::scene::{
    Affine, FillRule, Gradient, GradientGeometry, Point, Rgba, Scene, Shape, ShapeKind, Spread,
    Texture, TextureFilter,
};
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

/// The distinct alphas of a scene, in first-use order: `/G{i}` is `alphas[i]`.
#[derive(Default)]
struct Alphas(Vec<f32>);

impl Alphas {
    /// The graphics-state name for `a`, adding it if new.
    fn name(&mut self, a: f32) -> String {
        let i = match self.0.iter().position(|x| *x == a) {
            Some(i) => i,
            None => {
                self.0.push(a);
                self.0.len() - 1
            }
        };
        format!("/G{i}")
    }
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

/// What a pattern `/P{i}` of the page paints.
enum Paint<'a> {
    Texture(&'a Texture),
    /// A gradient and the range of its parameter `t` the shape covers.
    Gradient(&'a Gradient, [f32; 2]),
}

impl Paint<'_> {
    /// How many objects it takes (the pattern last).
    fn objects(&self) -> usize {
        match self {
            Paint::Texture(_) => 3,
            Paint::Gradient(..) => 1,
        }
    }
}

/// The page's content stream, the alphas it names and the paints its patterns `/P{i}` show.
fn content(scene: &Scene) -> (String, Alphas, Vec<Paint<'_>>) {
    let (w, h) = (scene.width as f32, scene.height as f32);
    let mut out = String::new();
    let mut alphas = Alphas::default();
    let mut paints = Vec::new();
    // Canvas pixels, y down, onto the page in points, y up.
    op(
        &mut out,
        &[PT_PER_PX, 0.0, 0.0, -PT_PER_PX, 0.0, h * PT_PER_PX],
        "cm",
    );
    out.push_str("1 J 1 j\n");
    if scene.background.a > 0.0 {
        let _ = writeln!(out, "q {} gs", alphas.name(scene.background.a));
        color(&mut out, scene.background, "rg");
        op(&mut out, &[0.0, 0.0, w, h], "re");
        out.push_str("f Q\n");
    }
    for shape in &scene.shapes {
        let g = shape.gradients.as_deref();
        let fill_op = match shape.fill_rule {
            FillRule::NonZero => "f",
            FillRule::EvenOdd => "f*",
        };
        if let (Some(t), Some(_)) = (g.and_then(|g| g.texture.as_deref()), shape.fill) {
            let _ = writeln!(out, "q /Pattern cs /P{} scn", paints.len());
            paints.push(Paint::Texture(t));
            path(&mut out, shape);
            let _ = writeln!(out, "{fill_op} Q");
        } else if let (Some(gr), Some(_)) = (g.and_then(|g| g.fill.as_ref()), shape.fill) {
            gradient_paint(&mut out, &mut alphas, &mut paints, gr, shape, "cs", "scn");
            path(&mut out, shape);
            let _ = writeln!(out, "{fill_op} Q");
        } else if let Some(f) = shape.fill.filter(|f| f.a > 0.0) {
            let _ = writeln!(out, "q {} gs", alphas.name(f.a));
            color(&mut out, f, "rg");
            path(&mut out, shape);
            let _ = writeln!(out, "{fill_op} Q");
        }
        let Some(s) = shape.stroke.filter(|s| s.width > 0.0) else {
            continue;
        };
        if let Some(gr) = g.and_then(|g| g.stroke.as_ref()) {
            gradient_paint(&mut out, &mut alphas, &mut paints, gr, shape, "CS", "SCN");
        } else if s.color.a > 0.0 {
            let _ = writeln!(out, "q {} gs", alphas.name(s.color.a));
            color(&mut out, s.color, "RG");
        } else {
            continue;
        }
        op(&mut out, &[s.width], "w");
        path(&mut out, shape);
        out.push_str("S Q\n");
    }
    (out, alphas, paints)
}

/// Opens a graphics state painting with gradient `gr` on `shape` as the next pattern, through
/// `space` and `set` (`cs`/`scn` for fills, `CS`/`SCN` for strokes), its alpha the stops' mean.
fn gradient_paint<'a>(
    out: &mut String,
    alphas: &mut Alphas,
    paints: &mut Vec<Paint<'a>>,
    gr: &'a Gradient,
    shape: &Shape,
    space: &str,
    set: &str,
) {
    let gs = alphas.name(mean_alpha(gr));
    let _ = writeln!(out, "q {gs} gs /Pattern {space} /P{} {set}", paints.len());
    paints.push(Paint::Gradient(gr, t_range(gr, shape)));
}

/// The mean of a gradient's stop alphas (a shading has none of its own).
fn mean_alpha(g: &Gradient) -> f32 {
    let n = g.stops.len().max(1) as f32;
    g.stops.iter().map(|s| s.color.a).sum::<f32>() / n
}

/// The range of a linear gradient's parameter over the shape's control points (which bound
/// its outline; a stroke's half width added), whole periods outward; `[0, 1]` for `pad` and
/// for radial gradients.
fn t_range(g: &Gradient, shape: &Shape) -> [f32; 2] {
    let GradientGeometry::Linear { x1, y1, x2, y2 } = g.geometry else {
        return [0.0, 1.0];
    };
    let (dx, dy) = (x2 - x1, y2 - y1);
    let len2 = dx * dx + dy * dy;
    if g.spread == Spread::Pad || len2.is_nan() || len2 <= 0.0 {
        return [0.0, 1.0];
    }
    // Canvas → gradient space (a singular map gives non-finite `t`s, which are passed over).
    let inv = Affine(g.transform.inverse_f64().map(|v| v as f32));
    let pad = shape.stroke.map_or(0.0, |s| s.width / 2.0);
    let (mut lo, mut hi) = (0.0f32, 1.0f32);
    for p in &shape.points {
        for (ox, oy) in [(-pad, -pad), (pad, -pad), (-pad, pad), (pad, pad)] {
            let q = inv.apply(Point::new(p.x + ox, p.y + oy));
            let t = ((q.x - x1) * dx + (q.y - y1) * dy) / len2;
            if t.is_finite() {
                (lo, hi) = (lo.min(t), hi.max(t));
            }
        }
    }
    // At most 256 periods: past that the stripes are finer than any page shows.
    let lo = lo.floor().max(hi.ceil() - 256.0);
    [lo, hi.ceil().min(lo + 256.0)]
}

/// ` [a b c d e f]`: gradient or texel space → canvas (`m`) → page points (y up).
fn page_matrix(m: &Affine, page_h: f32) -> String {
    let [a, b, c, d, e, f] = m.0;
    let k = PT_PER_PX;
    format!(
        "[{}]",
        nums([k * a, -k * b, k * c, -k * d, k * e, page_h - k * f])
    )
}

/// The stops of `g` as a function of `t` over `range` (whole periods of `repeat` or `reflect`,
/// else `[0, 1]`): a stitching function of linear pieces between stops.
fn stop_function(g: &Gradient, range: [f32; 2]) -> String {
    // Stops covering [0, 1], colours opaque (the alpha is the pattern's graphics state).
    let mut stops: Vec<(f32, Rgba)> = g
        .stops
        .iter()
        .map(|s| (s.offset.clamp(0.0, 1.0), s.color))
        .collect();
    if stops.is_empty() {
        stops.push((0.0, Rgba::BLACK));
    }
    if stops[0].0 > 0.0 {
        stops.insert(0, (0.0, stops[0].1));
    }
    if let Some(&(o, c)) = stops.last()
        && o < 1.0
    {
        stops.push((1.0, c));
    }
    let rgb = |c: Rgba| nums([c.r, c.g, c.b]);
    let piece = |a: Rgba, b: Rgba| {
        format!(
            "<< /FunctionType 2 /Domain [0 1] /C0 [{}] /C1 [{}] /N 1 >>",
            rgb(a),
            rgb(b)
        )
    };
    // One period: a piece per pair of stops (a pair at one offset is a hard step).
    let mut funcs = Vec::new();
    let mut bounds = Vec::new();
    for w in stops.windows(2) {
        funcs.push(piece(w[0].1, w[1].1));
        bounds.push(w[1].0);
    }
    bounds.pop();
    let period = |flip: bool, lo: f32| {
        let (mut f, mut b) = (funcs.clone(), bounds.clone());
        let mut encode = vec!["0 1"; f.len()];
        if flip {
            f.reverse();
            b = b.iter().rev().map(|v| 1.0 - v).collect();
            encode = vec!["1 0"; f.len()];
        }
        format!(
            "<< /FunctionType 3 /Domain [{}] /Functions [{}] /Bounds [{}] /Encode [{}] >>",
            nums([lo, lo + 1.0]),
            f.join(" "),
            nums(b.iter().map(|v| lo + v)),
            encode.join(" ")
        )
    };
    let [lo, hi] = range;
    if g.spread == Spread::Pad || hi - lo <= 1.0 && lo == 0.0 {
        return period(false, 0.0);
    }
    // Whole periods: each its own stitched function, mirrored on odd ones for `reflect`.
    let n = (hi - lo).round().max(1.0) as i64;
    let starts: Vec<f32> = (0..n).map(|k| lo + k as f32).collect();
    let parts: Vec<String> = starts
        .iter()
        .map(|&start| {
            let odd = (start as i64).rem_euclid(2) == 1;
            period(g.spread == Spread::Reflect && odd, start)
        })
        .collect();
    format!(
        "<< /FunctionType 3 /Domain [{}] /Functions [{}] /Bounds [{}] /Encode [{}] >>",
        nums([lo, hi]),
        parts.join(" "),
        nums(starts[1..].iter().copied()),
        nums(starts.iter().flat_map(|&s| [s, s + 1.0]))
    )
}

/// The shading pattern of gradient `g` over the parameter range `range` on a page `page_h`
/// points high.
fn gradient_object(g: &Gradient, range: [f32; 2], page_h: f32) -> Vec<u8> {
    let [lo, hi] = range;
    let (kind, coords) = match g.geometry {
        GradientGeometry::Linear { x1, y1, x2, y2 } => {
            // The axis at the range's ends: t = lo and t = hi.
            let at = |t: f32| [x1 + t * (x2 - x1), y1 + t * (y2 - y1)];
            (2, nums(at(lo).into_iter().chain(at(hi))))
        }
        GradientGeometry::Radial {
            cx,
            cy,
            r,
            fx,
            fy,
            fr,
        } => {
            // From the focal circle (t = 0) to the end circle (t = 1).
            (3, nums([fx, fy, fr, cx, cy, r]))
        }
    };
    format!(
        "<< /Type /Pattern /PatternType 2 /Matrix {} /Shading << /ShadingType {kind} \
         /ColorSpace /DeviceRGB /Coords [{coords}] /Domain [{}] /Function {} \
         /Extend [true true] >> >>",
        page_matrix(&g.transform, page_h),
        nums([lo, hi]),
        stop_function(g, range)
    )
    .into_bytes()
}

/// `data` deflated (zlib, as `/FlateDecode` reads it).
fn deflate(data: &[u8]) -> Vec<u8> {
    use std::io::Write as _;
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    // Writing into memory cannot fail.
    let _ = z.write_all(data);
    z.finish().unwrap_or_default()
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

/// The three objects that draw texture `t` as a tiling pattern on a page `page_h` points high:
/// the texels' colours (straight RGB), their alpha (the soft mask, object `first + 1`), and the
/// pattern (cell = the texture, placed by its transform and the page's flip); `first` is the
/// colour image's object number.
fn texture_objects(t: &Texture, first: usize, page_h: f32) -> [Vec<u8>; 3] {
    let (w, h) = (t.width, t.height);
    let straight = t.straight_pixels();
    let rgb: Vec<u8> = straight
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    let alpha: Vec<u8> = straight.chunks_exact(4).map(|p| p[3]).collect();
    let interpolate = t.filter != TextureFilter::Nearest;
    let image = |space: &str, extra: &str, data: &[u8]| {
        stream_object(
            &format!(
                "/Type /XObject /Subtype /Image /Width {w} /Height {h} /ColorSpace {space} \
                 /BitsPerComponent 8 /Interpolate {interpolate} /Filter /FlateDecode{extra}"
            ),
            &deflate(data),
        )
    };
    let color = image("/DeviceRGB", &format!(" /SMask {} 0 R", first + 1), &rgb);
    let mask = image("/DeviceGray", "", &alpha);
    let matrix = page_matrix(&t.transform, page_h);
    // The image's unit square onto the cell, its first row at texel row 0.
    let cell = format!("q {w} 0 0 -{h} 0 {h} cm /I Do Q");
    let pattern = stream_object(
        &format!(
            "/Type /Pattern /PatternType 1 /PaintType 1 /TilingType 1 /BBox [0 0 {w} {h}] \
             /XStep {w} /YStep {h} /Matrix {matrix} /Resources << /XObject << /I {first} 0 R >> >>"
        ),
        cell.as_bytes(),
    );
    [color, mask, pattern]
}

/// `scene` as a one-page vector PDF (see the module docs).
pub fn to_pdf(scene: &Scene) -> Vec<u8> {
    let (stream, alphas, paints) = content(scene);
    let mut states = String::new();
    for (i, a) in alphas.0.iter().enumerate() {
        let _ = write!(states, "/G{i} << /Type /ExtGState /ca ");
        num(&mut states, *a);
        states.push_str(" /CA ");
        num(&mut states, *a);
        states.push_str(" >> ");
    }
    let page_h = scene.height as f32 * PT_PER_PX;
    let media = nums([scene.width as f32 * PT_PER_PX, page_h]);
    // Objects 1–5 as below, then each paint's objects from 6 on, its pattern last.
    let mut patterns = String::new();
    let mut firsts = Vec::with_capacity(paints.len());
    let mut next = 6;
    for (i, p) in paints.iter().enumerate() {
        firsts.push(next);
        next += p.objects();
        let _ = write!(patterns, "/P{i} {} 0 R ", next - 1);
    }
    let mut objects: Vec<Vec<u8>> = vec![
        b"<< /Type /Catalog /Pages 2 0 R >>".to_vec(),
        b"<< /Type /Pages /Kids [3 0 R] /Count 1 >>".to_vec(),
        format!(
            "<< /Type /Page /Parent 2 0 R /MediaBox [0 0 {media}] \
             /Resources << /ExtGState << {states}>> /Pattern << {patterns}>> >> /Contents 4 0 R >>"
        )
        .into_bytes(),
        stream_object("", stream.as_bytes()),
        b"<< /Producer (vectorfusion) >>".to_vec(),
    ];
    for (p, first) in paints.iter().zip(firsts) {
        match p {
            Paint::Texture(t) => objects.extend(texture_objects(t, first, page_h)),
            Paint::Gradient(g, range) => objects.push(gradient_object(g, *range, page_h)),
        }
    }
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
mod tests {
    use super::*;
    use crate::scene::Stroke;

    fn scene() -> Scene {
        let mut s = Scene::new(40, 20, Rgba::WHITE).unwrap();
        s.shapes
            .push(Shape::circle(10.0, 10.0, 8.0, 4, Rgba::new(1.0, 0.0, 0.0, 0.5)).unwrap());
        let mut line = Shape::open_cubic(
            vec![
                Point::new(20.0, 2.0),
                Point::new(25.0, 2.0),
                Point::new(30.0, 18.0),
                Point::new(38.0, 18.0),
            ],
            Stroke::round(Rgba::new(0.0, 0.0, 1.0, 1.0), 2.0),
        )
        .unwrap();
        line.fill = None;
        s.shapes.push(line);
        s
    }

    /// The PDF as text with its binary-marker bytes as `?`, so byte offsets stay offsets.
    fn ascii(pdf: &[u8]) -> String {
        pdf.iter()
            .map(|&b| if b.is_ascii() { b as char } else { '?' })
            .collect()
    }

    #[test]
    fn numbers_are_short_and_finite() {
        let mut s = String::new();
        for v in [1.0, 0.5, -0.25, 1.23456, -0.00001, f32::NAN] {
            num(&mut s, v);
            s.push(' ');
        }
        assert_eq!(s, "1 0.5 -0.25 1.2346 0 0 ");
    }

    #[test]
    fn every_cross_reference_points_at_its_object() {
        cross_references_hold(&ascii(&to_pdf(&scene())), 5);
    }

    /// The PDF has `n` objects and each cross-reference entry points at its object.
    fn cross_references_hold(text: &str, n: usize) {
        assert!(text.starts_with("%PDF-1.4"));
        assert!(text.ends_with("%%EOF\n"));
        let start: usize = text
            .rsplit("startxref\n")
            .next()
            .and_then(|t| t.lines().next())
            .and_then(|l| l.parse().ok())
            .unwrap();
        assert!(text[start..].starts_with(&format!("xref\n0 {}\n", n + 1)));
        let entries: Vec<usize> = text[start..]
            .lines()
            .skip(3)
            .take(n)
            .map(|l| l[..10].parse().unwrap())
            .collect();
        for (i, off) in entries.iter().enumerate() {
            assert!(
                text[*off..].starts_with(&format!("{} 0 obj\n", i + 1)),
                "object {}",
                i + 1
            );
        }
        // The stream's declared length is its length (the end-of-line before `endstream` is not
        // counted).
        let s = text.find("stream\n").unwrap() + 7;
        let e = text.find("\nendstream").unwrap();
        let declared: usize = text[..s]
            .rsplit("/Length ")
            .next()
            .and_then(|t| t.split_whitespace().next())
            .and_then(|n| n.parse().ok())
            .unwrap();
        assert_eq!(declared, e - s);
    }

    #[test]
    fn a_texture_is_a_tiling_pattern_of_its_straight_texels() {
        use crate::scene::{Affine, Gradients, TextureEdge};
        let mut s = scene();
        let mut img = Shape::square(2.0, 2.0, 10.0, Rgba::BLACK).unwrap();
        img.gradients = Some(Box::new(Gradients {
            fill: None,
            stroke: None,
            texture: Some(Box::new(Texture {
                width: 2,
                height: 1,
                // premultiplied: red at half alpha, opaque blue
                pixels: vec![128, 0, 0, 128, 0, 0, 255, 255],
                transform: Affine([5.0, 0.0, 0.0, 10.0, 2.0, 2.0]),
                edge: TextureEdge::Pad,
                filter: TextureFilter::Nearest,
            })),
        }));
        s.shapes.push(img);
        let pdf = to_pdf(&s);
        let text = ascii(&pdf);
        cross_references_hold(&text, 8);
        assert!(text.contains("/Pattern << /P0 8 0 R >>"), "{text}");
        assert!(text.contains("q /Pattern cs /P0 scn\n2 2 m"), "{text}");
        assert!(text.contains("/SMask 7 0 R"));
        assert!(text.contains("/Interpolate false"));
        // texel space → canvas → points, y flipped on the 15 pt page
        assert!(
            text.contains("/XStep 2 /YStep 1 /Matrix [3.75 0 0 -7.5 1.5 13.5]"),
            "{text}"
        );
        assert!(text.contains("q 2 0 0 -1 0 1 cm /I Do Q"));
        // The colour image holds straight RGB, the mask the alpha.
        let streams: Vec<Vec<u8>> = pdf
            .windows(7)
            .enumerate()
            .filter(|(i, w)| w == b"stream\n" && pdf[i - 1] == b'\n')
            .map(|(i, _)| {
                let head = &text[..i];
                let n: usize = head
                    .rsplit("/Length ")
                    .next()
                    .and_then(|t| t.split_whitespace().next())
                    .and_then(|n| n.parse().ok())
                    .unwrap();
                pdf[i + 7..i + 7 + n].to_vec()
            })
            .collect();
        let inflate = |b: &[u8]| {
            use std::io::Read as _;
            let mut out = Vec::new();
            flate2::read::ZlibDecoder::new(b)
                .read_to_end(&mut out)
                .unwrap();
            out
        };
        assert_eq!(inflate(&streams[1]), [255, 0, 0, 0, 0, 255]);
        assert_eq!(inflate(&streams[2]), [128, 255]);
    }

    #[test]
    fn paths_fills_strokes_and_opacities_are_drawn_in_order() {
        let text = ascii(&to_pdf(&scene()));
        assert!(text.contains("/MediaBox [0 0 30 15]"), "{text}");
        assert!(text.contains("0.75 0 0 -0.75 0 15 cm"));
        // background, red fill at half alpha, blue stroke of width 2
        let bg = text.find("1 1 1 rg\n0 0 40 20 re\nf Q").unwrap();
        let red = text.find("1 0 0 rg").unwrap();
        let blue = text.find("0 0 1 RG\n2 w").unwrap();
        assert!(bg < red && red < blue);
        assert!(text.contains("/G1 << /Type /ExtGState /ca 0.5 /CA 0.5 >>"));
        assert_eq!(text.matches(" c\n").count(), 4 + 1, "4 segments + 1");
        assert!(text.contains("S Q"));
    }
}
