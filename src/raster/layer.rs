//! Groups as layers: opacity, clip and mask, forward and backward.
//!
//! A group's shapes are painted onto a transparent layer `G` (premultiplied), which is then
//! composited over the layer below `P` with the per-pixel factor `m = opacity × f`:
//! `out = P (1 - m G.a) + m G` (a group with another blend mode mixes the colours first, see
//! `blend`). `f` is the product of the group's clip chain and mask chain,
//! drawn once per scene over the whole canvas by this same rasteriser:
//! - a clip's shapes are filled opaque (each by its fill rule) over transparency and its factor
//!   is the alpha, i.e. the union `1 - Π(1 - coverage)`; a clip's own clip multiplies it;
//! - a mask's content is drawn over transparency; its factor is the alpha or the luminance
//!   `0.2125 r + 0.7154 g + 0.0721 b` of the premultiplied colour (as resvg); a mask's own
//!   mask multiplies it.
//!
//! The backward pass differentiates the compositing exactly: the layer below gets
//! `g (1 - m G.a)`, the group's layer `m g` (minus `m Σ g P` on its alpha), the opacity
//! `Σ f Σ_c g_c (G_c - G.a P_c)`. Clip and mask content are constants (not parameters), so the
//! clipped and masked shapes and the opacity get exact gradients. The tape keeps `P` and `G`
//! (8 floats per pixel of the group's box) per group and band.

use super::Antialias;
use super::blend::{blend_px, blend_px_back};
use super::engine::{
    BandGrad, BandTape, GradScratch, PaintScratch, Rec, RecKind, backward_layer, box_clip,
    paint_layer,
};
use super::geom::{Layer, SceneT};
use super::real::Real;
use super::walk::Clip;
use crate::scene::{BlendMode, Clip as ClipPath, Content, Group, Mask, MaskKind, Rgba, Scene};

/// A group in the working precision, with its clip and mask drawn.
#[derive(Clone, Debug)]
pub(crate) struct GroupT<T> {
    pub start: usize,
    pub end: usize,
    pub opacity: T,
    pub blend: BlendMode,
    /// Clip × mask per canvas pixel (row-major, `width × height`); `None` when neither.
    pub factor: Option<Vec<T>>,
}

/// The groups of `scene`, their clips and masks drawn at flattening tolerance `tol`.
pub(crate) fn groups_t<T: Real>(scene: &Scene, tol: f32, aa: Antialias) -> Vec<GroupT<T>> {
    let (w, h) = (scene.width, scene.height);
    scene
        .groups
        .iter()
        .map(|g| GroupT {
            start: g.start,
            end: g.end,
            opacity: T::of(g.opacity),
            blend: g.blend,
            factor: group_factor(g, w, h, tol, aa),
        })
        .collect()
}

fn group_factor<T: Real>(g: &Group, w: u32, h: u32, tol: f32, aa: Antialias) -> Option<Vec<T>> {
    let clip = g.clip.as_deref().map(|c| clip_factor(c, w, h, tol, aa));
    let mask = g.mask.as_deref().map(|m| mask_factor(m, w, h, tol, aa));
    match (clip, mask) {
        (Some(mut c), Some(m)) => {
            c.iter_mut().zip(&m).for_each(|(a, b)| *a *= *b);
            Some(c)
        }
        (c, m) => c.or(m),
    }
}

/// Draws `content` over transparency on a `w × h` canvas (premultiplied RGBA).
fn draw<T: Real>(content: &Content, w: u32, h: u32, tol: f32, aa: Antialias) -> Vec<T> {
    let scene = Scene {
        width: w,
        height: h,
        background: Rgba::TRANSPARENT,
        shapes: content.shapes.clone(),
        groups: content.groups.clone(),
    };
    super::render_t(&SceneT::<T>::from_scene_aa(&scene, tol, aa))
}

fn clip_factor<T: Real>(c: &ClipPath, w: u32, h: u32, tol: f32, aa: Antialias) -> Vec<T> {
    let mut opaque = c.content.clone();
    for s in &mut opaque.shapes {
        s.fill = Some(Rgba::BLACK);
        s.stroke = None;
        s.gradients = None;
    }
    let mut f: Vec<T> = draw::<T>(&opaque, w, h, tol, aa)
        .chunks_exact(4)
        .map(|p| p[3])
        .collect();
    if let Some(inner) = &c.clip {
        let g = clip_factor::<T>(inner, w, h, tol, aa);
        f.iter_mut().zip(&g).for_each(|(a, b)| *a *= *b);
    }
    f
}

