//! SDS's re-initialisation of faint or tiny closed paths: a new random circle in place, with
//! the optimiser's parameters and moments of the path reset (a path painted with a gradient
//! gets a gradient of the same kind and stop count, painting as the circle's flat colour).

use super::{ReinitConfig, SdsError};
use crate::optim::Adam;
use crate::scene::{ParamGroup, Params, Scene, Shape};
use crate::stages::styles::random_circle;
use rand::Rng;

/// Shoelace area of a shape's control polygon.
fn control_area(points: &[crate::scene::Point]) -> f32 {
    let n = points.len();
    let mut a = 0.0;
    for i in 0..n {
        let (p, q) = (points[i], points[(i + 1) % n]);
        a += p.x * q.y - q.x * p.y;
    }
    0.5 * a.abs()
}

/// Re-initialises faint / tiny closed cubic paths in place (new random circle) and resets their
/// Adam moments. Returns the number re-initialised.
pub(super) fn reinit_faint<R: Rng>(
    scene: &mut Scene,
    params: &mut Params,
    adam: &mut Adam,
    cfg: &ReinitConfig,
    rng: &mut R,
) -> Result<u32, SdsError> {
    let mut count = 0;
    let mut fill_idx = 0usize;
    let size = scene.width.min(scene.height);
    for i in 0..scene.shapes.len() {
        let sh = &scene.shapes[i];
        let Some(fill) = sh.fill else { continue };
        let faint = fill.a < cfg.min_opacity
            || cfg
                .min_area
                .is_some_and(|m| sh.is_closed() && control_area(&sh.points) < m);
        let same_layout = sh.kind == crate::scene::ShapeKind::ClosedCubic
            && sh.points.len() == 12
            && sh.gradients.as_ref().is_none_or(|g| g.stroke.is_none());
        if faint && same_layout {
            let mut fresh = random_circle(size, rng)?;
            let off = Params::point_offset(scene, i);
            let np = 2 * fresh.points.len();
            let pts = params.get_mut(ParamGroup::Points);
            for (k, p) in fresh.points.iter().enumerate() {
                pts[off + 2 * k] = p.x;
                pts[off + 2 * k + 1] = p.y;
            }
            if let Some(f) = fresh.fill {
                params.get_mut(ParamGroup::Fill)[4 * fill_idx..4 * fill_idx + 4]
                    .copy_from_slice(&f.to_array());
            }
            adam.reset_range(ParamGroup::Points, off..off + np);
            adam.reset_range(ParamGroup::Fill, 4 * fill_idx..4 * fill_idx + 4);
            restart_paint(scene, i, &mut fresh, params, adam);
            scene.shapes[i] = fresh;
            count += 1;
        }
        fill_idx += 1;
    }
    Ok(count)
}

/// When shape `i` is painted with a gradient, gives `fresh` (its replacement) a gradient of the
/// same kind and stops painting as its flat colour, and writes it into `params` (moments
/// reset).
fn restart_paint(scene: &Scene, i: usize, fresh: &mut Shape, params: &mut Params, adam: &mut Adam) {
    let Some(old) = scene.shapes[i]
        .gradients
        .as_ref()
        .and_then(|g| g.fill.as_ref())
    else {
        return;
    };
    let g = crate::vector::fill::restart_like(old, fresh);
    let (og, os) = Params::paint_offset(scene, i);
    let (ng, ns) = (g.geometry.values().len(), 5 * g.stops.len());
    let v = g.params();
    params.get_mut(ParamGroup::PaintGeometry)[og..og + ng].copy_from_slice(&v[..ng]);
    params.get_mut(ParamGroup::PaintStops)[os..os + ns].copy_from_slice(&v[ng..]);
    adam.reset_range(ParamGroup::PaintGeometry, og..og + ng);
    adam.reset_range(ParamGroup::PaintStops, os..os + ns);
    fresh.gradients = Some(Box::new(crate::scene::Gradients {
        fill: Some(g),
        stroke: None,
        texture: None,
    }));
}
