//! Linear layers as one GEMM each with the bias (and a residual) folded into the accumulator,
//! including the two layout changes of a spatial transformer: channels-first activations in,
//! token rows out (`proj_in`) and back (`proj_out` + residual), read through strides instead of
//! a transposed copy.
//!
//! Weights are PyTorch's `[out, in]`.

use super::{KernelError, KernelResult, check_len, gemm_strided};
use gemm::Parallelism;
use rayon::prelude::*;

/// A strided read-only matrix: element `(r, c)` is `data[r·rs + c·cs]`. Invariant (checked by
/// [`View::new`]): every element lies inside `data`.
#[derive(Clone, Copy)]
pub(crate) struct View<'a> {
    data: &'a [f32],
    rs: usize,
    cs: usize,
}

impl<'a> View<'a> {
    pub(crate) fn new(
        data: &'a [f32],
        rows: usize,
        cols: usize,
        rs: usize,
        cs: usize,
    ) -> KernelResult<Self> {
        if rows > 0 && cols > 0 && (rows - 1) * rs + (cols - 1) * cs >= data.len() {
            return Err(KernelError::Window {
                op: "matrix view",
                rows,
                cols,
                len: data.len(),
            });
        }
        Ok(Self { data, rs, cs })
    }
}

/// `dst[m, n] (row stride dst_rs) += a[m, k] · b[k, n]`, threaded inside the GEMM. `dst` must
/// hold the `m × n` window (checked).
pub(crate) fn gemm_acc(
    dst: &mut [f32],
    dst_rs: usize,
    (m, n, k): (usize, usize, usize),
    a: View,
    b: View,
    threads: Parallelism,
) -> KernelResult<()> {
    if m == 0 || n == 0 {
        return Ok(());
    }
    if (m - 1) * dst_rs + n > dst.len() {
        return Err(KernelError::Window {
            op: "gemm",
            rows: m,
            cols: n,
            len: dst.len(),
        });
    }
    if k == 0 {
        return Ok(());
    }
    // SAFETY: the views and the output window were bounds-checked; `dst` is borrowed mutably.
    unsafe {
        gemm_strided(
            (m, n, k),
            (dst.as_mut_ptr(), dst_rs),
            true,
            (a.data.as_ptr(), a.rs, a.cs),
            (b.data.as_ptr(), b.rs, b.cs),
            1.0,
            threads,
        );
    }
    Ok(())
}

fn all_threads() -> Parallelism {
    Parallelism::Rayon(rayon::current_num_threads())
}

fn check_weight(w: &[f32], o: usize, i: usize, bias: Option<&[f32]>) -> KernelResult<()> {
    if w.len() != o * i {
        return Err(KernelError::Length {
            op: "linear",
            what: "weight",
            got: w.len(),
            want: o * i,
        });
    }
    if let Some(b) = bias.filter(|b| b.len() != o) {
        return Err(KernelError::Length {
            op: "linear",
            what: "bias",
            got: b.len(),
            want: o,
        });
    }
    Ok(())
}

/// A linear layer's weight `W [out, in]` as it is stored.
#[derive(Clone, Copy, Debug)]
pub enum Weight<'a> {
    /// PyTorch's layout: row `o` holds the weights of output `o`.
    OutIn(&'a [f32]),
    /// Transposed, `[in, out]`: what a product of few rows reads fastest (`gemm` packs it
    /// with vector copies instead of a strided gather).
    InOut(&'a [f32]),
}

impl<'a> Weight<'a> {
    fn data(self) -> &'a [f32] {
        match self {
            Weight::OutIn(w) | Weight::InOut(w) => w,
        }
    }

    /// `Wᵀ [i, o]` as a strided matrix.
    fn view(self, i: usize, o: usize) -> KernelResult<View<'a>> {
        match self {
            Weight::OutIn(w) => View::new(w, i, o, 1, i),
            Weight::InOut(w) => View::new(w, i, o, o, 1),
        }
    }
}