fn mask_factor<T: Real>(m: &Mask, w: u32, h: u32, tol: f32, aa: Antialias) -> Vec<T> {
    let img = draw::<T>(&m.content, w, h, tol, aa);
    let mut f: Vec<T> = match m.kind {
        MaskKind::Alpha => img.chunks_exact(4).map(|p| p[3]).collect(),
        MaskKind::Luminance => {
            let [wr, wg, wb] = MaskKind::LUMINANCE_WEIGHTS.map(T::c);
            img.chunks_exact(4)
                .map(|p| wr * p[0] + wg * p[1] + wb * p[2])
                .collect()
        }
    };
    if let Some(inner) = &m.mask {
        let g = mask_factor::<T>(inner, w, h, tol, aa);
        f.iter_mut().zip(&g).for_each(|(a, b)| *a *= *b);
    }
    f
}

/// One step of painting a scene with groups.
#[derive(Clone, Copy, Debug)]
enum Op {
    Paint(usize),
    Push(usize),
    Pop(usize),
}

/// The steps in paint order, and each group's pixel box (the union of its layers' boxes).
fn plan<T: Real>(sc: &SceneT<T>, ls: &[Layer<T>]) -> (Vec<Op>, Vec<[i32; 4]>) {
    let mut ops = Vec::with_capacity(ls.len() + 2 * sc.groups.len());
    let mut boxes = vec![[i32::MAX, i32::MAX, i32::MIN, i32::MIN]; sc.groups.len()];
    let mut open: Vec<usize> = Vec::new();
    let mut next = 0;
    for (li, l) in ls.iter().enumerate() {
        while let Some(&gi) = open.last()
            && sc.groups[gi].end <= l.shape
        {
            ops.push(Op::Pop(gi));
            open.pop();
        }
        while next < sc.groups.len() && sc.groups[next].start <= l.shape {
            // A group whose shapes painted no layer draws nothing.
            if sc.groups[next].end > l.shape {
                ops.push(Op::Push(next));
                open.push(next);
            }
            next += 1;
        }
        ops.push(Op::Paint(li));
        for &gi in &open {
            let b = &mut boxes[gi];
            b[0] = b[0].min(l.bbox[0]);
            b[1] = b[1].min(l.bbox[1]);
            b[2] = b[2].max(l.bbox[2]);
            b[3] = b[3].max(l.bbox[3]);
        }
    }
    ops.extend(open.iter().rev().map(|&gi| Op::Pop(gi)));
    (ops, boxes)
}

const EMPTY: Clip = Clip {
    x0: 0,
    x1: 0,
    y0: 0,
    y1: 0,
};

/// The rows of `clip` as (band offset of the row's first pixel, its factor `f` without the
/// opacity: `None` for 1).
fn rows<T: Real>(
    g: &GroupT<T>,
    width: usize,
    clip: Clip,
    y0: i32,
) -> impl Iterator<Item = (usize, Option<&[T]>)> {
    let (x0, x1) = (clip.x0.max(0) as usize, clip.x1.max(0) as usize);
    (clip.y0..clip.y1).map(move |y| {
        let base = 4 * ((y - y0) as usize * width + x0);
        let row = y as usize * width;
        (base, g.factor.as_ref().map(|f| &f[row + x0..row + x1]))
    })
}

/// [`super::engine`]'s band painter for a scene with groups.
pub(crate) fn forward_band<T: Real>(
    sc: &SceneT<T>,
    ls: &[Layer<T>],
    (y0, y1): (i32, i32),
    img: &mut [T],
    mut tape: Option<&mut BandTape<T>>,
    st: &mut PaintScratch<T>,
) {
    let w = sc.width as usize;
    let (ops, boxes) = plan(sc, ls);
    // Layers of the open groups, innermost last; `img` is below them all.
    let mut stack: Vec<Vec<T>> = Vec::new();
    let mut spare: Vec<Vec<T>> = Vec::new();
    for op in ops {
        match op {
            Op::Paint(li) => {
                let top = stack.last_mut().map_or(&mut *img, |b| &mut b[..]);
                paint_layer(sc, li, &ls[li], (y0, y1), top, tape.as_deref_mut(), st);
            }
            Op::Push(gi) => {
                let clip = box_clip(boxes[gi], y0, y1).unwrap_or(EMPTY);
                let mut buf = spare.pop().unwrap_or_default();
                buf.resize(img.len(), T::zero());
                let cw = 4 * (clip.x1 - clip.x0).max(0) as usize;
                for (base, _) in rows(&sc.groups[gi], w, clip, y0) {
                    buf[base..base + cw].fill(T::zero());
                }
                stack.push(buf);
                if let Some(t) = tape.as_deref_mut() {
                    let kind = RecKind::Push;
                    t.recs.push(Rec {
                        kind,
                        layer: gi as u32,
                        clip,
                        offset: 0,
                        edges: 0,
                    });
                }
            }
            Op::Pop(gi) => {
                let Some(buf) = stack.pop() else { continue };
                let clip = box_clip(boxes[gi], y0, y1).unwrap_or(EMPTY);
                let below = stack.last_mut().map_or(&mut *img, |b| &mut b[..]);
                if let Some(t) = tape.as_deref_mut() {
                    let (kind, offset) = (RecKind::Pop, t.group.len());
                    t.recs.push(Rec {
                        kind,
                        layer: gi as u32,
                        clip,
                        offset,
                        edges: 0,
                    });
                }
                let mut rec = tape.as_deref_mut().map(|t| &mut t.group);
                let group = &sc.groups[gi];
                let cw = 4 * (clip.x1 - clip.x0).max(0) as usize;
                for (base, f) in rows(group, w, clip, y0) {
                    let (p, g) = (&mut below[base..base + cw], &buf[base..base + cw]);
                    if let Some(r) = rec.as_deref_mut() {
                        r.extend_from_slice(p);
                        r.extend_from_slice(g);
                    }
                    composite_row(p, g, group, f);
                }
                spare.push(buf);
            }
        }
    }
}

