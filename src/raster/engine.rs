//! Banded forward and backward passes over the layers of a scene.
//!
//! The canvas is cut into horizontal bands that are processed in parallel (rayon); inside a
//! band, layers are painted in order, each only over its bounding box ∩ band.

use super::geom::{Layer, LayerKind, SceneT, polyline_backward};
use super::real::Real;
use super::stroke;
use super::walk::{Clip, deposit, edge_grad};
use rayon::prelude::*;

/// What the forward pass remembers per band for the backward pass: for every layer touching
/// the band, the raw accumulated winding integral `A` and the colour underneath (`dst`) over
/// the layer's box ∩ band; for every group closed in the band, its layer and what lay under it
/// (`group`, see `layer`). Memory is proportional to the painted area.
#[derive(Clone, Debug, Default)]
pub(crate) struct BandTape<T> {
    pub recs: Vec<Rec>,
    pub area: Vec<T>,
    pub dst: Vec<T>,
    pub group: Vec<T>,
}

/// One step of the forward pass in a band.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum RecKind {
    /// Layer `layer` painted.
    Paint,
    /// Group `layer` opened (a transparent layer started).
    Push,
    /// Group `layer` closed (composited onto the layer below).
    Pop,
}

#[derive(Clone, Copy, Debug)]
pub(crate) struct Rec {
    pub kind: RecKind,
    pub layer: u32,
    pub clip: Clip,
    pub offset: usize,
}

/// Row range of each band.
pub(crate) fn bands(height: u32) -> Vec<(i32, i32)> {
    let threads = rayon::current_num_threads().max(1) as u32;
    let target = (threads * 4).max(1);
    let bh = height.div_ceil(target).max(16);
    let mut out = Vec::new();
    let mut y = 0;
    while y < height {
        let y1 = (y + bh).min(height);
        out.push((y as i32, y1 as i32));
        y = y1;
    }
    out
}

fn premul_bg<T: Real>(bg: [T; 4]) -> [T; 4] {
    [bg[0] * bg[3], bg[1] * bg[3], bg[2] * bg[3], bg[3]]
}

/// Coverage of a fill from its winding integral `A`: `min(|A|, 1)` (nonzero), or the distance
/// of `A` to the nearest even integer (even-odd: 0 on even windings, 1 on odd ones, linear in
/// between, exact where one edge crosses a pixel).
#[inline]
fn coverage<T: Real>(a: T, even_odd: bool) -> T {
    if even_odd {
        (a - T::c(2.0) * (a * T::c(0.5)).round()).abs()
    } else {
        a.abs().min(T::one())
    }
}

/// `d coverage / dA` (see [`coverage`]; 0 where the nonzero coverage saturates).
#[inline]
fn coverage_slope<T: Real>(a: T, even_odd: bool) -> T {
    let r = if even_odd {
        a - T::c(2.0) * (a * T::c(0.5)).round()
    } else if a.abs() < T::one() {
        a
    } else {
        return T::zero();
    };
    if r < T::zero() { -T::one() } else { T::one() }
}

/// A pixel box `[x0, y0, x1, y1)` ∩ the band rows `y0..y1`, if not empty.
pub(crate) fn box_clip(bbox: [i32; 4], y0: i32, y1: i32) -> Option<Clip> {
    let [bx0, by0, bx1, by1] = bbox;
    let c = Clip {
        x0: bx0,
        x1: bx1,
        y0: by0.max(y0),
        y1: by1.min(y1),
    };
    (c.x0 < c.x1 && c.y0 < c.y1).then_some(c)
}

fn layer_clip<T>(l: &Layer<T>, y0: i32, y1: i32) -> Option<Clip> {
    box_clip(l.bbox, y0, y1)
}

fn for_each_edge<T: Real>(l: &Layer<T>, mut f: impl FnMut(usize, usize)) {
    for &(start, len) in &l.contours {
        let (s, n) = (start as usize, len as usize);
        for k in 0..n {
            f(s + k, s + (k + 1) % n);
        }
    }
}

/// Scratch buffers of one band's forward pass.
#[derive(Default)]
pub(crate) struct PaintScratch<T> {
    acc: Vec<T>,
    vals: Vec<T>,
    stroke: stroke::Scratch<T>,
}

