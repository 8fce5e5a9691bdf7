//! `vectorize --fill linear|radial` as a user runs it: the SVG carries the gradients, resvg draws
//! it as our rasteriser does, a gradient target is traced closer than with flat fills, the same
//! seed gives the same SVG, and bad values are usage errors (exit 2).

use std::path::{Path, PathBuf};
use std::process::Command;
use vectorfusion::raster;
use vectorfusion::scene::{Rgba, Scene, Shape};
use vectorfusion::vector::fill::FillKind;

fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vf-live-fill-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A 48 px icon of two shapes painted with linear gradients (dark to light).
fn write_gradient_icon(path: &Path) -> vectorfusion::image::Image {
    let mut s = Scene::new(48, 48, Rgba::WHITE).unwrap();
    s.shapes
        .push(Shape::circle(20.0, 20.0, 14.0, 4, Rgba::new(0.9, 0.2, 0.1, 1.0)).unwrap());
    s.shapes
        .push(Shape::square(24.0, 24.0, 20.0, Rgba::new(0.1, 0.3, 0.9, 1.0)).unwrap());
    FillKind::Linear.paint_new(&mut s);
    for sh in &mut s.shapes {
        let g = sh.gradients.as_mut().unwrap().fill.as_mut().unwrap();
        g.stops[1].color = Rgba::new(1.0, 0.95, 0.6, 1.0);
    }
    let img = raster::render(&s);
    img.save_png(path).unwrap();
    img
}

fn vectorize(input: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
        .args(["vectorize", input.to_str().unwrap(), "-o"])
        .arg(out)
        .args(["--schedule", "2,2", "--iters", "40", "--size", "48", "-q"])
        .args(["--seed", "3"])
        .args(extra)
        .output()
        .unwrap()
}

fn traced(input: &Path, out: &Path, extra: &[&str]) -> String {
    let o = vectorize(input, out, extra);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::read_to_string(out).unwrap()
}

#[test]
fn gradient_fills_are_written_and_render_as_resvg_does() {
    let d = tmpdir("e2e");
    let input = d.join("in.png");
    let target = write_gradient_icon(&input);
    let flat = traced(&input, &d.join("flat.svg"), &[]);
    assert!(!flat.contains("Gradient"));
    let linear = traced(&input, &d.join("linear.svg"), &["--fill", "linear"]);
    assert!(linear.contains("<linearGradient"), "{linear}");
    assert!(linear.contains("fill=\"url(#g"), "{linear}");
    vectorfusion::svg::check_safe_output(&linear).unwrap();
    // resvg and our rasteriser agree on the written SVG.
    let ours = raster::render(&vectorfusion::svg::from_svg(&linear).unwrap());
    let theirs = vectorfusion::stages::live::tracer::render_svg(&linear, 48, 48).unwrap();
    let agree = vectorfusion::image::psnr(&ours, &theirs);
    assert!(agree > 35.0, "ours vs resvg: {agree:.1} dB");
    // On a target drawn with gradients, gradients trace it closer than flat fills.
    let score = |svg: &str| {
        let back = vectorfusion::stages::live::tracer::render_svg(svg, 48, 48).unwrap();
        vectorfusion::image::psnr(&back, &target)
    };
    let (pf, pl) = (score(&flat), score(&linear));
    assert!(pl > pf, "linear {pl:.2} dB vs flat {pf:.2} dB");
    let radial = traced(&input, &d.join("radial.svg"), &["--fill", "radial"]);
    assert!(radial.contains("<radialGradient"), "{radial}");
}

#[test]
fn the_same_seed_gives_the_same_gradient_svg() {
    let d = tmpdir("seed");
    let input = d.join("in.png");
    write_gradient_icon(&input);
    let a = traced(&input, &d.join("a.svg"), &["--fill", "radial"]);
    let b = traced(&input, &d.join("b.svg"), &["--fill", "radial"]);
    assert_eq!(a, b);
}

#[test]
fn bad_fill_values_are_usage_errors() {
    let d = tmpdir("bad");
    let input = d.join("in.png");
    write_gradient_icon(&input);
    let out = d.join("x.svg");
    let o = vectorize(&input, &out, &["--fill", "conic"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--fill"));
    let o = vectorize(&input, &out, &["--fill", "linear", "--colors", "4"]);
    assert_eq!(o.status.code(), Some(2));
    let msg = String::from_utf8_lossy(&o.stderr);
    assert!(msg.contains("--fill") && msg.contains("palette"), "{msg}");
    assert!(!out.exists());
}
