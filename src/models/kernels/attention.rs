//! Multi-head scaled dot-product attention, fused and tiled over queries.
//!
//! `q [b, n, c]`, `k, v [b, m, c]` with `c = heads · d` (head `h` is columns `h·d..(h+1)·d`, as
//! the projections write them: no split/merge copies). Each task takes one image, one head and a
//! tile of queries: scores `S = scale · Q Kᵀ` into a per-thread buffer, `e^(S − max)` with the row
//! sums, `O = P V`, then each output row divided by its sum. The full `n × m` score matrix (1 GiB
//! per layer for the UNet at 512 px with candle) never exists.

use super::math;
use super::{KernelError, KernelResult, SyncPtr, check_len, gemm_strided};
use gemm::Parallelism;
use rayon::prelude::*;
use std::cell::RefCell;

/// Shape of one attention call. Invariant (checked by [`AttentionGeom::new`]): `heads ≥ 1`
/// divides `c`.
#[derive(Clone, Copy, Debug)]
pub struct AttentionGeom {
    pub b: usize,
    pub n: usize,
    pub m: usize,
    pub c: usize,
    pub heads: usize,
    /// Query `i` sees keys `0..=i` only (a text encoder's causal mask).
    pub causal: bool,
}

impl AttentionGeom {
    pub fn new(b: usize, n: usize, m: usize, c: usize, heads: usize) -> KernelResult<Self> {
        if heads == 0 || !c.is_multiple_of(heads) {
            return Err(KernelError::Geometry {
                op: "attention",
                reason: format!("{c} channels not divisible by {heads} heads"),
            });
        }
        Ok(Self {
            b,
            n,
            m,
            c,
            heads,
            causal: false,
        })
    }

    /// The same shape with a causal mask.
    pub fn causal(self) -> Self {
        Self {
            causal: true,
            ..self
        }
    }

    /// Queries per task: about 256 Ki scores (1 MiB) per tile.
    fn tile(&self) -> usize {
        ((1 << 18) / self.m.max(1)).clamp(16, 256)
    }
}

thread_local! {
    static SCORES: RefCell<Vec<f32>> = const { RefCell::new(Vec::new()) };
}

