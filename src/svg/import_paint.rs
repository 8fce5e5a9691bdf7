//! usvg paints → scene paints: a flat colour, or a gradient with its flat stand-in.
//!
//! usvg has already resolved what SVG leaves to the renderer: `href` inheritance of stops and
//! attributes, stop offsets clamped into `[0, 1]` and made non-decreasing, `stop-opacity`,
//! `objectBoundingBox` units (folded into the gradient transform, with the bounding box of the
//! path's fill, also for strokes), a gradient with one stop as that stop's colour, `r = 0` as
//! the last stop's colour, and a missing or invalid reference as the fallback colour or none.
//! Here the gradient's transform is composed with the path's canvas transform and the paint
//! opacity multiplied into every stop. A pattern becomes a repeating texture (`import_pattern`);
//! a stroke painted with one is drawn as its outline, filled with the texture.

use crate::scene::{
    Affine, Gradient, GradientGeometry, GradientStop, Gradients, Rgba, Spread, Texture,
};
use resvg::usvg;

/// A path's paint as the scene draws it: the flat colour (a gradient's stand-in) and the
/// gradient, if any.
pub(super) struct Painted {
    pub color: Rgba,
    pub gradient: Option<Gradient>,
    /// A pattern's tile (see `import_pattern`), painted instead of `color` (a stroke with one
    /// is drawn as its filled outline).
    pub texture: Option<Box<Texture>>,
}

fn c8(c: usvg::Color, a: f32) -> Rgba {
    let f = |v: u8| v as f32 / 255.0;
    Rgba::new(f(c.red), f(c.green), f(c.blue), a).clamped()
}

fn affine(ts: usvg::Transform) -> Affine {
    Affine([ts.sx, ts.ky, ts.kx, ts.sy, ts.tx, ts.ty])
}

/// `paint` at `opacity`, in the canvas space of a path whose transform is `ts`.
pub(super) fn painted(paint: &usvg::Paint, opacity: f32, ts: usvg::Transform) -> Painted {
    let (base, geometry) = match paint {
        usvg::Paint::Color(c) => {
            return Painted {
                color: c8(*c, opacity),
                gradient: None,
                texture: None,
            };
        }
        usvg::Paint::Pattern(p) => {
            let texture = super::import_pattern::texture(p, ts, opacity);
            return Painted {
                color: texture
                    .as_ref()
                    .map_or(Rgba::TRANSPARENT, Texture::mean_color),
                gradient: None,
                texture: texture.map(Box::new),
            };
        }
        usvg::Paint::LinearGradient(g) => (
            &**g as &usvg::BaseGradient,
            GradientGeometry::Linear {
                x1: g.x1(),
                y1: g.y1(),
                x2: g.x2(),
                y2: g.y2(),
            },
        ),
        usvg::Paint::RadialGradient(g) => (
            &**g as &usvg::BaseGradient,
            GradientGeometry::Radial {
                cx: g.cx(),
                cy: g.cy(),
                r: g.r().get(),
                fx: g.fx(),
                fy: g.fy(),
                fr: g.fr().get(),
            },
        ),
    };
    let gradient = Gradient {
        geometry,
        transform: affine(ts.pre_concat(base.transform())),
        spread: match base.spread_method() {
            usvg::SpreadMethod::Pad => Spread::Pad,
            usvg::SpreadMethod::Reflect => Spread::Reflect,
            usvg::SpreadMethod::Repeat => Spread::Repeat,
        },
        stops: base
            .stops()
            .iter()
            .map(|s| GradientStop {
                offset: s.offset().get(),
                color: c8(s.color(), s.opacity().get() * opacity),
            })
            .collect(),
    };
    let mut gradient = gradient;
    degenerate_radial(&mut gradient);
    let color = gradient.mean_color();
    // A degenerate transform (a zero-size bounding box) paints nothing, as in resvg.
    match gradient.validate() {
        Ok(()) => Painted {
            color,
            gradient: Some(gradient),
            texture: None,
        },
        Err(_) => Painted {
            color: Rgba::TRANSPARENT,
            gradient: None,
            texture: None,
        },
    }
}

