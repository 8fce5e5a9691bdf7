//! Banded forward and backward passes over the layers of a scene.
//!
//! The canvas is cut into horizontal bands that are processed in parallel (rayon); inside a
//! band, layers are painted in order, each only over its bounding box ∩ band.

use super::Antialias;
use super::composite::{Area, composite, composite_back};
use super::geom::{Layer, LayerKind, SceneT};
use super::grad::{GradT, reduce};
use super::paint::{Flat, GradientShade};
use super::real::Real;
use super::stroke;
use super::texture::TextureShade;
use super::walk::{Clip, Piece, deposit, deposit_record, edge_grad_recorded};
use rayon::prelude::*;

/// What the forward pass remembers per band for the backward pass: for every layer touching
/// the band, the raw accumulated winding integral `A` and the colour underneath (`dst`) over
/// the layer's box ∩ band; for every group closed in the band, its layer and what lay under it
/// (`group`, see `layer`); for every fill, the pieces of its edges inside the band (`pieces`,
/// one range of it per edge in `spans`), so that the backward pass does not walk them again.
/// Memory is proportional to the painted area and the outlines' length.
#[derive(Clone, Debug, Default)]
pub(crate) struct BandTape<T> {
    pub recs: Vec<Rec>,
    pub area: Vec<T>,
    pub dst: Vec<T>,
    pub group: Vec<T>,
    pub pieces: Vec<Piece<T>>,
    pub spans: Vec<(u32, u32)>,
    /// The band's image and its loss gradient in [`forward_backward`] (kept for reuse).
    pub img: Vec<T>,
    pub grad: Vec<T>,
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
    /// A painted fill's first edge in [`BandTape::spans`].
    pub edges: usize,
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

/// Calls `f(a, b)` with the vertex indices of every edge of every contour of `l`.
pub(crate) fn for_each_edge<T: Real>(l: &Layer<T>, mut f: impl FnMut(usize, usize)) {
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
    sampled: super::sampled::Scratch<T>,
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
        t.pieces.clear();
        t.spans.clear();
        t.area.reserve(total);
        t.dst.reserve(4 * total);
    }
    if !sc.groups.is_empty() {
        super::layer::forward_band(sc, ls, (y0, y1), img, tape, &mut st);
        return;
    }
    for (li, l) in ls.iter().enumerate() {
        paint_layer(sc, li, l, (y0, y1), img, tape.as_deref_mut(), &mut st);
    }
}

