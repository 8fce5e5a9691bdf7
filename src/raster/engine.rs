//! Banded forward and backward passes over the layers of a scene.
//!
//! The canvas is cut into horizontal bands that are processed in parallel (rayon); inside a
//! band, layers are painted in order, each only over its bounding box ∩ band.

use super::geom::{Layer, LayerKind, SceneT, polyline_backward};
use super::paint::{Flat, GradientShade, Shade};
use super::real::Real;
use super::stroke;
use super::walk::{Clip, deposit, edge_grad};
use rayon::prelude::*;

/// What the forward pass remembers per band for the backward pass: for every layer touching
/// the band, the raw accumulated winding integral `A` and the colour underneath (`dst`) over
/// the layer's box ∩ band. Memory is proportional to the painted area.
#[derive(Clone, Debug, Default)]
pub(crate) struct BandTape<T> {
    pub recs: Vec<Rec>,
    pub area: Vec<T>,
    pub dst: Vec<T>,
}

#[derive(Clone, Copy, Debug)]
pub(crate) struct Rec {
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

fn premul_bg<T: Real>([r, g, b, a]: [T; 4]) -> [T; 4] {
    [r * a, g * a, b * a, a]
}

#[inline]
fn coverage<T: Real>(a: T) -> T {
    a.abs().min(T::one())
}

fn layer_clip<T>(l: &Layer<T>, y0: i32, y1: i32) -> Option<Clip> {
    let [x0, by0, x1, by1] = l.bbox;
    let (y0, y1) = (by0.max(y0), by1.min(y1));
    (x0 < x1 && y0 < y1).then_some(Clip { x0, x1, y0, y1 })
}

fn for_each_edge<T: Real>(l: &Layer<T>, mut f: impl FnMut(usize, usize)) {
    for &(start, len) in &l.contours {
        let (s, n) = (start as usize, len as usize);
        for k in 0..n {
            f(s + k, s + (k + 1) % n);
        }
    }
}

/// Paints one band. `img` holds the band's rows (4 channels, full width).
fn forward_band<T: Real>(
    sc: &SceneT<T>,
    ls: &[Layer<T>],
    (y0, y1): (i32, i32),
    img: &mut [T],
    mut tape: Option<&mut BandTape<T>>,
) {
    let w = sc.width as usize;
    let bg = premul_bg(sc.bg);
    for px in img.chunks_exact_mut(4) {
        px.copy_from_slice(&bg);
    }
    let mut acc: Vec<T> = Vec::new();
    let mut vals: Vec<T> = Vec::new();
    let mut scratch = stroke::Scratch::default();
    if let Some(t) = tape.as_deref_mut() {
        let total: usize = ls
            .iter()
            .filter_map(|l| layer_clip(l, y0, y1))
            .map(|c| ((c.x1 - c.x0) * (c.y1 - c.y0)) as usize)
            .sum();
        t.recs.clear();
        t.area.clear();
        t.dst.clear();
        t.area.reserve(total);
        t.dst.reserve(4 * total);
    }
    for (li, l) in ls.iter().enumerate() {
        let Some(clip) = layer_clip(l, y0, y1) else {
            continue;
        };
        let cw = (clip.x1 - clip.x0) as usize;
        let rows = (clip.y1 - clip.y0) as usize;
        // Per-pixel value the coverage is a function of: the winding integral A for fills
        // (coverage min(|A|, 1)), the coverage itself for strokes. Written straight into the
        // tape when there is one.
        let (buf, dst_buf) = match tape.as_deref_mut() {
            Some(t) => {
                t.recs.push(Rec {
                    layer: li as u32,
                    clip,
                    offset: t.area.len(),
                });
                (&mut t.area, Some(&mut t.dst))
            }
            None => {
                vals.clear();
                (&mut vals, None)
            }
        };
        let start = buf.len();
        buf.resize(start + cw * rows, T::zero());
        let out = &mut buf[start..];
        match l.kind {
            LayerKind::Fill => {
                let stride = cw + 1;
                acc.clear();
                acc.resize(stride * rows, T::zero());
                for_each_edge(l, |a, b| {
                    deposit(l.verts[a], l.verts[b], clip, &mut acc, stride)
                });
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
                    &mut scratch,
                );
            }
        }
        let fill = l.kind == LayerKind::Fill;
        let at = Area { clip, y0, w, fill };
        let dst = dst_buf;
        match l.paint {
            None => composite(
                &at,
                out,
                img,
                dst,
                &Flat {
                    c: l.color,
                    dc: [T::zero(); 4],
                },
            ),
            Some(pi) => composite(&at, out, img, dst, &GradientShade::new(&sc.paints[pi])),
        }
    }
}

/// Where a layer is composited within a band: its clip, the band's first row and the canvas
/// width, and whether `out` holds winding integrals (fills) or coverages (strokes).
struct Area {
    clip: Clip,
    y0: i32,
    w: usize,
    fill: bool,
}

