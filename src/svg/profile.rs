//! The safe-output profile: what every SVG this project writes must satisfy, so it opens the
//! same, and harmlessly, in browsers, design tools and renderers. Checked by tests on every
//! output path (results, snapshots, `vectorize`, `generate`).
//!
//! - XML without a DTD, entities or processing instructions other than the XML declaration;
//! - elements from an allowlist (`svg`, `g`, `path`, `rect`, `metadata`, `title`, `desc`, and
//!   the paint servers: `defs`, `linearGradient`, `radialGradient`, `stop`, and `pattern` with
//!   one `image` for textures) in the SVG namespace, each with attributes from its allowlist: no
//!   `<script>`, `<foreignObject>`, `<use>`, event handlers (`on*`), no `style` but an image's
//!   `image-rendering:smooth` (a CSS-only value: bilinear sampling), no `href` but an
//!   image's embedded PNG (`data:image/png;base64,…`), and no `url(…)` value but a
//!   fill or stroke naming a gradient of the same file (`url(#id)`), so nothing runs and nothing
//!   outside the file is fetched; `id` only on `<g>`, `<path>` and gradients, and only a plain
//!   name (a letter, then letters, digits, `_`, `-`);
//! - the root has `viewBox`, `width` and `height`; every number is finite.
//!
//! Our writer ([`super::to_svg`], [`super::with_metadata`]) builds documents from a scene, so an
//! imported SVG's scripts and handlers never reach the output.

use resvg::usvg::roxmltree::{self, Node, NodeType};

const SVG_NS: &str = "http://www.w3.org/2000/svg";

/// The one `style` the writer uses: bilinear sampling of an image, a value CSS allows only in
/// a style (`image-rendering="smooth"` as an attribute is ignored by renderers).
pub(crate) const SMOOTH_STYLE: &str = "image-rendering:smooth";

/// Attributes allowed on each element (presentation attributes our writer uses).
fn allowed(tag: &str, attr: &str) -> bool {
    const PAINT: &[&str] = &[
        "fill",
        "fill-opacity",
        "fill-rule",
        "stroke",
        "stroke-width",
        "stroke-opacity",
        "stroke-linecap",
        "stroke-linejoin",
        "opacity",
        "transform",
    ];
    match tag {
        "svg" => matches!(attr, "width" | "height" | "viewBox" | "version"),
        "g" => attr == "id" || PAINT.contains(&attr),
        "path" => matches!(attr, "d" | "id") || PAINT.contains(&attr),
        "rect" => matches!(attr, "x" | "y" | "width" | "height") || PAINT.contains(&attr),
        "linearGradient" | "radialGradient" => matches!(
            attr,
            "id" | "gradientUnits"
                | "gradientTransform"
                | "spreadMethod"
                | "x1"
                | "y1"
                | "x2"
                | "y2"
                | "cx"
                | "cy"
                | "r"
                | "fx"
                | "fy"
                | "fr"
        ),
        "stop" => matches!(attr, "offset" | "stop-color" | "stop-opacity"),
        "pattern" => matches!(
            attr,
            "id" | "patternUnits" | "width" | "height" | "patternTransform"
        ),
        "image" => matches!(
            attr,
            "width" | "height" | "preserveAspectRatio" | "image-rendering" | "style" | "href"
        ),
        _ => false,
    }
}

