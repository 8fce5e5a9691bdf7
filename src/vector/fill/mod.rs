//! What the vector stage paints fills with: flat colours (the default, the SVGs of before) or
//! one linear or radial gradient per path, optimised with the geometry ([`FillKind`]).
//!
//! A new path's gradient starts as its flat colour (two stops of that colour spanning the
//! path's control box: vertical for `linear`, centred for `radial`), so the first render is the
//! flat one; the optimiser then moves the stops and the geometry
//! ([`crate::scene::ParamGroup::PaintGeometry`], [`crate::scene::ParamGroup::PaintStops`]).
//! A palette (`colors`, `palette`) picks flat colours and is refused with a gradient fill.

use crate::scene::{
    Affine, Gradient, GradientGeometry, GradientStop, Gradients, Rgba, Scene, Shape, Spread,
};
use serde::{Deserialize, Serialize};

/// The fill paint of the paths a run creates.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "snake_case")]
pub enum FillKind {
    /// One colour per path.
    #[default]
    Flat,
    /// A two-or-more-stop linear gradient per path.
    Linear,
    /// A radial gradient per path.
    Radial,
}

impl FillKind {
    /// Whether this is the default (left out of serialised plans and requests).
    pub fn is_flat(&self) -> bool {
        *self == FillKind::Flat
    }

    /// Refuses a palette with a gradient fill (a palette chooses flat colours): the message
    /// follows the field name `fill`.
    pub fn check_with_palette(self, palette: bool) -> Result<(), String> {
        if palette && !self.is_flat() {
            return Err(format!(
                "{} cannot be combined with colors or palette (a palette picks flat colours)",
                self.name()
            ));
        }
        Ok(())
    }

    /// The name as the API and the command line spell it.
    pub fn name(self) -> &'static str {
        match self {
            FillKind::Flat => "flat",
            FillKind::Linear => "linear",
            FillKind::Radial => "radial",
        }
    }

    /// The gradient that paints `shape` exactly as its flat fill does: two stops of the fill
    /// colour across its control box. `None` for `flat` or a shape without a fill.
    pub fn gradient_for(self, shape: &Shape) -> Option<Gradient> {
        let c = shape.fill?;
        let (lo, hi) = shape.control_bounds();
        let (cx, cy) = (0.5 * (lo.x + hi.x), 0.5 * (lo.y + hi.y));
        let geometry = match self {
            FillKind::Flat => return None,
            FillKind::Linear => GradientGeometry::Linear {
                x1: cx,
                y1: lo.y,
                x2: cx,
                y2: hi.y.max(lo.y + 1.0),
            },
            FillKind::Radial => GradientGeometry::Radial {
                cx,
                cy,
                r: (0.5 * (hi.x - lo.x).max(hi.y - lo.y)).max(0.5),
                fx: cx,
                fy: cy,
                fr: 0.0,
            },
        };
        let stop = |offset| GradientStop { offset, color: c };
        Some(Gradient {
            geometry,
            transform: Affine::IDENTITY,
            spread: Spread::Pad,
            stops: vec![stop(0.0), stop(1.0)],
        })
    }

    /// Gives every filled shape of `scene` that has no fill gradient yet its flat-equivalent
    /// gradient (nothing for `flat`). Returns how many shapes got one.
    pub fn paint_new(self, scene: &mut Scene) -> usize {
        let mut n = 0;
        for sh in &mut scene.shapes {
            if fill_gradient(sh).is_some() {
                continue;
            }
            let Some(g) = self.gradient_for(sh) else {
                continue;
            };
            let stroke = sh.gradients.take().and_then(|g| g.stroke);
            sh.gradients = Some(Box::new(Gradients {
                fill: Some(g),
                stroke,
                texture: None,
            }));
            n += 1;
        }
        n
    }
}

/// A gradient of `old`'s kind and stop offsets that paints `shape` as its flat colour (its
/// geometry spans `shape`'s control box): what replaces a re-initialised path's gradient
/// without changing the parameter layout.
pub fn restart_like(old: &Gradient, shape: &Shape) -> Gradient {
    let kind = match old.geometry {
        GradientGeometry::Linear { .. } => FillKind::Linear,
        GradientGeometry::Radial { .. } => FillKind::Radial,
    };
    let mut g = kind.gradient_for(shape).unwrap_or_else(|| old.clone());
    let color = shape.fill.unwrap_or(Rgba::TRANSPARENT);
    g.stops = old
        .stops
        .iter()
        .map(|s| GradientStop {
            offset: s.offset,
            color,
        })
        .collect();
    g
}

/// Decimals of gradient geometry (pixels) and stop offsets in the written SVG.
const GEOMETRY_DECIMALS: i32 = 1;
const OFFSET_DECIMALS: i32 = 2;

/// Makes `scene`'s gradients what a short SVG writes: a transform that only scales uniformly
/// and translates is folded into the geometry; geometry and offsets are rounded
/// ([`GEOMETRY_DECIMALS`], [`OFFSET_DECIMALS`]) and stop colours to 8 bits, so the SVG renders
/// as the scene does; a fill gradient whose stops all have one colour becomes that flat fill.
pub fn tidy_gradients(scene: &mut Scene) {
    for sh in &mut scene.shapes {
        let Some(gs) = sh.gradients.as_deref_mut() else {
            continue;
        };
        for g in [gs.fill.as_mut(), gs.stroke.as_mut()].into_iter().flatten() {
            tidy(g);
        }
        if let Some(g) = &gs.fill
            && g.stops.windows(2).all(|w| w[0].color == w[1].color)
        {
            sh.fill = Some(g.stops[0].color);
            gs.fill = None;
        } else if let (Some(g), Some(f)) = (&gs.fill, &mut sh.fill) {
            *f = g.mean_color();
        }
        if gs.fill.is_none() && gs.stroke.is_none() {
            sh.gradients = None;
        }
    }
}

/// One gradient rounded as [`tidy_gradients`] says.
fn tidy(g: &mut Gradient) {
    g.fold_uniform_transform();
    g.round_geometry(10f32.powi(GEOMETRY_DECIMALS));
    let round = |v: f32, d: i32| {
        let k = 10f32.powi(d);
        (v * k).round() / k
    };
    let mut values: Vec<f32> = g.params();
    let ng = g.geometry.values().len();
    for stop in values[ng..].chunks_exact_mut(5) {
        stop[0] = round(stop[0], OFFSET_DECIMALS);
        for c in &mut stop[1..4] {
            *c = (*c * 255.0).round() / 255.0;
        }
        stop[4] = round(stop[4], 3);
    }
    g.set_params(&values);
}

/// The gradient painting `shape`'s fill, if any.
pub fn fill_gradient(shape: &Shape) -> Option<&Gradient> {
    shape.gradients.as_deref().and_then(|g| g.fill.as_ref())
}

/// The stop alphas of `flat` gradient-paint stops ([`crate::scene::ParamGroup::PaintStops`]
/// layout: `offset, r, g, b, a` per stop).
pub fn stop_alphas(stops: &mut [f32]) -> impl Iterator<Item = &mut f32> {
    stops.iter_mut().skip(4).step_by(5)
}

#[cfg(test)]
mod tests;