/// `softmax(scale · Q Kᵀ) V` per head; returns `[b, n, c]`.
pub fn attention(
    g: &AttentionGeom,
    q: &[f32],
    k: &[f32],
    v: &[f32],
    scale: f32,
) -> KernelResult<Vec<f32>> {
    let AttentionGeom {
        b,
        n,
        m,
        c,
        heads,
        causal,
    } = *g;
    check_len("attention", "q", q.len(), b * n * c)?;
    check_len("attention", "k", k.len(), b * m * c)?;
    check_len("attention", "v", v.len(), b * m * c)?;
    let mut out = vec![0f32; b * n * c];
    if n == 0 || c == 0 {
        return Ok(out);
    }
    if m == 0 {
        // an empty softmax; PyTorch gives NaN, zeros are the safe answer
        return Ok(out);
    }
    let d = c / heads;
    let tile = g.tile();
    let tiles = n.div_ceil(tile);
    let dst = SyncPtr(out.as_mut_ptr());
    (0..b * heads * tiles).into_par_iter().for_each(|task| {
        let (bi, rest) = (task / (heads * tiles), task % (heads * tiles));
        let (h, t) = (rest / tiles, rest % tiles);
        let q0 = t * tile;
        let rows = tile.min(n - q0);
        let qoff = (bi * n + q0) * c + h * d;
        let kvoff = bi * m * c + h * d;
        SCORES.with_borrow_mut(|s| {
            s.resize(rows * m, 0.0);
            // SAFETY: the q/k/v lengths were checked against the shape above, so the strided
            // reads (rows × d at stride c from qoff; m × d at stride c from kvoff) stay inside;
            // `s` holds rows × m values; this task alone writes output rows q0..q0+rows, columns
            // h·d..(h+1)·d of image bi.
            unsafe {
                gemm_strided(
                    (rows, m, d),
                    (s.as_mut_ptr(), m),
                    false,
                    (q.as_ptr().add(qoff), c, 1),
                    (k.as_ptr().add(kvoff), 1, c),
                    scale,
                    Parallelism::None,
                );
            }
            let mut inv = [0f32; 256];
            math::vectorised(
                #[inline(always)]
                || {
                    for (r, row) in s.chunks_exact_mut(m).enumerate() {
                        let seen = if causal { (q0 + r + 1).min(m) } else { m };
                        inv[r] = 1.0 / math::exp_shifted_sum_wide(&mut row[..seen]);
                        row[seen..].fill(0.0);
                    }
                },
            );
            // SAFETY: as above: this task's output window, v read inside its checked length.
            unsafe {
                let o = dst.get().add(qoff);
                gemm_strided(
                    (rows, d, m),
                    (o, c),
                    false,
                    (s.as_ptr(), m, 1),
                    (v.as_ptr().add(kvoff), c, 1),
                    1.0,
                    Parallelism::None,
                );
                for (r, &iv) in inv.iter().enumerate().take(rows) {
                    let row = std::slice::from_raw_parts_mut(o.add(r * c), d);
                    row.iter_mut().for_each(|x| *x *= iv);
                }
            }
        });
    });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::kernels::{max_abs_diff, test_values};

    fn naive(g: &AttentionGeom, q: &[f32], k: &[f32], v: &[f32], scale: f32) -> Vec<f32> {
        let AttentionGeom {
            b,
            n,
            m,
            c,
            heads,
            causal,
        } = *g;
        let d = c / heads;
        let mut out = vec![0f32; b * n * c];
        for bi in 0..b {
            for h in 0..heads {
                for i in 0..n {
                    let seen = if causal { (i + 1).min(m) } else { m };
                    let s: Vec<f64> = (0..seen)
                        .map(|j| {
                            (0..d)
                                .map(|x| {
                                    q[(bi * n + i) * c + h * d + x] as f64
                                        * k[(bi * m + j) * c + h * d + x] as f64
                                })
                                .sum::<f64>()
                                * scale as f64
                        })
                        .collect();
                    let mx = s.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
                    let e: Vec<f64> = s.iter().map(|x| (x - mx).exp()).collect();
                    let z: f64 = e.iter().sum();
                    for x in 0..d {
                        out[(bi * n + i) * c + h * d + x] = (0..seen)
                            .map(|j| e[j] * v[(bi * m + j) * c + h * d + x] as f64)
                            .sum::<f64>()
                            as f32
                            / z as f32;
                    }
                }
            }
        }
        out
    }

    #[test]
    fn fused_attention_matches_the_definition() {
        // n spans several query tiles (tile = 256 for m = 70), cross-attention shape m != n
        for (b, n, m, c, heads, causal) in [
            (2, 300, 70, 12, 3, false),
            (1, 5, 5, 8, 1, false),
            (1, 40, 1100, 4, 2, false),
            // causal over several query tiles (tile = 256 for m = 600)
            (2, 600, 600, 6, 2, true),
        ] {
            let g = AttentionGeom::new(b, n, m, c, heads).unwrap();
            let g = if causal { g.causal() } else { g };
            let q = test_values(b * n * c, 1);
            let k: Vec<f32> = test_values(b * m * c, 2).iter().map(|x| x * 4.0).collect();
            let v = test_values(b * m * c, 3);
            let got = attention(&g, &q, &k, &v, 0.7).unwrap();
            let want = naive(&g, &q, &k, &v, 0.7);
            let err = max_abs_diff(&got, &want);
            assert!(err < 1e-5, "({b},{n},{m},{c},{heads}): {err}");
        }
        assert!(AttentionGeom::new(1, 1, 1, 6, 4).is_err());
        let g = AttentionGeom::new(1, 2, 2, 4, 2).unwrap();
        assert!(attention(&g, &[0.0; 7], &[0.0; 8], &[0.0; 8], 1.0).is_err());
    }
}
