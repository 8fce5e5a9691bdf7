//! The input adjoint of [`super::conv2d`].
//!
//! For stride 1 it is the forward convolution of the output gradient with the flipped,
//! transposed kernel ([`flip_transpose`]), padded by `k − 1 − p`. For larger strides the padded
//! input is viewed as `s²` *phase planes* (`P_{a,b}[c, i, j] = x_pad[c, s·i + a, s·j + b]`,
//! each `hq × wq`); on the output grid of pitch `wq` tap `(kh, kw)` reads plane
//! `(kh mod s, kw mod s)` at offset `(kh / s) · wq + kw / s`, so each phase plane of the
//! gradient gathers `Σ_{taps of that phase} W_tapᵀ · dgrid` from shifted views of one buffer
//! (`tap_gemm`), with no zero-dilated gradient.

use super::{COL, ConvGeom, TILE_FLOATS, conv2d};
use crate::models::kernels::{
    KernelError, KernelResult, SyncPtr, check_len, gemm_strided, winograd,
};
use gemm::Parallelism;
use rayon::prelude::*;

impl ConvGeom {
    /// Height and width of one phase plane.
    fn phase_hw(&self) -> (usize, usize) {
        let (hp, wp) = self.padded();
        (hp.div_ceil(self.stride), wp.div_ceil(self.stride))
    }

    /// Taps `(kh, kw, phase, in-plane offset)`.
    fn taps(&self) -> Vec<(usize, usize, usize, usize)> {
        let (s, k) = (self.stride, self.k);
        let (_, wq) = self.phase_hw();
        let mut v = Vec::with_capacity(k * k);
        for kh in 0..k {
            for kw in 0..k {
                v.push((kh, kw, (kh % s) * s + kw % s, (kh / s) * wq + kw / s));
            }
        }
        v
    }
}

/// One GEMM operand of a tap: `lhs[i, j] = lhs[i·rs + j·cs]` (`m × kk`), and where its
/// right-hand side starts in the shared source buffer.
struct Tap<'a> {
    lhs: &'a [f32],
    lhs_rs: usize,
    lhs_cs: usize,
    src_off: usize,
}

/// `out[i, q] = Σ_taps lhs_t[i, :] · src[:, src_off_t + q]` for `q < n`, where `out` rows have
/// pitch `out_rs` and `src` rows pitch `src_rs` (an empty tap list writes zeros).
///
/// With several taps, each column tile first gathers its `taps · kk` source rows (contiguous
/// runs, so plain copies) into one `[taps·kk, cols]` block and runs a single GEMM of depth
/// `taps · kk` against the packed `[m, taps·kk]` left-hand side: one long accumulation in
/// registers instead of `taps` short ones that each reload the output tile.
#[allow(clippy::too_many_arguments)]
fn tap_gemm(
    m: usize,
    kk: usize,
    n: usize,
    out: &mut [f32],
    out_rs: usize,
    taps: &[Tap],
    src: &[f32],
    src_rs: usize,
) -> KernelResult<()> {
    if m == 0 || n == 0 {
        return Ok(());
    }
    // Bounds of every access, checked once so the GEMMs below cannot go out of range.
    if (m - 1) * out_rs + n > out.len() {
        return Err(KernelError::Window {
            op: "conv2d",
            rows: m,
            cols: n,
            len: out.len(),
        });
    }
    if kk == 0 {
        return Err(KernelError::Geometry {
            op: "conv2d",
            reason: "zero GEMM depth".into(),
        });
    }
    for t in taps {
        let lhs_end = (m - 1) * t.lhs_rs + (kk - 1) * t.lhs_cs + 1;
        let src_end = t.src_off + (kk - 1) * src_rs + n;
        if lhs_end > t.lhs.len() || src_end > src.len() {
            return Err(KernelError::Geometry {
                op: "conv2d",
                reason: "tap view out of range".into(),
            });
        }
    }
    let depth = taps.len() * kk;
    // left-hand side packed as [m, taps·kk] (only needed when gathering)
    let packed: Vec<f32> = if taps.len() > 1 {
        let mut p = vec![0f32; m * depth];
        p.par_chunks_mut(depth).enumerate().for_each(|(i, row)| {
            for (ti, t) in taps.iter().enumerate() {
                for j in 0..kk {
                    row[ti * kk + j] = t.lhs[i * t.lhs_rs + j * t.lhs_cs];
                }
            }
        });
        p
    } else {
        Vec::new()
    };
    let tn = (TILE_FLOATS / (m + depth)).clamp(256, 2048).min(n);
    let tiles = n.div_ceil(tn);
    let out_ptr = SyncPtr(out.as_mut_ptr());
    (0..tiles).into_par_iter().for_each(|t_idx| {
        let q0 = t_idx * tn;
        let cols = tn.min(n - q0);
        let dst = out_ptr;
        match taps {
            [] => {
                for i in 0..m {
                    // SAFETY: row i, columns [q0, q0 + cols) lie inside `out` (checked above)
                    // and belong to this tile only.
                    unsafe {
                        let row = dst.get().add(i * out_rs + q0);
                        std::slice::from_raw_parts_mut(row, cols).fill(0.0);
                    }
                }
            }
            [t] => {
                // SAFETY: all views were bounds-checked above; tiles write disjoint columns.
                unsafe {
                    gemm_strided(
                        (m, cols, kk),
                        (dst.get().add(q0), out_rs),
                        false,
                        (t.lhs.as_ptr(), t.lhs_rs, t.lhs_cs),
                        (src.as_ptr().add(t.src_off + q0), src_rs, 1),
                        1.0,
                        Parallelism::None,
                    );
                }
            }
            _ => {
                COL.with_borrow_mut(|col| {
                    col.resize(depth * cols, 0.0);
                    for (ti, t) in taps.iter().enumerate() {
                        for j in 0..kk {
                            let s0 = t.src_off + j * src_rs + q0;
                            col[(ti * kk + j) * cols..(ti * kk + j + 1) * cols]
                                .copy_from_slice(&src[s0..s0 + cols]);
                        }
                    }
                    // SAFETY: the output view was bounds-checked above; `packed` is m × depth and
                    // `col` depth × cols; tiles write disjoint columns.
                    unsafe {
                        gemm_strided(
                            (m, cols, depth),
                            (dst.get().add(q0), out_rs),
                            false,
                            (packed.as_ptr(), depth, 1),
                            (col.as_ptr(), cols, 1),
                            1.0,
                            Parallelism::None,
                        );
                    }
                });
            }
        }
    });
    Ok(())
}

