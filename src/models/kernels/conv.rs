//! 2-D convolution on the CPU, with its input adjoint (the gradient with respect to the input).
//!
//! Forward: 3×3 stride-1 geometries go to Winograd F(2×2, 3×3) ([`winograd`]); every other
//! geometry runs a row-tiled im2col GEMM ([`conv2d_im2col`]): tiles of output rows in parallel,
//! each gathering its `[ci·k·k, rows·wo]` patch block from contiguous input row segments and
//! running one GEMM written straight into the output (candle's CPU path copies every input
//! value `k²` times, one pixel at a time, and transposes in and out of NHWC).
//!
//! Adjoint: for stride 1 it is the forward convolution of the output gradient with the flipped,
//! transposed kernel ([`flip_transpose`]), padded by `k − 1 − p`. For larger strides the padded
//! input is viewed as `s²` *phase planes* (`P_{a,b}[c, i, j] = x_pad[c, s·i + a, s·j + b]`,
//! each `hq × wq`); on the output grid of pitch `wq` tap `(kh, kw)` reads plane
//! `(kh mod s, kw mod s)` at offset `(kh / s) · wq + kw / s`, so each phase plane of the
//! gradient gathers `Σ_{taps of that phase} W_tapᵀ · dgrid` from shifted views of one buffer
//! (`tap_gemm`), with no zero-dilated gradient.

use super::{SyncPtr, winograd};
use gemm::{Parallelism, gemm};
use rayon::prelude::*;

/// Geometry of one convolution over `[b, ci, h, w]` inputs with a `[co, ci, k, k]` kernel.
///
/// Invariants (established by [`ConvGeom::new`]): every size is ≥ 1, and the padded input is at
/// least `k` in each direction, so the output has at least one pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConvGeom {
    pub b: usize,
    pub ci: usize,
    pub h: usize,
    pub w: usize,
    pub co: usize,
    pub k: usize,
    pub stride: usize,
    /// Zero padding: top, bottom, left, right.
    pub pad: [usize; 4],
}

/// Column tiles of at most this many floats of (output + input) rows, to stay in L2.
const TILE_FLOATS: usize = 96 * 1024;

impl ConvGeom {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        b: usize,
        ci: usize,
        h: usize,
        w: usize,
        co: usize,
        k: usize,
        stride: usize,
        pad: [usize; 4],
    ) -> Result<Self, String> {
        if [b, ci, h, w, co, k, stride].contains(&0) {
            return Err(format!(
                "conv2d: zero-sized geometry (b {b}, ci {ci}, h {h}, w {w}, co {co}, k {k}, stride {stride})"
            ));
        }
        let g = Self {
            b,
            ci,
            h,
            w,
            co,
            k,
            stride,
            pad,
        };
        let (hp, wp) = g.padded();
        if hp < k || wp < k {
            return Err(format!(
                "conv2d: padded input {hp}x{wp} smaller than the {k}x{k} kernel"
            ));
        }
        Ok(g)
    }

    fn padded(&self) -> (usize, usize) {
        (
            self.h + self.pad[0] + self.pad[1],
            self.w + self.pad[2] + self.pad[3],
        )
    }

    /// Output height and width.
    pub fn out_hw(&self) -> (usize, usize) {
        let (hp, wp) = self.padded();
        (
            (hp - self.k) / self.stride + 1,
            (wp - self.k) / self.stride + 1,
        )
    }

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
) -> Result<(), String> {
    if m == 0 || n == 0 {
        return Ok(());
    }
    // Bounds of every access, checked once so the GEMMs below cannot go out of range.
    if (m - 1) * out_rs + n > out.len() {
        return Err("conv2d: output buffer too small".into());
    }
    if kk == 0 {
        return Err("conv2d: zero GEMM depth".into());
    }
    for t in taps {
        let lhs_end = (m - 1) * t.lhs_rs + (kk - 1) * t.lhs_cs + 1;
        let src_end = t.src_off + (kk - 1) * src_rs + n;
        if lhs_end > t.lhs.len() || src_end > src.len() {
            return Err("conv2d: tap view out of range".into());
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
                    gemm(
                        m,
                        cols,
                        kk,
                        dst.get().add(q0),
                        1,
                        out_rs as isize,
                        false,
                        t.lhs.as_ptr(),
                        t.lhs_cs as isize,
                        t.lhs_rs as isize,
                        src.as_ptr().add(t.src_off + q0),
                        1,
                        src_rs as isize,
                        1.0,
                        1.0,
                        false,
                        false,
                        false,
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
                        gemm(
                            m,
                            cols,
                            depth,
                            dst.get().add(q0),
                            1,
                            out_rs as isize,
                            false,
                            packed.as_ptr(),
                            1,
                            depth as isize,
                            col.as_ptr(),
                            1,
                            cols as isize,
                            1.0,
                            1.0,
                            false,
                            false,
                            false,
                            Parallelism::None,
                        );
                    }
                });
            }
        }
    });
    Ok(())
}

