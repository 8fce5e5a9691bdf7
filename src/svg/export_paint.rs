//! Gradient paint → SVG: one `<linearGradient>` / `<radialGradient>` per painted gradient in a
//! `<defs>` after the background, in user space (`gradientUnits="userSpaceOnUse"`, the canvas),
//! with stable ids `g1, g2, …` in scene order (shape by shape, fill before stroke). Numbers are
//! written exactly (the shortest decimal that reads back as the same `f32`) and stop colours
//! at 8 bits per channel, so an imported gradient exports and re-imports unchanged.

use super::export::{hex, push_attr};
use crate::scene::{Gradient, GradientGeometry, Scene, Spread};
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

/// The id of every shape's fill and stroke gradient (`None` where the paint is flat).
pub(super) fn gradient_ids(scene: &Scene) -> Vec<(Option<String>, Option<String>)> {
    let mut k = 0;
    let mut next = |present: bool| {
        present.then(|| {
            k += 1;
            format!("g{k}")
        })
    };
    scene
        .shapes
        .iter()
        .map(|sh| {
            let g = sh.gradients.as_deref();
            let f = next(g.is_some_and(|g| g.fill.is_some() || g.texture.is_some()));
            let s = next(g.is_some_and(|g| g.stroke.is_some()));
            (f, s)
        })
        .collect()
}

/// Writes the `<defs>` of every gradient and texture of `scene` (nothing when there is none),
/// in the order of [`gradient_ids`].
pub(super) fn push_defs(out: &mut String, scene: &Scene) {
    let paints = scene.shapes.iter().filter_map(|s| s.gradients.as_deref());
    if paints.clone().next().is_none() {
        return;
    }
    out.push_str("<defs>\n");
    let mut k = 0;
    let mut id = || {
        k += 1;
        format!("g{k}")
    };
    for g in paints {
        if let Some(t) = &g.texture {
            super::export_texture::push_texture(out, t, &id());
        }
        for g in g.iter() {
            push_gradient(out, g, &id());
        }
    }
    out.push_str("</defs>\n");
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
