use super::*;

fn sample_scene() -> Scene {
    let mut s = Scene::new(64, 48, Rgba::WHITE).unwrap();
    s.shapes
        .push(Shape::circle(20.0, 20.0, 12.0, 4, Rgba::new(1.0, 0.0, 0.0, 0.5)).unwrap());
    s.shapes.push(
        Shape::polygon(
            vec![
                Point::new(30.0, 5.0),
                Point::new(60.0, 10.0),
                Point::new(40.0, 40.0),
            ],
            Rgba::new(0.0, 0.4, 1.0, 1.0),
        )
        .unwrap(),
    );
    s.shapes.push(
        Shape::open_cubic(
            vec![
                Point::new(5.0, 40.0),
                Point::new(20.0, 30.0),
                Point::new(35.0, 47.0),
                Point::new(60.0, 35.0),
            ],
            Stroke {
                color: Rgba::new(0.0, 0.0, 0.0, 0.75),
                width: 3.0,
            },
        )
        .unwrap(),
    );
    s
}

#[test]
fn export_is_compact_and_deterministic() {
    let s = sample_scene();
    let a = to_svg(&s, &SvgOptions::default());
    assert_eq!(a, to_svg(&s, &SvgOptions::default()));
    assert_eq!(a.matches("<path").count(), 3);
    assert!(a.contains(r##"<rect width="64" height="48" fill="#ffffff"/>"##));
    assert!(a.contains(r##"fill="#ff0000" fill-opacity="0.5""##), "{a}");
    assert!(a.contains(r##"fill="none" stroke="#000000" stroke-width="3" stroke-opacity="0.75""##));
    assert!(a.contains("M30 5L60 10L40 40Z"), "{a}");
    // No redundant attributes: opaque fill has no fill-opacity.
    assert_eq!(a.matches("fill-opacity").count(), 1);
    let mut t = s.clone();
    t.background = Rgba::TRANSPARENT;
    assert!(!to_svg(&t, &SvgOptions::default()).contains("<rect"));
    let p0 = to_svg(&s, &SvgOptions { precision: 0 });
    assert!(!p0.contains("M32."), "{p0}");
}

#[test]
fn export_import_round_trip() {
    let s = sample_scene();
    let svg = to_svg(&s, &SvgOptions { precision: 4 });
    let back = from_svg(&svg).unwrap();
    assert_eq!((back.width, back.height), (64, 48));
    assert_eq!(back.background, Rgba::WHITE);
    assert_eq!(back.shapes.len(), 3);
    assert_eq!(back.shapes[0].kind, ShapeKind::ClosedCubic);
    assert_eq!(back.shapes[0].points.len(), 12);
    for (p, q) in s.shapes[0].points.iter().zip(&back.shapes[0].points) {
        assert!((p.x - q.x).abs() < 1e-3 && (p.y - q.y).abs() < 1e-3);
    }
    let f = back.shapes[0].fill.unwrap();
    assert!((f.a - 0.5).abs() < 1e-3 && f.r == 1.0);
    assert_eq!(back.shapes[2].kind, ShapeKind::OpenCubic);
    let st = back.shapes[2].stroke.unwrap();
    assert!((st.width - 3.0).abs() < 1e-4 && (st.color.a - 0.75).abs() < 1e-3);
}

#[test]
fn import_handles_primitives_groups_transforms_and_styles() {
    let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="100" height="50" viewBox="0 0 200 100">
      <style>.c { fill: #00ff00; }</style>
      <g transform="translate(10 5)" opacity="0.5">
        <rect x="0" y="0" width="20" height="10" style="fill:blue"/>
        <circle class="c" cx="50" cy="50" r="10"/>
        <ellipse cx="100" cy="50" rx="20" ry="10" fill="red" stroke="black" stroke-width="4"/>
        <polygon points="150,10 190,10 170,40"/>
        <path d="M10 80 A 10 10 0 0 1 30 80 Q 40 90 50 80 T 70 80 H 90 V 95 h -5 v -5 l -3 3 z"/>
        <polyline points="0,0 10,10 20,0" fill="none" stroke="red"/>
      </g>
    </svg>"#;
    let s = from_svg(svg).unwrap();
    assert_eq!((s.width, s.height), (100, 50));
    assert_eq!(s.background, Rgba::TRANSPARENT);
    // rect, circle, ellipse (fill+stroke on one shape), polygon, path, polyline stroke.
    assert_eq!(s.shapes.len(), 6, "{:#?}", s.shapes);
    let rect = &s.shapes[0];
    assert_eq!(rect.fill.unwrap().b, 1.0);
    assert!((rect.fill.unwrap().a - 0.5).abs() < 1e-6, "group opacity");
    // viewBox halves, translate(10,5) → rect corner at (5, 2.5).
    let (lo, hi) = rect.control_bounds();
    assert!(
        (lo.x - 5.0).abs() < 1e-4 && (lo.y - 2.5).abs() < 1e-4,
        "{lo:?}"
    );
    assert!(
        (hi.x - 15.0).abs() < 1e-4 && (hi.y - 7.5).abs() < 1e-4,
        "{hi:?}"
    );
    assert_eq!(s.shapes[1].fill.unwrap().g, 1.0);
    let ell = &s.shapes[2];
    assert!(ell.stroke.is_some());
    assert!(
        (ell.stroke.unwrap().width - 2.0).abs() < 1e-4,
        "width scaled by viewBox"
    );
    assert_eq!(s.shapes[5].kind, ShapeKind::OpenCubic);
    assert!(s.validate().is_ok());
}

#[test]
fn holes_survive_via_bridges() {
    // Donut: outer and inner circle in the same direction with evenodd, and opposite with nonzero.
    for (rule, inner) in [
        (
            "evenodd",
            "M 30 20 A 10 10 0 1 1 10 20 A 10 10 0 1 1 30 20 Z",
        ),
        (
            "nonzero",
            "M 30 20 A 10 10 0 1 0 10 20 A 10 10 0 1 0 30 20 Z",
        ),
    ] {
        let svg = format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="40">
            <path fill-rule="{rule}" d="M 40 20 A 20 20 0 1 1 0 20 A 20 20 0 1 1 40 20 Z {inner}"/></svg>"#
        );
        let s = from_svg(&svg).unwrap();
        assert_eq!(s.shapes.len(), 1);
        let im = crate::raster::render(&s);
        // Centre is a hole, the ring is filled.
        assert!(im.pixel(20, 20)[3] < 0.01, "{rule}: hole filled");
        assert!(im.pixel(20, 5)[3] > 0.99, "{rule}: ring empty");
    }
}

#[test]
fn bad_svg_is_an_error() {
    for bad in [
        "",
        "not xml",
        "<svg",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="0" height="10"/>"#,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="100000" height="10"/>"#,
        r#"<html/>"#,
    ] {
        assert!(from_svg(bad).is_err(), "{bad:?} accepted");
    }
    // Garbage path data is skipped, not a panic.
    let s = from_svg(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10"><path d="M 1 1 L nan Q"/></svg>"#,
    );
    assert!(s.is_ok());
}

#[test]
fn bench_scene_json_loads() {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/bench/scene64.json"
    ))
    .unwrap();
    let s = scene_from_json(&text).unwrap();
    assert_eq!((s.width, s.height, s.shapes.len()), (512, 512, 64));
    assert!(s.shapes.iter().all(|p| p.points.len() == 12));
    let a = s.shapes[0].fill.unwrap().a;
    assert!((a - 0.843_103).abs() < 1e-5);
    assert!(scene_from_json("{").is_err());
    assert!(
        scene_from_json(r#"{"width":4,"height":4,"paths":[{"points":[[0,0]],"fill":[1,0,0]}]}"#)
            .is_err()
    );
    // serde form of Scene also loads.
    let again = scene_from_json(&serde_json::to_string(&s).unwrap()).unwrap();
    assert_eq!(again, s);
}

#[test]
fn metadata_is_escaped_and_the_document_still_parses() {
    let svg = to_svg(&sample_scene(), &SvgOptions::default());
    let out = with_metadata(&svg, "icon \"a<b>&c\" (CC-BY-4.0)\u{7}");
    assert!(
        out.contains("<metadata>icon &quot;a&lt;b&gt;&amp;c&quot; (CC-BY-4.0)</metadata>"),
        "{out}"
    );
    assert!(out.starts_with("<svg "));
    assert!(out.find("<metadata>").unwrap() > out.find('>').unwrap());
    assert!(parse_usvg(&out).is_ok());
    assert_eq!(from_svg(&out).unwrap().width, 64);
    assert_eq!(with_metadata("not svg", "x"), "not svg");
}