/// Gradient of [`conv2d`] with respect to its input: `dy [b, co, ho, wo]`, `weight
/// [co, ci, k, k]`; returns `[b, ci, h, w]`. The weights' gradient is never formed.
pub fn conv2d_input_grad(g: &ConvGeom, dy: &[f32], weight: &[f32]) -> KernelResult<Vec<f32>> {
    conv2d_input_grad_prepared(g, dy, weight, None)
}

/// The flipped, transposed kernel `W'[ci, co, k−1−kh, k−1−kw] = W[co, ci, kh, kw]`: the input
/// gradient of a stride-1 convolution is the convolution of `dy` with it.
pub fn flip_transpose(weight: &[f32], co: usize, ci: usize, k: usize) -> Vec<f32> {
    let mut wt = vec![0f32; co * ci * k * k];
    for (c, dst) in wt.chunks_exact_mut(co * k * k).enumerate() {
        for o in 0..co {
            let src = &weight[(o * ci + c) * k * k..(o * ci + c + 1) * k * k];
            let d = &mut dst[o * k * k..(o + 1) * k * k];
            for (i, v) in src.iter().enumerate() {
                d[k * k - 1 - i] = *v;
            }
        }
    }
    wt
}

/// [`conv2d_input_grad`] with the Winograd transform of [`flip_transpose`]`(weight)` when the
/// caller caches it (used for 3×3 stride-1 geometries).
pub fn conv2d_input_grad_prepared(
    g: &ConvGeom,
    dy: &[f32],
    weight: &[f32],
    wino_flipped: Option<&[f32]>,
) -> KernelResult<Vec<f32>> {
    let ConvGeom {
        b,
        ci,
        h,
        w,
        co,
        k,
        stride: s,
        pad,
    } = *g;
    let (ho, wo) = g.out_hw();
    check_len("conv2d", "output gradient", dy.len(), b * co * ho * wo)?;
    check_len("conv2d", "weight", weight.len(), co * ci * k * k)?;
    if s == 1 && pad.iter().all(|&p| p < k) {
        // dx = correlation of dy with the flipped, transposed kernel, padded by k − 1 − p
        let gt = ConvGeom::new(b, co, ho, wo, ci, k, 1, pad.map(|p| k - 1 - p))?;
        if let (Some(u), true) = (wino_flipped, winograd::applies(&gt)) {
            return winograd::conv2d(&gt, dy, u, None);
        }
        let wt = flip_transpose(weight, co, ci, k);
        return conv2d(&gt, dy, &wt, None);
    }
    let (hq, wq) = g.phase_hw();
    let plane = hq * wq;
    let kk2 = k * k;
    let taps_geo = g.taps();
    let front = taps_geo.iter().map(|t| t.3).max().unwrap_or(0);
    let pitch = front + plane;
    let mut dgrid = vec![0f32; co * pitch];
    let mut dphases = vec![0f32; s * s * ci * plane];
    let mut dx = vec![0f32; b * ci * h * w];
    for bi in 0..b {
        let dy_b = &dy[bi * co * ho * wo..(bi + 1) * co * ho * wo];
        dgrid
            .par_chunks_mut(pitch)
            .zip(dy_b.par_chunks(ho * wo))
            .for_each(|(row, src)| {
                for y in 0..ho {
                    let at = front + y * wq;
                    row[at..at + wo].copy_from_slice(&src[y * wo..(y + 1) * wo]);
                }
            });
        for phase in 0..s * s {
            // Wᵀ of each tap in this phase: lhs[i = ci, j = co] = weight[co, ci, kh, kw]
            let taps: Vec<Tap> = taps_geo
                .iter()
                .filter(|t| t.2 == phase)
                .map(|&(kh, kw, _, off)| Tap {
                    lhs: &weight[kh * k + kw..],
                    lhs_rs: kk2,
                    lhs_cs: ci * kk2,
                    src_off: front - off,
                })
                .collect();
            let out = &mut dphases[phase * ci * plane..(phase + 1) * ci * plane];
            tap_gemm(ci, co, plane, out, plane, &taps, &dgrid, pitch)?;
        }
        // gather the padded-input gradient back from the phase planes, dropping the padding
        let (pt, pl) = (pad[0], pad[2]);
        let dphases = &dphases;
        dx[bi * ci * h * w..(bi + 1) * ci * h * w]
            .par_chunks_mut(h * w)
            .enumerate()
            .for_each(|(c, dst)| {
                for y in 0..h {
                    let yp = y + pt;
                    let (i, a) = (yp / s, yp % s);
                    for x in 0..w {
                        let xp = x + pl;
                        let (j, bb) = (xp / s, xp % s);
                        let phase = a * s + bb;
                        dst[y * w + x] = dphases[(phase * ci + c) * plane + i * wq + j];
                    }
                }
            });
    }
    Ok(dx)
}