/// Token rows: `x [rows, i] -> x·Wᵀ + bias (+ residual [rows, o])`.
pub fn linear(
    x: &[f32],
    i: usize,
    w: Weight,
    o: usize,
    bias: Option<&[f32]>,
    residual: Option<&[f32]>,
) -> KernelResult<Vec<f32>> {
    check_weight(w.data(), o, i, bias)?;
    if i == 0 || !x.len().is_multiple_of(i) {
        return Err(KernelError::Rows {
            op: "linear",
            len: x.len(),
            row: i,
        });
    }
    let rows = x.len() / i;
    let mut y = match residual {
        Some(r) if r.len() == rows * o => r.to_vec(),
        Some(r) => {
            return Err(KernelError::Length {
                op: "linear",
                what: "residual",
                got: r.len(),
                want: rows * o,
            });
        }
        None => vec![0f32; rows * o],
    };
    if let Some(b) = bias {
        y.par_chunks_mut(o)
            .for_each(|r| r.iter_mut().zip(b).for_each(|(y, b)| *y += b));
    }
    let threads = rayon::current_num_threads();
    let block = match w {
        Weight::OutIn(_) if rows <= 128 => 32,
        _ => 96,
    };
    if threads > 1 && rows <= FEW_ROWS && i >= MIN_DEPTH && o >= 2 * block {
        // A short product (a text encoder's 77 tokens): `gemm` splits its few rows poorly over
        // the threads, so the threads take blocks of output columns, 96 wide (32 for up to 128
        // rows of an `[out, in]` weight): the fastest in a sweep of 32–384 on 77 and 154 rows
        // with AVX-512.
        let (x, w) = (View::new(x, rows, i, i, 1)?, w.view(i, o)?);
        let blocks = o.div_ceil(block);
        let dst = SendPtr(y.as_mut_ptr());
        (0..blocks).into_par_iter().for_each(|blk| {
            let c0 = blk * block;
            let cols = block.min(o - c0);
            let dst = &dst;
            // SAFETY: the views were bounds-checked for the whole product; block `blk` reads
            // columns c0..c0+cols of `Wᵀ` and writes only those columns of `y`
            // (rows × o, row stride o), which no other block writes.
            unsafe {
                gemm_strided(
                    (rows, cols, i),
                    (dst.0.add(c0), o),
                    true,
                    (x.data.as_ptr(), x.rs, x.cs),
                    (w.data.as_ptr().add(c0 * w.cs), w.rs, w.cs),
                    1.0,
                    Parallelism::None,
                );
            }
        });
        return Ok(y);
    }
    gemm_acc(
        &mut y,
        o,
        (rows, o, i),
        View::new(x, rows, i, i, 1)?,
        w.view(i, o)?,
        Parallelism::Rayon(threads),
    )?;
    Ok(y)
}

/// Products of at most this many rows are split by output columns across threads ([`linear`]).
const FEW_ROWS: usize = 256;
/// ... when each output sums at least this many products (the full-size text encoders' 768 and
/// more; the tiny test models stay on `gemm`'s own threading).
pub const MIN_DEPTH: usize = 512;

/// A raw pointer the column blocks of [`linear`] share; each writes only its own columns.
struct SendPtr(*mut f32);
// SAFETY: the blocks write disjoint columns (see `linear`); nothing else touches the buffer
// while they run.
unsafe impl Sync for SendPtr {}

/// Channels-first in, tokens out: `x [b, i, n] -> [b, n, o]`, `y[b, p, :] = W·x[b, :, p] + bias`.
pub fn linear_from_channels(
    x: &[f32],
    (b, i, n): (usize, usize, usize),
    w: &[f32],
    o: usize,
    bias: Option<&[f32]>,
) -> KernelResult<Vec<f32>> {
    check_weight(w, o, i, bias)?;
    if x.len() != b * i * n {
        return Err(KernelError::Length {
            op: "linear",
            what: "input",
            got: x.len(),
            want: b * i * n,
        });
    }
    let mut y = vec![0f32; b * n * o];
    if let Some(bv) = bias {
        y.par_chunks_mut(o).for_each(|r| r.copy_from_slice(bv));
    }
    if n == 0 {
        return Ok(y);
    }
    for bi in 0..b {
        let xb = &x[bi * i * n..(bi + 1) * i * n];
        gemm_acc(
            &mut y[bi * n * o..(bi + 1) * n * o],
            o,
            (n, o, i),
            View::new(xb, n, i, 1, n)?,
            View::new(w, i, o, 1, i)?,
            all_threads(),
        )?;
    }
    Ok(y)
}

