//! Element-wise pieces, in parallel chunks (candle's CPU element-wise ops run on one thread and
//! allocate a tensor per step: `dy * (out > 0)` is three passes there).

use super::{KernelError, KernelResult, math};
use rayon::prelude::*;

const CHUNK: usize = 1 << 15;

/// `v = max(v, 0)` in place.
pub fn relu_inplace(v: &mut [f32]) {
    v.par_chunks_mut(CHUNK)
        .for_each(|c| c.iter_mut().for_each(|x| *x = x.max(0.0)));
}

/// `v = f(v)` in place (compiled for AVX2 + FMA when available, so `f` may vectorise).
pub fn map_inplace(v: &mut [f32], f: impl Fn(f32) -> f32 + Sync) {
    v.par_chunks_mut(CHUNK).for_each(|c| {
        math::vectorised(
            #[inline(always)]
            || c.iter_mut().for_each(|x| *x = f(*x)),
        )
    });
}

/// `max(a + b, 0)`.
pub fn add_relu(a: &[f32], b: &[f32]) -> KernelResult<Vec<f32>> {
    zip_map("add_relu", a, b, |a, b| (a + b).max(0.0))
}

/// Input gradient of a ReLU from its output: `dy · [out > 0]`.
pub fn relu_backward(out: &[f32], dy: &[f32]) -> KernelResult<Vec<f32>> {
    zip_map(
        "relu_backward",
        out,
        dy,
        |o, g| if o > 0.0 { g } else { 0.0 },
    )
}

/// `(a + b) · s`.
pub fn add_scaled(a: &[f32], b: &[f32], s: f32) -> KernelResult<Vec<f32>> {
    zip_map("add_scaled", a, b, |a, b| (a + b) * s)
}

/// `x[b, c, n] += v[b, c]` (a per-image, per-channel offset such as a time embedding).
pub fn add_per_channel(x: &mut [f32], v: &[f32], n: usize) -> KernelResult<()> {
    if n == 0 || x.len() != v.len() * n {
        return Err(KernelError::Length {
            op: "add_per_channel",
            what: "input",
            got: x.len(),
            want: v.len() * n,
        });
    }
    x.par_chunks_mut(n)
        .zip(v.par_iter())
        .for_each(|(xc, &o)| xc.iter_mut().for_each(|x| *x += o));
    Ok(())
}

/// GEGLU: `h [rows, 2·inner] -> h[:, ..inner] · gelu(h[:, inner..])` (exact GELU).
pub fn geglu(h: &[f32], inner: usize) -> KernelResult<Vec<f32>> {
    if inner == 0 || !h.len().is_multiple_of(2 * inner) {
        return Err(KernelError::Rows {
            op: "geglu",
            len: h.len(),
            row: 2 * inner,
        });
    }
    let rows = h.len() / (2 * inner);
    let mut out = vec![0f32; rows * inner];
    let per = CHUNK / inner + 1;
    out.par_chunks_mut(per * inner)
        .zip(h.par_chunks(per * 2 * inner))
        .for_each(|(o, hc)| {
            math::vectorised(
                #[inline(always)]
                || {
                    for (orow, hrow) in o.chunks_exact_mut(inner).zip(hc.chunks_exact(2 * inner)) {
                        let (a, gate) = hrow.split_at(inner);
                        for ((o, &a), &g) in orow.iter_mut().zip(a).zip(gate) {
                            *o = a * math::gelu(g);
                        }
                    }
                },
            )
        });
    Ok(out)
}

/// Nearest-neighbour resize of `x [planes, h, w]` to `[planes, oh, ow]` (PyTorch's `nearest`:
/// source index `⌊i · h / oh⌋`).
pub fn upsample_nearest(
    x: &[f32],
    h: usize,
    w: usize,
    oh: usize,
    ow: usize,
) -> KernelResult<Vec<f32>> {
    if h == 0 || w == 0 || !x.len().is_multiple_of(h * w) {
        return Err(KernelError::Rows {
            op: "upsample",
            len: x.len(),
            row: h * w,
        });
    }
    let planes = x.len() / (h * w);
    let cols: Vec<usize> = (0..ow).map(|j| j * w / ow).collect();
    let mut out = vec![0f32; planes * oh * ow];
    if oh == 0 || ow == 0 {
        return Ok(out);
    }
    out.par_chunks_mut(oh * ow)
        .zip(x.par_chunks(h * w))
        .for_each(|(o, p)| {
            for (i, orow) in o.chunks_exact_mut(ow).enumerate() {
                let src = &p[(i * h / oh) * w..][..w];
                for (d, &j) in orow.iter_mut().zip(&cols) {
                    *d = src[j];
                }
            }
        });
    Ok(out)
}

