//! Tests of [`super`]: each count on small hand-written SVGs, our exporter's output, and speed.

use super::*;
use crate::scene::{Rgba, Scene, Shape};

fn doc(w: u32, h: u32, body: &str) -> String {
    format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}">{body}</svg>"#
    )
}

#[test]
fn compound_path_with_hole_is_valid() {
    // vtracer style: one path, outer ring and hole, even-odd, with a transform.
    let body = r##"<rect width="64" height="64" fill="#ffffff"/>
<path d="M0 0 L40 0 L40 40 L0 40 Z M10 10 L30 10 L30 30 L10 30 Z" fill="#204080" fill-rule="evenodd" transform="translate(12,12)"/>"##;
    let e = check_svg(&doc(64, 64, body)).unwrap();
    assert_eq!(e.paths, 1);
    assert_eq!(e.self_intersecting, 0);
    assert_eq!(e.hidden, 0);
    assert_eq!(e.slivers, 0);
    assert_eq!(e.colors, 2);
    // A hole touching its outer ring at one point is still valid (shapely agrees)...
    let touch =
        r##"<path d="M0 0 L40 0 L40 40 L0 40 Z M20 0 L30 20 L10 20 Z" fill-rule="evenodd"/>"##;
    assert_eq!(check_svg(&doc(64, 64, touch)).unwrap().self_intersecting, 0);
    // ...but a "hole" poking out through the outer ring is not.
    let cross =
        r##"<path d="M0 0 L40 0 L40 40 L0 40 Z M20 -5 L30 20 L10 20 Z" fill-rule="evenodd"/>"##;
    assert_eq!(check_svg(&doc(64, 64, cross)).unwrap().self_intersecting, 1);
}

#[test]
fn figure_eight_and_spike_count() {
    let body = r##"<path d="M10 10 L50 50 L50 10 L10 50 Z" fill="#ff0000"/>
<path d="M5 5 C20 -5 40 25 60 5 C40 25 20 -5 5 5 Z" fill="#00ff00"/>
<path d="M2 40 L20 40 L30 40 L20 40 L20 60 L2 60 Z" fill="#0000ff"/>
<path d="M40 40 C50 40 60 50 60 60 C50 60 40 50 40 40 Z" fill="#000000"/>"##;
    let e = check_svg(&doc(64, 64, body)).unwrap();
    assert_eq!(e.paths, 4);
    // Bowtie, the curved figure-eight (its two cubics cross) and the folded spike.
    assert_eq!(e.self_intersecting, 3);
}

#[test]
fn stroke_only_paths_are_not_self_intersecting() {
    let body =
        r##"<path d="M10 10 L50 50 L50 10 L10 50" fill="none" stroke="#000" stroke-width="2"/>"##;
    let e = check_svg(&doc(64, 64, body)).unwrap();
    assert_eq!(
        (e.paths, e.self_intersecting, e.hidden, e.slivers),
        (1, 0, 0, 0)
    );
}

#[test]
fn path_under_an_opaque_one_is_hidden() {
    let body = r##"<rect width="64" height="64" fill="#ffffff"/>
<circle cx="32" cy="32" r="10" fill="#ff0000"/>
<rect x="10" y="10" width="44" height="44" fill="#00ff00"/>
<circle cx="32" cy="32" r="10" fill="#0000ff" fill-opacity="0"/>
<path d="M0 0 L1 0 Z" fill="#123456"/>"##;
    let e = check_svg(&doc(64, 64, body)).unwrap();
    assert_eq!(e.paths, 4);
    // The red disc (covered), the transparent disc and the zero-area path.
    assert_eq!(e.hidden, 3);
    assert_eq!(e.slivers, 0);
    // Half-covered stays visible.
    let half = r##"<circle cx="32" cy="32" r="10" fill="#ff0000"/>
<rect x="32" y="0" width="32" height="64" fill="#00ff00"/>"##;
    assert_eq!(check_svg(&doc(64, 64, half)).unwrap().hidden, 0);
}

#[test]
fn thin_strip_and_speck_are_slivers() {
    let body = r##"<rect width="64" height="64" fill="#ffffff"/>
<rect x="10" y="10.35" width="40" height="0.3" fill="#000000"/>
<rect x="30" y="30" width="1" height="1" fill="#000000"/>
<rect x="40" y="40" width="10" height="1" fill="#000000"/>"##;
    let e = check_svg(&doc(64, 64, body)).unwrap();
    assert_eq!(e.paths, 3);
    assert_eq!(e.hidden, 0);
    // The 0.3-px strip (mean width 0.3) and the 1-px² speck; the 10 × 1 bar is editable.
    assert_eq!(e.slivers, 2);
}