/// Tokens in, channels-first out, plus a residual: `t [b, n, i] -> r + [b, o, n]` with
/// `y[b, :, p] = W·t[b, p, :] + bias`.
pub fn linear_to_channels(
    t: &[f32],
    (b, n, i): (usize, usize, usize),
    w: &[f32],
    o: usize,
    bias: Option<&[f32]>,
    residual: &[f32],
) -> KernelResult<Vec<f32>> {
    check_weight(w, o, i, bias)?;
    check_len("linear", "input", t.len(), b * n * i)?;
    check_len("linear", "residual", residual.len(), b * o * n)?;
    let mut y = residual.to_vec();
    if n == 0 {
        return Ok(y);
    }
    if let Some(bv) = bias {
        y.par_chunks_mut(n)
            .enumerate()
            .for_each(|(idx, p)| p.iter_mut().for_each(|v| *v += bv[idx % o]));
    }
    for bi in 0..b {
        let tb = &t[bi * n * i..(bi + 1) * n * i];
        gemm_acc(
            &mut y[bi * o * n..(bi + 1) * o * n],
            n,
            (o, n, i),
            View::new(w, o, i, i, 1)?,
            View::new(tb, i, n, 1, i)?,
            all_threads(),
        )?;
    }
    Ok(y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::kernels::test_values;

    fn naive(
        x: impl Fn(usize, usize) -> f32,
        rows: usize,
        i: usize,
        w: &[f32],
        o: usize,
    ) -> Vec<f32> {
        let mut y = vec![0f32; rows * o];
        for r in 0..rows {
            for oo in 0..o {
                y[r * o + oo] = (0..i).map(|k| x(r, k) * w[oo * i + k]).sum();
            }
        }
        y
    }

    #[test]
    fn the_three_layouts_match_a_naive_product() {
        let (b, i, n, o) = (2, 5, 7, 3);
        let w = test_values(o * i, 1);
        let bias = test_values(o, 2);
        let x = test_values(b * n * i, 3);
        let res = test_values(b * n * o, 4);
        // tokens
        let y = linear(&x, i, Weight::OutIn(&w), o, Some(&bias), Some(&res)).unwrap();
        let want = naive(|r, k| x[r * i + k], b * n, i, &w, o);
        for (idx, v) in y.iter().enumerate() {
            assert!((v - (want[idx] + bias[idx % o] + res[idx])).abs() < 1e-5);
        }
        // channels-first x [b, i, n] -> tokens
        let y = linear_from_channels(&x, (b, i, n), &w, o, Some(&bias)).unwrap();
        let want = naive(|r, k| x[(r / n) * i * n + k * n + r % n], b * n, i, &w, o);
        for (idx, v) in y.iter().enumerate() {
            assert!((v - (want[idx] + bias[idx % o])).abs() < 1e-5);
        }
        // tokens t [b, n, i] -> channels-first + residual
        let y = linear_to_channels(&x, (b, n, i), &w, o, Some(&bias), &res).unwrap();
        let want = naive(|r, k| x[r * i + k], b * n, i, &w, o);
        for bi in 0..b {
            for oo in 0..o {
                for p in 0..n {
                    let got = y[bi * o * n + oo * n + p];
                    let exp = want[(bi * n + p) * o + oo] + bias[oo] + res[bi * o * n + oo * n + p];
                    assert!((got - exp).abs() < 1e-5);
                }
            }
        }
        assert!(linear(&x, i, Weight::OutIn(&w[1..]), o, None, None).is_err());
        assert!(linear(&x, i, Weight::InOut(&w[1..]), o, None, None).is_err());
        assert!(linear(&x, i, Weight::OutIn(&w), o, None, Some(&res[1..])).is_err());
        assert!(linear_to_channels(&x, (b, n, i), &w, o, None, &res[1..]).is_err());
        assert!(View::new(&x, 100, 1, 1, 1).is_err());
    }

    /// Short products split by column blocks over two threads (77 rows, 32-wide blocks and a
    /// partial last one; 150 rows, 96-wide), from either weight layout, and the unsplit
    /// product of the transposed layout give the naive product with bias and residual.
    #[test]
    fn column_blocks_of_short_products_match_a_naive_product() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        for (rows, i, o) in [(77, 512, 100), (150, 520, 200), (77, 512, 300), (20, 7, 5)] {
            let w = test_values(o * i, 5);
            let wt: Vec<f32> = (0..i * o).map(|n| w[(n % o) * i + n / o]).collect();
            let bias = test_values(o, 6);
            let x = test_values(rows * i, 7);
            let res = test_values(rows * o, 8);
            let want = naive(|r, k| x[r * i + k], rows, i, &w, o);
            for weight in [Weight::OutIn(&w), Weight::InOut(&wt)] {
                let y = pool.install(|| linear(&x, i, weight, o, Some(&bias), Some(&res)).unwrap());
                for (idx, v) in y.iter().enumerate() {
                    let exp = want[idx] + bias[idx % o] + res[idx];
                    assert!((v - exp).abs() < 1e-3, "{rows}x{o}: {v} vs {exp} at {idx}");
                }
            }
        }
    }
}