/// Paints one band. `img` holds the band's rows (4 channels, full width).
fn forward_band<T: Real>(
    sc: &SceneT<T>,
    ls: &[Layer<T>],
    (y0, y1): (i32, i32),
    img: &mut [T],
    mut tape: Option<&mut BandTape<T>>,
) {
    let bg = premul_bg(sc.bg);
    for px in img.chunks_exact_mut(4) {
        px.copy_from_slice(&bg);
    }
    let mut st = PaintScratch::default();
    if let Some(t) = tape.as_deref_mut() {
        let total: usize = ls
            .iter()
            .filter_map(|l| layer_clip(l, y0, y1))
            .map(|c| ((c.x1 - c.x0) * (c.y1 - c.y0)) as usize)
            .sum();
        t.recs.clear();
        t.area.clear();
        t.dst.clear();
        t.group.clear();
        t.area.reserve(total);
        t.dst.reserve(4 * total);
    }
    if !sc.groups.is_empty() {
        super::layer::forward_band(sc, ls, (y0, y1), img, tape, &mut st);
        return;
    }
    for (li, l) in ls.iter().enumerate() {
        paint_layer(sc.width, li, l, (y0, y1), img, tape.as_deref_mut(), &mut st);
    }
}

/// Paints layer `li` onto `img` (the band's rows of the layer it belongs to).
pub(crate) fn paint_layer<T: Real>(
    width: u32,
    li: usize,
    l: &Layer<T>,
    (y0, y1): (i32, i32),
    img: &mut [T],
    tape: Option<&mut BandTape<T>>,
    st: &mut PaintScratch<T>,
) {
    let Some(clip) = layer_clip(l, y0, y1) else {
        return;
    };
    let w = width as usize;
    let cw = (clip.x1 - clip.x0) as usize;
    let rows = (clip.y1 - clip.y0) as usize;
    // Per-pixel value the coverage is a function of: the winding integral A for fills
    // (coverage min(|A|, 1) or its even-odd fold), the coverage itself for strokes. Written
    // straight into the tape when there is one.
    let (buf, mut dst_buf) = match tape {
        Some(t) => {
            t.recs.push(Rec {
                kind: RecKind::Paint,
                layer: li as u32,
                clip,
                offset: t.area.len(),
            });
            (&mut t.area, Some(&mut t.dst))
        }
        None => {
            st.vals.clear();
            (&mut st.vals, None)
        }
    };
    let start = buf.len();
    buf.resize(start + cw * rows, T::zero());
    let out = &mut buf[start..];
    match l.kind {
        LayerKind::Fill => {
            let stride = cw + 1;
            let acc = &mut st.acc;
            acc.clear();
            acc.resize(stride * rows, T::zero());
            for_each_edge(l, |a, b| deposit(l.verts[a], l.verts[b], clip, acc, stride));
            for (arow, vrow) in acc.chunks_exact(stride).zip(out.chunks_exact_mut(cw)) {
                let mut s = T::zero();
                for (v, &dv) in vrow.iter_mut().zip(arow) {
                    s += dv;
                    *v = s;
                }
            }
        }
        LayerKind::Stroke => {
            stroke::coverage(
                &l.poly,
                l.closed,
                l.radius,
                l.style,
                clip,
                out,
                &mut st.stroke,
            );
        }
    }
    let fill = l.kind == LayerKind::Fill;
    let eo = l.even_odd;
    let [r, g, b, ca] = l.color;
    for row in 0..rows {
        let vrow = &out[row * cw..(row + 1) * cw];
        let iy = (clip.y0 - y0) as usize + row;
        let base = 4 * (iy * w + clip.x0 as usize);
        let prow = &mut img[base..base + 4 * cw];
        if let Some(d) = dst_buf.as_deref_mut() {
            d.extend_from_slice(prow);
        }
        for (&v, p) in vrow.iter().zip(prow.chunks_exact_mut(4)) {
            let cov = if fill { coverage(v, eo) } else { v };
            let alpha = cov * ca;
            if alpha > T::zero() {
                let keep = T::one() - alpha;
                p[0] = r * alpha + p[0] * keep;
                p[1] = g * alpha + p[1] * keep;
                p[2] = b * alpha + p[2] * keep;
                p[3] = alpha + p[3] * keep;
            }
        }
    }
}

