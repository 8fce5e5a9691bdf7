//! Texture paints: `<image>` (data URLs, files) and `<pattern>` imported and drawn by our
//! rasteriser against resvg's render of the same text (the suite's tolerance), the image
//! limits of the guard, and export → import round trips.

#[path = "common/golden.rs"]
mod golden;

use base64::Engine;
use golden::{Tolerance, compare, mean_abs_diff, resvg_render};
use vectorfusion::raster;
use vectorfusion::svg::{
    ImageLimits, SvgOptions, check_safe_output, from_svg, import_svg, import_svg_in, to_svg,
};

/// A smooth `w × h` RGBA picture (bilinear and resvg's bicubic filter agree on it), encoded.
fn picture(w: u32, h: u32, format: image::ImageFormat) -> Vec<u8> {
    let img = image::RgbaImage::from_fn(w, h, |x, y| {
        let a = if format == image::ImageFormat::Png {
            255 - (x * 60 / w) as u8
        } else {
            255
        };
        image::Rgba([(x * 255 / w) as u8, (y * 255 / h) as u8, 160, a])
    });
    let mut out = std::io::Cursor::new(Vec::new());
    if format == image::ImageFormat::Jpeg {
        image::DynamicImage::ImageRgba8(img)
            .into_rgb8()
            .write_to(&mut out, format)
            .unwrap();
    } else {
        img.write_to(&mut out, format).unwrap();
    }
    out.into_inner()
}

/// Our import and rasteriser draw `text` as resvg does (the suite's tolerance).
fn drawn_as_resvg(name: &str, scene: &vectorfusion::scene::Scene, text: &str) {
    compare(
        name,
        &raster::render(scene),
        &resvg_render(text),
        &Tolerance::SUITE,
    );
}

fn data_url(mime: &str, bytes: &[u8]) -> String {
    let b64 = base64::engine::general_purpose::STANDARD.encode(bytes);
    format!("data:{mime};base64,{b64}")
}

fn doc(body: &str) -> String {
    format!(
        r##"<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" width="120" height="90"><rect width="120" height="90" fill="#fff"/>{body}</svg>"##
    )
}