/// A padded radial gradient whose focal circle is its end circle (SVG 2's `fr = r`, which no
/// spec defines) as resvg draws it: the first stop's colour inside the circle, the last one's
/// outside.
fn degenerate_radial(g: &mut Gradient) {
    let GradientGeometry::Radial {
        cx,
        cy,
        r,
        fx,
        fy,
        fr,
    } = &mut g.geometry
    else {
        return;
    };
    // tiny-skia's threshold, relative to the gradient's own units.
    let near = |a: f32, b: f32| (a - b).abs() <= (1.0 / 32768.0) * (1.0 + a.abs().max(b.abs()));
    let same = near(*cx, *fx) && near(*cy, *fy) && near(*r, *fr) && *r > 0.0;
    let (Some(first), Some(last)) = (g.stops.first(), g.stops.last()) else {
        return;
    };
    if g.spread != Spread::Pad || !same {
        return;
    }
    let stop = |offset, color| GradientStop { offset, color };
    g.stops = vec![
        stop(0.0, first.color),
        stop(1.0, first.color),
        stop(1.0, last.color),
    ];
    *fr = 0.0;
}

/// The shape's gradients, or `None` when both paints are flat.
pub(super) fn gradients(
    fill: Option<Gradient>,
    stroke: Option<Gradient>,
) -> Option<Box<Gradients>> {
    (fill.is_some() || stroke.is_some()).then(|| {
        Box::new(Gradients {
            fill,
            stroke,
            texture: None,
        })
    })
}

/// The XML tree of `text` (which passed the guard), for warnings about what usvg drops.
pub(super) fn source_tree(text: &str) -> Option<resvg::usvg::roxmltree::Document<'_>> {
    use resvg::usvg::roxmltree;
    let opts = roxmltree::ParsingOptions {
        allow_dtd: true,
        ..Default::default()
    };
    roxmltree::Document::parse_with_options(text, opts).ok()
}

/// One warning per `fill` or `stroke` (attribute or `style` declaration) that refers to no
/// gradient or pattern: usvg draws its fallback colour, or nothing, silently. `text` already
/// passed the guard (its size and node count are bounded).
pub(super) fn dangling_paint_warnings(text: &str) -> Vec<String> {
    let Some(doc) = source_tree(text) else {
        return Vec::new();
    };
    let servers: std::collections::HashSet<&str> = doc
        .descendants()
        .filter(|n| {
            matches!(
                n.tag_name().name(),
                "linearGradient" | "radialGradient" | "pattern"
            )
        })
        .filter_map(|n| n.attribute("id"))
        .collect();
    let mut out = Vec::new();
    for node in doc.descendants().filter(|n| n.is_element()) {
        let style = node.attribute("style").unwrap_or("");
        let declared = style.split(';').filter_map(|d| d.split_once(':'));
        let attrs = ["fill", "stroke"]
            .into_iter()
            .filter_map(|p| node.attribute(p).map(|v| (p, v)));
        for (prop, value) in attrs.chain(declared.map(|(p, v)| (p.trim(), v))) {
            let Some(rest) = value.trim().strip_prefix("url(") else {
                continue;
            };
            let Some((link, fallback)) = rest.split_once(')') else {
                continue;
            };
            let id = link
                .trim()
                .trim_matches(['"', '\''])
                .trim_start_matches('#');
            if servers.contains(id) || !matches!(prop, "fill" | "stroke") {
                continue;
            }
            let on = match node.attribute("id") {
                Some(own) => format!("<{} id=\"{own}\">", node.tag_name().name()),
                None => format!("<{}>", node.tag_name().name()),
            };
            let drawn = match fallback.trim() {
                "" => "not painted".to_string(),
                f => format!("painted {f}"),
            };
            out.push(format!(
                "{prop} of {on} refers to #{id}, which is no gradient or pattern: {drawn}"
            ));
        }
    }
    out
}
