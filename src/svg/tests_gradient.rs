//! Gradient paint through import (usvg's resolution rules), export and the round trip.

use super::*;
use crate::scene::{Affine, GradientGeometry, Rgba, Spread};

/// The fill gradient of shape `i`.
fn fill_gradient(s: &crate::scene::Scene, i: usize) -> &crate::scene::Gradient {
    s.shapes[i]
        .gradients
        .as_ref()
        .unwrap()
        .fill
        .as_ref()
        .unwrap()
}

const SVG: &str = r##"<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" width="100" height="80">
<defs>
  <linearGradient id="base" x1="0" y1="0" x2="1" y2="0">
    <stop offset="0.2" stop-color="#ff0000"/>
    <stop offset="0.1" stop-color="#00ff00" stop-opacity="0.5"/>
    <stop offset="1.5" stop-color="#0000ff"/>
  </linearGradient>
  <linearGradient id="lin" xlink:href="#base" spreadMethod="reflect" gradientTransform="rotate(30)"/>
  <radialGradient id="rad" gradientUnits="userSpaceOnUse" cx="60" cy="40" r="20" fx="55" fy="38" fr="2" spreadMethod="repeat">
    <stop offset="0" stop-color="#fff"/>
    <stop offset="1" stop-color="#123456"/>
  </radialGradient>
  <linearGradient id="one"><stop offset="0.5" stop-color="#abcdef"/></linearGradient>
</defs>
<rect x="10" y="10" width="40" height="20" fill="url(#lin)" fill-opacity="0.5"/>
<circle cx="60" cy="40" r="20" fill="url(#rad)" stroke="url(#lin)" stroke-width="4"/>
<path d="M10 60 L50 75 L90 60" fill="none" stroke="url(#lin)" stroke-width="6"/>
<rect x="70" y="5" width="10" height="10" fill="url(#one)"/>
<rect x="85" y="5" width="10" height="10" fill="url(#missing) #00ff00"/>
</svg>"##;

#[test]
fn gradients_import_with_usvg_rules() {
    let s = from_svg(SVG).unwrap();
    assert_eq!(s.shapes.len(), 5);
    let g = fill_gradient(&s, 0);
    // Inherited stops; offsets clamped into [0, 1] and made non-decreasing; opacity folded in.
    // (usvg nudges an equal offset down by an ulp or so.)
    let offsets: Vec<f32> = g.stops.iter().map(|s| s.offset).collect();
    assert!(
        (offsets[0] - 0.2).abs() < 1e-6 && offsets[1..] == [0.2, 1.0],
        "{offsets:?}"
    );
    assert_eq!(g.stops[0].color, Rgba::new(1.0, 0.0, 0.0, 0.5));
    assert_eq!(g.stops[1].color, Rgba::new(0.0, 1.0, 0.0, 0.25));
    assert_eq!(g.spread, Spread::Reflect);
    // objectBoundingBox units: (0, 0) is the box corner and (1, 0) a box width away, rotated.
    let o = g.transform.apply(crate::scene::Point::new(0.0, 0.0));
    let x = g.transform.apply(crate::scene::Point::new(1.0, 0.0));
    assert!(
        (o.x - 10.0).abs() < 1e-4 && (o.y - 10.0).abs() < 1e-4,
        "{o:?}"
    );
    let a = 30f32.to_radians();
    assert!((x.x - 10.0 - 40.0 * a.cos()).abs() < 1e-3, "{x:?}");
    assert!((x.y - 10.0 - 20.0 * a.sin()).abs() < 1e-3, "{x:?}");
    // The flat stand-in is the mean stop colour.
    assert_eq!(s.shapes[0].fill, Some(g.mean_color()));
    // Radial with focal point and focal radius, fill and stroke both painted.
    let gs = s.shapes[1].gradients.as_ref().unwrap();
    let rad = gs.fill.as_ref().unwrap();
    assert_eq!(
        rad.geometry,
        GradientGeometry::Radial {
            cx: 60.0,
            cy: 40.0,
            r: 20.0,
            fx: 55.0,
            fy: 38.0,
            fr: 2.0
        }
    );
    assert_eq!(
        (rad.spread, rad.transform),
        (Spread::Repeat, Affine::IDENTITY)
    );
    assert!(gs.stroke.is_some());
    // An open stroke with an objectBoundingBox gradient.
    assert!(s.shapes[2].gradients.as_ref().unwrap().stroke.is_some());
    // One stop is a flat colour; a missing reference falls back to its fallback colour.
    assert!(s.shapes[3].gradients.is_none());
    assert_eq!(
        s.shapes[3].fill.unwrap().to_array()[..3],
        [171.0 / 255.0, 205.0 / 255.0, 239.0 / 255.0]
    );
    assert!(s.shapes[4].gradients.is_none());
    assert_eq!(s.shapes[4].fill, Some(Rgba::new(0.0, 1.0, 0.0, 1.0)));
}

