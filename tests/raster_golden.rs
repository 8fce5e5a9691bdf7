//! Golden-image tests: our rasteriser against resvg on the SVG our exporter writes.
//! On failure a side-by-side PNG (ours | resvg | 8x amplified difference) is written to
//! `$CARGO_TARGET_TMPDIR/golden_<name>.png`.

use vectorfusion::image::Image;
use vectorfusion::scene::{Point, Rgba, Scene, Shape, Stroke};
use vectorfusion::svg::{SvgOptions, scene_from_json, to_svg};
use vectorfusion::{raster, svg};

#[path = "common/golden.rs"]
mod golden;

use golden::{Tolerance, resvg_render};

fn compare(name: &str, ours: &Image, theirs: &Image) -> f64 {
    golden::compare(name, ours, theirs, &Tolerance::GOLDEN)
}

fn check(name: &str, scene: &Scene) -> f64 {
    scene.validate().unwrap();
    let ours = raster::render(scene);
    let text = to_svg(
        scene,
        &SvgOptions {
            precision: 4,
            ..Default::default()
        },
    );
    let theirs = resvg_render(&text);
    compare(name, &ours, &theirs)
}

fn scene64() -> Scene {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/bench/scene64.json"
    ))
    .unwrap();
    scene_from_json(&text).unwrap()
}

fn st(r: f32, g: f32, b: f32, a: f32, width: f32) -> Stroke {
    Stroke::round(Rgba::new(r, g, b, a), width)
}

fn pts(v: &[(f32, f32)]) -> Vec<Point> {
    v.iter().map(|&(x, y)| Point::new(x, y)).collect()
}

#[test]
fn golden_scene64_512_and_256() {
    let s = scene64();
    let d = check("scene64_512", &s);
    eprintln!("scene64 512: {:.3}/255", d * 255.0);
    check("scene64_256", &s.scaled_to_width(256));
}

#[test]
fn golden_strokes() {
    let mut s = Scene::new(128, 96, Rgba::new(0.9, 0.95, 1.0, 1.0)).unwrap();
    let curves = [
        ((5.0, 80.0), (30.0, 10.0), (70.0, 100.0), (120.0, 20.0), 1.0),
        ((10.0, 10.0), (60.0, 10.0), (60.0, 60.0), (110.0, 60.0), 3.5),
        ((20.0, 50.0), (120.0, 90.0), (0.0, 90.0), (100.0, 40.0), 7.0),
        ((64.0, 5.0), (64.0, 5.0), (64.0, 30.0), (64.0, 30.0), 0.6),
    ];
    for (i, (a, b, c, d, w)) in curves.iter().enumerate() {
        let col = [
            (0.0, 0.0, 0.0, 1.0),
            (0.8, 0.1, 0.1, 0.7),
            (0.1, 0.3, 0.9, 0.5),
            (0.0, 0.5, 0.0, 1.0),
        ][i];
        s.shapes.push(
            Shape::open_cubic(pts(&[*a, *b, *c, *d]), st(col.0, col.1, col.2, col.3, *w)).unwrap(),
        );
    }
    // Multi-segment open path with a sharp corner.
    s.shapes.push(
        Shape::open_cubic(
            pts(&[
                (10.0, 90.0),
                (20.0, 70.0),
                (30.0, 70.0),
                (40.0, 90.0),
                (50.0, 70.0),
                (60.0, 70.0),
                (70.0, 90.0),
            ]),
            st(0.5, 0.0, 0.5, 0.9, 2.5),
        )
        .unwrap(),
    );
    // Closed filled shape with a stroke.
    let mut c = Shape::circle(95.0, 70.0, 15.0, 4, Rgba::new(1.0, 0.8, 0.0, 0.8)).unwrap();
    c.stroke = Some(st(0.2, 0.2, 0.2, 1.0, 2.0));
    s.shapes.push(c);
    check("strokes", &s);
}

/// The share cap is what catches a lost thin stroke: without the 2 px line the mean stays well
/// inside its tolerance, but the share of very different pixels does not.
#[test]
fn a_missing_thin_stroke_fails_the_golden_check_by_its_share() {
    let mut s = Scene::new(256, 256, Rgba::WHITE).unwrap();
    s.shapes.push(
        Shape::open_cubic(
            pts(&[(40.0, 100.0), (40.0, 110.0), (40.0, 130.0), (40.0, 140.0)]),
            st(0.0, 0.0, 0.0, 1.0, 2.0),
        )
        .unwrap(),
    );
    let theirs = resvg_render(&to_svg(&s, &SvgOptions::default()));
    let t = Tolerance::GOLDEN;
    assert!(golden::share_off_by(&raster::render(&s), &theirs, t.large) <= t.max_share);
    s.shapes.clear();
    let lost = raster::render(&s);
    let mean = golden::mean_abs_diff(&lost, &theirs);
    let large = golden::share_off_by(&lost, &theirs, t.large);
    assert!(mean <= t.mean, "mean {:.3}/255", mean * 255.0);
    assert!(large > t.max_share, "share {large}");
}

