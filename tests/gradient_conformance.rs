//! Gradient conformance: our importer and rasteriser against resvg on SVGs written here, one per
//! gradient attribute (units, coordinates and percentages, `gradientTransform`, spread methods,
//! stops and their clamping, `stop-opacity`, `href` inheritance, focal point and radius, strokes,
//! group transforms, fallbacks). The rule is the resvg suite harness's
//! (`scripts/resvg_suite.py`): over premultiplied RGBA in 0..255, a mean absolute difference of
//! at most 1.5 and at most 1 % of the pixels off by more than 16. On failure a triptych (ours |
//! resvg | 8x difference) is written to `$CARGO_TARGET_TMPDIR/golden_gradient_<name>.png`.

mod common;

use common::golden::{mean_abs_diff, resvg_render, share_off_by, write_triptych};
use vectorfusion::{raster, svg};

const MAX_MEAN_ABS: f64 = 1.5 / 255.0;
const OFF_BY: f32 = 16.0 / 255.0;
const MAX_OFF_SHARE: f64 = 0.01;

/// An SVG of 96 × 96 px with these definitions and this content.
fn doc(defs: &str, body: &str) -> String {
    format!(
        r##"<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" width="96" height="96" viewBox="0 0 96 96"><defs>{defs}</defs>{body}</svg>"##
    )
}

const STOPS: &str = r##"<stop offset="0" stop-color="#e63946"/><stop offset="0.5" stop-color="#f1c453"/><stop offset="1" stop-color="#1d3557"/>"##;