/// Forward over all bands; returns the premultiplied image and (optionally) the tapes.
pub(crate) fn forward<T: Real>(
    sc: &SceneT<T>,
    ls: &[Layer<T>],
    with_tape: bool,
    mut recycled: Vec<BandTape<T>>,
) -> (Vec<T>, Vec<BandTape<T>>) {
    let w = sc.width as usize;
    let bs = bands(sc.height);
    let mut img = vec![T::zero(); 4 * w * sc.height as usize];
    let mut chunks: Vec<&mut [T]> = Vec::with_capacity(bs.len());
    let mut rest: &mut [T] = &mut img;
    for &(y0, y1) in &bs {
        let (head, tail) = rest.split_at_mut(4 * w * (y1 - y0) as usize);
        chunks.push(head);
        rest = tail;
    }
    recycled.resize_with(bs.len(), BandTape::default);
    recycled.truncate(bs.len());
    let tapes: Vec<BandTape<T>> = chunks
        .into_par_iter()
        .zip(bs.par_iter())
        .zip(recycled.into_par_iter())
        .map(|((chunk, &band), mut t)| {
            forward_band(sc, ls, band, chunk, with_tape.then_some(&mut t));
            t
        })
        .collect();
    (img, tapes)
}

/// Per-band gradient partial sums.
pub(crate) struct BandGrad<T> {
    /// Per layer, per outline vertex.
    dverts: Vec<Vec<[T; 2]>>,
    /// Per layer, straight RGBA.
    dcolor: Vec<[T; 4]>,
    /// Per layer, stroke half-width.
    dradius: Vec<T>,
    dbg: [T; 4],
    /// Per group, its opacity.
    pub dopacity: Vec<T>,
}

/// Scratch buffers of one band's backward pass.
#[derive(Default)]
pub(crate) struct GradScratch<T> {
    gbuf: Vec<T>,
    stroke: stroke::Scratch<T>,
}

fn backward_band<T: Real>(
    sc: &SceneT<T>,
    ls: &[Layer<T>],
    y0: i32,
    tape: &BandTape<T>,
    dimg: &[T],
) -> BandGrad<T> {
    let mut g: Vec<T> = dimg.to_vec();
    let mut out = BandGrad {
        dverts: vec![Vec::new(); ls.len()],
        dcolor: vec![[T::zero(); 4]; ls.len()],
        dradius: vec![T::zero(); ls.len()],
        dbg: [T::zero(); 4],
        dopacity: vec![T::zero(); sc.groups.len()],
    };
    let mut st = GradScratch::default();
    if sc.groups.is_empty() {
        for rec in tape.recs.iter().rev() {
            backward_layer(sc.width, ls, y0, tape, rec, &mut g, &mut out, &mut st);
        }
    } else {
        super::layer::backward_band(sc, ls, y0, tape, &mut g, &mut out, &mut st);
    }
    let bg = sc.bg;
    for gp in g.chunks_exact(4) {
        out.dbg[0] += gp[0] * bg[3];
        out.dbg[1] += gp[1] * bg[3];
        out.dbg[2] += gp[2] * bg[3];
        out.dbg[3] += gp[0] * bg[0] + gp[1] * bg[1] + gp[2] * bg[2] + gp[3];
    }
    out
}