thread_local! {
    /// Per-thread gather buffer of [`tap_gemm`], reused across tiles and calls (a fresh
    /// allocation per tile costs page faults on every use).
    static COL: std::cell::RefCell<Vec<f32>> = const { std::cell::RefCell::new(Vec::new()) };
}

pub(super) fn check_len(what: &str, got: usize, want: usize) -> Result<(), String> {
    if got != want {
        return Err(format!("conv2d: {what} has {got} values, expected {want}"));
    }
    Ok(())
}

/// The input, weight and bias lengths `g` implies.
fn check_inputs(
    g: &ConvGeom,
    x: &[f32],
    weight: &[f32],
    bias: Option<&[f32]>,
) -> Result<(), String> {
    check_len("input", x.len(), g.b * g.ci * g.h * g.w)?;
    check_len("weight", weight.len(), g.co * g.ci * g.k * g.k)?;
    if let Some(bias) = bias {
        check_len("bias", bias.len(), g.co)?;
    }
    Ok(())
}

/// Convolution forward: `x [b, ci, h, w]`, `weight [co, ci, k, k]`, optional `bias [co]`, all
/// contiguous; returns `[b, co, ho, wo]`.
pub fn conv2d(
    g: &ConvGeom,
    x: &[f32],
    weight: &[f32],
    bias: Option<&[f32]>,
) -> Result<Vec<f32>, String> {
    conv2d_prepared(g, x, weight, None, bias)
}

/// [`conv2d`] with the Winograd-transformed kernel ([`winograd::transform_kernel`]) when the
/// caller caches it; 3×3 stride-1 geometries use Winograd F(2×2, 3×3) (computing the transform
/// when `wino` is `None`), every other geometry the im2col GEMM.
pub fn conv2d_prepared(
    g: &ConvGeom,
    x: &[f32],
    weight: &[f32],
    wino: Option<&[f32]>,
    bias: Option<&[f32]>,
) -> Result<Vec<f32>, String> {
    check_inputs(g, x, weight, bias)?;
    if winograd::applies(g) {
        let owned;
        let u = match wino {
            Some(u) => u,
            None => {
                owned = winograd::transform_kernel(weight, g.co, g.ci);
                &owned
            }
        };
        return winograd::conv2d(g, x, u, bias);
    }
    conv2d_im2col(g, x, weight, bias)
}

