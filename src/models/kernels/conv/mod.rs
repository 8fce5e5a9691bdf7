//! 2-D convolution on the CPU; its input adjoint (the gradient with respect to the input) is in
//! `input_grad`.
//!
//! 3×3 stride-1 geometries go to Winograd F(2×2, 3×3) ([`winograd`]); every other geometry runs
//! a row-tiled im2col GEMM ([`conv2d_im2col`]): tiles of output rows in parallel, each gathering
//! its `[ci·k·k, rows·wo]` patch block from contiguous input row segments and running one GEMM
//! written straight into the output (candle's CPU path copies every input value `k²` times, one
//! pixel at a time, and transposes in and out of NHWC).

use super::{KernelError, KernelResult, SyncPtr, check_len, gemm_strided, winograd};
use gemm::Parallelism;
use rayon::prelude::*;

mod input_grad;
#[cfg(test)]
mod tests;

pub use input_grad::{conv2d_input_grad, conv2d_input_grad_prepared, flip_transpose};

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
    ) -> KernelResult<Self> {
        if [b, ci, h, w, co, k, stride].contains(&0) {
            return Err(KernelError::Geometry {
                op: "conv2d",
                reason: format!(
                    "zero-sized geometry (b {b}, ci {ci}, h {h}, w {w}, co {co}, k {k}, stride {stride})"
                ),
            });
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
            return Err(KernelError::Geometry {
                op: "conv2d",
                reason: format!("padded input {hp}x{wp} smaller than the {k}x{k} kernel"),
            });
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
}

thread_local! {
    /// Per-thread gather buffer of [`tap_gemm`], reused across tiles and calls (a fresh
    /// allocation per tile costs page faults on every use).
    static COL: std::cell::RefCell<Vec<f32>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// The input, weight and bias lengths `g` implies.
fn check_inputs(g: &ConvGeom, x: &[f32], weight: &[f32], bias: Option<&[f32]>) -> KernelResult<()> {
    check_len("conv2d", "input", x.len(), g.b * g.ci * g.h * g.w)?;
    check_len("conv2d", "weight", weight.len(), g.co * g.ci * g.k * g.k)?;
    if let Some(bias) = bias {
        check_len("conv2d", "bias", bias.len(), g.co)?;
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
) -> KernelResult<Vec<f32>> {
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
) -> KernelResult<Vec<f32>> {
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
    let mut out = vec![0f32; b * co * ho * wo];
    let out_ptr = SyncPtr(out.as_mut_ptr());
    for_each_row_block(b, ho, rows, |bi, y0, nr| {
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
                gemm_strided(
                    (co, cols, depth),
                    (dst, ho * wo),
                    bias.is_some(),
                    (weight.as_ptr(), depth, 1),
                    (rhs.as_ptr(), rhs_rs, 1),
                    1.0,
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

/// Runs `f(image, first_row, rows)` in parallel for every block of at most `per_block`
/// consecutive rows out of `total`, in each of `images` images: how the im2col and Winograd
/// convolutions share out their work (each block writes its own output rows).
pub(super) fn for_each_row_block(
    images: usize,
    total: usize,
    per_block: usize,
    f: impl Fn(usize, usize, usize) + Sync + Send,
) {
    let blocks = total.div_ceil(per_block);
    (0..images * blocks).into_par_iter().for_each(|job| {
        let (bi, blk) = (job / blocks, job % blocks);
        let first = blk * per_block;
        f(bi, first, per_block.min(total - first));
    });
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
