//! The `render` and `bench raster` commands, run as the real binary.

use std::process::Command;

const SCENE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/bench/scene64.json");

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
}

#[test]
fn render_writes_png_of_requested_size() {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let svg = dir.join("cli_in.svg");
    std::fs::write(
        &svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="20"><circle cx="10" cy="10" r="8" fill="red"/></svg>"#,
    )
    .unwrap();
    let out = dir.join("cli_out.png");
    let st = bin()
        .args([
            "render",
            svg.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--size",
            "80",
        ])
        .status()
        .unwrap();
    assert!(st.success());
    let img = vectorfusion::image::Image::open(&out).unwrap();
    assert_eq!((img.width, img.height), (80, 40));
    let c = img.pixel(20, 20);
    assert!(c[0] > 0.99 && c[1] < 0.01 && c[3] > 0.99, "{c:?}");
    assert_eq!(img.pixel(70, 20)[3], 0.0);

    // Bad input: clear error and a non-zero exit code, no panic.
    std::fs::write(&svg, "<svg").unwrap();
    let o = bin()
        .args(["render", svg.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "bad input exits 2 (README)");
    assert!(String::from_utf8_lossy(&o.stderr).contains("cannot parse SVG"));

    // An old Illustrator file in ISO-8859-1 is read by its declaration; bytes that are not
    // UTF-8 without one are bad input (2), named.
    let mut latin = b"<?xml version=\"1.0\" encoding=\"iso-8859-1\"?><svg xmlns=\"http://www.w3.org/2000/svg\" width=\"8\" height=\"8\"><title>caf".to_vec();
    latin.extend_from_slice(&[0xE9]);
    latin.extend_from_slice(b"</title><rect width=\"8\" height=\"8\" fill=\"red\"/></svg>");
    std::fs::write(&svg, &latin).unwrap();
    let o = bin()
        .args(["render", svg.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::write(
        &svg,
        &latin[latin.iter().position(|b| *b == b'>').unwrap() + 1..],
    )
    .unwrap();
    let o = bin()
        .args(["render", svg.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("not valid UTF-8"));

    // A missing input file is bad input too (2), with a message naming it.
    let missing = dir.join("missing.svg");
    let o = bin()
        .args([
            "render",
            missing.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "a missing input exits 2");
    assert!(String::from_utf8_lossy(&o.stderr).contains("missing.svg"));

    // Hostile input is refused at once, without growing: a circle of radius 1e38, an entity
    // bomb, and /dev/zero (read with a size cap, never to the end).
    let hostile = [
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64"><circle cx="1e38" cy="-1e38" r="1e38"/></svg>"#.to_string(),
        format!(
            r#"<!DOCTYPE svg [<!ENTITY a "{}">]><svg xmlns="http://www.w3.org/2000/svg" width="8" height="8"><text>{}</text></svg>"#,
            "x".repeat(100_000),
            "&a;".repeat(19_000)
        ),
    ];
    for text in &hostile {
        std::fs::write(&svg, text).unwrap();
        let o = bin()
            .args(["render", svg.to_str().unwrap(), "-o", out.to_str().unwrap()])
            .output()
            .unwrap();
        assert_eq!(
            o.status.code(),
            Some(2),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    if std::path::Path::new("/dev/zero").exists() {
        let o = bin()
            .args(["render", "/dev/zero", "-o", out.to_str().unwrap()])
            .output()
            .unwrap();
        assert_eq!(
            o.status.code(),
            Some(2),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(String::from_utf8_lossy(&o.stderr).contains("larger than"));
    }
}

#[test]
fn bench_raster_prints_json_with_the_documented_keys() {
    let o = bin()
        .args([
            "bench", "raster", "--scene", SCENE, "--size", "64", "--iters", "2", "--json",
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["size"], 64);
    for k in [
        "forward_ms",
        "supersampled_forward_ms",
        "forward_backward_ms",
        "tiny_skia_forward_ms",
        "loss",
    ] {
        let x = v[k].as_f64().unwrap_or(-1.0);
        assert!(x > 0.0 && x.is_finite(), "{k} = {x}");
    }
    let o = bin()
        .args(["bench", "raster", "--scene", SCENE, "--size", "0"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn render_names_what_the_import_could_not_draw() {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let svg = dir.join("cli_filter.svg");
    std::fs::write(
        &svg,
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="20" height="20"><filter id="f"><feGaussianBlur stdDeviation="2"/></filter><g id="soft" filter="url(#f)"><rect width="9" height="9"/></g><g id="a"><use href="#a"/></g></svg>"##,
    )
    .unwrap();
    let out = dir.join("cli_filter.png");
    let o = bin()
        .args(["render", svg.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("warning: filter on #soft ignored"), "{err}");
    assert!(err.contains("(a reference cycle)"), "{err}");
    // The content is drawn, unfiltered.
    let img = vectorfusion::image::Image::open(&out).unwrap();
    assert!(img.pixel(4, 4)[3] > 0.99);
}

#[test]
fn render_writes_a_vector_pdf_by_extension() {
    let dir = tempfile::tempdir().unwrap();
    let svg = dir.path().join("in.svg");
    std::fs::write(
        &svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="20"><clipPath id="c"><rect width="20" height="20"/></clipPath><circle clip-path="url(#c)" cx="20" cy="10" r="8" fill="red"/></svg>"#,
    )
    .unwrap();
    let pdf = dir.path().join("out.PDF");
    let o = bin()
        .args(["render", svg.to_str().unwrap(), "-o", pdf.to_str().unwrap()])
        .args(["--size", "80"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&std::fs::read(&pdf).unwrap()).into_owned();
    assert!(text.starts_with("%PDF-1.4"), "{text}");
    // 80 px wide at 0.75 pt a pixel; the clip is a clipping path.
    assert!(text.contains("/MediaBox [0 0 60 30]"), "{text}");
    assert!(text.contains("W n\n"), "{text}");
    // Another extension is refused as bad input, naming the flag; nothing is written.
    let jpg = dir.path().join("out.jpg");
    let o = bin()
        .args(["render", svg.to_str().unwrap(), "-o", jpg.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--output: render writes .png or .pdf"));
    assert!(!jpg.exists());
}

#[test]
fn render_antialias_supersampled_counts_samples() {
    // A rectangle whose left edge is at x = 1.3: exact coverage 0.7 in column 1; 16 samples a
    // pixel (at quarter-pixel centres) put three of four columns of samples inside: 0.75.
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let svg = dir.join("cli_aa.svg");
    std::fs::write(
        &svg,
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="8" height="8"><rect x="1.3" y="0" width="5" height="8" fill="#000"/></svg>"##,
    )
    .unwrap();
    let alpha = |aa: &str| {
        let out = dir.join(format!("cli_aa_{aa}.png"));
        let o = bin()
            .args(["render", svg.to_str().unwrap(), "-o", out.to_str().unwrap()])
            .args(["--antialias", aa])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        vectorfusion::image::Image::open(&out).unwrap().pixel(1, 4)[3]
    };
    assert!((alpha("exact") - 0.7).abs() < 0.003);
    assert!((alpha("supersampled") - 0.75).abs() < 0.003);
    let o = bin()
        .args([
            "render",
            svg.to_str().unwrap(),
            "-o",
            "x.png",
            "--antialias",
            "fine",
        ])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--antialias"));
}