#[test]
fn colours_include_background_stroke_and_gradient_stops() {
    let body = r##"<defs><linearGradient id="g"><stop offset="0" stop-color="#010203"/><stop offset="1" stop-color="#ff0000"/></linearGradient></defs>
<rect width="64" height="64" fill="#fafafa"/>
<rect x="5" y="5" width="20" height="20" fill="#ff0000" stroke="#00ff00"/>
<rect x="30" y="5" width="20" height="20" fill="red"/>
<rect x="5" y="30" width="20" height="20" fill="url(#g)"/>"##;
    let e = check_svg(&doc(64, 64, body)).unwrap();
    assert_eq!(e.paths, 3);
    assert_eq!(e.colors, 4);
}

#[test]
fn bad_input_is_an_error() {
    assert!(matches!(check_svg("not svg"), Err(CheckError::Parse(_))));
    assert!(check_svg("").is_err());
}

#[test]
fn scene_check_goes_through_the_exporter() {
    let mut s = Scene::new(100, 100, Rgba::WHITE).unwrap();
    s.shapes
        .push(Shape::circle(50.0, 50.0, 30.0, 4, Rgba::BLACK).unwrap());
    s.shapes
        .push(Shape::circle(50.0, 50.0, 10.0, 4, Rgba::BLACK).unwrap());
    s.shapes.push(
        Shape::closed_cubic(
            vec![
                crate::scene::Point::new(10.0, 10.0),
                crate::scene::Point::new(90.0, 90.0),
                crate::scene::Point::new(90.0, 10.0),
            ],
            Rgba::new(1.0, 0.0, 0.0, 1.0),
        )
        .unwrap(),
    );
    let e = check(&s);
    assert_eq!(
        e,
        check_svg(&crate::svg::to_svg(&s, &Default::default())).unwrap()
    );
    assert_eq!(e.paths, 3);
    // The small black disc on the big black disc changes no pixel.
    assert_eq!(e.hidden, 1);
    assert_eq!(e.colors, 3);
    // After repair nothing crosses itself.
    let before = e.self_intersecting;
    let mut fixed = s.clone();
    crate::vector::simple::make_scene_simple(&mut fixed, 0.25, 0.5);
    assert_eq!(check(&fixed).self_intersecting, 0);
    let _ = before;
}