/// The im2col + GEMM convolution (any geometry): output rows in tiles, in parallel; each tile
/// gathers its im2col block `[ci·k·k, rows·wo]` (row segments of the input, zero outside it)
/// into a per-thread buffer and runs one GEMM against the weight viewed as `[co, ci·k·k]`,
/// written straight into the output.
pub fn conv2d_im2col(
    g: &ConvGeom,
    x: &[f32],
    weight: &[f32],
    bias: Option<&[f32]>,
) -> Result<Vec<f32>, String> {
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
    check_inputs(g, x, weight, bias)?;
    let (ho, wo) = g.out_hw();
    let depth = ci * k * k;
    let plain = k == 1 && s == 1 && pad == [0; 4];
    // rows per tile: about TILE_FLOATS of (im2col + output) values, at least one row
    let rows = (TILE_FLOATS / ((depth + co) * wo)).clamp(1, ho);
    let rows = if rows * wo < 256 {
        256usize.div_ceil(wo).min(ho)
    } else {
        rows
    };
    let tiles = ho.div_ceil(rows);
    let mut out = vec![0f32; b * co * ho * wo];
    let out_ptr = SyncPtr(out.as_mut_ptr());
    (0..b * tiles).into_par_iter().for_each(|job| {
        let (bi, tile) = (job / tiles, job % tiles);
        let y0 = tile * rows;
        let nr = rows.min(ho - y0);
        let cols = nr * wo;
        let xb = &x[bi * ci * h * w..(bi + 1) * ci * h * w];
        // SAFETY: image bi, rows [y0, y0 + nr) of every output channel belong to this job only;
        // they lie inside `out` (b·co·ho·wo values).
        let dst = unsafe { out_ptr.get().add(bi * co * ho * wo + y0 * wo) };
        if let Some(bias) = bias {
            for (o, &bv) in bias.iter().enumerate() {
                // SAFETY: as above.
                unsafe { std::slice::from_raw_parts_mut(dst.add(o * ho * wo), cols).fill(bv) };
            }
        }
        let run = |rhs: &[f32], rhs_rs: usize| {
            // SAFETY: lhs is the co × depth weight, rhs depth × cols with row pitch rhs_rs, dst
            // co rows of cols values with pitch ho·wo, all in bounds as argued above.
            unsafe {
                gemm(
                    co,
                    cols,
                    depth,
                    dst,
                    1,
                    (ho * wo) as isize,
                    bias.is_some(),
                    weight.as_ptr(),
                    1,
                    depth as isize,
                    rhs.as_ptr(),
                    1,
                    rhs_rs as isize,
                    1.0,
                    1.0,
                    false,
                    false,
                    false,
                    Parallelism::None,
                )
            }
        };
        if plain {
            // a 1×1 convolution reads the input rows as they are
            run(&xb[y0 * w..], h * w);
            return;
        }
        COL.with_borrow_mut(|col| {
            col.clear();
            col.resize(depth * cols, 0.0);
            im2col_rows(g, xb, y0, nr, col);
            run(col, cols);
        });
    });
    Ok(out)
}

/// Fills `col [ci·k·k, nr·wo]` (zeroed) with the input patches of output rows `[y0, y0 + nr)`.
fn im2col_rows(g: &ConvGeom, x: &[f32], y0: usize, nr: usize, col: &mut [f32]) {
    let (ci, h, w, k, s) = (g.ci, g.h, g.w, g.k, g.stride);
    let (pt, pl) = (g.pad[0], g.pad[2]);
    let (_, wo) = g.out_hw();
    let cols = nr * wo;
    for c in 0..ci {
        let plane = &x[c * h * w..(c + 1) * h * w];
        for kh in 0..k {
            for kw in 0..k {
                let row = &mut col[((c * k + kh) * k + kw) * cols..][..cols];
                // output columns whose input column s·xo + kw − pl lies in [0, w)
                let lo = pl.saturating_sub(kw).div_ceil(s);
                let hi = if w + pl > kw {
                    ((w + pl - kw - 1) / s + 1).min(wo)
                } else {
                    0
                };
                for r in 0..nr {
                    let yi = (y0 + r) * s + kh;
                    if yi < pt || yi - pt >= h || lo >= hi {
                        continue;
                    }
                    let src = &plane[(yi - pt) * w..(yi - pt + 1) * w];
                    let dst = &mut row[r * wo..(r + 1) * wo];
                    let x0 = lo * s + kw - pl;
                    if s == 1 {
                        dst[lo..hi].copy_from_slice(&src[x0..x0 + hi - lo]);
                    } else {
                        for (j, d) in dst[lo..hi].iter_mut().enumerate() {
                            *d = src[x0 + j * s];
                        }
                    }
                }
            }
        }
    }
}