/// Backward through the painting of one layer (`rec`): `g` (the gradient of the band's rows of
/// the layer painted onto) becomes the gradient of what lay under it; the layer's colour,
/// outline and width gradients are added to `out`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn backward_layer<T: Real>(
    width: u32,
    ls: &[Layer<T>],
    y0: i32,
    tape: &BandTape<T>,
    rec: &Rec,
    g: &mut [T],
    out: &mut BandGrad<T>,
    st: &mut GradScratch<T>,
) {
    let w = width as usize;
    let li = rec.layer as usize;
    let l = &ls[li];
    let clip = rec.clip;
    let cw = (clip.x1 - clip.x0) as usize;
    let rows = (clip.y1 - clip.y0) as usize;
    // Every entry is written in the pixel loop below; only grow, never clear.
    let gbuf = &mut st.gbuf;
    if gbuf.len() < cw * rows {
        gbuf.resize(cw * rows, T::zero());
    }
    let [cr, cg, cb, ca] = l.color;
    let fill = l.kind == LayerKind::Fill;
    let eo = l.even_odd;
    let mut dc = [T::zero(); 4];
    let mut any = false;
    for row in 0..rows {
        let iy = (clip.y0 - y0) as usize + row;
        let base = 4 * (iy * w + clip.x0 as usize);
        let grow = &mut g[base..base + 4 * cw];
        let off = rec.offset + row * cw;
        let arow = &tape.area[off..off + cw];
        let drow = &tape.dst[4 * off..4 * (off + cw)];
        let gb = &mut gbuf[row * cw..(row + 1) * cw];
        for (((&a, d), gp), gbv) in arow
            .iter()
            .zip(drow.chunks_exact(4))
            .zip(grow.chunks_exact_mut(4))
            .zip(gb.iter_mut())
        {
            *gbv = T::zero();
            if a == T::zero() {
                // No coverage and no edge inside: nothing flows through this layer here.
                continue;
            }
            let cov = if fill { coverage(a, eo) } else { a };
            let alpha = cov * ca;
            let galpha = gp[0] * (cr - d[0])
                + gp[1] * (cg - d[1])
                + gp[2] * (cb - d[2])
                + gp[3] * (T::one() - d[3]);
            dc[0] += gp[0] * alpha;
            dc[1] += gp[1] * alpha;
            dc[2] += gp[2] * alpha;
            dc[3] += galpha * cov;
            let slope = if fill {
                coverage_slope(a, eo)
            } else {
                T::one()
            };
            let v = galpha * ca * slope;
            any |= v != T::zero();
            *gbv = v;
            let keep = T::one() - alpha;
            for c in gp.iter_mut() {
                *c *= keep;
            }
        }
    }
    for c in 0..4 {
        out.dcolor[li][c] += dc[c];
    }
    let gb = &st.gbuf[..cw * rows];
    if any && !fill {
        let dp = &mut out.dverts[li];
        if dp.is_empty() {
            dp.resize(l.poly.len(), [T::zero(); 2]);
        }
        let (poly, closed, style) = (&l.poly, l.closed, l.style);
        out.dradius[li] +=
            stroke::backward(poly, closed, l.radius, style, clip, gb, dp, &mut st.stroke);
    } else if any {
        let dv = &mut out.dverts[li];
        if dv.is_empty() {
            dv.resize(l.verts.len(), [T::zero(); 2]);
        }
        for_each_edge(l, |ia, ib| {
            let (mut d0, mut d1) = ([T::zero(); 2], [T::zero(); 2]);
            edge_grad(l.verts[ia], l.verts[ib], clip, gb, cw, &mut d0, &mut d1);
            for c in 0..2 {
                dv[ia][c] += d0[c];
                dv[ib][c] += d1[c];
            }
        });
    }
}

/// Gradients in the layout of [`crate::scene::Params`], in the working precision.
#[derive(Clone, Debug)]
pub(crate) struct GradT<T> {
    pub points: Vec<T>,
    pub fill: Vec<T>,
    pub stroke: Vec<T>,
    pub width: Vec<T>,
    pub bg: [T; 4],
    pub opacity: Vec<T>,
}

/// Backward over all bands, then the chain rule back to scene parameters.
pub(crate) fn backward<T: Real>(
    sc: &SceneT<T>,
    ls: &[Layer<T>],
    tapes: &[BandTape<T>],
    dimg: &[T],
) -> GradT<T> {
    let w = sc.width as usize;
    let bs = bands(sc.height);
    let parts: Vec<BandGrad<T>> = bs
        .par_iter()
        .zip(tapes.par_iter())
        .map(|(&(y0, y1), tape)| {
            let lo = 4 * w * y0 as usize;
            let hi = 4 * w * y1 as usize;
            backward_band(sc, ls, y0, tape, &dimg[lo..hi])
        })
        .collect();
    // Reduce over bands.
    let mut dverts: Vec<Vec<[T; 2]>> = ls
        .iter()
        .map(|l| vec![[T::zero(); 2]; l.verts.len().max(l.poly.len())])
        .collect();
    let mut dcolor = vec![[T::zero(); 4]; ls.len()];
    let mut dradius = vec![T::zero(); ls.len()];
    let mut dbg = [T::zero(); 4];
    let mut dopacity = vec![T::zero(); sc.groups.len()];
    for p in &parts {
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