/// Source-over of one layer's per-pixel values `out` onto the band `img`, recording the colour
/// underneath into `dst` when taping.
#[inline(always)]
fn composite<T: Real, S: Shade<T>>(
    at: &Area,
    out: &[T],
    img: &mut [T],
    mut dst: Option<&mut Vec<T>>,
    shade: &S,
) {
    let clip = at.clip;
    let cw = (clip.x1 - clip.x0) as usize;
    for row in 0..(clip.y1 - clip.y0) as usize {
        let vrow = &out[row * cw..(row + 1) * cw];
        let iy = (clip.y0 - at.y0) as usize + row;
        let base = 4 * (iy * at.w + clip.x0 as usize);
        let prow = &mut img[base..base + 4 * cw];
        if let Some(d) = dst.as_deref_mut() {
            d.extend_from_slice(prow);
        }
        let y = clip.y0 + row as i32;
        for (ix, (&v, p)) in vrow.iter().zip(prow.chunks_exact_mut(4)).enumerate() {
            let cov = if at.fill { coverage(v) } else { v };
            if cov == T::zero() {
                continue;
            }
            let [r, g, b, ca] = shade.color(clip.x0 + ix as i32, y);
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
struct BandGrad<T> {
    /// Per layer, per outline vertex.
    dverts: Vec<Vec<[T; 2]>>,
    /// Per layer, straight RGBA.
    dcolor: Vec<[T; 4]>,
    /// Per layer, stroke half-width.
    dradius: Vec<T>,
    /// Per gradient of the scene, its parameters (empty until touched).
    dpaint: Vec<Vec<T>>,
    dbg: [T; 4],
}

/// The backward pass over one band; `g` holds dL/d(output) of the band's rows and is used up.
fn backward_band<T: Real>(
    sc: &SceneT<T>,
    ls: &[Layer<T>],
    y0: i32,
    tape: &BandTape<T>,
    mut g: Vec<T>,
) -> BandGrad<T> {
    let w = sc.width as usize;
    let mut out = BandGrad {
        dverts: vec![Vec::new(); ls.len()],
        dcolor: vec![[T::zero(); 4]; ls.len()],
        dradius: vec![T::zero(); ls.len()],
        dpaint: vec![Vec::new(); sc.paints.len()],
        dbg: [T::zero(); 4],
    };
    let mut gbuf: Vec<T> = Vec::new();
    let mut scratch = stroke::Scratch::default();
    for rec in tape.recs.iter().rev() {
        let li = rec.layer as usize;
        let l = &ls[li];
        let clip = rec.clip;
        let cw = (clip.x1 - clip.x0) as usize;
        let rows = (clip.y1 - clip.y0) as usize;
        // Every entry is written in the pixel loop below; only grow, never clear.
        if gbuf.len() < cw * rows {
            gbuf.resize(cw * rows, T::zero());
        }
        let fill = l.kind == LayerKind::Fill;
        let at = Area { clip, y0, w, fill };
        let gb = &mut gbuf[..cw * rows];
        let any = match l.paint {
            None => {
                let mut flat = Flat {
                    c: l.color,
                    dc: [T::zero(); 4],
                };
                let any = composite_back(&at, rec.offset, tape, &mut g, gb, &mut flat);
                for c in 0..4 {
                    out.dcolor[li][c] += flat.dc[c];
                }
                any
            }
            Some(pi) => {
                let mut sh = GradientShade::new(&sc.paints[pi]);
                let any = composite_back(&at, rec.offset, tape, &mut g, gb, &mut sh);
                let dp = &mut out.dpaint[pi];
                if dp.is_empty() {
                    dp.resize(sh.d.len(), T::zero());
                }
                for (acc, v) in dp.iter_mut().zip(&sh.d) {
                    *acc += *v;
                }
                any
            }
        };
        if any && !fill {
            let dp = &mut out.dverts[li];
            if dp.is_empty() {
                dp.resize(l.poly.len(), [T::zero(); 2]);
            }
            out.dradius[li] += stroke::backward(
                &l.poly,
                l.closed,
                l.radius,
                l.style,
                clip,
                &gbuf[..cw * rows],
                dp,
                &mut scratch,
            );
        } else if any {
            let dv = &mut out.dverts[li];
            if dv.is_empty() {
                dv.resize(l.verts.len(), [T::zero(); 2]);
            }
            for_each_edge(l, |ia, ib| {
                let (mut d0, mut d1) = ([T::zero(); 2], [T::zero(); 2]);
                edge_grad(
                    l.verts[ia],
                    l.verts[ib],
                    clip,
                    &gbuf[..cw * rows],
                    cw,
                    &mut d0,
                    &mut d1,
                );
                for c in 0..2 {
                    dv[ia][c] += d0[c];
                    dv[ib][c] += d1[c];
                }
            });
        }
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

/// The backward of [`composite`] for one layer: takes `dL/d out` of the band (`g`, updated to
/// `dL/d below`), gives the colour source its gradients and writes `dL/d value` per pixel into
/// `gbuf` (the winding integral for fills, the coverage for strokes). Returns whether any of
/// those is non-zero.
#[inline(always)]
fn composite_back<T: Real, S: Shade<T>>(
    at: &Area,
    offset: usize,
    tape: &BandTape<T>,
    g: &mut [T],
    gbuf: &mut [T],
    shade: &mut S,
) -> bool {
    let (clip, fill) = (at.clip, at.fill);
    let cw = (clip.x1 - clip.x0) as usize;
    let mut any = false;
    for row in 0..(clip.y1 - clip.y0) as usize {
        let iy = (clip.y0 - at.y0) as usize + row;
        let base = 4 * (iy * at.w + clip.x0 as usize);
        let grow = &mut g[base..base + 4 * cw];
        let off = offset + row * cw;
        let arow = &tape.area[off..off + cw];
        let drow = &tape.dst[4 * off..4 * (off + cw)];
        let gb = &mut gbuf[row * cw..(row + 1) * cw];
        let y = clip.y0 + row as i32;
        for (ix, (((&a, d), gp), gbv)) in arow
            .iter()
            .zip(drow.chunks_exact(4))
            .zip(grow.chunks_exact_mut(4))
            .zip(gb.iter_mut())
            .enumerate()
        {
            *gbv = T::zero();
            if a == T::zero() {
                // No coverage and no edge inside: nothing flows through this layer here.
                continue;
            }
            let x = clip.x0 + ix as i32;
            let [cr, cg, cb, ca] = shade.color(x, y);
            let cov = if fill { coverage(a) } else { a };
            let alpha = cov * ca;
            let galpha = gp[0] * (cr - d[0])
                + gp[1] * (cg - d[1])
                + gp[2] * (cb - d[2])
                + gp[3] * (T::one() - d[3]);
            shade.grad(
                x,
                y,
                [gp[0] * alpha, gp[1] * alpha, gp[2] * alpha, galpha * cov],
            );
            if !fill || a.abs() < T::one() {
                let dcov = galpha * ca;
                let v = if fill && a < T::zero() { -dcov } else { dcov };
                any |= v != T::zero();
                *gbv = v;
            }
            let keep = T::one() - alpha;
            for c in gp.iter_mut() {
                *c *= keep;
            }
        }
    }
    any
}

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
            backward_band(sc, ls, y0, tape, dimg[lo..hi].to_vec())
        })
        .collect();
    reduce(sc, ls, &parts)
}

/// A loss of one band: given the band's pixel range (indices into the image, row-major), its
/// rendered premultiplied RGBA and a zeroed buffer of the same length, writes
/// dL/d(rendered RGBA) into the buffer and returns the band's share of the loss.
pub(crate) type BandLoss<'a, T> = dyn Fn(std::ops::Range<usize>, &[T], &mut [T]) -> f64 + Sync + 'a;

/// [`forward`] with a tape, `loss` and [`backward`] fused band by band: one parallel pass, with
/// the loss computed in parallel too. The gradients are those of [`backward`] given the
/// per-band loss gradients; returns the loss (the band shares summed in band order), the
/// gradients and the band tapes for reuse.
pub(crate) fn forward_backward<T: Real>(
    sc: &SceneT<T>,
    ls: &[Layer<T>],
    mut recycled: Vec<BandTape<T>>,
    loss: &BandLoss<'_, T>,
) -> (f64, GradT<T>, Vec<BandTape<T>>) {
    let w = sc.width as usize;
    let bs = bands(sc.height);
    recycled.resize_with(bs.len(), BandTape::default);
    recycled.truncate(bs.len());
    let done: Vec<(f64, BandGrad<T>, BandTape<T>)> = bs
        .par_iter()
        .zip(recycled.into_par_iter())
        .map(|(&(y0, y1), mut tape)| {
            let px = w * y0 as usize..w * y1 as usize;
            let mut img = vec![T::zero(); 4 * px.len()];
            forward_band(sc, ls, (y0, y1), &mut img, Some(&mut tape));
            let mut g = vec![T::zero(); img.len()];
            let l = loss(px, &img, &mut g);
            let grad = backward_band(sc, ls, y0, &tape, g);
            (l, grad, tape)
        })
        .collect();
    let mut total = 0.0;
    let mut parts = Vec::with_capacity(done.len());
    let mut tapes = Vec::with_capacity(done.len());
    for (l, g, t) in done {
        total += l;
        parts.push(g);
        tapes.push(t);
    }
    (total, reduce(sc, ls, &parts), tapes)
}

/// Sums the bands' partial gradients (in band order) and takes them back to the parameters.
fn reduce<T: Real>(sc: &SceneT<T>, ls: &[Layer<T>], parts: &[BandGrad<T>]) -> GradT<T> {
    let mut dverts: Vec<Vec<[T; 2]>> = ls
        .iter()
        .map(|l| vec![[T::zero(); 2]; l.verts.len().max(l.poly.len())])
        .collect();
    let mut dcolor = vec![[T::zero(); 4]; ls.len()];
    let mut dradius = vec![T::zero(); ls.len()];
    let mut dbg = [T::zero(); 4];
    for p in parts {
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
