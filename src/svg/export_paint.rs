//! Gradient paint → SVG: one `<linearGradient>` / `<radialGradient>` per distinct gradient in a
//! `<defs>` after the background, in user space (`gradientUnits="userSpaceOnUse"`, the canvas),
//! with stable ids `g1, g2, …` in scene order (shape by shape, fill before stroke; shapes
//! painted alike share one; [`PaintDefs`]). Numbers are
//! written exactly (the shortest decimal that reads back as the same `f32`) and stop colours
//! at 8 bits per channel, so an imported gradient exports and re-imports unchanged.

use super::export::{hex, push_attr};
use crate::scene::{Gradient, GradientGeometry, Shape, Spread};
use std::fmt::Write;

/// `v` as the shortest decimal that reads back as the same `f32`, without a leading zero
/// (`.25`, `-.5`; `-0` as `0`).
pub(super) fn exact(v: f32) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let s = format!("{v}");
    if let Some(rest) = s.strip_prefix("0.") {
        format!(".{rest}")
    } else if let Some(rest) = s.strip_prefix("-0.") {
        format!("-.{rest}")
    } else {
        s
    }
}

/// The paint servers of a document's shapes (gradients, and textures as patterns), each
/// distinct one written once: two shapes painted with the same gradient refer to one element.
/// Ids are `g1, g2, …` in the order the shapes ask for them (fill before stroke).
#[derive(Default)]
pub(super) struct PaintDefs {
    /// The elements, in id order.
    pub(super) text: String,
    /// Each element's text with an empty id → its id.
    seen: std::collections::HashMap<String, String>,
}

impl PaintDefs {
    /// The ids of `sh`'s fill (a texture or a gradient) and stroke paint servers (`None` where
    /// the paint is flat), writing the ones not written yet.
    pub(super) fn of_shape(&mut self, sh: &Shape) -> (Option<String>, Option<String>) {
        let Some(g) = sh.gradients.as_deref() else {
            return (None, None);
        };
        let fill = if let Some(t) = &g.texture {
            let mut el = String::new();
            super::export_texture::push_texture(&mut el, t, "");
            Some(self.entry(el))
        } else {
            g.fill.as_ref().map(|g| self.gradient(g))
        };
        (fill, g.stroke.as_ref().map(|g| self.gradient(g)))
    }

    fn gradient(&mut self, g: &Gradient) -> String {
        let mut el = String::new();
        push_gradient(&mut el, g, "");
        self.entry(el)
    }

    /// The id of element `el` (written with `id=""`), written now if it is new.
    fn entry(&mut self, el: String) -> String {
        if let Some(id) = self.seen.get(&el) {
            return id.clone();
        }
        let id = format!("g{}", self.seen.len() + 1);
        self.text
            .push_str(&el.replacen(r#" id="""#, &format!(r#" id="{id}""#), 1));
        self.seen.insert(el, id.clone());
        id
    }
}

pub(super) fn push_gradient(out: &mut String, g: &Gradient, id: &str) {
    let tag = match g.geometry {
        GradientGeometry::Linear { .. } => "linearGradient",
        GradientGeometry::Radial { .. } => "radialGradient",
    };
    let _ = write!(out, "<{tag}");
    push_attr(out, "id", id);
    push_attr(out, "gradientUnits", "userSpaceOnUse");
    for (&name, v) in g.geometry.names().iter().zip(g.geometry.values()) {
        // `fr` is SVG 2's, and 0 by default: written only when it is not.
        if name != "fr" || v > 0.0 {
            push_attr(out, name, &exact(v));
        }
    }
    if g.transform != crate::scene::Affine::IDENTITY {
        let m: Vec<String> = g.transform.0.iter().map(|v| exact(*v)).collect();
        push_attr(
            out,
            "gradientTransform",
            &format!("matrix({})", m.join(" ")),
        );
    }
    match g.spread {
        Spread::Pad => {}
        Spread::Reflect => push_attr(out, "spreadMethod", "reflect"),
        Spread::Repeat => push_attr(out, "spreadMethod", "repeat"),
    }
    out.push_str(">\n");
    for s in &g.stops {
        out.push_str("<stop");
        // 0 is the default offset.
        if s.offset != 0.0 {
            push_attr(out, "offset", &exact(s.offset));
        }
        push_attr(out, "stop-color", &hex(s.color));
        if s.color.a != 1.0 {
            push_attr(out, "stop-opacity", &exact(s.color.a));
        }
        out.push_str("/>\n");
    }
    let _ = writeln!(out, "</{tag}>");
}
