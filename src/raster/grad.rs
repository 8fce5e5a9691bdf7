//! The bands' partial gradients summed and taken back to the scene's parameters.

use super::engine::BandGrad;
use super::geom::{Layer, LayerKind, SceneT, polyline_backward};
use super::real::Real;

/// Gradients in the layout of [`crate::scene::Params`], in the working precision.
#[derive(Clone, Debug)]
pub(crate) struct GradT<T> {
    pub points: Vec<T>,
    pub fill: Vec<T>,
    pub stroke: Vec<T>,
    pub width: Vec<T>,
    pub bg: [T; 4],
    /// Every gradient parameter, in [`crate::scene::paint::scene_gradient_params`] order.
    pub paint: Vec<T>,
    /// Per group, its opacity.
    pub opacity: Vec<T>,
}

/// The bands' gradient-parameter gradients, summed and concatenated in parameter order.
fn reduce_paint<T: Real>(sc: &SceneT<T>, parts: &[BandGrad<T>]) -> Vec<T> {
    let mut out = Vec::new();
    for (pi, p) in sc.paints.iter().enumerate() {
        let start = out.len();
        out.resize(start + p.num_params(), T::zero());
        for part in parts {
            for (acc, v) in out[start..].iter_mut().zip(&part.dpaint[pi]) {
                *acc += *v;
            }
        }
    }
    out
}

/// Sums the bands' partial gradients (in band order) and takes them back to the parameters.
pub(crate) fn reduce<T: Real>(sc: &SceneT<T>, ls: &[Layer<T>], parts: &[BandGrad<T>]) -> GradT<T> {
    let mut dverts: Vec<Vec<[T; 2]>> = ls
        .iter()
        .map(|l| vec![[T::zero(); 2]; l.verts.len().max(l.poly.len())])
        .collect();
    let mut dcolor = vec![[T::zero(); 4]; ls.len()];
    let mut dradius = vec![T::zero(); ls.len()];
    let mut dbg = [T::zero(); 4];
    let mut dopacity = vec![T::zero(); sc.groups.len()];
    for p in parts {
        for (acc, v) in dopacity.iter_mut().zip(&p.dopacity) {
            *acc += *v;
        }
        for (li, dv) in p.dverts.iter().enumerate() {
            for (acc, v) in dverts[li].iter_mut().zip(dv) {
                acc[0] += v[0];
                acc[1] += v[1];
            }
            for c in 0..4 {
                dcolor[li][c] += p.dcolor[li][c];
            }
            dradius[li] += p.dradius[li];
        }
        for c in 0..4 {
            dbg[c] += p.dbg[c];
        }
    }
    let paint = reduce_paint(sc, parts);
    // Parameter layout offsets.
    let mut pt_off = Vec::with_capacity(sc.shapes.len());
    let mut fill_idx = Vec::with_capacity(sc.shapes.len());
    let mut stroke_idx = Vec::with_capacity(sc.shapes.len());
    let (mut np, mut nf, mut ns) = (0, 0, 0);
    for s in &sc.shapes {
        pt_off.push(np);
        np += 2 * s.pts.len();
        fill_idx.push(nf);
        if s.fill.is_some() {
            nf += 1;
        }
        stroke_idx.push(ns);
        if s.stroke.is_some() {
            ns += 1;
        }
    }
    let mut grad = GradT {
        points: vec![T::zero(); np],
        fill: vec![T::zero(); 4 * nf],
        stroke: vec![T::zero(); 4 * ns],
        width: vec![T::zero(); ns],
        bg: dbg,
        paint,
        opacity: dopacity,
    };
    for (li, l) in ls.iter().enumerate() {
        let s = &sc.shapes[l.shape];
        let dpts = &mut grad.points[pt_off[l.shape]..pt_off[l.shape] + 2 * s.pts.len()];
        match l.kind {
            LayerKind::Fill => {
                polyline_backward(s, &dverts[li], dpts);
                let k = 4 * fill_idx[l.shape];
                for c in 0..4 {
                    grad.fill[k + c] += dcolor[li][c];
                }
            }
            LayerKind::Stroke => {
                let dr = dradius[li];
                polyline_backward(s, &dverts[li], dpts);
                let k = stroke_idx[l.shape];
                for c in 0..4 {
                    grad.stroke[4 * k + c] += dcolor[li][c];
                }
                // r = max(w, 0) / 2; widths of valid scenes are >= 0 (right derivative at 0).
                grad.width[k] += T::c(0.5) * dr;
            }
        }
    }
    grad
}