/// Gradient of [`conv2d`] with respect to its input: `dy [b, co, ho, wo]`, `weight
/// [co, ci, k, k]`; returns `[b, ci, h, w]`. The weights' gradient is never formed.
pub fn conv2d_input_grad(g: &ConvGeom, dy: &[f32], weight: &[f32]) -> Result<Vec<f32>, String> {
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
) -> Result<Vec<f32>, String> {
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
    check_len("output gradient", dy.len(), b * co * ho * wo)?;
    check_len("weight", weight.len(), co * ci * k * k)?;
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Direct definition of the convolution, for reference.
    fn naive(g: &ConvGeom, x: &[f32], wt: &[f32], bias: Option<&[f32]>) -> Vec<f32> {
        let (ho, wo) = g.out_hw();
        let mut out = vec![0f32; g.b * g.co * ho * wo];
        for b in 0..g.b {
            for o in 0..g.co {
                for y in 0..ho {
                    for xo in 0..wo {
                        let mut acc = bias.map_or(0.0, |bs| bs[o] as f64);
                        for c in 0..g.ci {
                            for kh in 0..g.k {
                                for kw in 0..g.k {
                                    let yi = (y * g.stride + kh) as isize - g.pad[0] as isize;
                                    let xi = (xo * g.stride + kw) as isize - g.pad[2] as isize;
                                    if yi < 0 || xi < 0 || yi >= g.h as isize || xi >= g.w as isize
                                    {
                                        continue;
                                    }
                                    let xv =
                                        x[((b * g.ci + c) * g.h + yi as usize) * g.w + xi as usize];
                                    let wv = wt[((o * g.ci + c) * g.k + kh) * g.k + kw];
                                    acc += (xv * wv) as f64;
                                }
                            }
                        }
                        out[((b * g.co + o) * ho + y) * wo + xo] = acc as f32;
                    }
                }
            }
        }
        out
    }

    fn rand(n: usize, seed: u64) -> Vec<f32> {
        crate::models::kernels::test_values(n, seed.wrapping_add(0x5eed))
    }

    fn geoms() -> Vec<ConvGeom> {
        let mut v = Vec::new();
        for &(b, ci, h, w, co, k, s, pad) in &[
            (1, 3, 9, 7, 5, 3, 1, [1, 1, 1, 1]),
            (2, 4, 8, 8, 6, 3, 2, [1, 1, 1, 1]),
            (1, 5, 9, 10, 3, 3, 2, [0, 1, 0, 1]), // the VAE downsampler
            (2, 6, 5, 4, 7, 1, 1, [0, 0, 0, 0]),
            (1, 2, 6, 6, 3, 1, 2, [0, 0, 0, 0]),
            (1, 3, 7, 7, 2, 5, 1, [2, 2, 2, 2]),
            (1, 2, 11, 9, 3, 3, 3, [0, 2, 1, 0]),
            (1, 70, 20, 20, 65, 3, 1, [1, 1, 1, 1]), // several tiles
            // Winograd F(2x2, 3x3): odd sizes, no or asymmetric padding, batches, many blocks
            (2, 3, 7, 9, 4, 3, 1, [1, 1, 1, 1]),
            (1, 4, 3, 3, 2, 3, 1, [0, 0, 0, 0]),
            (1, 5, 8, 6, 3, 3, 1, [0, 0, 0, 0]),
            (1, 3, 6, 7, 5, 3, 1, [2, 0, 1, 2]),
            (1, 8, 37, 41, 9, 3, 1, [1, 1, 1, 1]),
        ] {
            v.push(ConvGeom::new(b, ci, h, w, co, k, s, pad).unwrap());
        }
        v
    }

    #[test]
    fn forward_matches_the_definition() {
        for (i, g) in geoms().into_iter().enumerate() {
            let x = rand(g.b * g.ci * g.h * g.w, 1 + i as u64);
            let wt = rand(g.co * g.ci * g.k * g.k, 100 + i as u64);
            let bias = rand(g.co, 200 + i as u64);
            for bias in [None, Some(bias.as_slice())] {
                let want = naive(&g, &x, &wt, bias);
                for (name, got) in [
                    ("dispatch", conv2d(&g, &x, &wt, bias).unwrap()),
                    ("im2col", conv2d_im2col(&g, &x, &wt, bias).unwrap()),
                ] {
                    let err = got
                        .iter()
                        .zip(&want)
                        .map(|(a, b)| (a - b).abs())
                        .fold(0f32, f32::max);
                    assert!(err < 1e-4, "{name} {g:?}: max abs error {err}");
                }
            }
        }
    }

    /// `<A x, v> = <x, Aᵀ v>` for random `x`, `v`: the adjoint is exact.
    #[test]
    fn input_grad_is_the_adjoint() {
        for (i, g) in geoms().into_iter().enumerate() {
            let (ho, wo) = g.out_hw();
            let x = rand(g.b * g.ci * g.h * g.w, 7 + i as u64);
            let wt = rand(g.co * g.ci * g.k * g.k, 70 + i as u64);
            let v = rand(g.b * g.co * ho * wo, 700 + i as u64);
            let ax = conv2d(&g, &x, &wt, None).unwrap();
            let atv = conv2d_input_grad(&g, &v, &wt).unwrap();
            let u = winograd::transform_kernel(&flip_transpose(&wt, g.co, g.ci, g.k), g.ci, g.co);
            let prepared = conv2d_input_grad_prepared(&g, &v, &wt, Some(&u)).unwrap();
            if g.k == 3 && g.stride == 1 {
                let d = atv
                    .iter()
                    .zip(&prepared)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0f32, f32::max);
                assert!(d < 1e-4, "{g:?}: cached Winograd kernel differs by {d}");
            }
            let lhs: f64 = ax
                .iter()
                .zip(&v)
                .map(|(a, b)| (*a as f64) * (*b as f64))
                .sum();
            let rhs: f64 = x
                .iter()
                .zip(&atv)
                .map(|(a, b)| (*a as f64) * (*b as f64))
                .sum();
            assert!(
                (lhs - rhs).abs() <= 1e-4 * (1.0 + lhs.abs()),
                "{g:?}: <Ax,v> {lhs} vs <x,A^T v> {rhs}"
            );
        }
    }

    #[test]
    fn bad_geometry_is_an_error() {
        assert!(ConvGeom::new(1, 1, 2, 2, 1, 3, 1, [0; 4]).is_err());
        assert!(ConvGeom::new(1, 0, 2, 2, 1, 1, 1, [0; 4]).is_err());
        let g = ConvGeom::new(1, 2, 4, 4, 2, 3, 1, [1; 4]).unwrap();
        assert!(conv2d(&g, &[0.0; 5], &[0.0; 36], None).is_err());
        assert!(conv2d_input_grad(&g, &[0.0; 31], &[0.0; 36]).is_err());
        // the Winograd entry point checks its own inputs (a short kernel transform, a geometry
        // it does not handle)
        assert!(winograd::conv2d(&g, &[0.0; 32], &[0.0; 63], None).is_err());
        assert!(winograd::conv2d(&g, &[0.0; 32], &[0.0; 64], None).is_ok());
        let g2 = ConvGeom::new(1, 2, 4, 4, 2, 3, 2, [1; 4]).unwrap();
        assert!(winograd::conv2d(&g2, &[0.0; 32], &[0.0; 64], None).is_err());
    }
}
