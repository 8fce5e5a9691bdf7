//! Scene → vector PDF (PDF 1.4, one page, no dependencies): every path stays a path, so a
//! designer's tool opens it as editable vectors, as it opens the SVG.
//!
//! The page has the SVG's size at CSS resolution (96 px = 72 pt, so 1 px = 0.75 pt); the content
//! stream flips y once (`cm`) and then draws in canvas pixels, in scene order: the background as
//! a full-page rectangle when it is not transparent, then each shape's fill (nonzero rule, as the
//! rasteriser and the SVG) and stroke (round caps and joins, as the rasteriser draws them).
//! Opacities go through one `ExtGState` per distinct alpha (`/ca` for fills, `/CA` for strokes).
//!
//! Invariant: the output is a complete PDF whose cross-reference offsets are exact; writing
//! cannot fail for a valid [`Scene`] (non-finite numbers are written as `0`).

use crate::scene::{Point, Rgba, Scene, Shape, ShapeKind};
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

/// The page's content stream and the alphas it names.
fn content(scene: &Scene) -> (String, Alphas) {
    let (w, h) = (scene.width as f32, scene.height as f32);
    let mut out = String::new();
    let mut alphas = Alphas::default();
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
        if let Some(f) = shape.fill.filter(|f| f.a > 0.0) {
            let _ = writeln!(out, "q {} gs", alphas.name(f.a));
            color(&mut out, f, "rg");
            path(&mut out, shape);
            out.push_str("f Q\n");
        }
        if let Some(s) = shape.stroke.filter(|s| s.color.a > 0.0 && s.width > 0.0) {
            let _ = writeln!(out, "q {} gs", alphas.name(s.color.a));
            color(&mut out, s.color, "RG");
            op(&mut out, &[s.width], "w");
            path(&mut out, shape);
            out.push_str("S Q\n");
        }
    }
    (out, alphas)
}

/// `scene` as a one-page vector PDF (see the module docs).
pub fn to_pdf(scene: &Scene) -> Vec<u8> {
    let (stream, alphas) = content(scene);
    let mut states = String::new();
    for (i, a) in alphas.0.iter().enumerate() {
        let _ = write!(states, "/G{i} << /Type /ExtGState /ca ");
        num(&mut states, *a);
        states.push_str(" /CA ");
        num(&mut states, *a);
        states.push_str(" >> ");
    }
    let mut media = String::new();
    for v in [
        scene.width as f32 * PT_PER_PX,
        scene.height as f32 * PT_PER_PX,
    ] {
        media.push(' ');
        num(&mut media, v);
    }
    let objects = [
        "<< /Type /Catalog /Pages 2 0 R >>".to_string(),
        "<< /Type /Pages /Kids [3 0 R] /Count 1 >>".to_string(),
        format!(
            "<< /Type /Page /Parent 2 0 R /MediaBox [0 0{media}] \
             /Resources << /ExtGState << {states}>> >> /Contents 4 0 R >>"
        ),
        format!("<< /Length {} >>\nstream\n{stream}endstream", stream.len()),
        "<< /Producer (vectorfusion) >>".to_string(),
    ];
    let mut pdf = b"%PDF-1.4\n%\xe2\xe3\xcf\xd3\n".to_vec();
    let mut offsets = Vec::with_capacity(objects.len());
    for (i, body) in objects.iter().enumerate() {
        offsets.push(pdf.len());
        pdf.extend_from_slice(format!("{} 0 obj\n{body}\nendobj\n", i + 1).as_bytes());
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
        let text = ascii(&to_pdf(&scene()));
        assert!(text.starts_with("%PDF-1.4"));
        assert!(text.ends_with("%%EOF\n"));
        let start: usize = text
            .rsplit("startxref\n")
            .next()
            .and_then(|t| t.lines().next())
            .and_then(|l| l.parse().ok())
            .unwrap();
        assert!(text[start..].starts_with("xref\n0 6\n"));
        let entries: Vec<usize> = text[start..]
            .lines()
            .skip(3)
            .take(5)
            .map(|l| l[..10].parse().unwrap())
            .collect();
        for (i, off) in entries.iter().enumerate() {
            assert!(
                text[*off..].starts_with(&format!("{} 0 obj\n", i + 1)),
                "object {}",
                i + 1
            );
        }
        // The stream's declared length is its length.
        let s = text.find("stream\n").unwrap() + 7;
        let e = text.find("endstream").unwrap();
        let declared: usize = text[..s]
            .rsplit("/Length ")
            .next()
            .and_then(|t| t.split_whitespace().next())
            .and_then(|n| n.parse().ok())
            .unwrap();
        assert_eq!(declared, e - s);
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
