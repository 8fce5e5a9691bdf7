//! 3×3, stride-1 convolution by Winograd's minimal filtering F(2×2, 3×3).
//!
//! Each 2×2 output tile is `Aᵀ [ Σ_ci (G g Gᵀ) ⊙ (Bᵀ d B) ] A` for the 4×4 input tile `d`: the 16
//! element-wise products over channels become 16 GEMMs `[co, ci] × [ci, tiles]`, which cost
//! 16/36 of the direct convolution's multiply-adds (2.25× fewer). The transforms use only
//! additions and halvings, so f32 results stay within ~1e-6 relative of the direct sum.
//!
//! Work runs in blocks of whole tile rows, in parallel; each block transforms its input into a
//! per-thread `[16, ci, T]` buffer (vectorised along tile columns after splitting every padded
//! input row into even and odd samples), runs the 16 GEMMs into `[16, co, T]`, and writes its
//! output rows with the inverse transform.

use super::conv::{ConvGeom, for_each_row_block};
use super::{KernelError, KernelResult, SyncPtr, check_len, gemm_strided};
use gemm::Parallelism;
use std::cell::RefCell;

/// `U[ξ, co, ci] = (G g Gᵀ)[ξ]` for every `[co, ci, 3, 3]` kernel `g`, `ξ = 4·i + j`.
pub fn transform_kernel(weight: &[f32], co: usize, ci: usize) -> Vec<f32> {
    let mut u = vec![0f32; 16 * co * ci];
    let n = co * ci;
    for (idx, g) in weight.chunks_exact(9).enumerate().take(n) {
        // G g: 4×3
        let mut t = [[0f32; 3]; 4];
        for c in 0..3 {
            let (g0, g1, g2) = (g[c], g[3 + c], g[6 + c]);
            t[0][c] = g0;
            t[1][c] = 0.5 * (g0 + g1 + g2);
            t[2][c] = 0.5 * (g0 - g1 + g2);
            t[3][c] = g2;
        }
        // (G g) Gᵀ: 4×4
        for (i, r) in t.iter().enumerate() {
            let v = [
                r[0],
                0.5 * (r[0] + r[1] + r[2]),
                0.5 * (r[0] - r[1] + r[2]),
                r[2],
            ];
            for (j, &x) in v.iter().enumerate() {
                u[(i * 4 + j) * n + idx] = x;
            }
        }
    }
    u
}

#[derive(Default)]
struct Scratch {
    v: Vec<f32>,
    m: Vec<f32>,
    rows: Vec<f32>,
}