/// The layers composited in the check equal resvg's render of the whole document (groups,
/// transforms, a viewBox that scales, opacity on a group of one path).
#[test]
fn layers_composite_to_the_document_render() {
    let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="80" height="60" viewBox="0 0 40 30">
<rect width="40" height="30" fill="#eeeeee"/>
<g transform="translate(5,3) rotate(10)"><path d="M0 0 C10 -5 20 5 15 15 Z" fill="#336699"/>
<g opacity="0.5"><circle cx="20" cy="10" r="6" fill="#aa2200"/></g></g>
<path d="M2 28 L38 2" stroke="#000" stroke-width="1.5" fill="none"/></svg>"##;
    let tree = crate::svg::parse_usvg(svg).unwrap();
    let (w, h) = (80usize, 60usize);
    let mut walk = Walk {
        w: 80,
        h: 60,
        pixmap: tiny_skia::Pixmap::new(80, 60).unwrap(),
        mask: tiny_skia::Mask::new(80, 60).unwrap(),
        layers: Vec::new(),
        colors: BTreeSet::new(),
        counts: Editability::default(),
        background_seen: false,
        layer_pixels: 0,
    };
    walk.group(tree.root(), 1.0).unwrap();
    let mut canvas = vec![0f32; 4 * w * h];
    for l in &walk.layers {
        let [x0, y0, x1, y1] = l.rect;
        for y in y0..y1 {
            for x in x0..x1 {
                let s = &l.rgba[4 * ((y - y0) * (x1 - x0) + x - x0)..][..4];
                let sa = s[3] as f32 / 255.0;
                for k in 0..4 {
                    let c = &mut canvas[4 * (y * w + x) + k];
                    *c = s[k] as f32 / 255.0 + (1.0 - sa) * *c;
                }
            }
        }
    }
    let mut full = tiny_skia::Pixmap::new(80, 60).unwrap();
    resvg::render(&tree, tiny_skia::Transform::identity(), &mut full.as_mut());
    let worst = full
        .data()
        .iter()
        .zip(&canvas)
        .map(|(&a, &b)| (a as f32 / 255.0 - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst <= 3.0 / 255.0, "worst channel difference {worst}");
    assert_eq!(walk.counts.paths, 3);
}

/// 64 paths at 256 px: the check must stay far under a second.
#[test]
fn sixty_four_paths_at_256_px_are_fast() {
    let mut s = Scene::new(256, 256, Rgba::WHITE).unwrap();
    for i in 0..64 {
        let (x, y) = ((i % 8) as f32 * 30.0 + 20.0, (i / 8) as f32 * 30.0 + 20.0);
        let c = Rgba::new((i % 4) as f32 / 4.0, (i % 7) as f32 / 7.0, 0.5, 1.0);
        s.shapes
            .push(Shape::circle(x, y, 12.0 + (i % 5) as f32 * 8.0, 6, c).unwrap());
    }
    let t = std::time::Instant::now();
    let e = check(&s);
    let secs = t.elapsed().as_secs_f64();
    assert_eq!(e.paths, 64);
    eprintln!("check of 64 paths at 256 px: {secs:.3} s");
    assert!(secs < 1.0, "{secs} s");
}

/// Cross-check helper (ignored): with `VF_CHECK_DIR` set, writes 12 LIVE-like scenes of
/// randomly deformed circles there as SVG (`random_*.svg`), then prints one JSON line of
/// counts per `*.svg` in the folder, for `scripts/svg_editability.py` to compare against.
#[test]
#[ignore]
fn print_counts_of_svg_dir() {
    use rand::{RngExt, SeedableRng};
    let Ok(dir) = std::env::var("VF_CHECK_DIR") else {
        return;
    };
    let dir = std::path::Path::new(&dir);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    for k in 0..12 {
        let mut s = Scene::new(128, 128, Rgba::WHITE).unwrap();
        for _ in 0..16 {
            let r = 6.0 + 20.0 * rng.random::<f32>();
            let (cx, cy) = (128.0 * rng.random::<f32>(), 128.0 * rng.random::<f32>());
            let c = Rgba::new(rng.random(), rng.random(), rng.random(), 1.0);
            let mut sh =
                Shape::circle(cx, cy, r, 4 + (rng.random::<u32>() % 4) as usize, c).unwrap();
            let amp = r * 1.2 * rng.random::<f32>();
            for p in &mut sh.points {
                p.x += amp * (2.0 * rng.random::<f32>() - 1.0);
                p.y += amp * (2.0 * rng.random::<f32>() - 1.0);
            }
            s.shapes.push(sh);
        }
        std::fs::write(
            dir.join(format!("random_{k:02}.svg")),
            crate::svg::to_svg(&s, &Default::default()),
        )
        .unwrap();
        let mut fixed = s.clone();
        crate::vector::simple::make_scene_simple(&mut fixed, 0.25, 0.5);
        std::fs::write(
            dir.join(format!("random_{k:02}_fixed.svg")),
            crate::svg::to_svg(&fixed, &Default::default()),
        )
        .unwrap();
    }
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "svg"))
        .collect();
    files.sort();
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        let name = f.file_name().unwrap().to_string_lossy().to_string();
        if std::env::var("VF_CHECK_DETAILS").is_ok() {
            // Which filled paths fail (indices in paint order, the background is path 0), and
            // how many paths there are.
            let tree = crate::svg::parse_usvg(&text).unwrap();
            let mut bad = Vec::new();
            fn walk(g: &usvg::Group, i: &mut usize, bad: &mut Vec<usize>) {
                for n in g.children() {
                    match n {
                        usvg::Node::Group(c) => walk(c, i, bad),
                        usvg::Node::Path(p) if p.is_visible() => {
                            if p.fill().is_some()
                                && !rings_valid(&rings_of(p.data(), p.abs_transform()))
                            {
                                bad.push(*i);
                            }
                            *i += 1;
                        }
                        _ => {}
                    }
                }
            }
            let mut count = 0usize;
            walk(tree.root(), &mut count, &mut bad);
            println!("DETAIL {name} {count} {bad:?}");
        }
        match check_svg(&text) {
            Ok(e) => println!(
                "RUST {}",
                serde_json::json!({"file": name, "paths": e.paths, "self_intersecting": e.self_intersecting, "hidden": e.hidden, "slivers": e.slivers, "colors": e.colors})
            ),
            Err(err) => println!(
                "RUST {}",
                serde_json::json!({"file": name, "error": err.to_string()})
            ),
        }
    }
}