#[test]
fn images_render_as_resvg() {
    let png = data_url("image/png", &picture(24, 16, image::ImageFormat::Png));
    let jpeg = data_url("image/jpeg", &picture(20, 20, image::ImageFormat::Jpeg));
    // The MIME type is wrong: the bytes are sniffed.
    let sniffed = data_url("text/plain", &picture(24, 16, image::ImageFormat::Png));
    let cases = [
        (
            // Whole-pixel edges: resvg fills an image rectangle without anti-aliasing.
            "meet",
            format!(r#"<image x="10" y="5" width="96" height="80" href="{png}"/>"#),
        ),
        (
            "slice_transform_opacity",
            format!(
                r#"<g opacity=".6"><image x="10" y="5" width="60" height="70" preserveAspectRatio="xMaxYMin slice" transform="rotate(12 40 40)" xlink:href="{png}"/></g>"#
            ),
        ),
        (
            "none_jpeg_clipped",
            format!(
                r#"<clipPath id="c"><circle cx="60" cy="45" r="38"/></clipPath><image clip-path="url(#c)" width="120" height="90" preserveAspectRatio="none" href="{jpeg}"/>"#
            ),
        ),
        (
            "auto_size_sniffed_under_a_path",
            format!(
                r##"<image x="30" y="20" href="{sniffed}"/><path d="M5 80 L60 10 L115 80" stroke="#c22" stroke-width="6" fill="none"/>"##
            ),
        ),
    ];
    for (name, body) in cases {
        let text = doc(&body);
        let import = import_svg(&text).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(import.warnings.is_empty(), "{name}: {:?}", import.warnings);
        drawn_as_resvg(name, &import.scene, &text);
    }
}

/// A `n × n` checkerboard of hard-edged red and translucent blue texels, encoded as a PNG: every
/// filter draws it differently when it is magnified.
fn checkerboard(n: u32) -> Vec<u8> {
    let img = image::RgbaImage::from_fn(n, n, |x, y| {
        if (x + y) % 2 == 0 {
            image::Rgba([220, 30, 30, 255])
        } else {
            image::Rgba([20, 60, 200, 150])
        }
    });
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

#[test]
fn each_image_rendering_filters_as_resvg() {
    // A magnified, rotated checkerboard: bicubic (the default `optimizeQuality` and
    // `high-quality`), bilinear (`smooth`) and nearest (`optimizeSpeed`, `pixelated`) each match
    // resvg closely, and each is far from what the other filters draw.
    use vectorfusion::scene::TextureFilter;
    let png = data_url("image/png", &checkerboard(6));
    let tight = Tolerance {
        mean: 0.25 / 255.0,
        large: 16.0 / 255.0,
        max_share: 0.002,
    };
    for (rendering, want) in [
        ("", TextureFilter::Bicubic),
        ("high-quality", TextureFilter::Bicubic),
        ("smooth", TextureFilter::Bilinear),
        ("optimizeSpeed", TextureFilter::Nearest),
        ("pixelated", TextureFilter::Nearest),
    ] {
        let attr = if rendering.is_empty() {
            String::new()
        } else {
            // CSS's values (`smooth`, `high-quality`, `pixelated`) count only in a style.
            format!(r#" style="image-rendering:{rendering}""#)
        };
        let text = doc(&format!(
            r#"<image x="22" y="8" width="74" height="74" transform="rotate(9 60 45)"{attr} href="{png}"/>"#
        ));
        let import = import_svg(&text).unwrap();
        assert!(
            import.warnings.is_empty(),
            "{rendering}: {:?}",
            import.warnings
        );
        let theirs = resvg_render(&text);
        let name = format!(
            "image_rendering_{}",
            if rendering.is_empty() {
                "default"
            } else {
                rendering
            }
        );
        let d = compare(&name, &raster::render(&import.scene), &theirs, &tight);
        let texture = |s: &mut vectorfusion::scene::Scene| {
            let t = s
                .shapes
                .iter_mut()
                .find_map(|s| s.gradients.as_mut()?.texture.as_mut());
            t.expect("the image is a textured shape").filter
        };
        let mut other = import.scene.clone();
        assert_eq!(texture(&mut other), want, "{rendering}");
        for f in [
            TextureFilter::Nearest,
            TextureFilter::Bilinear,
            TextureFilter::Bicubic,
        ] {
            if f == want {
                continue;
            }
            for s in &mut other.shapes {
                if let Some(t) = s.gradients.as_mut().and_then(|g| g.texture.as_mut()) {
                    t.filter = f;
                }
            }
            let wrong = mean_abs_diff(&raster::render(&other), &theirs);
            assert!(
                wrong > 3.0 * d.max(0.05 / 255.0),
                "{rendering} drawn {f:?}: {wrong} vs {d}"
            );
        }
    }
}

const PATTERNS: &[(&str, &str)] = &[
    (
        "user_space_transform",
        r##"<pattern id="p" patternUnits="userSpaceOnUse" width="20" height="16" patternTransform="rotate(20) translate(3 2)">
          <rect width="10" height="8" fill="#2a6"/><circle cx="14" cy="11" r="4" fill="#c33"/></pattern>
        <rect x="5" y="5" width="110" height="80" fill="url(#p)"/>"##,
    ),
    (
        "bbox_units_view_box_href",
        r##"<pattern id="base" width=".25" height=".5" viewBox="0 0 10 10" preserveAspectRatio="xMidYMid meet">
          <circle cx="5" cy="5" r="4" fill="#36c"/></pattern>
        <pattern id="p" href="#base" x=".1"/>
        <ellipse cx="60" cy="45" rx="50" ry="38" fill="url(#p)" opacity=".8"/>"##,
    ),
    (
        "nested_pattern",
        r##"<pattern id="dots" patternUnits="userSpaceOnUse" width="6" height="6">
          <circle cx="3" cy="3" r="2" fill="#000"/></pattern>
        <pattern id="p" patternUnits="userSpaceOnUse" width="40" height="30">
          <rect width="30" height="20" fill="url(#dots)"/></pattern>
        <rect width="120" height="90" fill="url(#p)"/>"##,
    ),
];

#[test]
fn patterns_render_as_resvg() {
    for (name, body) in PATTERNS {
        let text = doc(body);
        let scene = from_svg(&text).unwrap_or_else(|e| panic!("{name}: {e}"));
        let tex = scene.shapes.iter().filter_map(|s| s.gradients.as_deref());
        assert!(tex.filter(|g| g.texture.is_some()).count() >= 1, "{name}");
        drawn_as_resvg(name, &scene, &text);
    }
}

#[test]
fn the_png_of_a_written_svg_draws_its_textures() {
    // `result.png` and `-o out.png` render the written SVG with resvg: its embedded PNGs are
    // decoded (within the image limits), so the picture shows the image, as our render does.
    let png = data_url("image/png", &picture(24, 16, image::ImageFormat::Png));
    let scene = from_svg(&doc(&format!(
        r#"<image x="10" y="5" width="96" height="80" href="{png}"/>"#
    )))
    .unwrap();
    let out = to_svg(&scene, &SvgOptions::default());
    let bytes = vectorfusion::svg::render_png(&out, 512.0).unwrap();
    let rgba = image::load_from_memory(&bytes).unwrap().into_rgba8();
    assert_eq!(rgba.dimensions(), (120, 90));
    let theirs = vectorfusion::image::Image {
        width: 120,
        height: 90,
        data: rgba
            .pixels()
            .flat_map(|p| {
                let a = f32::from(p[3]) / 255.0;
                [0, 1, 2]
                    .map(|c| f32::from(p[c]) / 255.0 * a)
                    .into_iter()
                    .chain([a])
            })
            .collect(),
    };
    compare(
        "result_png",
        &raster::render(&scene),
        &theirs,
        &Tolerance::SUITE,
    );
}

/// A written texture whose image has `style="STYLE"`.
fn out_with_style(style: &str) -> String {
    format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="4" height="4" viewBox="0 0 4 4"><defs><pattern id="g1" width="1" height="1"><image width="1" height="1" style="{style}" href="data:image/png;base64,AAAA"/></pattern></defs><path d="M0 0H4V4Z" fill="url(#g1)"/></svg>"#
    )
}

#[test]
fn textures_export_and_import_again_as_drawn() {
    let png = data_url("image/png", &picture(24, 16, image::ImageFormat::Png));
    let image = format!(
        r#"<image x="10" y="5" width="96" height="80" image-rendering="pixelated" href="{png}"/>"#
    );
    for (name, body) in [("image", image.as_str()), PATTERNS[0]] {
        let a = from_svg(&doc(body)).unwrap();
        let out = to_svg(&a, &SvgOptions::default());
        assert!(
            out.contains("<pattern") && out.contains("data:image/png;base64,"),
            "{name}"
        );
        let b = from_svg(&out).unwrap_or_else(|e| panic!("{name}: {e}\n{out}"));
        let (ia, ib) = (raster::render(&a), raster::render(&b));
        compare(name, &ib, &ia, &Tolerance::SUITE);
        // resvg draws the export as we draw the scene.
        compare(name, &ia, &resvg_render(&out), &Tolerance::SUITE);
    }
    // Each filter is written so that it draws as itself, within the safe-output profile.
    use vectorfusion::scene::TextureFilter;
    let mut scene = from_svg(&doc(&image)).unwrap();
    for f in [
        TextureFilter::Nearest,
        TextureFilter::Bilinear,
        TextureFilter::Bicubic,
    ] {
        for s in &mut scene.shapes {
            if let Some(t) = s.gradients.as_mut().and_then(|g| g.texture.as_mut()) {
                t.filter = f;
            }
        }
        let out = to_svg(&scene, &SvgOptions::default());
        check_safe_output(&out).unwrap_or_else(|e| panic!("{f:?}: {e}"));
        let back = from_svg(&out).unwrap();
        let name = format!("export_{f:?}");
        compare(
            &name,
            &raster::render(&back),
            &raster::render(&scene),
            &Tolerance::SUITE,
        );
        compare(
            &name,
            &raster::render(&scene),
            &resvg_render(&out),
            &Tolerance::SUITE,
        );
    }
    let styled = out_with_style("fill:red");
    assert!(
        check_safe_output(&styled).is_err(),
        "another style is refused"
    );
    // The safe-output profile takes an embedded PNG only.
    for href in [
        "https://example.com/a.png",
        "data:image/svg+xml;base64,PHN2Zy8+",
        "a.png",
    ] {
        let bad = format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="4" height="4" viewBox="0 0 4 4"><defs><pattern id="g1" width="1" height="1"><image width="1" height="1" href="{href}"/></pattern></defs><path d="M0 0H4V4Z" fill="url(#g1)"/></svg>"#
        );
        assert!(check_safe_output(&bad).is_err(), "{href}");
    }
}

fn png_doc(bytes: &[u8]) -> String {
    doc(&format!(
        r#"<image id="i" width="50" height="50" href="{}"/>"#,
        data_url("image/png", bytes)
    ))
}

#[test]
fn image_limits_drop_the_image_with_a_warning() {
    let small = picture(8, 8, image::ImageFormat::Png);
    let tight = |f: fn(&mut ImageLimits)| {
        let mut l = ImageLimits::DEFAULT;
        f(&mut l);
        l
    };
    let drawn = |text: &str, limits: ImageLimits| {
        let i = import_svg_in(text, None, limits).unwrap();
        let textured = i
            .scene
            .shapes
            .iter()
            .any(|s| s.gradients.as_deref().is_some_and(|g| g.texture.is_some()));
        (textured, i.warnings)
    };
    assert!(drawn(&png_doc(&small), ImageLimits::DEFAULT).0);
    // Pixels of one image.
    let (ok, w) = drawn(&png_doc(&small), tight(|l| l.max_pixels = 63));
    assert!(
        !ok && w.iter().any(|w| w.contains("over the limit")),
        "{w:?}"
    );
    // Pixels over the whole import: two images of 64 pixels, 100 allowed.
    let two = doc(&format!(
        r#"<image width="5" height="5" href="{0}"/><image x="9" width="5" height="5" href="{0}"/>"#,
        data_url("image/png", &small)
    ));
    let i = import_svg_in(&two, None, tight(|l| l.max_total_pixels = 100)).unwrap();
    assert_eq!(i.scene.shapes.len(), 1, "{:?}", i.warnings);
    // A decompression bomb: 4000 × 4000 of one colour is a few kB of PNG; the allocation
    // limit refuses it while decoding, within the pixel limits.
    let bomb = image::RgbaImage::new(4000, 4000);
    let mut bytes = std::io::Cursor::new(Vec::new());
    bomb.write_to(&mut bytes, image::ImageFormat::Png).unwrap();
    assert!(bytes.get_ref().len() < 2_000_000);
    let (ok, w) = drawn(&png_doc(bytes.get_ref()), tight(|l| l.max_alloc = 1 << 20));
    assert!(
        !ok && w.iter().any(|w| w.contains("cannot decode")),
        "{w:?}"
    );
    // Garbage behind a PNG type, and a truncated PNG: dropped, never a panic.
    let (ok, w) = drawn(&png_doc(b"not a picture at all"), ImageLimits::DEFAULT);
    assert!(!ok && !w.is_empty());
    let (ok, _) = drawn(&png_doc(&small[..small.len() / 2]), ImageLimits::DEFAULT);
    assert!(!ok);
}

#[test]
fn svg_images_nest_within_the_depth_limit() {
    let inner = r##"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10"><rect x="2" y="1" width="6" height="5" fill="#c33"/></svg>"##;
    let one = doc(&format!(
        r#"<image width="40" height="40" href="{}"/>"#,
        data_url("image/svg+xml", inner.as_bytes())
    ));
    let s = from_svg(&one).unwrap();
    // Drawn as its content, clipped to its viewport.
    assert_eq!(s.shapes.len(), 1);
    assert!(s.groups.iter().any(|g| g.clip.is_some()));
    drawn_as_resvg("svg_image", &s, &one);
    let limits = ImageLimits {
        max_svg_depth: 0,
        ..ImageLimits::DEFAULT
    };
    let i = import_svg_in(&one, None, limits).unwrap();
    assert!(i.scene.shapes.is_empty() && i.warnings.iter().any(|w| w.contains("nest")));
}

#[test]
fn external_images_are_read_only_beside_a_named_file() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("pic.png"),
        picture(8, 8, image::ImageFormat::Png),
    )
    .unwrap();
    let text = doc(r#"<image width="40" height="40" href="pic.png"/>"#);
    let i = import_svg(&text).unwrap();
    assert!(i.scene.shapes.is_empty());
    assert!(
        i.warnings
            .iter()
            .any(|w| w.contains("pic.png") && w.contains("dropped")),
        "{:?}",
        i.warnings
    );
    let i = import_svg_in(&text, Some(dir.path()), ImageLimits::DEFAULT).unwrap();
    assert_eq!(i.scene.shapes.len(), 1, "{:?}", i.warnings);
    // Through the file loader the command line uses.
    let path = dir.path().join("a.svg");
    std::fs::write(&path, &text).unwrap();
    assert_eq!(
        vectorfusion::svg::load_import(&path)
            .unwrap()
            .scene
            .shapes
            .len(),
        1
    );
}