/// `f(a[i], b[i])` for two equally long slices, in parallel chunks.
fn zip_map(
    name: &'static str,
    a: &[f32],
    b: &[f32],
    f: impl Fn(f32, f32) -> f32 + Sync,
) -> KernelResult<Vec<f32>> {
    if a.len() != b.len() {
        return Err(KernelError::Length {
            op: name,
            what: "second operand",
            got: b.len(),
            want: a.len(),
        });
    }
    let mut out = vec![0f32; a.len()];
    out.par_chunks_mut(CHUNK)
        .zip(a.par_chunks(CHUNK).zip(b.par_chunks(CHUNK)))
        .for_each(|(o, (a, b))| {
            for ((o, a), b) in o.iter_mut().zip(a).zip(b) {
                *o = f(*a, *b);
            }
        });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relu_pieces() {
        let a: Vec<f32> = (0..70_000).map(|i| (i as f32 * 0.37).sin()).collect();
        let b: Vec<f32> = (0..70_000).map(|i| (i as f32 * 0.11).cos() * 0.5).collect();
        let y = add_relu(&a, &b).unwrap();
        assert!(
            y.iter()
                .zip(a.iter().zip(&b))
                .all(|(y, (a, b))| *y == (a + b).max(0.0))
        );
        let d = relu_backward(&y, &a).unwrap();
        assert!(
            d.iter()
                .zip(y.iter().zip(&a))
                .all(|(d, (y, g))| *d == if *y > 0.0 { *g } else { 0.0 })
        );
        let mut r = a.clone();
        relu_inplace(&mut r);
        assert!(r.iter().zip(&a).all(|(r, a)| *r == a.max(0.0)));
        assert!(add_relu(&a, &b[1..]).is_err() && relu_backward(&a[1..], &b).is_err());
    }

    #[test]
    fn geglu_upsample_and_channel_offsets() {
        let h: Vec<f32> = (0..3 * 10).map(|i| (i as f32 * 0.31).sin() * 3.0).collect();
        let g = geglu(&h, 5).unwrap();
        for r in 0..3 {
            for j in 0..5 {
                let (a, x) = (h[r * 10 + j], h[r * 10 + 5 + j]);
                assert!((g[r * 5 + j] - a * math::gelu(x)).abs() < 1e-6);
            }
        }
        assert!(geglu(&h[1..], 5).is_err());
        // 2x: every source pixel becomes a 2x2 block; 2 -> 3 follows floor(i * 2 / 3)
        let x = [1.0, 2.0, 3.0, 4.0];
        let u = upsample_nearest(&x, 2, 2, 4, 4).unwrap();
        assert_eq!(&u[..8], &[1.0, 1.0, 2.0, 2.0, 1.0, 1.0, 2.0, 2.0]);
        assert_eq!(&u[8..12], &[3.0, 3.0, 4.0, 4.0]);
        let u = upsample_nearest(&x, 2, 2, 3, 3).unwrap();
        assert_eq!(u, vec![1.0, 1.0, 2.0, 1.0, 1.0, 2.0, 3.0, 3.0, 4.0]);
        let mut y = vec![1.0f32; 6];
        add_per_channel(&mut y, &[1.0, 2.0], 3).unwrap();
        assert_eq!(y, vec![2.0, 2.0, 2.0, 3.0, 3.0, 3.0]);
        assert!(add_per_channel(&mut y, &[1.0], 3).is_err());
        assert_eq!(add_scaled(&[1.0], &[2.0], 0.5).unwrap(), vec![1.5]);
    }
}