/// [`super::engine`]'s band backward pass for a scene with groups: `g` is the gradient of the
/// band's image on entry and of the background under everything on return.
pub(crate) fn backward_band<T: Real>(
    sc: &SceneT<T>,
    ls: &[Layer<T>],
    y0: i32,
    tape: &BandTape<T>,
    g: &mut Vec<T>,
    out: &mut BandGrad<T>,
    st: &mut GradScratch<T>,
) {
    let w = sc.width as usize;
    // Gradients of the layers below the current one, innermost last.
    let mut stack: Vec<Vec<T>> = Vec::new();
    let mut spare: Vec<Vec<T>> = Vec::new();
    for rec in tape.recs.iter().rev() {
        let gi = rec.layer as usize;
        match rec.kind {
            RecKind::Paint => backward_layer(sc, ls, y0, tape, rec, g, out, st),
            RecKind::Pop => {
                let mut inner = spare.pop().unwrap_or_default();
                inner.resize(g.len(), T::zero());
                let group = &sc.groups[gi];
                let cw = 4 * (rec.clip.x1 - rec.clip.x0).max(0) as usize;
                let mut k = rec.offset;
                let mut dop = T::zero();
                for (base, f) in rows(group, w, rec.clip, y0) {
                    let (p, gl) = (&tape.group[k..k + cw], &tape.group[k + cw..k + 2 * cw]);
                    k += 2 * cw;
                    let grads = (&mut g[base..base + cw], &mut inner[base..base + cw]);
                    dop += composite_row_backward(p, gl, group, f, grads);
                }
                out.dopacity[gi] += dop;
                stack.push(std::mem::replace(g, inner));
            }
            RecKind::Push => {
                if let Some(below) = stack.pop() {
                    spare.push(std::mem::replace(g, below));
                }
            }
        }
    }
}

/// `p = p (1 - m g.a) + m g` over one row, `m = opacity × f` per pixel (or the group's blend
/// mode).
fn composite_row<T: Real>(p: &mut [T], g: &[T], group: &GroupT<T>, f: Option<&[T]>) {
    let opacity = group.opacity;
    for (i, (pp, gp)) in p.chunks_exact_mut(4).zip(g.chunks_exact(4)).enumerate() {
        if gp[3] == T::zero() {
            continue;
        }
        let m = f.map_or(opacity, |f| opacity * f[i]);
        if !group.blend.is_normal() {
            blend_px(group.blend, pp, gp, m);
            continue;
        }
        let keep = T::one() - m * gp[3];
        for c in 0..4 {
            pp[c] = pp[c] * keep + m * gp[c];
        }
    }
}

/// Backward of [`composite_row`] given what lay below (`p`) and the group's layer (`gl`):
/// `go` (the gradient of the result) becomes the gradient of `p`, `inner` is set to the
/// gradient of the layer; returns the gradient of the opacity.
fn composite_row_backward<T: Real>(
    p: &[T],
    gl: &[T],
    group: &GroupT<T>,
    f: Option<&[T]>,
    (go, inner): (&mut [T], &mut [T]),
) -> T {
    let opacity = group.opacity;
    let mut dop = T::zero();
    let px = p.chunks_exact(4).zip(gl.chunks_exact(4));
    let grads = go.chunks_exact_mut(4).zip(inner.chunks_exact_mut(4));
    for (i, ((p, gl), (go, gi))) in px.zip(grads).enumerate() {
        let fi = f.map_or(T::one(), |f| f[i]);
        let m = opacity * fi;
        if !group.blend.is_normal() {
            dop += blend_px_back(group.blend, (p, gl, m), go, gi) * fi;
            continue;
        }
        let (mut dm, mut gp) = (T::zero(), T::zero());
        for c in 0..4 {
            dm += go[c] * (gl[c] - gl[3] * p[c]);
            gp += go[c] * p[c];
            gi[c] = m * go[c];
        }
        gi[3] -= m * gp;
        dop += dm * fi;
        let keep = T::one() - m * gl[3];
        go.iter_mut().for_each(|v| *v *= keep);
    }
    dop
}