/// As usvg: an SVG image reads no files, so an SVG file drawing itself is drawn once (its own
/// `href` dropped), and a picture beside it is not read from inside a `data:` SVG image.
#[test]
fn an_svg_image_reads_no_files() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("pic.png"),
        picture(8, 8, image::ImageFormat::Png),
    )
    .unwrap();
    let selfish = doc(
        r##"<rect width="4" height="4" fill="#123"/><image x="8" y="8" width="20" height="20" href="self.svg"/>"##,
    );
    std::fs::write(dir.path().join("self.svg"), &selfish).unwrap();
    let i = import_svg_in(&selfish, Some(dir.path()), ImageLimits::DEFAULT).unwrap();
    // Drawn as the same document whose image holds the picture without its image.
    let once = doc(&format!(
        r##"<rect width="4" height="4" fill="#123"/><image x="8" y="8" width="20" height="20" href="{}"/>"##,
        data_url(
            "image/svg+xml",
            doc(r##"<rect width="4" height="4" fill="#123"/>"##).as_bytes()
        )
    ));
    let expected = import_svg_in(&once, None, ImageLimits::DEFAULT).unwrap();
    assert_eq!(i.scene, expected.scene, "{:?}", i.warnings);
    assert!(
        i.warnings
            .iter()
            .any(|w| w.contains("self.svg") && w.contains("inside an SVG image")),
        "{:?}",
        i.warnings
    );
    let inner = doc(r#"<image width="40" height="40" href="pic.png"/>"#);
    let outer = doc(&format!(
        r#"<image width="40" height="40" href="{}"/>"#,
        data_url("image/svg+xml", inner.as_bytes())
    ));
    let i = import_svg_in(&outer, Some(dir.path()), ImageLimits::DEFAULT).unwrap();
    let empty = doc(&format!(
        r#"<image width="40" height="40" href="{}"/>"#,
        data_url("image/svg+xml", doc("").as_bytes())
    ));
    let expected = import_svg_in(&empty, None, ImageLimits::DEFAULT).unwrap();
    assert_eq!(i.scene, expected.scene, "{:?}", i.warnings);
    // The same picture at the top level is read.
    let top = import_svg_in(&inner, Some(dir.path()), ImageLimits::DEFAULT).unwrap();
    let without = import_svg_in(&doc(""), None, ImageLimits::DEFAULT).unwrap();
    assert_eq!(top.scene.shapes.len(), without.scene.shapes.len() + 1);
}

/// `render --size` draws pattern tiles at the output's resolution, a pattern nested in a tile
/// once (not twice): at 2× the nested pattern still matches resvg's render at 2×.
#[test]
fn nested_patterns_render_as_resvg_when_scaled() {
    let body = PATTERNS
        .iter()
        .find(|(n, _)| *n == "nested_pattern")
        .map(|(_, b)| *b)
        .unwrap();
    let text = doc(body);
    let dir = std::env::temp_dir().join(format!("vf-nested-pattern-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (svg, png) = (dir.join("nested.svg"), dir.join("nested.png"));
    std::fs::write(&svg, &text).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
        .args(["render", svg.to_str().unwrap(), "-o", png.to_str().unwrap()])
        .args(["--size", "240"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let ours = vectorfusion::image::Image::open(&png).unwrap();
    // The same picture at 2× for resvg: twice the size, the same viewBox (opaque, so straight
    // and premultiplied colours agree).
    let twice = text.replacen(
        r#"width="120" height="90">"#,
        r#"width="240" height="180" viewBox="0 0 120 90">"#,
        1,
    );
    assert_ne!(twice, text);
    compare(
        "nested_pattern_2x",
        &ours,
        &resvg_render(&twice),
        &Tolerance::SUITE,
    );
    let _ = std::fs::remove_dir_all(&dir);
}