#[test]
fn golden_polygons_pixel_art() {
    let mut s = Scene::new(64, 64, Rgba::WHITE).unwrap();
    for i in 0..8 {
        for j in 0..8 {
            let v = ((i * 7 + j * 3) % 8) as f32 / 8.0;
            s.shapes.push(
                Shape::square(
                    8.0 * i as f32,
                    8.0 * j as f32,
                    8.0,
                    Rgba::new(v, 1.0 - v, 0.5, 1.0),
                )
                .unwrap(),
            );
        }
    }
    s.shapes.push(
        Shape::polygon(
            pts(&[(3.3, 5.1), (60.2, 20.7), (20.4, 58.9)]),
            Rgba::new(0.0, 0.0, 0.0, 0.6),
        )
        .unwrap(),
    );
    // Sub-pixel squares at fractional positions.
    for k in 0..10 {
        let x = 5.0 + 5.3 * k as f32;
        s.shapes.push(
            Shape::square(
                x,
                40.37,
                0.4 + 0.3 * k as f32,
                Rgba::new(0.1, 0.1, 0.9, 1.0),
            )
            .unwrap(),
        );
    }
    check("polygons", &s);
}

#[test]
fn golden_overlapping_self_intersecting_off_canvas() {
    let mut s = Scene::new(100, 80, Rgba::TRANSPARENT).unwrap();
    // Pentagram: self-intersecting, nonzero fills the centre.
    let star: Vec<(f32, f32)> = (0..5)
        .map(|k| {
            let a = -std::f32::consts::FRAC_PI_2 + k as f32 * 4.0 * std::f32::consts::PI / 5.0;
            (30.0 + 25.0 * a.cos(), 40.0 + 25.0 * a.sin())
        })
        .collect();
    s.shapes
        .push(Shape::polygon(pts(&star), Rgba::new(0.9, 0.2, 0.2, 1.0)).unwrap());
    // Figure-eight cubic path.
    s.shapes.push(
        Shape::closed_cubic(
            pts(&[
                (55.0, 10.0),
                (95.0, 10.0),
                (55.0, 70.0),
                (95.0, 70.0),
                (55.0, 70.0),
                (95.0, 10.0),
            ]),
            Rgba::new(0.1, 0.6, 0.3, 0.75),
        )
        .unwrap(),
    );
    // Overlapping translucent circles, one partly off canvas.
    s.shapes
        .push(Shape::circle(20.0, 20.0, 30.0, 4, Rgba::new(0.2, 0.2, 1.0, 0.5)).unwrap());
    s.shapes
        .push(Shape::circle(95.0, 75.0, 20.0, 5, Rgba::new(1.0, 1.0, 0.0, 0.6)).unwrap());
    s.shapes
        .push(Shape::circle(-30.0, 40.0, 10.0, 4, Rgba::BLACK).unwrap());
    check("overlap", &s);
}

#[test]
fn export_then_resvg_matches_our_render_after_import() {
    // Import a third-party style SVG, render it ourselves and with resvg.
    let text = r##"<svg xmlns="http://www.w3.org/2000/svg" width="80" height="60" viewBox="0 0 80 60">
      <rect width="80" height="60" fill="#fafafa"/>
      <g transform="rotate(10 40 30)">
        <ellipse cx="30" cy="30" rx="20" ry="12" fill="#3366cc" fill-opacity="0.8"/>
        <path d="M10 50 Q 40 0 70 50" fill="none" stroke="#cc3300" stroke-width="3"
              stroke-linecap="round" stroke-linejoin="round"/>
        <polygon points="50,10 75,20 60,35" fill="green"/>
      </g>
    </svg>"##;
    let scene = svg::from_svg(text).unwrap();
    let ours = raster::render(&scene);
    let theirs = resvg_render(text);
    compare("import", &ours, &theirs);
}

#[test]
fn imported_caps_joins_dashes_and_skewed_strokes_match_resvg() {
    // What designers draw: butt and square caps, miter joins (one past its limit), bevels, a
    // dash pattern with an offset, and strokes under a skew and an unequal scale.
    let text = r##"<svg xmlns="http://www.w3.org/2000/svg" width="120" height="90" viewBox="0 0 120 90">
      <rect width="120" height="90" fill="#fff"/>
      <path d="M10 15H50" stroke="#c30" stroke-width="8.3"/>
      <path d="M10 32.3H50" stroke="#36c" stroke-width="8.3" stroke-linecap="square"/>
      <path d="M62.3 10.4l20 18.1 20-18.1" fill="none" stroke="#093" stroke-width="6.1"/>
      <path d="M62.3 40.4l20 8.1 20-8.1" fill="none" stroke="#093" stroke-width="6.1" stroke-miterlimit="1.5"/>
      <path d="M10.2 50.3h30.1v20.2z" fill="#fc6" stroke="#333" stroke-width="4.2" stroke-linejoin="bevel"/>
      <path d="M50.3 60.1h60.2" stroke="#606" stroke-width="4.1" stroke-dasharray="9 4.5 2 4" stroke-dashoffset="3.2"/>
      <g transform="translate(60 70) skewX(30) scale(1.5 1)">
        <path d="M0.3 2.2h24.1v12.2" fill="none" stroke="#c06" stroke-width="3.1"/>
      </g>
    </svg>"##;
    let scene = svg::from_svg(text).unwrap();
    let ours = raster::render(&scene);
    let theirs = resvg_render(text);
    compare("caps_joins_dashes_skew", &ours, &theirs);
    // The export keeps the caps and joins; resvg draws it as we do.
    let exported = to_svg(&scene, &SvgOptions::default());
    assert!(
        exported.contains(r#"stroke-linejoin="bevel""#),
        "{exported}"
    );
    assert!(
        exported.contains(r#"stroke-linecap="square""#),
        "{exported}"
    );
    compare("caps_joins_export", &ours, &resvg_render(&exported));
}