thread_local! {
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

/// Whether [`conv2d`] handles this geometry (3×3, stride 1).
pub fn applies(g: &ConvGeom) -> bool {
    g.k == 3 && g.stride == 1
}

/// The convolution of [`super::conv::conv2d`] for 3×3 stride-1 geometries, given the transformed
/// kernel `u` from [`transform_kernel`].
pub fn conv2d(g: &ConvGeom, x: &[f32], u: &[f32], bias: Option<&[f32]>) -> KernelResult<Vec<f32>> {
    let ConvGeom {
        b, ci, h, w, co, ..
    } = *g;
    if !applies(g) {
        return Err(KernelError::Geometry {
            op: "Winograd F(2x2, 3x3)",
            reason: format!("needs a 3x3 stride-1 convolution, got {g:?}"),
        });
    }
    check_len("conv2d", "input", x.len(), b * ci * h * w)?;
    check_len("conv2d", "Winograd kernel", u.len(), 16 * co * ci)?;
    if let Some(bias) = bias {
        check_len("conv2d", "bias", bias.len(), co)?;
    }
    let (ho, wo) = g.out_hw();
    let (th, tw) = (ho.div_ceil(2), wo.div_ceil(2));
    // tiles per block: enough columns for an efficient GEMM, small enough for the caches, and at
    // least two blocks (one per core here) per image when the image allows it
    let target = (2usize << 20) / (16 * (ci + co));
    let target = target.clamp(128, 1024);
    let rows = (target / tw).clamp(1, th.div_ceil(2).max(1));
    let mut out = vec![0f32; b * co * ho * wo];
    let out_ptr = SyncPtr(out.as_mut_ptr());
    for_each_row_block(b, th, rows, |bi, ty0, nr| {
        let t = nr * tw;
        let xb = &x[bi * ci * h * w..(bi + 1) * ci * h * w];
        SCRATCH.with_borrow_mut(|s| {
            s.v.resize(16 * ci * t, 0.0);
            s.m.resize(16 * co * t, 0.0);
            input_transform(g, xb, ty0, nr, tw, &mut s.v, &mut s.rows);
            let n = co * ci;
            for xi in 0..16 {
                // SAFETY: u holds 16 · co · ci values (checked by the caller), v 16 · ci · t and
                // m 16 · co · t; each call reads/writes the ξ-th slab only.
                unsafe {
                    gemm_strided(
                        (co, t, ci),
                        (s.m.as_mut_ptr().add(xi * co * t), t),
                        false,
                        (u.as_ptr().add(xi * n), ci, 1),
                        (s.v.as_ptr().add(xi * ci * t), t, 1),
                        1.0,
                        Parallelism::None,
                    );
                }
            }
            output_transform(g, &s.m, ty0, nr, tw, bias, out_ptr, bi);
        });
    });
    Ok(out)
}

/// `V[ξ, c, tile] = (Bᵀ d B)[ξ]` for the tiles of tile rows `[ty0, ty0 + nr)`.
///
/// Per channel, every padded input row of the block (`2·nr + 2` rows; neighbouring tile rows
/// share two) is split once into even and odd samples and column-transformed (`d B`) into
/// `E[row, j, tx]`; the row transform (`Bᵀ ·`) then combines four consecutive rows.
fn input_transform(
    g: &ConvGeom,
    x: &[f32],
    ty0: usize,
    nr: usize,
    tw: usize,
    v: &mut [f32],
    rows: &mut Vec<f32>,
) {
    let (ci, h, w) = (g.ci, g.h, g.w);
    let (pt, pl) = (g.pad[0], g.pad[2]);
    let t = nr * tw;
    let half = tw + 1;
    let prows = 2 * nr + 2;
    rows.resize(2 * half + prows * 4 * tw, 0.0);
    let (eo, e) = rows.split_at_mut(2 * half);
    let (even, odd) = eo.split_at_mut(half);
    // input columns feeding even / odd padded columns: padded p = xcol + pl
    for c in 0..ci {
        let plane = &x[c * h * w..(c + 1) * h * w];
        for pr in 0..prows {
            let er = &mut e[pr * 4 * tw..(pr + 1) * 4 * tw];
            let yi = 2 * ty0 + pr;
            if yi < pt || yi - pt >= h {
                er.fill(0.0);
                continue;
            }
            let src = &plane[(yi - pt) * w..(yi - pt + 1) * w];
            deinterleave(src, pl, even, odd);
            let (e0, rest) = er.split_at_mut(tw);
            let (e1, rest) = rest.split_at_mut(tw);
            let (e2, e3) = rest.split_at_mut(tw);
            let (ev0, ev1) = (&even[..tw], &even[1..half]);
            let (od0, od1) = (&odd[..tw], &odd[1..half]);
            for tx in 0..tw {
                e0[tx] = ev0[tx] - ev1[tx];
                e1[tx] = od0[tx] + ev1[tx];
                e2[tx] = ev1[tx] - od0[tx];
                e3[tx] = od0[tx] - od1[tx];
            }
        }
        for r in 0..nr {
            for j in 0..4 {
                let row = |dr: usize| {
                    let at = ((2 * r + dr) * 4 + j) * tw;
                    &e[at..at + tw]
                };
                let (r0, r1, r2, r3) = (row(0), row(1), row(2), row(3));
                let at = |i: usize| ((i * 4 + j) * ci + c) * t + r * tw;
                for (d, (a, b)) in v[at(0)..at(0) + tw].iter_mut().zip(r0.iter().zip(r2)) {
                    *d = a - b;
                }
                for (d, (a, b)) in v[at(1)..at(1) + tw].iter_mut().zip(r1.iter().zip(r2)) {
                    *d = a + b;
                }
                for (d, (a, b)) in v[at(2)..at(2) + tw].iter_mut().zip(r2.iter().zip(r1)) {
                    *d = a - b;
                }
                for (d, (a, b)) in v[at(3)..at(3) + tw].iter_mut().zip(r1.iter().zip(r3)) {
                    *d = a - b;
                }
            }
        }
    }
}

/// `even[m] = row_pad[2m]`, `odd[m] = row_pad[2m + 1]` for the row zero-padded by `pl` on the
/// left (and with zeros past its end).
fn deinterleave(src: &[f32], pl: usize, even: &mut [f32], odd: &mut [f32]) {
    let w = src.len();
    for (par, dst) in [(0usize, even), (1usize, odd)] {
        // padded column 2m + par holds src[2m + par − pl] when that lies in [0, w)
        let n = dst.len();
        let first = pl.saturating_sub(par).div_ceil(2).min(n);
        let end = ((w + pl).saturating_sub(par)).div_ceil(2).min(n);
        dst[..first].fill(0.0);
        if first < end {
            let x0 = 2 * first + par - pl;
            for (m, d) in dst[first..end].iter_mut().enumerate() {
                *d = src[x0 + 2 * m];
            }
        }
        dst[end.max(first)..].fill(0.0);
    }
}

/// `y = Aᵀ M A (+ bias)` for the tiles of tile rows `[ty0, ty0 + nr)` of image `bi`, into the
/// `[b, co, ho, wo]` output behind `out`. Only output rows `[2·ty0, 2·(ty0 + nr)) ∩ [0, ho)` are
/// touched: those belong to this block alone, so blocks can run at the same time.
#[allow(clippy::too_many_arguments)]
fn output_transform(
    g: &ConvGeom,
    m: &[f32],
    ty0: usize,
    nr: usize,
    tw: usize,
    bias: Option<&[f32]>,
    out: SyncPtr,
    bi: usize,
) {
    let co = g.co;
    let (ho, wo) = g.out_hw();
    let t = nr * tw;
    let mut p = vec![0f32; 8 * tw];
    for o in 0..co {
        let bv = bias.map_or(0.0, |bs| bs[o]);
        for r in 0..nr {
            let ty = ty0 + r;
            let at = |xi: usize| (xi * co + o) * t + r * tw;
            // P[a][j] = (Aᵀ M)[a][j]
            for j in 0..4 {
                let (m0, m1, m2, m3) = (
                    &m[at(j)..at(j) + tw],
                    &m[at(4 + j)..at(4 + j) + tw],
                    &m[at(8 + j)..at(8 + j) + tw],
                    &m[at(12 + j)..at(12 + j) + tw],
                );
                let (pa, pb) = p.split_at_mut(4 * tw);
                let p0 = &mut pa[j * tw..(j + 1) * tw];
                let p1 = &mut pb[j * tw..(j + 1) * tw];
                for tx in 0..tw {
                    p0[tx] = m0[tx] + m1[tx] + m2[tx];
                    p1[tx] = m1[tx] - m2[tx] - m3[tx];
                }
            }
            for a in 0..2 {
                let y = 2 * ty + a;
                if y >= ho {
                    break;
                }
                let pr = &p[a * 4 * tw..(a + 1) * 4 * tw];
                let (q0, rest) = pr.split_at(tw);
                let (q1, rest) = rest.split_at(tw);
                let (q2, q3) = rest.split_at(tw);
                // SAFETY: row y < ho of channel o of image bi lies inside the b·co·ho·wo output,
                // and only this block writes it (see above).
                let orow = unsafe {
                    std::slice::from_raw_parts_mut(out.get().add(((bi * co + o) * ho + y) * wo), wo)
                };
                // full tiles write two columns; an odd width leaves one column for the last
                let full = wo / 2;
                for (tx, pair) in orow.chunks_exact_mut(2).take(full).enumerate() {
                    pair[0] = q0[tx] + q1[tx] + q2[tx] + bv;
                    pair[1] = q1[tx] - q2[tx] - q3[tx] + bv;
                }
                if wo % 2 == 1 {
                    let tx = full;
                    orow[wo - 1] = q0[tx] + q1[tx] + q2[tx] + bv;
                }
            }
        }
    }
}
