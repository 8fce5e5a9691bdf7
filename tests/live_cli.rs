//! The `vectorize` and `bench vectorize` commands as a user runs them.

use std::path::PathBuf;
use std::process::Command;
use vectorfusion::raster;
use vectorfusion::scene::{Rgba, Scene, Shape};

fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vf-live-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn write_icon(path: &std::path::Path) {
    let mut s = Scene::new(48, 48, Rgba::WHITE).unwrap();
    s.shapes
        .push(Shape::circle(20.0, 20.0, 12.0, 4, Rgba::new(0.9, 0.2, 0.1, 1.0)).unwrap());
    s.shapes
        .push(Shape::square(26.0, 26.0, 16.0, Rgba::new(0.1, 0.3, 0.9, 1.0)).unwrap());
    raster::render(&s).save_png(path).unwrap();
}

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
}

#[test]
fn vectorize_writes_svg_and_preview() {
    let d = tmpdir("vec");
    let input = d.join("in.png");
    write_icon(&input);
    let out = bin()
        .args(["vectorize", input.to_str().unwrap(), "-o"])
        .arg(d.join("out.svg"))
        .args(["--schedule", "2,2", "--iters", "30", "--size", "48", "-q"])
        .arg("--preview")
        .arg(d.join("prev.png"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let svg = std::fs::read_to_string(d.join("out.svg")).unwrap();
    assert!(svg.contains("<path"));
    vectorfusion::svg::check_safe_output(&svg).unwrap();
    let scene = vectorfusion::svg::from_svg(&svg).unwrap();
    assert!(!scene.shapes.is_empty() && scene.shapes.len() <= 4);
    assert!(d.join("prev.png").exists());
    let msg = String::from_utf8_lossy(&out.stderr);
    assert!(msg.contains("PSNR"), "{msg}");
}

#[test]
fn vectorize_writes_pdf_and_png_by_extension() {
    let d = tmpdir("vec-formats");
    let input = d.join("in.png");
    write_icon(&input);
    for (name, magic) in [("out.pdf", &b"%PDF-1.4"[..]), ("out.png", &b"\x89PNG"[..])] {
        let out = bin()
            .args(["vectorize", input.to_str().unwrap(), "-o"])
            .arg(d.join(name))
            .args(["--schedule", "2", "--iters", "10", "--size", "32", "-q"])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let bytes = std::fs::read(d.join(name)).unwrap();
        assert!(bytes.starts_with(magic), "{name}");
    }
}

#[test]
fn vectorize_reports_clear_errors() {
    let d = tmpdir("err");
    let junk = d.join("junk.png");
    std::fs::write(&junk, b"definitely not a png").unwrap();
    let out = bin()
        .args(["vectorize", junk.to_str().unwrap(), "-o", "/dev/null"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("not a readable"));

    let missing = bin()
        .args(["vectorize", "/nonexistent/x.png", "-o", "/dev/null"])
        .output()
        .unwrap();
    assert_eq!(missing.status.code(), Some(2));

    let input = d.join("in.png");
    write_icon(&input);
    let bad_paths = bin()
        .args([
            "vectorize",
            input.to_str().unwrap(),
            "-o",
            "/dev/null",
            "--paths",
            "many",
        ])
        .output()
        .unwrap();
    assert_eq!(bad_paths.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad_paths.stderr).contains("--paths"));

    // Huge images are refused before decoding.
    let huge = d.join("huge.png");
    image::RgbaImage::new(5000, 8).save(&huge).unwrap();
    let out = bin()
        .args(["vectorize", huge.to_str().unwrap(), "-o", "/dev/null"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("larger than"));
}

#[test]
fn bench_vectorize_prints_json_rows() {
    let d = tmpdir("bench");
    write_icon(&d.join("a.png"));
    let out = bin()
        .args(["bench", "vectorize", "--images"])
        .arg(&d)
        .args(["--paths", "4", "--json"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["images"], 1);
    let rows = v["rows"].as_array().unwrap();
    let methods: Vec<&str> = rows.iter().map(|r| r["method"].as_str().unwrap()).collect();
    for m in [
        "vtracer-default",
        "vtracer-polygon",
        "vtracer-tuned",
        "live",
    ] {
        assert!(methods.contains(&m), "{methods:?}");
    }
    for r in rows {
        assert!(r["psnr_mean"].as_f64().unwrap() > 15.0, "{r}");
        assert!(r["svg_bytes_mean"].as_f64().unwrap() > 50.0);
        assert!(r["seconds_mean"].as_f64().unwrap() >= 0.0);
        assert!(r["paths"].as_u64().is_some());
    }
    let live = rows.iter().find(|r| r["method"] == "live").unwrap();
    assert_eq!(live["paths"], 4);
}

/// `--init pixels` copies a sprite exactly, one outline per region of a colour; an image too
/// large for a square per pixel, or a byte target, is refused (exit 2).
#[test]
fn vectorize_init_pixels_copies_pixel_art() {
    let d = tmpdir("pixels");
    let input = d.join("sprite.png");
    let mut sprite = image::RgbaImage::new(16, 12);
    for (x, y, p) in sprite.enumerate_pixels_mut() {
        *p = match (x, y) {
            (0, _) | (_, 0) => image::Rgba([0, 0, 0, 0]),
            (4..=7, 3..=6) => image::Rgba([30, 90, 220, 255]),
            _ => image::Rgba([240, 150, 40, 255]),
        };
    }
    sprite.save(&input).unwrap();
    let svg = d.join("sprite.svg");
    let args = [
        "vectorize",
        input.to_str().unwrap(),
        "--init",
        "pixels",
        "-q",
        "-o",
    ];
    let out = bin().args(args).arg(&svg).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let text = std::fs::read_to_string(&svg).unwrap();
    assert_eq!(text.matches("<path").count(), 2, "{text}");
    let back = vectorfusion::svg::from_svg(&text).unwrap();
    let drawn = raster::render(&back);
    let want = vectorfusion::image::Image::decode(&std::fs::read(&input).unwrap()).unwrap();
    let (_, worst) = vectorfusion::vector::export::diff(&drawn, &want);
    assert!(worst < 1e-3, "{worst}");

    let big = d.join("big.png");
    image::RgbaImage::new(300, 8).save(&big).unwrap();
    for (img, extra) in [(&big, None), (&input, Some("--max-bytes"))] {
        let mut cmd = bin();
        cmd.args(["vectorize", img.to_str().unwrap(), "--init", "pixels", "-q"]);
        if let Some(flag) = extra {
            cmd.args([flag, "2000"]);
        }
        let out = cmd.args(["-o", "/dev/null"]).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains("init pixels"), "{err}");
    }
}
