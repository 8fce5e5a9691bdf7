//! The bounds of `guard`, each tried with the input it exists for.
use super::*;

fn check(text: &str) -> Result<usvg::Tree, SvgRejected> {
    parse_repaired(text, &SvgLimits::DEFAULT, &usvg::Options::default()).map(|p| p.tree)
}

fn numbers(s: &str, path_like: bool) -> Vec<f64> {
    let mut v = Vec::new();
    scan_numbers(s, path_like, |x| {
        v.push(x);
        Ok(())
    })
    .unwrap();
    v
}

fn svg(body: &str) -> String {
    format!(r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 24 24">{body}</svg>"#)
}

#[test]
fn scans_numbers_as_svg_writes_them() {
    assert_eq!(
        numbers("M.5.5L1e3-2 3E+1z", true),
        [0.5, 0.5, 1000.0, -2.0, 30.0]
    );
    assert_eq!(numbers("12px 1em 50%", false), [12.0, 1.0, 50.0]);
    // Names, hex colours, url(…) and quoted strings hold no numbers; nor does a lone sign.
    assert!(
        numbers(
            "#1e3838 url(#a1e99) cls-1e9 - . 'F 9e99' url(data:a+3e99)",
            false
        )
        .is_empty()
    );
    assert_eq!(numbers("translate(-.5,+2)", false), [-0.5, 2.0]);
    assert_eq!(numbers("1e999", true), [f64::INFINITY]);
}

#[test]
fn ordinary_svgs_pass() {
    let icon = r##"<?xml version="1.0"?>
<!DOCTYPE svg PUBLIC "-//W3C//DTD SVG 1.1//EN" "http://www.w3.org/Graphics/SVG/1.1/DTD/svg11.dtd" [
  <!ENTITY ns_svg "http://www.w3.org/2000/svg">
  <!ENTITY ns_xlink "http://www.w3.org/1999/xlink">
]>
<svg xmlns="&ns_svg;" xmlns:xlink="&ns_xlink;"
 xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape"
 xmlns:sodipodi="http://sodipodi.sourceforge.net/DTD/sodipodi-0.dtd"
 inkscape:version="1.0 (4035a4f, 2020-05-01)" width="4096" height="4096" viewBox="0 0 24 24">
  <sodipodi:namedview inkscape:zoom="1e30"><sodipodi:guide position="1e30,0"/></sodipodi:namedview>
  <style>@font-face{font-family:"F 9e99";src:url(data:font/woff2;base64,AAA+3e99)} .cls-1{fill:#1e3838;stroke-width:1.5px}</style>
  <defs><path id="p" d="M2 2h20v20H2z"/><marker id="m"><path d="M0 0L1 1"/></marker></defs>
  <g transform="translate(-3500 -2200)"><use xlink:href="#p" class="cls-1" transform="translate(3500 2200) rotate(45 12 12)"/></g>
  <path d="M1 1L5 5L9 1" marker-end="url(#m)" stroke="black"/>
  <circle cx="12" cy="12" r="5" style="fill:#ff0000;opacity:.5"/>
</svg>"##;
    check(icon).unwrap();
    check(r#"<svg xmlns="http://www.w3.org/2000/svg"><rect width="10" height="10"/></svg>"#)
        .unwrap();
}

#[test]
fn refuses_entity_bombs_and_huge_numbers() {
    let cases = [
        (
            r#"<!DOCTYPE svg [<!ENTITY x SYSTEM "file:///etc/passwd">]><svg xmlns="http://www.w3.org/2000/svg">&x;</svg>"#.to_string(),
            "external",
        ),
        (
            // The issue's 157 KB request: one 100 KB entity used 19,000 times.
            format!(
                r#"<!DOCTYPE svg [<!ENTITY a "{}">]>{}"#,
                "x".repeat(100_000),
                svg(&format!("<text>{}</text>", "&a;".repeat(19_000)))
            ),
            "expands entities",
        ),
        (svg(r#"<circle r="1e38"/>"#), "outside"),
        (svg(r#"<path d="M0 0L1e39 0"/>"#), "outside"),
        (svg(r#"<path d="M0 0L9 9" style="stroke-width:1e30"/>"#), "outside"),
        (svg(r#"<style>path{stroke-width:1e30}</style>"#), "outside"),
        (svg(r#"<g transform="matrix(1e20 0 0 1 0 0)"/>"#), "outside"),
        (
            r#"<svg xmlns="http://www.w3.org/2000/svg" xmlns:s="http://www.w3.org/2000/svg"><circle s:r="1e38"/></svg>"#.to_string(),
            "outside",
        ),
        (
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="2e7" height="8"/>"#.to_string(),
            "outside",
        ),
        (svg(r#"<circle cx="12" cy="12" r="1537"/>"#), "draws as far"),
        (
            svg(&format!(
                "{}<rect width=\"9\" height=\"9\"/>{}",
                r#"<g transform="scale(50)">"#.repeat(4),
                "</g>".repeat(4)
            )),
            "draws as far",
        ),
        (
            svg(r#"<defs><pattern id="p" width="3000" height="3000" patternUnits="userSpaceOnUse"><rect width="9" height="9"/></pattern></defs><rect width="24" height="24" fill="url(#p)"/>"#),
            "pattern tile",
        ),
    ];
    for (text, want) in &cases {
        let e = check(text)
            .err()
            .unwrap_or_else(|| panic!("accepted: {text:.200}"));
        assert!(e.to_string().contains(want), "{text:.200}: {e}");
    }
}

/// A `<use>` tree doubling at each of 40 levels (2^40 elements once expanded), with an
/// `href` written `before` the id (to try a spelling the counter might miss).
fn doubling(before: &str) -> String {
    let mut doc = String::from(
        r#"<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink"><defs><path id="u0" d="M0 0L1 1"/>"#,
    );
    for i in 1..=40 {
        doc.push_str(&format!(
            r##"<g id="u{i}"><use {before}"#u{p}"/><use {before}"#u{p}"/></g>"##,
            p = i - 1
        ));
    }
    doc.push_str(r##"</defs><use href="#u40"/></svg>"##);
    doc
}

#[test]
fn refuses_expansion_bombs_deep_nesting_and_cycles() {
    for before in ["href=", "href= ' ' + ", "xlink:href=\"#u0\" href="] {
        let doc = doubling(before).replace("' ' + \"", "\" ");
        let e = check(&doc).unwrap_err();
        assert!(e.to_string().contains("expands"), "{before}: {e}");
    }
    // A decoy with the same id after the real one: usvg keeps the first.
    let mut doc = doubling("href=");
    doc = doc.replace("</defs>", r#"<g id="u40"/></defs>"#);
    assert!(check(&doc).unwrap_err().to_string().contains("expands"));
    // Clip paths doubling through url(#…): each use is a renderer layer.
    let mut clips = String::from(r#"<clipPath id="c0"><rect width="1" height="1"/></clipPath>"#);
    for i in 1..=30 {
        clips.push_str(&format!(
            r#"<clipPath id="c{i}"><rect width="1" height="1" clip-path="url(#c{p})"/><rect width="2" height="2" clip-path="url(#c{p})"/></clipPath>"#,
            p = i - 1
        ));
    }
    let e = check(&svg(&format!(
        r#"<defs>{clips}</defs><rect width="9" height="9" clip-path="url(#c30)"/>"#
    )))
    .unwrap_err();
    assert!(
        e.to_string().contains("times") || e.to_string().contains("expands"),
        "{e}"
    );
    // Markers count once per vertex.
    let marker = svg(&format!(
        r##"<marker id="m">{}</marker><path marker-mid="url(#m)" d="M0 0{}"/>"##,
        "<g/>".repeat(1000),
        " 1 1".repeat(1000)
    ));
    assert!(check(&marker).unwrap_err().to_string().contains("expands"));
    // Deep nesting, directly or through a chain of references.
    let deep = svg(&format!("{}{}", "<g>".repeat(200), "</g>".repeat(200)));
    assert!(check(&deep).unwrap_err().to_string().contains("deep"));
    let mut chain = String::from(r#"<defs><g id="g0"/>"#);
    for i in 1..=200 {
        chain.push_str(&format!(
            r##"<g id="g{i}"><use href="#g{p}"/></g>"##,
            p = i - 1
        ));
    }
    chain.push_str(r##"</defs><use href="#g200"/>"##);
    assert!(
        check(&svg(&chain))
            .unwrap_err()
            .to_string()
            .contains("deep")
    );
    assert!(
        check(&svg(&"<g/>".repeat(600_000)))
            .unwrap_err()
            .to_string()
            .contains("XML nodes")
    );
    let limits = SvgLimits {
        max_bytes: 10,
        ..SvgLimits::DEFAULT
    };
    let e = parse_repaired(&svg(""), &limits, &usvg::Options::default())
        .err()
        .expect("refused");
    assert!(e.to_string().contains("bytes"), "{e}");
}

fn repaired(text: &str) -> Result<Parsed, SvgRejected> {
    parse_repaired(text, &SvgLimits::DEFAULT, &usvg::Options::default())
}

fn paths(g: &usvg::Group) -> usize {
    g.children()
        .iter()
        .map(|n| match n {
            usvg::Node::Group(c) => paths(c),
            usvg::Node::Path(_) => 1,
            _ => 0,
        })
        .sum()
}

fn first_fill(g: &usvg::Group) -> Option<usvg::Paint> {
    g.children().iter().find_map(|n| match n {
        usvg::Node::Group(c) => first_fill(c),
        usvg::Node::Path(p) => p.fill().map(|f| f.paint().clone()),
        _ => None,
    })
}

#[test]
fn breaks_reference_cycles_where_they_close() {
    // Two uses that contain each other: the inner link is dropped, the rest drawn.
    let cycle = svg(
        r##"<g id="a"><use href="#b"/><rect width="4" height="4"/></g><g id="b"><use xlink:href="#a" xmlns:xlink="http://www.w3.org/1999/xlink"/></g>"##,
    );
    let p = repaired(&cycle).unwrap();
    assert_eq!(p.warnings.len(), 1, "{:?}", p.warnings);
    assert!(p.warnings[0].contains("cycle"), "{}", p.warnings[0]);
    assert!(paths(p.tree.root()) >= 1);
    // A pattern painting itself: that fill becomes `none` (as usvg does), the square is drawn
    // with the pattern's other content.
    let pattern = svg(
        r##"<pattern id="p" width="4" height="4" patternUnits="userSpaceOnUse"><rect width="2" height="2" style="stroke:red;fill:url(#p)"/></pattern><rect id="r" width="9" height="9" fill="url(#p)"/>"##,
    );
    let p = repaired(&pattern).unwrap();
    assert_eq!(p.warnings.len(), 1, "{:?}", p.warnings);
    assert!(p.warnings[0].contains("<rect>"), "{}", p.warnings[0]);
    // A ring of gradients inheriting through `href`: nothing dropped, each element inherits
    // from the rest of the ring (usvg stops where the chain returns), so `g3` gets g2's stops.
    let ring = svg(
        r##"<linearGradient id="g1" href="#g2"/><linearGradient id="g2" href="#g3"><stop offset="0" stop-color="white"/><stop offset="1" stop-color="black"/></linearGradient><linearGradient id="g3" href="#g1"/><rect width="9" height="9" fill="url(#g3)"/>"##,
    );
    let p = repaired(&ring).unwrap();
    assert!(p.warnings.is_empty(), "{:?}", p.warnings);
    let fill = first_fill(p.tree.root()).expect("a filled path");
    match fill {
        usvg::Paint::LinearGradient(g) => assert_eq!(g.stops().len(), 2),
        other => panic!("{other:?}"),
    }
    // More cycles than MAX_REPAIRS: refused (each repair re-reads the text).
    let many: String = (0..=MAX_REPAIRS)
        .map(|i| format!(r##"<g id="g{i}"><use href="#g{i}"/></g>"##))
        .collect();
    let e = repaired(&svg(&many)).err().expect("refused");
    assert!(e.to_string().contains("repairs"), "{e}");
}

#[test]
fn entities_with_markup_expand_and_nested_entities_are_dropped() {
    let markup = r#"<!DOCTYPE svg [<!ENTITY r "<rect width='4' height='4'/><rect x='5' width='4' height='4'/>">]><svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 24 24"><g>&r;</g></svg>"#;
    let p = repaired(markup).unwrap();
    assert!(p.warnings.is_empty(), "{:?}", p.warnings);
    assert_eq!(paths(p.tree.root()), 2);
    let nested = r#"<!DOCTYPE svg [<!ENTITY b "x"><!ENTITY a "&b;&b;">]><svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 24 24"><rect width="4" height="4"/><text>&a;</text></svg>"#;
    let p = repaired(nested).unwrap();
    assert_eq!(p.warnings.len(), 1, "{:?}", p.warnings);
    assert!(p.warnings[0].contains("\"a\""), "{}", p.warnings[0]);
    assert_eq!(paths(p.tree.root()), 1);
}

#[test]
fn markers_inside_their_own_drawing_are_passed_over_as_usvg_does() {
    // Two markers drawing a path that carries both (resvg's `marker/recursive-5`): nothing is
    // repaired; the outer marker draws the path with the other marker once, the inner one the
    // bare path.
    let nested = svg(
        r##"<marker id="m1" markerWidth="6" markerHeight="6" orient="auto"><use href="#p1"/></marker>
        <marker id="m2" markerWidth="6" markerHeight="6" orient="auto"><use href="#p1"/></marker>
        <path id="p1" d="M1 1 5 3 1 5" fill="none" stroke="blue" marker-start="url(#m1)" marker-end="url(#m2)"/>
        <path d="M2 2 20 20" stroke="green" marker-start="url(#m1)" marker-end="url(#m2)"/>"##,
    );
    let p = repaired(&nested).unwrap();
    assert!(p.warnings.is_empty(), "{:?}", p.warnings);
    // usvg itself: the same tree as without the guard.
    let plain = usvg::Tree::from_str(&nested, &usvg::Options::default()).unwrap();
    assert_eq!(paths(p.tree.root()), paths(plain.root()));
    assert!(paths(p.tree.root()) >= 6, "{}", paths(p.tree.root()));
    // Eight markers each drawing every other one: 8! nestings, refused by the element limit
    // (quickly: the walk stops at the limit).
    let k = 8;
    let mut bomb = String::new();
    for i in 0..k {
        bomb.push_str(&format!(
            r##"<marker id="n{i}" markerWidth="4" markerHeight="4">{}</marker>"##,
            (0..k)
                .map(|j| format!(r##"<path d="M0 0 1 1 2 0" marker-start="url(#n{j})"/>"##))
                .collect::<String>()
        ));
    }
    bomb.push_str(r##"<path d="M0 0 9 9 18 0" marker-start="url(#n0)"/>"##);
    let t = std::time::Instant::now();
    let e = check(&svg(&bomb)).unwrap_err();
    assert!(e.to_string().contains("expands"), "{e}");
    assert!(t.elapsed().as_secs() < 10, "{:?}", t.elapsed());
}