fn cases() -> Vec<(&'static str, String)> {
    let rect = r#"<rect x="8" y="12" width="80" height="70" fill="url(#g)"/>"#;
    let circle = r#"<circle cx="48" cy="48" r="40" fill="url(#g)"/>"#;
    let lin = |attrs: &str| format!(r#"<linearGradient id="g" {attrs}>{STOPS}</linearGradient>"#);
    let rad = |attrs: &str| format!(r#"<radialGradient id="g" {attrs}>{STOPS}</radialGradient>"#);
    vec![
        ("linear_bbox_default", doc(&lin(""), rect)),
        (
            "linear_bbox_diagonal",
            doc(&lin(r#"x1="0" y1="0" x2="1" y2="1""#), circle),
        ),
        (
            "linear_percent",
            doc(&lin(r#"x1="20%" y1="10%" x2="80%" y2="30%""#), rect),
        ),
        (
            "linear_user_space",
            doc(
                &lin(r#"gradientUnits="userSpaceOnUse" x1="20" y1="30" x2="70" y2="60""#),
                rect,
            ),
        ),
        (
            "linear_transform",
            doc(
                &lin(
                    r#"gradientUnits="userSpaceOnUse" x1="30" y1="0" x2="60" y2="0" gradientTransform="rotate(35 48 48) skewX(10)""#,
                ),
                circle,
            ),
        ),
        (
            "linear_reflect",
            doc(&lin(r#"x1="0.4" x2="0.6" spreadMethod="reflect""#), rect),
        ),
        (
            "linear_repeat",
            doc(
                &lin(r#"x1="0.3" y1="0.3" x2="0.5" y2="0.45" spreadMethod="repeat""#),
                rect,
            ),
        ),
        (
            "stops_clamped_unsorted_hard_edge",
            doc(
                r##"<linearGradient id="g"><stop offset="-0.5" stop-color="red"/><stop offset="0.4" stop-color="lime"/><stop offset="0.3" stop-color="blue"/><stop offset="0.7" stop-color="blue"/><stop offset="0.7" stop-color="black"/><stop offset="150%" stop-color="white"/></linearGradient>"##,
                rect,
            ),
        ),
        (
            "stop_opacity_and_fill_opacity",
            doc(
                r##"<linearGradient id="g"><stop offset="0" stop-color="#00f" stop-opacity="0.2"/><stop offset="1" stop-color="#f00" stop-opacity="0.9"/></linearGradient>"##,
                r##"<rect x="0" y="30" width="96" height="30" fill="#0a0"/><rect x="8" y="12" width="80" height="70" fill="url(#g)" fill-opacity="0.7"/>"##,
            ),
        ),
        (
            "href_inherits_stops_and_attributes",
            doc(
                &format!(
                    r##"<linearGradient id="base" x1="0" y1="1" x2="0" y2="0" spreadMethod="reflect">{STOPS}</linearGradient><linearGradient id="g" xlink:href="#base" y1="0.6" y2="0.4"/>"##
                ),
                rect,
            ),
        ),
        ("radial_bbox_default", doc(&rad(""), rect)),
        ("radial_focal", doc(&rad(r#"fx="0.3" fy="0.35""#), circle)),
        (
            "radial_user_space_focal_radius",
            doc(
                &rad(
                    r#"gradientUnits="userSpaceOnUse" cx="50" cy="46" r="36" fx="38" fy="40" fr="8""#,
                ),
                rect,
            ),
        ),
        (
            "radial_reflect",
            doc(&rad(r#"r="0.2" spreadMethod="reflect""#), rect),
        ),
        (
            "radial_repeat",
            doc(&rad(r#"r="0.15" fx="0.45" spreadMethod="repeat""#), rect),
        ),
        (
            "radial_transform",
            doc(
                &rad(
                    r#"gradientTransform="translate(0.5 0.5) scale(1 0.5) rotate(30) translate(-0.5 -0.5)""#,
                ),
                circle,
            ),
        ),
        (
            "stroke_linear_bbox",
            doc(
                &lin(r#"x1="0" y1="0" x2="1" y2="0""#),
                r#"<path d="M10 20 C40 90 60 -10 86 70" fill="none" stroke="url(#g)" stroke-width="10"/>"#,
            ),
        ),
        (
            "stroke_radial_closed",
            doc(
                &rad(r#"gradientUnits="userSpaceOnUse" cx="48" cy="48" r="44""#),
                r##"<rect x="14" y="14" width="68" height="68" rx="10" fill="#ddd" stroke="url(#g)" stroke-width="12"/>"##,
            ),
        ),
        (
            "stroke_under_skew_as_outline",
            doc(
                &lin(r#"x1="0" y1="0" x2="1" y2="1""#),
                r#"<g transform="skewX(25) scale(1 0.8)"><path d="M5 20 L40 90 L70 15" fill="none" stroke="url(#g)" stroke-width="9" stroke-linejoin="round"/></g>"#,
            ),
        ),
        (
            "group_transform",
            doc(
                &lin(r#"x1="0" y1="0" x2="1" y2="1""#),
                r#"<g transform="translate(48 48) rotate(20) scale(1.2)"><rect x="-30" y="-25" width="60" height="50" fill="url(#g)"/></g>"#,
            ),
        ),
        (
            "fallbacks",
            doc(
                r##"<linearGradient id="one"><stop offset="0.5" stop-color="#456"/></linearGradient><radialGradient id="zero" r="0">{STOPS}</radialGradient>"##,
                r##"<rect x="4" y="4" width="40" height="40" fill="url(#one)"/><rect x="52" y="4" width="40" height="40" fill="url(#missing) #c80"/><rect x="4" y="52" width="40" height="40" fill="url(#zero)"/><rect x="52" y="52" width="40" height="40" fill="url(#nothing)"/>"##,
            ),
        ),
    ]
}

#[test]
fn gradients_render_as_resvg_renders_them() {
    let mut failures = Vec::new();
    for (name, text) in cases() {
        let scene = svg::from_svg(&text).unwrap_or_else(|e| panic!("{name}: {e}"));
        let ours = raster::render(&scene);
        let theirs = resvg_render(&text);
        let mean = mean_abs_diff(&ours, &theirs);
        let off = share_off_by(&ours, &theirs, OFF_BY);
        eprintln!(
            "{name}: mean abs diff {:.3}/255, {:.2}% of pixels off by more than 16",
            mean * 255.0,
            off * 100.0
        );
        if mean > MAX_MEAN_ABS || off > MAX_OFF_SHARE {
            let path = write_triptych(&format!("gradient_{name}"), &ours, &theirs);
            failures.push(format!(
                "{name}: mean {:.3}/255, {:.2}% off by > 16 ({path})",
                mean * 255.0,
                off * 100.0
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn every_case_imports_a_gradient_where_it_should() {
    for (name, text) in cases() {
        let scene = svg::from_svg(&text).unwrap();
        let n = scene
            .shapes
            .iter()
            .filter(|s| s.gradients.is_some())
            .count();
        assert_eq!(n > 0, name != "fallbacks", "{name}: {n} gradient shapes");
    }
}
