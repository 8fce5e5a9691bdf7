//! `bench raster --paint linear|radial`: the benchmark scene with every fill painted by a
//! gradient, and tiny-skia's shader for a scene gradient (the in-run baseline draws them too).

use crate::scene::{
    Affine, Gradient, GradientGeometry, GradientStop, Gradients, Rgba, Scene, Spread,
};
use resvg::tiny_skia;

/// What `bench raster` paints the fills with.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BenchPaint {
    /// The scene's flat colours.
    #[default]
    Flat,
    /// A 3-stop linear gradient across each shape's control box.
    Linear,
    /// A 3-stop radial gradient centred in each shape's control box, focal point off centre.
    Radial,
}

/// `scene` with every fill painted by a gradient of `paint` (from the fill colour through white
/// to the colour at half brightness); `Flat` leaves it as it is.
pub fn with_gradients(scene: &Scene, paint: BenchPaint) -> Scene {
    let mut out = scene.clone();
    if paint == BenchPaint::Flat {
        return out;
    }
    for sh in &mut out.shapes {
        let Some(c) = sh.fill else { continue };
        let (lo, hi) = sh.control_bounds();
        let (w, h) = ((hi.x - lo.x).max(1.0), (hi.y - lo.y).max(1.0));
        let geometry = match paint {
            BenchPaint::Radial => GradientGeometry::Radial {
                cx: lo.x + 0.5 * w,
                cy: lo.y + 0.5 * h,
                r: 0.5 * w.max(h),
                fx: lo.x + 0.35 * w,
                fy: lo.y + 0.35 * h,
                fr: 0.0,
            },
            _ => GradientGeometry::Linear {
                x1: lo.x,
                y1: lo.y,
                x2: hi.x,
                y2: hi.y,
            },
        };
        let dark = Rgba::new(0.5 * c.r, 0.5 * c.g, 0.5 * c.b, c.a);
        let stop = |offset, color| GradientStop { offset, color };
        let g = Gradient {
            geometry,
            transform: Affine::IDENTITY,
            spread: Spread::Pad,
            stops: vec![
                stop(0.0, c),
                stop(
                    0.5,
                    Rgba {
                        a: c.a,
                        ..Rgba::WHITE
                    },
                ),
                stop(1.0, dark),
            ],
        };
        sh.fill = Some(g.mean_color());
        sh.gradients = Some(Box::new(Gradients {
            fill: Some(g),
            stroke: None,
            texture: None,
        }));
    }
    out
}

/// tiny-skia's shader for `g`.
pub fn shader(g: &Gradient) -> Option<tiny_skia::Shader<'static>> {
    let stops = g
        .stops
        .iter()
        .map(|s| {
            let c = s.color;
            let color = tiny_skia::Color::from_rgba(c.r, c.g, c.b, c.a)?;
            Some(tiny_skia::GradientStop::new(s.offset, color))
        })
        .collect::<Option<Vec<_>>>()?;
    let mode = match g.spread {
        Spread::Pad => tiny_skia::SpreadMode::Pad,
        Spread::Reflect => tiny_skia::SpreadMode::Reflect,
        Spread::Repeat => tiny_skia::SpreadMode::Repeat,
    };
    let [a, b, c, d, e, f] = g.transform.0;
    let ts = tiny_skia::Transform::from_row(a, b, c, d, e, f);
    let v = g.geometry.values();
    match g.geometry {
        GradientGeometry::Linear { .. } => tiny_skia::LinearGradient::new(
            (v[0], v[1]).into(),
            (v[2], v[3]).into(),
            stops,
            mode,
            ts,
        ),
        // Focal circle (fx, fy, fr) to end circle (cx, cy, r).
        GradientGeometry::Radial { .. } => {
            let (start, end) = ((v[3], v[4]).into(), (v[0], v[1]).into());
            tiny_skia::RadialGradient::new(start, v[5], end, v[2], stops, mode, ts)
        }
    }
}
