//! Supersampled coverage, the forward-only alternative to exact area coverage
//! ([`Antialias::Supersampled`]): a pixel's coverage is the share of its 16 sample points, the
//! centres of a 4 × 4 grid of sub-cells, that lie inside the fill (by its rule) or the stroke.
//! This is how tiny-skia (resvg's renderer) and Skia's CPU scan converter anti-alias paths
//! (four sub-scanlines sampled at their centres, span ends rounded to quarter pixels), so a
//! pixel-for-pixel comparison with them does not differ on every edge that falls between
//! quarter pixels, where exact coverage and theirs part by up to 1/8.
//!
//! It reuses the exact machinery at 4× resolution: a sub-cell crossed by one straight edge has
//! at least half its area on the side of its centre (a line through a square leaves the larger
//! part on the centre's side), so the winding integral of a sub-cell rounded to an integer is
//! the winding number at its centre, and a stroke's sub-cell coverage of at least ½ says the
//! centre is inside. The geometry is shifted by 1/64 of a sub-cell (tiny-skia's fixed-point
//! step) so that a sample exactly on an edge counts as Skia counts it: inside on a right or
//! bottom edge, outside on a left or top one. A stroke at most one pixel wide is drawn as
//! tiny-skia draws such "hairlines": the coverage of a one-pixel-wide line times the width.
//!
//! [`Antialias::Supersampled`]: super::Antialias::Supersampled

use super::engine::for_each_edge;
use super::geom::{Layer, LayerKind};
use super::real::Real;
use super::stroke;
use super::walk::{Clip, deposit};

/// Sub-cells per pixel side.
const SUB: i32 = 4;
/// Pixel rows drawn at a time.
const CHUNK_ROWS: i32 = 16;
/// The shift, in sub-cells, that breaks ties of samples lying on an edge.
const TIE_SHIFT: f64 = 1.0 / 64.0;

/// Scratch buffers reused across layers.
#[derive(Default)]
pub(crate) struct Scratch<T> {
    acc: Vec<T>,
    inside: Vec<T>,
    poly: Vec<[T; 2]>,
    stroke: stroke::Scratch<T>,
}

fn to_sub<T: Real>(p: [T; 2]) -> [T; 2] {
    let (k, e) = (T::c(SUB as f64), T::c(TIE_SHIFT));
    [p[0] * k + e, p[1] * k + e]
}

/// Writes the supersampled coverage (in `0..=1`, the fill rule applied) of layer `l` over
/// `clip` into `out` (`cw * rows`), [`CHUNK_ROWS`] pixel rows at a time so that the sub-cell
/// buffers stay small whatever the canvas.
pub(crate) fn coverage<T: Real>(l: &Layer<T>, clip: Clip, out: &mut [T], s: &mut Scratch<T>) {
    // A stroke at most a pixel wide is what tiny-skia draws as a hairline: a one-pixel line's
    // coverage (exact here, analytic there) scaled by the width; no sub-cells.
    if l.kind == LayerKind::Stroke && l.radius <= T::c(0.5) {
        let one_px_radius = T::c(0.5);
        stroke::coverage(
            &l.poly,
            l.closed,
            one_px_radius,
            l.style,
            clip,
            out,
            &mut s.stroke,
        );
        let width = l.radius * T::c(2.0);
        out.iter_mut().for_each(|v| *v *= width);
        return;
    }
    let cw = (clip.x1 - clip.x0) as usize;
    let mut y = clip.y0;
    while y < clip.y1 {
        let y1 = (y + CHUNK_ROWS).min(clip.y1);
        let rows = (y - clip.y0) as usize * cw..(y1 - clip.y0) as usize * cw;
        chunk(l, Clip { y0: y, y1, ..clip }, &mut out[rows], s);
        y = y1;
    }
}

fn chunk<T: Real>(l: &Layer<T>, clip: Clip, out: &mut [T], s: &mut Scratch<T>) {
    let sub = Clip {
        x0: clip.x0 * SUB,
        x1: clip.x1 * SUB,
        y0: clip.y0 * SUB,
        y1: clip.y1 * SUB,
    };
    let scw = (sub.x1 - sub.x0) as usize;
    let srows = (sub.y1 - sub.y0) as usize;
    s.inside.clear();
    s.inside.resize(scw * srows, T::zero());
    match l.kind {
        LayerKind::Fill => {
            let stride = scw + 1;
            s.acc.clear();
            s.acc.resize(stride * srows, T::zero());
            let acc = &mut s.acc;
            for_each_edge(l, |a, b| {
                deposit(to_sub(l.verts[a]), to_sub(l.verts[b]), sub, acc, stride)
            });
            let half = T::c(0.5);
            for (arow, irow) in s
                .acc
                .chunks_exact(stride)
                .zip(s.inside.chunks_exact_mut(scw))
            {
                let mut a = T::zero();
                for (v, &da) in irow.iter_mut().zip(arow) {
                    a += da;
                    let winding = (a + half).floor_i32();
                    let inside = if l.even_odd {
                        winding % 2 != 0
                    } else {
                        winding != 0
                    };
                    *v = if inside { T::one() } else { T::zero() };
                }
            }
        }
        LayerKind::Stroke => {
            s.poly.clear();
            s.poly.extend(l.poly.iter().map(|&p| to_sub(p)));
            let r = l.radius * T::c(SUB as f64);
            stroke::coverage(
                &s.poly,
                l.closed,
                r,
                l.style,
                sub,
                &mut s.inside,
                &mut s.stroke,
            );
            let half = T::c(0.5);
            for v in &mut s.inside {
                *v = if *v >= half { T::one() } else { T::zero() };
            }
        }
    }
    let cw = (clip.x1 - clip.x0) as usize;
    let w = T::c(1.0 / (SUB * SUB) as f64);
    out.fill(T::zero());
    for (sy, irow) in s.inside.chunks_exact(scw).enumerate() {
        let orow = &mut out[(sy / SUB as usize) * cw..][..cw];
        for (sx, &v) in irow.iter().enumerate() {
            orow[sx / SUB as usize] += v * w;
        }
    }
}
