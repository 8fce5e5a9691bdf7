//! What the import draws and what it warns about.
use super::*;
use crate::svg::walk::MAX_WARNINGS;

#[test]
fn background_color_covers_the_canvas_whatever_the_view_box_origin() {
    // usvg draws a root `background-color` as a path over the viewBox inside the root group;
    // mapped by the path's own (identity) transform it covered a quarter of the canvas.
    for view_box in ["0 0 200 200", "-100 -100 200 200", "50 -30 200 200"] {
        let svg = format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100" viewBox="{view_box}" style="background-color:#0000ff80"/>"#
        );
        let import = import_svg(&svg).unwrap();
        let bg = import.scene.background;
        assert_eq!([bg.r, bg.g, bg.b], [0.0, 0.0, 1.0], "{view_box}");
        assert!((bg.a - 128.0 / 255.0).abs() < 1e-6, "{view_box}: {bg:?}");
        assert!(import.scene.shapes.is_empty(), "{view_box}");
        let img = crate::raster::render(&import.scene);
        for (x, y) in [(2, 2), (97, 2), (2, 97), (97, 97)] {
            let px = img.pixel(x, y);
            assert!(
                (px[2] - 128.0 / 255.0).abs() < 1e-3,
                "{view_box} ({x},{y}): {px:?}"
            );
        }
    }
    // A shape drawn in viewBox units lands where the viewBox maps it.
    let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100" viewBox="-100 -100 200 200"><rect x="0" y="0" width="100" height="100"/></svg>"#;
    let scene = from_svg(svg).unwrap();
    let (lo, hi) = scene.shapes[0].control_bounds();
    assert_eq!((lo, hi), (Point::new(50.0, 50.0), Point::new(100.0, 100.0)));
}

#[test]
fn filters_are_named_in_warnings_clip_paths_and_masks_are_kept() {
    let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="20" height="20">
        <filter id="f"><feGaussianBlur stdDeviation="2"/></filter>
        <clipPath id="c"><rect width="5" height="5"/></clipPath>
        <mask id="m"><rect width="5" height="5" fill="white"/></mask>
        <g id="blurred" filter="url(#f)"><rect width="10" height="10" fill="red"/></g>
        <rect id="clipped" width="10" height="10" clip-path="url(#c)"/>
        <rect id="masked" width="10" height="10" mask="url(#m)"/>
        <rect width="10" height="10"/>
    </svg>"##;
    let import = import_svg(svg).unwrap();
    let w = &import.warnings;
    assert!(
        w.iter()
            .any(|w| w.starts_with("filter on #blurred ignored")),
        "{w:?}"
    );
    assert_eq!(w.len(), 1, "{w:?}");
    let groups = &import.scene.groups;
    assert_eq!(groups.len(), 2, "{groups:?}");
    assert!(groups[0].clip.is_some() && (groups[0].start, groups[0].end) == (1, 2));
    assert!(groups[1].mask.is_some() && (groups[1].start, groups[1].end) == (2, 3));
    // The content is drawn as it is (unfiltered), nothing else in its place.
    assert_eq!(import.scene.shapes.len(), 4);
    assert_eq!(
        import.scene.shapes[0].fill,
        Some(Rgba::new(1.0, 0.0, 0.0, 1.0))
    );
    // A plain drawing has no warnings; many warnings are capped.
    assert!(import_svg(r#"<svg xmlns="http://www.w3.org/2000/svg" width="9" height="9"><rect width="4" height="4"/></svg>"#).unwrap().warnings.is_empty());
    let many: String = (0..40)
        .map(|i| format!(r#"<rect id="r{i}" width="4" height="4" filter="url(#f)"/>"#))
        .collect();
    let svg = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="9" height="9"><filter id="f"><feFlood/></filter>{many}</svg>"#
    );
    let w = import_svg(&svg).unwrap().warnings;
    assert_eq!(w.len(), MAX_WARNINGS + 1, "{w:?}");
    assert!(w[MAX_WARNINGS].starts_with("24 more"), "{w:?}");
}

#[test]
fn reference_cycles_are_broken_with_a_warning() {
    let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="20" height="20">
        <g id="a"><rect width="5" height="5"/><use href="#a"/></g></svg>"##;
    let import = import_svg(svg).unwrap();
    assert_eq!(import.scene.shapes.len(), 1);
    assert_eq!(import.warnings.len(), 1, "{:?}", import.warnings);
    assert!(
        import.warnings[0].contains("<use>"),
        "{:?}",
        import.warnings
    );
}

#[test]
fn text_and_plus_lighter_are_named_in_warnings() {
    let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="20" height="20">
        <text id="t1" x="2" y="10">Hi</text><text x="2" y="18">there</text>
        <rect id="lit" width="10" height="10" style="mix-blend-mode:plus-lighter"/>
        <rect id="mul" width="10" height="10" style="mix-blend-mode:multiply"/>
    </svg>"#;
    // No fonts at all: the text is dropped, with a warning each.
    let no_fonts = std::sync::Arc::new(crate::svg::fonts::load(None, false));
    let import =
        super::import_svg_with_fonts(svg, None, super::ImageLimits::DEFAULT, no_fonts).unwrap();
    let w = &import.warnings;
    assert!(w.contains(&r#"<text id="t1"> ignored (text is not drawn: no fonts)"#.to_string()));
    assert!(w.contains(&"a <text> ignored (text is not drawn: no fonts)".to_string()));
    assert!(
        w.iter()
            .any(|w| w.starts_with("mix-blend-mode plus-lighter on #lit")),
        "{w:?}"
    );
    assert_eq!(w.len(), 3, "{w:?}");
    // plus-lighter is drawn as normal (no group); multiply is a group of its own.
    let g = &import.scene.groups;
    assert_eq!(g.len(), 1, "{g:?}");
    assert_eq!(
        (g[0].start, g[0].end, g[0].blend),
        (1, 2, crate::scene::BlendMode::Multiply)
    );
}