/// The first way a written SVG leaves the profile (messages read after "the SVG …").
#[derive(Debug, thiserror::Error)]
pub enum ProfileViolation {
    #[error("has a DTD")]
    Dtd,
    #[error("is not XML: {0}")]
    NotXml(#[source] roxmltree::Error),
    #[error("the root element is not <svg>")]
    Root,
    #[error("the root has no {0}")]
    RootAttribute(&'static str),
    #[error("has a processing instruction")]
    ProcessingInstruction,
    #[error("<{0}> is not in the SVG namespace")]
    Namespace(String),
    #[error("has the element <{0}>")]
    Element(String),
    #[error("<{0}> holds elements")]
    Nested(String),
    #[error("<{tag}> has the attribute {name}")]
    Attribute { tag: String, name: String },
    #[error("<{tag}> has the id {id:.80}")]
    Id { tag: String, id: String },
    #[error("<{tag} {name}> refers to another resource")]
    Reference { tag: String, name: String },
    #[error("<{tag} {name}> has a non-finite number: {value:.80}")]
    NonFinite {
        tag: String,
        name: String,
        value: String,
    },
}

/// Checks `svg` against the profile; the error names the first violation.
pub fn check_safe_output(svg: &str) -> Result<(), ProfileViolation> {
    if svg.contains("<!DOCTYPE") || svg.contains("<!ENTITY") {
        return Err(ProfileViolation::Dtd);
    }
    let doc = roxmltree::Document::parse(svg).map_err(ProfileViolation::NotXml)?;
    let root = doc.root_element();
    if root.tag_name().name() != "svg" {
        return Err(ProfileViolation::Root);
    }
    for a in ["viewBox", "width", "height"] {
        if root.attribute(a).is_none() {
            return Err(ProfileViolation::RootAttribute(a));
        }
    }
    for node in doc.descendants() {
        match node.node_type() {
            NodeType::PI => return Err(ProfileViolation::ProcessingInstruction),
            NodeType::Element => check_element(node)?,
            _ => {}
        }
    }
    Ok(())
}

/// An id as our writer spells them: a letter, then letters, digits, `_` or `-` (at most 64).
fn plain_id(v: &str) -> bool {
    let mut chars = v.chars();
    chars.next().is_some_and(|c| c.is_ascii_alphabetic())
        && v.len() <= 64
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

/// A fill or stroke naming a paint of the same file: `url(#id)` with a plain id.
fn local_paint_ref(attr: &str, value: &str) -> bool {
    matches!(attr, "fill" | "stroke")
        && value
            .strip_prefix("url(#")
            .and_then(|v| v.strip_suffix(')'))
            .is_some_and(plain_id)
}

/// An image's `href`: a PNG inside the file (`data:image/png;base64,…`), nothing fetched.
fn embedded_png(v: &str) -> bool {
    v.strip_prefix("data:image/png;base64,").is_some_and(|b| {
        b.bytes()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, b'+' | b'/' | b'='))
    })
}

fn check_element(node: Node) -> Result<(), ProfileViolation> {
    let tag = node.tag_name().name();
    if node.tag_name().namespace() != Some(SVG_NS) {
        return Err(ProfileViolation::Namespace(tag.to_string()));
    }
    if !matches!(
        tag,
        "svg"
            | "g"
            | "path"
            | "rect"
            | "metadata"
            | "title"
            | "desc"
            | "defs"
            | "linearGradient"
            | "radialGradient"
            | "stop"
            | "pattern"
            | "image"
    ) {
        return Err(ProfileViolation::Element(tag.to_string()));
    }
    let text_only = matches!(tag, "metadata" | "title" | "desc");
    if text_only && node.children().any(|c| c.is_element()) {
        return Err(ProfileViolation::Nested(tag.to_string()));
    }
    let (tag, owned) = (tag.to_string(), |s: &str| s.to_string());
    for a in node.attributes() {
        let name = a.name();
        if a.namespace().is_some() || !allowed(&tag, name) {
            let name = owned(name);
            return Err(ProfileViolation::Attribute { tag, name });
        }
        let v = a.value();
        if name == "href" {
            if !embedded_png(v) {
                let name = owned(name);
                return Err(ProfileViolation::Reference { tag, name });
            }
            continue;
        }
        if name == "style" && v != SMOOTH_STYLE {
            let name = owned(name);
            return Err(ProfileViolation::Attribute { tag, name });
        }
        if name == "id" && !plain_id(v) {
            let id = owned(v);
            return Err(ProfileViolation::Id { tag, id });
        }
        if v.contains("url(") && !local_paint_ref(name, v) {
            let name = owned(name);
            return Err(ProfileViolation::Reference { tag, name });
        }
        // Our number writer spells non-finite values as Rust does: NaN, inf, -inf.
        if v.contains("NaN") || v.contains("inf") {
            let (name, value) = (owned(name), owned(v));
            return Err(ProfileViolation::NonFinite { tag, name, value });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::check_safe_output;
    use crate::scene::{Point, Rgba, Scene, Shape};
    use crate::svg::{SvgOptions, from_svg, to_svg, with_metadata};

    #[test]
    fn written_svgs_pass_and_hostile_imports_come_out_clean() {
        let hostile = r##"<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" width="32" height="32" onload="alert(1)">
  <script>alert(2)</script>
  <foreignObject width="9" height="9"><div xmlns="http://www.w3.org/1999/xhtml">x</div></foreignObject>
  <a xlink:href="javascript:alert(3)"><rect width="32" height="32" fill="#102030" onclick="alert(4)"/></a>
  <path d="M4 4L28 4L16 28Z" fill="red" style="fill:url(#x)" onmouseover="alert(5)"/>
  <image href="https://example.com/x.png" width="8" height="8"/>
</svg>"##;
        let scene = from_svg(hostile).unwrap();
        let out = to_svg(&scene, &SvgOptions::default());
        check_safe_output(&out).unwrap();
        assert!(!out.contains("alert") && !out.contains("script") && !out.contains("href"));
        // A caption or icon name with markup in the metadata stays text.
        let meta = with_metadata(&out, "<script>alert(6)</script> & \"x\"");
        check_safe_output(&meta).unwrap();
        assert!(meta.contains("&lt;script&gt;"));
        // The checker itself refuses what it exists to refuse.
        for bad in [
            hostile,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="4" height="4"/>"#,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="4" height="4" viewBox="0 0 4 4"><path d="MNaN 0"/></svg>"#,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="4" height="4" viewBox="0 0 4 4"><path d="M0 0" fill="url(https://example.com/#a)"/></svg>"#,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="4" height="4" viewBox="0 0 4 4"><path d="M0 0" transform="url(#a)"/></svg>"#,
        ] {
            assert!(check_safe_output(bad).is_err(), "{bad}");
        }
        let mut s = Scene::new(8, 8, Rgba::new(1.0, 1.0, 1.0, 1.0)).unwrap();
        s.shapes.push(
            Shape::closed_cubic(
                (0..6)
                    .map(|i| Point::new(i as f32, (i * i) as f32 / 4.0))
                    .collect(),
                Rgba::new(0.2, 0.4, 0.6, 0.5),
            )
            .unwrap(),
        );
        check_safe_output(&to_svg(&s, &SvgOptions::default())).unwrap();
        // Gradient paint: <defs>, the gradients and their stops, fills naming them.
        crate::vector::fill::FillKind::Radial.paint_new(&mut s);
        let out = to_svg(&s, &SvgOptions::default());
        assert!(
            out.contains("<radialGradient") && out.contains("url(#g1)"),
            "{out}"
        );
        check_safe_output(&out).unwrap();
    }
}