#[test]
fn dangling_paint_references_are_named_in_warnings() {
    let w = import_svg(SVG).unwrap().warnings;
    assert_eq!(
        w,
        ["fill of <rect> refers to #missing, which is no gradient or pattern: painted #00ff00"],
        "{w:?}"
    );
    let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="8" height="8"><g id="g"/><rect id="r" width="8" height="8" style="stroke: url('#nope')" fill="url(#g)"/></svg>"#;
    let w = import_svg(svg).unwrap().warnings;
    assert_eq!(w.len(), 2, "{w:?}");
    assert!(
        w[0].starts_with(r#"fill of <rect id="r"> refers to #g"#) && w[0].ends_with("not painted")
    );
    assert!(
        w[1].starts_with("stroke of") && w[1].contains("#nope"),
        "{w:?}"
    );
}

#[test]
fn gradients_round_trip_through_export() {
    let s = from_svg(SVG).unwrap();
    let opts = SvgOptions {
        precision: MAX_PRECISION,
        ..Default::default()
    };
    let svg = to_svg(&s, &opts);
    assert!(
        svg.contains(r#"<linearGradient id="g1" gradientUnits="userSpaceOnUse""#),
        "{svg}"
    );
    assert!(
        svg.contains(r#"fill="url(#g1)""#) && svg.contains(r#"stroke="url(#g3)""#),
        "{svg}"
    );
    let back = from_svg(&svg).unwrap();
    assert_eq!(back, s, "{svg}");
    // And once more: the export is stable.
    assert_eq!(to_svg(&back, &opts), svg);
}

#[test]
fn scaled_scenes_move_their_gradients() {
    let s = from_svg(SVG).unwrap();
    let big = s.scaled_to_width(200);
    let g0 = fill_gradient(&s, 1);
    let g1 = fill_gradient(&big, 1);
    let p = crate::scene::Point::new(3.0, 4.0);
    let (a, b) = (g0.transform.apply(p), g1.transform.apply(p));
    assert!((2.0 * a.x - b.x).abs() < 1e-4 && (2.0 * a.y - b.y).abs() < 1e-4);
    big.validate().unwrap();
}

#[test]
fn shapes_painted_alike_share_one_paint_server() {
    // Two rectangles with one gradient, a third with another, an image twice: one element
    // each, in and out of a group.
    let png = {
        use base64::Engine;
        let mut img = crate::image::Image::new(4, 4);
        for (i, px) in img.data.chunks_exact_mut(4).enumerate() {
            px.copy_from_slice(&[(i % 4) as f32 / 3.0, (i / 4) as f32 / 3.0, 0.5, 1.0]);
        }
        base64::engine::general_purpose::STANDARD.encode(img.encode_png().unwrap())
    };
    for group in ["", r#" opacity="0.5""#] {
        let src = format!(
            r##"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64">
<linearGradient id="a" gradientUnits="userSpaceOnUse" x1="0" y1="0" x2="64" y2="0">
<stop offset="0" stop-color="#f00"/><stop offset="1" stop-color="#00f"/></linearGradient>
<linearGradient id="b" gradientUnits="userSpaceOnUse" x1="0" y1="0" x2="0" y2="64">
<stop offset="0" stop-color="#f00"/><stop offset="1" stop-color="#00f"/></linearGradient>
<g{group}>
<rect x="2" y="2" width="20" height="20" fill="url(#a)"/>
<rect x="30" y="2" width="20" height="20" fill="url(#a)"/>
<rect x="2" y="30" width="20" height="20" stroke="url(#b)"/>
<image x="30" y="30" width="8" height="8" href="data:image/png;base64,{png}"/>
<image x="30" y="30" width="8" height="8" href="data:image/png;base64,{png}"/>
</g></svg>"##
        );
        let s = from_svg(&src).unwrap();
        let svg = to_svg(&s, &SvgOptions::default());
        assert_eq!(svg.matches("<linearGradient").count(), 2, "{svg}");
        assert_eq!(svg.matches("<pattern").count(), 1, "{svg}");
        assert_eq!(svg.matches(r#"fill="url(#g1)""#).count(), 2, "{svg}");
        let back = from_svg(&svg).unwrap();
        let (a, b) = (crate::raster::render(&s), crate::raster::render(&back));
        // A texture goes back through a pattern tile (resampled): the suite's tolerance.
        let d: f32 = a.data.iter().zip(&b.data).map(|(x, y)| (x - y).abs()).sum();
        assert!(d / (a.data.len() as f32) < 1.5 / 255.0, "{svg}");
    }
}
