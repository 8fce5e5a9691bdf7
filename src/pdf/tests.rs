use super::*;
use crate::scene::{Stroke, TextureFilter};

fn scene() -> Scene {
    let mut s = Scene::new(40, 20, Rgba::WHITE).unwrap();
    s.shapes
        .push(Shape::circle(10.0, 10.0, 8.0, 4, Rgba::new(1.0, 0.0, 0.0, 0.5)).unwrap());
    let mut line = Shape::open_cubic(
        Point::list(&[(20.0, 2.0), (25.0, 2.0), (30.0, 18.0), (38.0, 18.0)]),
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
    cross_references_hold(&ascii(&to_pdf(&scene())), 6);
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

/// A 10-pixel square at (2, 2) filled with a 2×1 texture of premultiplied `pixels`, one texel
/// 5 × 10 pixels, drawn nearest.
fn image_square(pixels: Vec<u8>) -> Shape {
    use crate::scene::{Affine, Gradients, TextureEdge};
    let mut img = Shape::square(2.0, 2.0, 10.0, Rgba::BLACK).unwrap();
    img.gradients = Some(Box::new(Gradients {
        fill: None,
        stroke: None,
        texture: Some(Box::new(Texture {
            width: 2,
            height: 1,
            pixels,
            transform: Affine([5.0, 0.0, 0.0, 10.0, 2.0, 2.0]),
            edge: TextureEdge::Pad,
            filter: TextureFilter::Nearest,
        })),
    }));
    img
}

#[test]
fn a_texture_is_a_tiling_pattern_of_its_straight_texels() {
    let mut s = scene();
    // premultiplied: red at half alpha, opaque blue
    s.shapes
        .push(image_square(vec![128, 0, 0, 128, 0, 0, 255, 255]));
    let pdf = to_pdf(&s);
    let text = ascii(&pdf);
    cross_references_hold(&text, 9);
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
    let streams = streams(&pdf);
    assert_eq!(inflate(&streams[1]), [255, 0, 0, 0, 0, 255]);
    assert_eq!(inflate(&streams[2]), [128, 255]);
}

/// The content of every stream object of `pdf`, in order.
fn streams(pdf: &[u8]) -> Vec<Vec<u8>> {
    let text = ascii(pdf);
    pdf.windows(7)
        .enumerate()
        .filter(|(i, w)| *w == b"stream\n" && pdf[i - 1] == b'\n')
        .map(|(i, _)| {
            let n: usize = text[..i]
                .rsplit("/Length ")
                .next()
                .and_then(|t| t.split_whitespace().next())
                .and_then(|n| n.parse().ok())
                .unwrap();
            pdf[i + 7..i + 7 + n].to_vec()
        })
        .collect()
}

fn inflate(b: &[u8]) -> Vec<u8> {
    try_inflate(b).unwrap()
}

fn try_inflate(b: &[u8]) -> Option<Vec<u8>> {
    use std::io::Read as _;
    let mut out = Vec::new();
    flate2::read::ZlibDecoder::new(b)
        .read_to_end(&mut out)
        .ok()?;
    Some(out)
}

#[test]
fn an_image_in_a_luminance_mask_is_drawn_in_svg_luminance_greys() {
    use crate::scene::{Content, Group, Mask, MaskKind};
    let mut s = scene();
    let n = s.shapes.len();
    // opaque red, opaque green
    let img = image_square(vec![255, 0, 0, 255, 0, 255, 0, 255]);
    let mut g = Group::new(0..n, 1.0);
    g.mask = Some(Box::new(Mask {
        kind: MaskKind::Luminance,
        content: Content {
            shapes: vec![img],
            groups: Vec::new(),
        },
        mask: None,
    }));
    s.groups.push(g);
    let pdf = to_pdf(&s);
    let greys: Vec<Vec<u8>> = streams(&pdf)
        .iter()
        .filter_map(|b| try_inflate(b))
        .filter(|b| b.len() == 6)
        .collect();
    // SVG's luminance of red (0.2125) and green (0.7154), as greys
    assert_eq!(greys, [vec![54, 54, 54, 182, 182, 182]], "{}", ascii(&pdf));
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

#[test]
fn groups_are_forms_with_their_clip_mask_opacity_and_blend() {
    let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="20">
        <clipPath id="one"><rect x="2" y="2" width="10" height="10"/></clipPath>
        <clipPath id="two"><circle cx="20" cy="10" r="5"/><circle cx="26" cy="10" r="5"/></clipPath>
        <linearGradient id="g"><stop offset="0" stop-color="#fff"/><stop offset="1" stop-color="#000"/></linearGradient>
        <mask id="m" maskUnits="userSpaceOnUse" x="0" y="0" width="40" height="20"><rect width="40" height="20" fill="url(#g)"/></mask>
        <g clip-path="url(#one)" opacity="0.5"><rect width="20" height="20" fill="red"/></g>
        <g clip-path="url(#two)" style="mix-blend-mode:multiply"><rect width="40" height="20" fill="blue"/></g>
        <g mask="url(#m)"><rect width="40" height="20" fill="green"/></g></svg>"##;
    let scene = crate::svg::from_svg(svg).unwrap();
    assert_eq!(scene.groups.len(), 3);
    let text = ascii(&to_pdf(&scene));
    // One gradient pattern (object 6), then the forms: the first two groups' shapes (7, 8),
    // the two-circle clip's coverage (9), the third group's shapes (10), the mask's content
    // (11) and the masked group (12); the resources they share (13).
    cross_references_hold(&text, 6 + 6 + 1);
    // Every form and the page name the one resources dictionary.
    assert_eq!(text.matches("/Resources 13 0 R").count(), 7, "{text}");
    assert_eq!(text.matches("/ExtGState <<").count(), 1, "{text}");
    // A one-shape clip is a clipping path around the group's form, painted at half opacity.
    assert!(text.contains("q\n2 2 m\n"), "{text}");
    assert!(text.contains("h\nW n\n/G1 gs /X0 Do Q"), "{text}");
    assert!(text.contains("/G1 << /Type /ExtGState /ca 0.5 /CA 0.5 /BM /Normal >>"));
    // A clip of two shapes is an alpha soft mask of their opaque fills; the blend mode is the
    // group's state.
    assert!(
        text.contains("/SMask << /Type /Mask /S /Alpha /G 9 0 R >>"),
        "{text}"
    );
    assert!(text.contains("/BM /Multiply"));
    // The mask reads its content's luminosity; the masked group is a form of its own.
    assert!(
        text.contains("/SMask << /Type /Mask /S /Luminosity /G 11 0 R >>"),
        "{text}"
    );
    assert!(text.contains("/Group << /S /Transparency /I true /CS /DeviceRGB >>"));
    // The gradient inside the mask's form is placed in canvas pixels (no page flip).
    assert!(
        text.contains("/PatternType 2 /Matrix [40 0 0 20 0 0]"),
        "{text}"
    );
}

#[test]
fn stop_opacities_are_a_soft_mask_of_greys() {
    let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="20">
        <linearGradient id="g"><stop offset="0" stop-color="#f00"/><stop offset="1" stop-color="#00f" stop-opacity=".25"/></linearGradient>
        <rect width="40" height="20" fill="url(#g)"/></svg>"##;
    let text = ascii(&to_pdf(&crate::svg::from_svg(svg).unwrap()));
    // The colours (object 6) on the page, the alphas (7) in the mask's form (8).
    cross_references_hold(&text, 9);
    assert!(text.contains("/C0 [1 0 0] /C1 [0 0 1]"), "{text}");
    assert!(text.contains("/C0 [1 1 1] /C1 [0.25 0.25 0.25]"), "{text}");
    assert!(text.contains("/SMask << /Type /Mask /S /Luminosity /G 8 0 R >>"));
    assert!(text.contains("q /G0 gs /Pattern cs /P0 scn"));
    assert!(text.contains("q /Pattern cs /P1 scn\n0 0 40 20 re\nf Q"));
}

#[test]
fn strokes_keep_their_caps_joins_and_miter_limit() {
    let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="20">
        <path d="M2 2 L20 18 L38 2" fill="none" stroke="#000" stroke-width="3" stroke-linecap="butt" stroke-linejoin="miter" stroke-miterlimit="3"/>
        <path d="M2 10 L38 10" fill="none" stroke="#000" stroke-linecap="square" stroke-linejoin="bevel"/>
        <path d="M2 16 L38 16" fill="none" stroke="#000"/></svg>"##;
    let text = ascii(&to_pdf(&crate::svg::from_svg(svg).unwrap()));
    assert!(text.contains("3 w\n0 J\n0 j\n3 M\n"), "{text}");
    assert!(text.contains("1 w\n2 J\n2 j\n"), "{text}");
    // SVG's defaults (butt, miter 4) are said; round is the page's own.
    assert!(text.contains("1 J 1 j\n"));
    assert_eq!(text.matches(" M\n").count(), 2, "{text}");
}

#[test]
fn a_zero_length_subpath_with_square_caps_is_a_filled_square() {
    let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="20">
        <path d="M10 10 L10 10" fill="none" stroke="#00f" stroke-width="4" stroke-linecap="square"/>
        <path d="M30 10 L30 10" fill="none" stroke="#f00" stroke-width="4" stroke-linecap="round"/></svg>"##;
    let text = ascii(&to_pdf(&crate::svg::from_svg(svg).unwrap()));
    // the square one as a square fill in the stroke's colour; the round one stroked (PDF
    // draws a round cap on a zero-length subpath)
    assert!(text.contains("0 0 1 rg\n8 8 4 4 re\nf Q"), "{text}");
    assert!(text.contains("1 0 0 RG\n4 w\n"), "{text}");
    assert!(!text.contains("0 0 1 RG"), "{text}");
}

#[test]
fn a_pad_gradient_with_a_step_at_its_start_pads_with_the_outer_stop() {
    let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="20">
        <linearGradient id="g" x1="0.2" x2="0.8"><stop offset="0" stop-color="#000"/><stop offset="0" stop-color="#f00"/><stop offset="1" stop-color="#00f"/></linearGradient>
        <rect width="40" height="20" fill="url(#g)"/></svg>"##;
    let text = ascii(&to_pdf(&crate::svg::from_svg(svg).unwrap()));
    // t runs from -1/3 to 4/3 over the rect: black before 0, the stops, blue after 1.
    assert!(
        text.contains(
            "/Domain [-1 2] /Functions [<< /FunctionType 2 /Domain [0 1] /C0 [0 0 0] /C1 [0 0 0] /N 1 >>"
        ),
        "{text}"
    );
    assert!(
        text.contains("/C0 [0 0 1] /C1 [0 0 1] /N 1 >>] /Bounds [0 1]"),
        "{text}"
    );
}

#[test]
fn a_luminance_mask_is_drawn_in_svg_luminance_greys() {
    let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="20">
        <linearGradient id="g"><stop offset="0" stop-color="#0f0"/><stop offset="1" stop-color="#00f"/></linearGradient>
        <mask id="m" maskUnits="userSpaceOnUse" x="0" y="0" width="40" height="20">
          <rect width="20" height="20" fill="#f00"/><rect x="20" width="20" height="20" fill="url(#g)"/></mask>
        <mask id="a" mask-type="alpha" maskUnits="userSpaceOnUse" x="0" y="0" width="40" height="20">
          <rect width="40" height="20" fill="#f00" fill-opacity=".5"/></mask>
        <g mask="url(#m)"><rect width="40" height="20" fill="#f00"/></g>
        <g mask="url(#a)"><rect width="40" height="20" fill="#00f"/></g></svg>"##;
    let text = ascii(&to_pdf(&crate::svg::from_svg(svg).unwrap()));
    // Red as its SVG luminance; the gradient's stops as theirs (green 0.7154, blue 0.0721).
    assert!(text.contains("0.2125 0.2125 0.2125 rg"), "{text}");
    assert!(
        text.contains("/C0 [0.7154 0.7154 0.7154] /C1 [0.0721 0.0721 0.0721]"),
        "{text}"
    );
    // The masked shapes and an alpha mask's content keep their colours.
    assert_eq!(text.matches("1 0 0 rg").count(), 2, "{text}");
    assert!(text.contains("0 0 1 rg"));
}