/// Paints layer `li` onto `img` (the band's rows of the layer it belongs to).
pub(crate) fn paint_layer<T: Real>(
    sc: &SceneT<T>,
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
    let w = sc.width as usize;
    let cw = (clip.x1 - clip.x0) as usize;
    let rows = (clip.y1 - clip.y0) as usize;
    // Per-pixel value the coverage is a function of: the winding integral A for fills
    // (coverage min(|A|, 1) or its even-odd fold), the coverage itself for strokes. Written
    // straight into the tape when there is one.
    let (buf, dst_buf, record) = match tape {
        Some(t) => {
            t.recs.push(Rec {
                kind: RecKind::Paint,
                layer: li as u32,
                clip,
                offset: t.area.len(),
                edges: t.spans.len(),
            });
            (
                &mut t.area,
                Some(&mut t.dst),
                Some((&mut t.pieces, &mut t.spans)),
            )
        }
        None => {
            st.vals.clear();
            (&mut st.vals, None, None)
        }
    };
    let start = buf.len();
    buf.resize(start + cw * rows, T::zero());
    let out = &mut buf[start..];
    match l.kind {
        // Forward-only: a pass with a tape (a backward to follow) keeps exact coverage.
        _ if sc.aa == Antialias::Supersampled && record.is_none() => {
            super::sampled::coverage(l, clip, out, &mut st.sampled);
        }
        LayerKind::Fill => {
            let stride = cw + 1;
            let acc = &mut st.acc;
            acc.clear();
            acc.resize(stride * rows, T::zero());
            match record {
                Some((pieces, spans)) => for_each_edge(l, |a, b| {
                    let start = pieces.len() as u32;
                    deposit_record(l.verts[a], l.verts[b], clip, acc, pieces);
                    spans.push((start, pieces.len() as u32));
                }),
                None => for_each_edge(l, |a, b| deposit(l.verts[a], l.verts[b], clip, acc, stride)),
            }
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
    let at = Area {
        clip,
        y0,
        w,
        fill: l.kind == LayerKind::Fill,
        even_odd: l.even_odd,
    };
    if let Some(ti) = l.texture {
        return composite(&at, out, img, dst_buf, &TextureShade(&sc.textures[ti]));
    }
    match l.paint {
        None => {
            let flat = Flat {
                c: l.color,
                dc: [T::zero(); 4],
            };
            composite(&at, out, img, dst_buf, &flat);
        }
        Some(pi) => composite(&at, out, img, dst_buf, &GradientShade::new(&sc.paints[pi])),
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
    let chunks = band_chunks(&mut img, w, &bs);
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

/// `img` (whole rows, 4 channels, `w` wide, from the first band's first row) cut into the
/// rows of each band of `bs` (consecutive).
fn band_chunks<'a, T>(img: &'a mut [T], w: usize, bs: &[(i32, i32)]) -> Vec<&'a mut [T]> {
    let mut chunks = Vec::with_capacity(bs.len());
    let mut rest = img;
    for &(y0, y1) in bs {
        let (head, tail) = rest.split_at_mut(4 * w * (y1 - y0) as usize);
        chunks.push(head);
        rest = tail;
    }
    chunks
}

/// The bands of [`forward`] that meet the rows `rows`, painted as [`forward`] paints them (so
/// their pixels are [`forward`]'s bit for bit). Returns the first row painted and the painted
/// rows (whole bands, full width); no rows when `rows` meets no band.
pub(crate) fn forward_rows<T: Real>(
    sc: &SceneT<T>,
    ls: &[Layer<T>],
    rows: std::ops::Range<i32>,
) -> (i32, Vec<T>) {
    let w = sc.width as usize;
    let bs: Vec<(i32, i32)> = bands(sc.height)
        .into_iter()
        .filter(|&(y0, y1)| y0 < rows.end && rows.start < y1)
        .collect();
    let (Some(&(first, _)), Some(&(_, last))) = (bs.first(), bs.last()) else {
        return (0, Vec::new());
    };
    let mut img = vec![T::zero(); 4 * w * (last - first) as usize];
    band_chunks(&mut img, w, &bs)
        .into_par_iter()
        .zip(bs.par_iter())
        .for_each(|(chunk, &band)| forward_band(sc, ls, band, chunk, None));
    (first, img)
}

/// Per-band gradient partial sums.
pub(crate) struct BandGrad<T> {
    /// Per layer, per outline vertex.
    pub dverts: Vec<Vec<[T; 2]>>,
    /// Per layer, straight RGBA.
    pub dcolor: Vec<[T; 4]>,
    /// Per layer, stroke half-width.
    pub dradius: Vec<T>,
    /// Per gradient of the scene, its parameters (empty until touched).
    pub dpaint: Vec<Vec<T>>,
    pub dbg: [T; 4],
    /// Per group, its opacity.
    pub dopacity: Vec<T>,
}

/// Scratch buffers of one band's backward pass.
#[derive(Default)]
pub(crate) struct GradScratch<T> {
    gbuf: Vec<T>,
    stroke: stroke::Scratch<T>,
}

/// The backward pass over one band; `g` holds dL/d(output) of the band's rows and is used up.
fn backward_band<T: Real>(
    sc: &SceneT<T>,
    ls: &[Layer<T>],
    y0: i32,
    tape: &BandTape<T>,
    mut g: Vec<T>,
) -> (BandGrad<T>, Vec<T>) {
    let mut out = BandGrad {
        dverts: vec![Vec::new(); ls.len()],
        dcolor: vec![[T::zero(); 4]; ls.len()],
        dradius: vec![T::zero(); ls.len()],
        dpaint: vec![Vec::new(); sc.paints.len()],
        dbg: [T::zero(); 4],
        dopacity: vec![T::zero(); sc.groups.len()],
    };
    let mut st = GradScratch::default();
    if sc.groups.is_empty() {
        for rec in tape.recs.iter().rev() {
            backward_layer(sc, ls, y0, tape, rec, &mut g, &mut out, &mut st);
        }
    } else {
        super::layer::backward_band(sc, ls, y0, tape, &mut g, &mut out, &mut st);
    }
    let bg = sc.bg;
    for gp in g.chunks_exact(4) {
        // Where nothing reaches the background (under opaque paint) the sums would take zeros.
        if super::composite::all_zero(gp) {
            continue;
        }
        out.dbg[0] += gp[0] * bg[3];
        out.dbg[1] += gp[1] * bg[3];
        out.dbg[2] += gp[2] * bg[3];
        out.dbg[3] += gp[0] * bg[0] + gp[1] * bg[1] + gp[2] * bg[2] + gp[3];
    }
    (out, g)
}

/// Backward through the painting of one layer (`rec`): `g` (the gradient of the band's rows of
/// the layer painted onto) becomes the gradient of what lay under it; the layer's colour or
/// gradient, outline and width gradients are added to `out`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn backward_layer<T: Real>(
    sc: &SceneT<T>,
    ls: &[Layer<T>],
    y0: i32,
    tape: &BandTape<T>,
    rec: &Rec,
    g: &mut [T],
    out: &mut BandGrad<T>,
    st: &mut GradScratch<T>,
) {
    let li = rec.layer as usize;
    let l = &ls[li];
    let clip = rec.clip;
    let cw = (clip.x1 - clip.x0) as usize;
    let rows = (clip.y1 - clip.y0) as usize;
    // Every entry is written in the pixel loop below; only grow, never clear.
    if st.gbuf.len() < cw * rows {
        st.gbuf.resize(cw * rows, T::zero());
    }
    let fill = l.kind == LayerKind::Fill;
    let at = Area {
        clip,
        y0,
        w: sc.width as usize,
        fill,
        even_odd: l.even_odd,
    };
    let gb = &mut st.gbuf[..cw * rows];
    let any = match (l.texture, l.paint) {
        (Some(ti), _) => composite_back(
            &at,
            rec.offset,
            tape,
            g,
            gb,
            &mut TextureShade(&sc.textures[ti]),
        ),
        (None, None) => {
            let mut flat = Flat {
                c: l.color,
                dc: [T::zero(); 4],
            };
            let any = composite_back(&at, rec.offset, tape, g, gb, &mut flat);
            for c in 0..4 {
                out.dcolor[li][c] += flat.dc[c];
            }
            any
        }
        (None, Some(pi)) => {
            let mut sh = GradientShade::new(&sc.paints[pi]);
            let any = composite_back(&at, rec.offset, tape, g, gb, &mut sh);
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
        let mut k = rec.edges;
        for_each_edge(l, |ia, ib| {
            let (mut d0, mut d1) = ([T::zero(); 2], [T::zero(); 2]);
            let (s, e) = tape.spans[k];
            k += 1;
            let pieces = &tape.pieces[s as usize..e as usize];
            edge_grad_recorded(l.verts[ia], l.verts[ib], pieces, gb, &mut d0, &mut d1);
            for c in 0..2 {
                dv[ia][c] += d0[c];
                dv[ib][c] += d1[c];
            }
        });
    }
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
            backward_band(sc, ls, y0, tape, dimg[lo..hi].to_vec()).0
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
/// gradients and the band tapes for reuse. Scenes with groups take the same path: a group's
/// layers live within the band and its clip and mask factors are drawn per scene beforehand
/// (`SceneT::groups`), so every band is independent.
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
            // Every pixel is painted (the background first); the loss gets a zeroed gradient.
            let mut img = std::mem::take(&mut tape.img);
            img.resize(4 * px.len(), T::zero());
            forward_band(sc, ls, (y0, y1), &mut img, Some(&mut tape));
            let mut g = std::mem::take(&mut tape.grad);
            g.clear();
            g.resize(img.len(), T::zero());
            let l = loss(px, &img, &mut g);
            let (grad, g) = backward_band(sc, ls, y0, &tape, g);
            (tape.img, tape.grad) = (img, g);
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
