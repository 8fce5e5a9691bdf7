//! `<text>` drawn with real fonts: imported as the glyphs' outlines and drawn by our rasteriser
//! like resvg draws the same text with the same fonts (the golden tolerance), through the
//! process's font database as the CLI loads it (`VF_FONT_DIRS`, `VF_SYSTEM_FONTS=0`).
//!
//! Needs a directory of TrueType fonts: `VF_TEST_FONT_DIR`, else Debian's DejaVu
//! (`fonts-dejavu-core`, which `.ci/run` installs); without one the tests SKIP (fail in CI).

mod common;

use common::golden::{Tolerance, compare};
use resvg::usvg;
use std::path::PathBuf;
use std::process::Command;
use std::sync::Arc;
use vectorfusion::image::Image;
use vectorfusion::raster;
use vectorfusion::svg::{ImageLimits, fonts, import_svg_with_fonts};

fn font_dir() -> Option<PathBuf> {
    let dirs = [
        std::env::var_os("VF_TEST_FONT_DIR").map(PathBuf::from),
        Some(PathBuf::from("/usr/share/fonts/truetype/dejavu")),
    ];
    dirs.into_iter().flatten().find(|d| {
        std::fs::read_dir(d).is_ok_and(|mut it| {
            it.any(|e| e.is_ok_and(|e| e.path().extension().is_some_and(|x| x == "ttf")))
        })
    })
}

const SVG: &str = r##"<svg xmlns="http://www.w3.org/2000/svg" width="160" height="80" viewBox="0 0 160 80">
  <rect width="160" height="80" fill="#fff"/>
  <text x="8" y="34" font-family="sans-serif" font-size="28" fill="#c33">Hi <tspan fill="#36c" font-weight="bold">there</tspan></text>
  <text x="8" y="70" font-family="serif" font-size="24" fill="none" stroke="#093" stroke-width="1.5" letter-spacing="2">Ag</text>
</svg>"##;

fn resvg_with(db: Arc<usvg::fontdb::Database>) -> Image {
    let opts = usvg::Options {
        fontdb: db,
        ..usvg::Options::default()
    };
    common::golden::resvg_render_with(SVG, &opts)
}

#[test]
fn text_becomes_glyph_outlines_drawn_as_resvg_draws_them() {
    let Some(dir) = font_dir() else {
        return common::skip("text_becomes_glyph_outlines", "no TrueType font directory");
    };
    let db = Arc::new(fonts::load(Some(dir.into_os_string()), false));
    let import = import_svg_with_fonts(SVG, None, ImageLimits::DEFAULT, Arc::clone(&db)).unwrap();
    assert!(
        !import.warnings.iter().any(|w| w.contains("text")),
        "{:?}",
        import.warnings
    );
    // Glyph outlines (usvg gives a span's glyphs as one path) in both fill colours, and the
    // stroked ones.
    let s = &import.scene;
    let filled = |r: f32, b: f32| {
        s.shapes.iter().filter(move |sh| {
            sh.fill
                .is_some_and(|f| (f.r - r).abs() < 0.01 && (f.b - b).abs() < 0.01)
        })
    };
    assert!(filled(0.8, 0.2).count() >= 1, "{} shapes", s.shapes.len());
    assert!(filled(0.2, 0.8).count() >= 1, "{} shapes", s.shapes.len());
    assert!(s.shapes.iter().any(|sh| sh.stroke.is_some()));
    // The same picture as resvg's with the same fonts, by the golden tolerance (the suite's
    // 1 % rule counts every anti-aliased glyph edge: tiny-skia's quarter-pixel grid against our
    // exact coverage moves about 2 % of this picture's pixels by over 16/255).
    let ours = raster::render(s);
    compare("svg_text", &ours, &resvg_with(db), &Tolerance::GOLDEN);
}

#[test]
fn the_cli_draws_text_with_the_fonts_it_is_given() {
    let Some(dir) = font_dir() else {
        return common::skip("the_cli_draws_text", "no TrueType font directory");
    };
    let tmp = std::env::temp_dir().join(format!("vf-svg-text-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let input = tmp.join("in.svg");
    std::fs::write(&input, SVG).unwrap();
    let render = |fonts: Option<&PathBuf>| {
        let out = tmp.join("out.png");
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_vectorfusion"));
        cmd.args(["render"]).arg(&input).arg("-o").arg(&out);
        cmd.env("VF_SYSTEM_FONTS", "0");
        match fonts {
            Some(d) => cmd.env("VF_FONT_DIRS", d),
            None => cmd.env_remove("VF_FONT_DIRS"),
        };
        let st = cmd.output().unwrap();
        assert!(
            st.status.success(),
            "{}",
            String::from_utf8_lossy(&st.stderr)
        );
        let img = image::open(&out).unwrap().to_rgb8();
        let inked = img
            .pixels()
            .filter(|p| p.0.iter().any(|&c| c < 200))
            .count();
        (inked, String::from_utf8_lossy(&st.stderr).to_string())
    };
    let (with, _) = render(Some(&dir));
    let (without, stderr) = render(None);
    assert!(with > 300, "{with} inked pixels with fonts");
    assert_eq!(without, 0, "no fonts, no text");
    assert!(stderr.contains("no fonts"), "{stderr}");
    let _ = std::fs::remove_dir_all(&tmp);
}

/// Text inside a pattern tile is drawn with the tile, and the import says nothing about it
/// (it once warned that the text was ignored, as when no font is loaded).
#[test]
fn text_in_a_pattern_tile_is_drawn_without_a_warning() {
    let Some(dir) = font_dir() else {
        return common::skip("text_in_a_pattern_tile", "no TrueType font directory");
    };
    let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="80" height="80">
      <pattern id="p" patternUnits="userSpaceOnUse" width="40" height="40">
        <text x="2" y="30" font-family="sans-serif" font-size="30">W</text>
      </pattern>
      <rect width="80" height="80" fill="url(#p)"/>
    </svg>"##;
    let db = Arc::new(fonts::load(Some(dir.into_os_string()), false));
    let import = import_svg_with_fonts(svg, None, ImageLimits::DEFAULT, Arc::clone(&db)).unwrap();
    assert!(import.warnings.is_empty(), "{:?}", import.warnings);
    let ours = raster::render(&import.scene);
    let opts = usvg::Options {
        fontdb: db,
        ..usvg::Options::default()
    };
    let want = common::golden::resvg_render_with(svg, &opts);
    let ink = |img: &Image| img.data.chunks(4).filter(|p| p[3] > 0.5).count();
    assert!(
        ink(&ours) > 100,
        "the glyphs are drawn: {} pixels",
        ink(&ours)
    );
    compare("text_in_a_pattern_tile", &ours, &want, &Tolerance::GOLDEN);
}
