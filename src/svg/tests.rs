use super::*;
use crate::scene::{Point, Rgba, Scene, Shape, ShapeKind, Stroke};

fn sample_scene() -> Scene {
    let mut s = Scene::new(64, 48, Rgba::WHITE).unwrap();
    s.shapes
        .push(Shape::circle(20.0, 20.0, 12.0, 4, Rgba::new(1.0, 0.0, 0.0, 0.5)).unwrap());
    s.shapes.push(
        Shape::polygon(
            Point::list(&[(30.0, 5.0), (60.0, 10.0), (40.0, 40.0)]),
            Rgba::new(0.0, 0.4, 1.0, 1.0),
        )
        .unwrap(),
    );
    s.shapes.push(
        Shape::open_cubic(
            Point::list(&[(5.0, 40.0), (20.0, 30.0), (35.0, 47.0), (60.0, 35.0)]),
            Stroke::round(Rgba::new(0.0, 0.0, 0.0, 0.75), 3.0),
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
    assert!(
        a.contains(r##"<rect width="64" height="48" fill="#fff"/>"##),
        "{a}"
    );
    assert!(a.contains(r##"fill="#f00" fill-opacity=".5""##), "{a}");
    assert!(
        a.contains(r##"fill="none" stroke="#000" stroke-width="3" stroke-opacity=".75" stroke-linecap="round" stroke-linejoin="round""##),
        "{a}"
    );
    // The triangle: relative where shorter, the closing edge left to Z.
    assert!(a.contains(r#"d="M30 5l30 5L40 40Z""#), "{a}");
    // No redundant attributes: opaque fill has no fill-opacity; black fill is the default.
    assert_eq!(a.matches("fill-opacity").count(), 1);
    assert!(!a.contains(r##"fill="#000""##), "{a}");
    let mut t = s.clone();
    t.background = Rgba::TRANSPARENT;
    assert!(!to_svg(&t, &SvgOptions::default()).contains("<rect"));
    let p0 = to_svg(
        &s,
        &SvgOptions {
            precision: 0,
            ..Default::default()
        },
    );
    assert!(!p0.contains("M32."), "{p0}");
}

#[test]
fn path_data_uses_shorthands() {
    let mut s = Scene::new(100, 100, Rgba::TRANSPARENT).unwrap();
    // Pixel-art cell: H/V and the closing edge to Z.
    s.shapes
        .push(Shape::square(3.0, 4.0, 1.0, Rgba::new(0.0, 0.0, 0.0, 1.0)).unwrap());
    // A closed cubic that is a rectangle written with straight cubics, and a smooth S join.
    let line = |a: Point, b: Point| {
        let l = |t: f32| Point::new(a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t);
        [a, l(1.0 / 3.0), l(2.0 / 3.0)]
    };
    let (p0, p1, p2) = (
        Point::new(10.0, 10.0),
        Point::new(40.0, 10.0),
        Point::new(40.0, 40.0),
    );
    let mut pts = Vec::new();
    pts.extend(line(p0, p1));
    // p1 → p2 as a curve, then p2 → (10, 40) smooth, then a straight edge back.
    pts.extend([p1, Point::new(50.0, 20.0), Point::new(50.0, 30.0)]);
    pts.extend([p2, Point::new(30.0, 50.0), Point::new(20.0, 50.0)]);
    pts.extend(line(Point::new(10.0, 40.0), p0));
    s.shapes
        .push(Shape::closed_cubic(pts, Rgba::new(0.2, 0.4, 0.6, 1.0)).unwrap());
    let svg = to_svg(&s, &SvgOptions::default());
    // Ties between the absolute and the relative form go to the absolute one.
    assert!(svg.contains(r#"<path d="M3 4H4V5H3Z"/>"#), "{svg}");
    assert!(
        svg.contains(r#"d="M10 10H40c10 10 10 20 0 30S20 50 10 40Z""#),
        "{svg}"
    );
    // The same shape moved by a fraction: relative numbers stay exact.
    let moved = Scene {
        shapes: s
            .shapes
            .iter()
            .map(|sh| Shape {
                points: sh
                    .points
                    .iter()
                    .map(|p| Point::new(p.x + 0.25, p.y + 0.5))
                    .collect(),
                ..sh.clone()
            })
            .collect(),
        ..s.clone()
    };
    let svg = to_svg(&moved, &SvgOptions::default());
    assert!(svg.contains(r#"d="M3.25 4.5h1v1h-1Z""#), "{svg}");
    assert!(
        svg.contains(r#"d="M10.25 10.5h30c10 10 10 20 0 30s-20 10-30 0Z""#),
        "{svg}"
    );
}

#[test]
fn groups_and_ids() {
    let mut s = Scene::new(64, 64, Rgba::WHITE).unwrap();
    let red = Rgba::new(1.0, 0.0, 0.0, 1.0);
    for i in 0..3 {
        s.shapes
            .push(Shape::square(i as f32 * 4.0, 0.0, 3.0, red).unwrap());
    }
    s.shapes
        .push(Shape::square(0.0, 10.0, 3.0, Rgba::BLACK).unwrap());
    s.shapes.push(Shape::square(0.0, 20.0, 3.0, red).unwrap());
    let opts = SvgOptions {
        group_by_color: true,
        ids: true,
        ..Default::default()
    };
    let svg = to_svg(&s, &opts);
    check_safe_output(&svg).unwrap();
    assert!(svg.contains(r##"<g id="c1" fill="#f00">"##), "{svg}");
    assert_eq!(svg.matches("<g").count(), 1, "{svg}");
    for k in 1..=5 {
        assert!(svg.contains(&format!(r#"id="p{k}""#)), "{svg}");
    }
    // Paths in the group carry no fill; the black one none at all; the lone red one its own.
    assert_eq!(svg.matches(r##"fill="#f00""##).count(), 2, "{svg}");
    assert!(svg.contains(r#"<path id="p4" d="M0 10H3v3H0Z"/>"#), "{svg}");
    let plain = to_svg(&s, &SvgOptions::default());
    assert!(!plain.contains("<g") && !plain.contains("id="), "{plain}");
    // Sketch-like scenes: the shared stroke goes on one group.
    let mut k = Scene::new(64, 64, Rgba::WHITE).unwrap();
    let st = Stroke::round(Rgba::BLACK, 1.5);
    for i in 0..3 {
        let y = 5.0 + 10.0 * i as f32;
        let pts = [(5.0, y), (20.0, y + 7.0), (40.0, y - 3.0), (60.0, y)];
        k.shapes.push(
            Shape::open_cubic(pts.iter().map(|&(x, y)| Point::new(x, y)).collect(), st).unwrap(),
        );
    }
    let svg = to_svg(&k, &SvgOptions::default());
    check_safe_output(&svg).unwrap();
    assert!(
        svg.contains(r##"<g fill="none" stroke="#000" stroke-width="1.5" stroke-linecap="round" stroke-linejoin="round">"##),
        "{svg}"
    );
    assert_eq!(svg.matches("stroke").count(), 4, "{svg}");
}

#[test]
fn stage_groups_have_stable_ids_and_keep_the_picture() {
    let mut s = Scene::new(64, 64, Rgba::WHITE).unwrap();
    let red = Rgba::new(1.0, 0.0, 0.0, 1.0);
    for (i, stage) in [Some(1), Some(1), Some(2), None, Some(1)]
        .into_iter()
        .enumerate()
    {
        let mut sq = Shape::square(i as f32 * 8.0, 4.0, 6.0, red).unwrap();
        sq.stage = stage;
        s.shapes.push(sq);
    }
    let opts = crate::vector::palette::Grouping::Stage.svg_options();
    let svg = to_svg(&s, &opts);
    check_safe_output(&svg).unwrap();
    let order: Vec<&str> = svg
        .split("id=\"")
        .skip(1)
        .map(|t| &t[..t.find('"').unwrap()])
        .collect();
    assert_eq!(
        order,
        ["s1", "p1", "p2", "s2", "p3", "p4", "s1-2", "p5"],
        "{svg}"
    );
    assert_eq!(svg.matches("<g").count(), 3, "{svg}");
    assert_eq!(svg, to_svg(&s, &opts));
    let back = from_svg(&svg).unwrap();
    let plain = from_svg(&to_svg(&s, &SvgOptions::default())).unwrap();
    assert_eq!(
        crate::raster::render(&back).data,
        crate::raster::render(&plain).data
    );
    // Without stages there is nothing to group.
    for sh in &mut s.shapes {
        sh.stage = None;
    }
    assert!(!to_svg(&s, &opts).contains("<g"));
}

#[test]
fn export_import_round_trip() {
    let s = sample_scene();
    let svg = to_svg(
        &s,
        &SvgOptions {
            precision: 4,
            ..Default::default()
        },
    );
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
fn user_units_per_pixel_scale_the_view_box_and_keep_the_scene() {
    let s = sample_scene();
    let opts = SvgOptions {
        precision: 0,
        units_per_px: 20,
        ..Default::default()
    };
    let svg = to_svg(&s, &opts);
    assert!(
        svg.contains(r#"width="64" height="48" viewBox="0 0 1280 960""#),
        "{svg}"
    );
    assert!(svg.contains(r#"<rect width="1280" height="960""#), "{svg}");
    assert!(svg.contains(r#"stroke-width="60""#), "{svg}");
    for d in svg.split(r#" d=""#).skip(1) {
        assert!(!d[..d.find('"').unwrap()].contains('.'), "{d}");
    }
    // Read back in pixels: every point on the 1/20 px grid, the stroke width exact.
    let back = from_svg(&svg).unwrap();
    assert_eq!((back.width, back.height), (64, 48));
    // (The triangle comes back as three cubics.)
    for i in [0, 2] {
        let (a, b) = (&s.shapes[i], &back.shapes[i]);
        assert_eq!(a.points.len(), b.points.len());
        for (p, q) in a.points.iter().zip(&b.points) {
            assert!((p.x - q.x).abs() <= 0.025 + 1e-4 && (p.y - q.y).abs() <= 0.025 + 1e-4);
        }
    }
    assert!((back.shapes[2].stroke.unwrap().width - 3.0).abs() < 1e-4);
    // The same picture as the pixel-unit document with two decimals.
    let px = from_svg(&to_svg(&s, &SvgOptions::default())).unwrap();
    let (a, b) = (crate::raster::render(&back), crate::raster::render(&px));
    let mean = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (x - y).abs() as f64)
        .sum::<f64>()
        / a.data.len() as f64;
    assert!(mean < 0.5 / 255.0, "{mean}");
    // 0 and 1 unit per pixel write pixels.
    for k in [0, 1] {
        let o = SvgOptions {
            units_per_px: k,
            ..Default::default()
        };
        assert_eq!(to_svg(&s, &o), to_svg(&s, &SvgOptions::default()));
    }
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
    assert_eq!(rect.fill.unwrap().a, 1.0);
    // The group's opacity applies to its children as one layer.
    assert_eq!(s.groups, vec![crate::scene::Group::new(0..6, 0.5)]);
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

/// A random scene with every shape kind and the cases the writer shortens: straight and
/// axis-aligned segments, smooth joins, repeated colours, strokes on closed shapes, stroke-only
/// closed shapes, coordinates on and off the decimal grid.
fn random_scene(seed: u64) -> Scene {
    use rand::{RngExt, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let (w, h) = (rng.random_range(16..=256u32), rng.random_range(16..=256u32));
    let background = match rng.random_range(0..3) {
        0 => Rgba::TRANSPARENT,
        1 => Rgba::WHITE,
        _ => Rgba::new(
            rng.random(),
            rng.random(),
            rng.random(),
            rng.random_range(0.1..1.0),
        ),
    };
    let mut scene = Scene::new(w, h, background).unwrap();
    let palette: Vec<Rgba> = (0..3)
        .map(|_| {
            let a = if rng.random_bool(0.5) {
                1.0
            } else {
                rng.random_range(0.1..1.0)
            };
            Rgba::new(rng.random(), rng.random(), rng.random(), a)
        })
        .collect();
    // Coordinates on a grid of 10^-q for q in 0..=3, or anywhere.
    let grid = rng.random_range(0..5);
    let coord = |rng: &mut rand_chacha::ChaCha8Rng, lo: f32, hi: f32| {
        let v: f32 = rng.random_range(lo..hi);
        if grid < 4 {
            let s = 10f32.powi(grid);
            (v * s).round() / s
        } else {
            v
        }
    };
    let line = |a: Point, b: Point| {
        let l = |t: f32| Point::new(a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t);
        [l(1.0 / 3.0), l(2.0 / 3.0)]
    };
    for _ in 0..rng.random_range(1..12) {
        let color = palette[rng.random_range(0..palette.len())];
        let (wf, hf) = (w as f32, h as f32);
        match rng.random_range(0..4) {
            0 => {
                let (x, y) = (
                    coord(&mut rng, 0.0, wf - 4.0),
                    coord(&mut rng, 0.0, hf - 4.0),
                );
                let side = coord(&mut rng, 2.0, 4.0).max(1.0);
                scene.shapes.push(Shape::square(x, y, side, color).unwrap());
            }
            1 => {
                let n = rng.random_range(3..8);
                let pts = (0..n)
                    .map(|_| Point::new(coord(&mut rng, 0.0, wf), coord(&mut rng, 0.0, hf)))
                    .collect();
                scene.shapes.push(Shape::polygon(pts, color).unwrap());
            }
            kind => {
                let closed = kind == 2;
                let n = rng.random_range(1..6);
                let mut anchors: Vec<Point> = (0..n + 1)
                    .map(|_| Point::new(coord(&mut rng, 0.0, wf), coord(&mut rng, 0.0, hf)))
                    .collect();
                if closed {
                    anchors[n] = anchors[0];
                }
                let mut pts = vec![anchors[0]];
                let mut prev_c2: Option<Point> = None;
                for i in 0..n {
                    let (a, mut b) = (anchors[i], anchors[i + 1]);
                    let c = match rng.random_range(0..5) {
                        0 => {
                            // Axis-aligned straight segment (not for the closing one).
                            if i + 1 < n || !closed {
                                b.y = a.y;
                                anchors[i + 1] = b;
                            }
                            line(a, b)
                        }
                        1 => line(a, b),
                        2 if prev_c2.is_some() => {
                            let q = prev_c2.unwrap_or(a);
                            let c1 = Point::new(2.0 * a.x - q.x, 2.0 * a.y - q.y);
                            [
                                c1,
                                Point::new(coord(&mut rng, 0.0, wf), coord(&mut rng, 0.0, hf)),
                            ]
                        }
                        _ => [
                            Point::new(coord(&mut rng, 0.0, wf), coord(&mut rng, 0.0, hf)),
                            Point::new(coord(&mut rng, 0.0, wf), coord(&mut rng, 0.0, hf)),
                        ],
                    };
                    pts.extend_from_slice(&c);
                    if i + 1 < n || !closed {
                        pts.push(b);
                    }
                    prev_c2 = Some(c[1]);
                }
                let stroke = Stroke::round(
                    palette[rng.random_range(0..palette.len())],
                    rng.random_range(1.0..4.0),
                );
                let shape = if closed {
                    let mut s = Shape::closed_cubic(pts, color).unwrap();
                    match rng.random_range(0..3) {
                        0 => s.stroke = Some(stroke),
                        1 => {
                            s.fill = Some(Rgba::new(0.3, 0.2, 0.1, 0.0));
                            s.stroke = Some(stroke);
                        }
                        _ => {}
                    }
                    s
                } else {
                    Shape::open_cubic(pts, stroke).unwrap()
                };
                scene.shapes.push(shape);
            }
        }
    }
    scene.validate().unwrap();
    scene
}

/// Compares `back` (imported) with `scene` (exported at `precision`): every segment's points
/// within half a unit of the last decimal (plus f32 noise), colours exactly as written.
fn assert_round_trip(scene: &Scene, back: &Scene, precision: u8, svg: &str) {
    let tol = 0.5 * 10f32.powi(-(precision as i32)) + 4.0 * f32::EPSILON * 256.0;
    assert_eq!((back.width, back.height), (scene.width, scene.height));
    let bg = if scene.background.a > 0.0 {
        written_color(scene.background, precision)
    } else {
        Rgba::TRANSPARENT
    };
    assert_eq!(back.background, bg, "{svg}");
    assert_eq!(back.shapes.len(), scene.shapes.len(), "{svg}");
    for (k, (a, b)) in scene.shapes.iter().zip(&back.shapes).enumerate() {
        assert_eq!(a.is_closed(), b.is_closed(), "shape {k}\n{svg}");
        assert_eq!(a.num_segments(), b.num_segments(), "shape {k}\n{svg}");
        for i in 0..a.num_segments() {
            for (p, q) in a.segment(i).iter().zip(b.segment(i)) {
                let d = (p.x - q.x).abs().max((p.y - q.y).abs());
                assert!(
                    d <= tol,
                    "shape {k} segment {i}: {p:?} vs {q:?} ({d} > {tol})\n{svg}"
                );
            }
        }
        let visible = |c: Option<Rgba>| c.filter(|c| c.a > 0.0);
        assert_eq!(
            visible(a.fill).map(|c| written_color(c, precision)),
            visible(b.fill),
            "shape {k} fill\n{svg}"
        );
        assert_eq!(a.stroke.is_some(), b.stroke.is_some(), "shape {k}\n{svg}");
        if let (Some(s), Some(t)) = (a.stroke, b.stroke) {
            assert_eq!(written_color(s.color, precision), t.color, "shape {k}");
            assert!((s.width - t.width).abs() <= tol, "shape {k} width");
        }
    }
}

#[test]
fn random_scenes_round_trip_with_every_option() {
    let mut letters = std::collections::BTreeSet::new();
    for seed in 0..60 {
        let scene = random_scene(seed);
        for precision in 0..=4u8 {
            for group_by_color in [false, true] {
                for ids in [false, true] {
                    let opts = SvgOptions {
                        precision,
                        group_by_color,
                        ids,
                        ..Default::default()
                    };
                    let svg = to_svg(&scene, &opts);
                    assert_eq!(svg, to_svg(&scene, &opts));
                    for d in svg.split(r#" d=""#).skip(1) {
                        letters.extend(
                            d.chars()
                                .take_while(|&c| c != '"')
                                .filter(char::is_ascii_alphabetic),
                        );
                    }
                    check_safe_output(&svg).unwrap_or_else(|e| panic!("{e}\n{svg}"));
                    let back = from_svg(&svg).unwrap_or_else(|e| panic!("{e}\n{svg}"));
                    assert_round_trip(&scene, &back, precision, &svg);
                }
            }
        }
    }
    // Every shorthand was exercised.
    let all: String = letters.into_iter().collect();
    assert_eq!(all, "CHLMSVZchlsv", "{all}");
}
