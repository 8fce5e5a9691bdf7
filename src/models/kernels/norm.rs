//! Group normalisation (optionally followed by SiLU) in one pass over each group, and its input
//! gradient in two. candle's op-by-op version walks every activation six or more times
//! (mean, subtract, square, mean, scale, affine, activation), writing a new tensor each time.
//!
//! Layout: `x [b, c, n]` contiguous (`n` = spatial size); group `g` of image `b` is the contiguous
//! run of `c / groups` channels, so groups are independent chunks and run in parallel. Statistics
//! accumulate in f64.

use super::math::{exp_fast, vectorised};
use super::{KernelError, KernelResult, check_len};
use rayon::prelude::*;

/// Shape and parameters of one group norm. Invariant (checked by [`GroupNormGeom::new`]):
/// `groups ≥ 1` divides `c`, and `gamma`/`beta` have `c` values.
#[derive(Clone, Copy, Debug)]
pub struct GroupNormGeom<'a> {
    pub b: usize,
    pub c: usize,
    pub n: usize,
    pub groups: usize,
    pub eps: f64,
    pub gamma: &'a [f32],
    pub beta: &'a [f32],
}

impl<'a> GroupNormGeom<'a> {
    pub fn new(
        (b, c, n): (usize, usize, usize),
        groups: usize,
        eps: f64,
        gamma: &'a [f32],
        beta: &'a [f32],
    ) -> KernelResult<Self> {
        if groups == 0 || c % groups != 0 {
            return Err(KernelError::Geometry {
                op: "group norm",
                reason: format!("{c} channels not divisible by {groups} groups"),
            });
        }
        check_len("group norm", "gamma", gamma.len(), c)?;
        check_len("group norm", "beta", beta.len(), c)?;
        Ok(Self {
            b,
            c,
            n,
            groups,
            eps,
            gamma,
            beta,
        })
    }

    fn group_len(&self) -> usize {
        self.c / self.groups * self.n
    }

    fn check(&self, what: &'static str, len: usize) -> KernelResult<()> {
        check_len("group norm", what, len, self.b * self.c * self.n)
    }
}

#[inline(always)]
fn sigmoid(a: f32) -> f32 {
    1.0 / (1.0 + exp_fast(-a))
}

/// `Σ f(x_i)` in f64, from 8-lane f32 partial sums over blocks of 1 024 values (each lane adds
/// at most 128 terms in f32), so the loop vectorises without f32's error on long sums.
#[inline(always)]
fn sum_f64(xs: &[f32], f: impl Fn(f32) -> f32) -> f64 {
    let mut total = 0f64;
    for block in xs.chunks(1024) {
        let mut acc = [0f32; 8];
        let mut ch = block.chunks_exact(8);
        for c in &mut ch {
            for l in 0..8 {
                acc[l] += f(c[l]);
            }
        }
        let rest: f32 = ch.remainder().iter().map(|&v| f(v)).sum();
        total += (acc.iter().sum::<f32>() + rest) as f64;
    }
    total
}

/// `(Σ a_i, Σ a_i·b_i)` in f64 with the blocking of [`sum_f64`].
#[inline(always)]
fn sums2_f64(a: &[f32], b: &[f32]) -> (f64, f64) {
    let (mut t1, mut t2) = (0f64, 0f64);
    for (ba, bb) in a.chunks(1024).zip(b.chunks(1024)) {
        let (mut a1, mut a2) = ([0f32; 8], [0f32; 8]);
        let (mut ca, mut cb) = (ba.chunks_exact(8), bb.chunks_exact(8));
        for (x, y) in (&mut ca).zip(&mut cb) {
            for l in 0..8 {
                a1[l] += x[l];
                a2[l] += x[l] * y[l];
            }
        }
        let (mut r1, mut r2) = (0f32, 0f32);
        for (&x, &y) in ca.remainder().iter().zip(cb.remainder()) {
            r1 += x;
            r2 += x * y;
        }
        t1 += (a1.iter().sum::<f32>() + r1) as f64;
        t2 += (a2.iter().sum::<f32>() + r2) as f64;
    }
    (t1, t2)
}

/// One `(image, group)` of [`group_norm`]: its values `xc`, its outputs `y` (and `x̂`).
#[inline(always)]
fn group_forward(
    g: &GroupNormGeom,
    idx: usize,
    xc: &[f32],
    (yc, xh): (&mut [f32], Option<&mut [f32]>),
    inv_out: &mut f32,
    silu: bool,
) {
    let len = xc.len() as f64;
    let mean = sum_f64(xc, |v| v) / len;
    let m32 = mean as f32;
    // two passes: the variance of the centred values (the residual mean error is ~1e-7 of the
    // spread, so its square is negligible)
    let var = sum_f64(xc, |v| (v - m32) * (v - m32)) / len;
    let inv_std = 1.0 / (var + g.eps).sqrt();
    *inv_out = inv_std as f32;
    let inv_std = inv_std as f32;
    let cpg = g.c / g.groups;
    let ch0 = (idx % g.groups) * cpg;
    for j in 0..cpg {
        let (ga, be) = (g.gamma[ch0 + j], g.beta[ch0 + j]);
        let r = j * g.n..(j + 1) * g.n;
        let (src, dst) = (&xc[r.clone()], &mut yc[r]);
        if silu {
            for (d, &v) in dst.iter_mut().zip(src) {
                let a = (v - m32) * inv_std * ga + be;
                *d = a * sigmoid(a);
            }
        } else {
            for (d, &v) in dst.iter_mut().zip(src) {
                *d = (v - m32) * inv_std * ga + be;
            }
        }
    }
    if let Some(xh) = xh {
        for (d, &v) in xh.iter_mut().zip(xc) {
            *d = (v - m32) * inv_std;
        }
    }
}

/// `(y, x̂ if kept, 1/σ per (image, group))`.
pub type GroupNormOut = (Vec<f32>, Option<Vec<f32>>, Vec<f32>);

/// Forward: returns `y = γ·x̂ + β` (then `silu(y)` when `silu`), the normalised input `x̂` (only
/// when `keep_xhat`, for the backward pass) and `1/σ` per `(image, group)`.
pub fn group_norm(
    g: &GroupNormGeom,
    x: &[f32],
    silu: bool,
    keep_xhat: bool,
) -> KernelResult<GroupNormOut> {
    g.check("input", x.len())?;
    let len = g.group_len();
    let mut y = vec![0f32; x.len()];
    let mut xhat = if keep_xhat {
        vec![0f32; x.len()]
    } else {
        Vec::new()
    };
    let mut inv = vec![0f32; g.b * g.groups];
    if len == 0 {
        return Ok((y, keep_xhat.then_some(xhat), inv));
    }
    let one = |idx: usize, yc: &mut [f32], xh: Option<&mut [f32]>, inv_out: &mut f32| {
        let xc = &x[idx * len..(idx + 1) * len];
        vectorised(
            #[inline(always)]
            || group_forward(g, idx, xc, (yc, xh), inv_out, silu),
        )
    };
    if keep_xhat {
        y.par_chunks_mut(len)
            .zip(xhat.par_chunks_mut(len))
            .zip(inv.par_iter_mut())
            .enumerate()
            .for_each(|(idx, ((yc, xh), iv))| one(idx, yc, Some(xh), iv));
    } else {
        y.par_chunks_mut(len)
            .zip(inv.par_iter_mut())
            .enumerate()
            .for_each(|(idx, (yc, iv))| one(idx, yc, None, iv));
    }
    Ok((y, keep_xhat.then_some(xhat), inv))
}

/// One `(image, group)` of [`group_norm_input_grad`].
#[inline(always)]
fn group_backward(
    g: &GroupNormGeom,
    idx: usize,
    (dyc, xh): (&[f32], &[f32]),
    dxc: &mut [f32],
    inv_std: f32,
    silu: bool,
) {
    let cpg = g.c / g.groups;
    let ch0 = (idx % g.groups) * cpg;
    // pass 1: d̂ = γ·dy_pre into dx
    for j in 0..cpg {
        let (ga, be) = (g.gamma[ch0 + j], g.beta[ch0 + j]);
        let cr = j * g.n..(j + 1) * g.n;
        let (d, gy, xv) = (&mut dxc[cr.clone()], &dyc[cr.clone()], &xh[cr]);
        if silu {
            for ((d, &gy), &xv) in d.iter_mut().zip(gy).zip(xv) {
                let a = xv * ga + be;
                let s = sigmoid(a);
                *d = gy * s * (1.0 + a * (1.0 - s)) * ga;
            }
        } else {
            for (d, &gy) in d.iter_mut().zip(gy) {
                *d = gy * ga;
            }
        }
    }
    // its two sums, then pass 2
    let (s1, s2) = sums2_f64(dxc, xh);
    let len = dxc.len() as f64;
    let (m1, m2) = ((s1 / len) as f32, (s2 / len) as f32);
    for (d, &xv) in dxc.iter_mut().zip(xh) {
        *d = (*d - m1 - xv * m2) * inv_std;
    }
}

/// Input gradient of [`group_norm`] given `dy` (the gradient of its output, after the SiLU when
/// `silu`), the saved `x̂` and `1/σ`: `dx = (d̂ − mean(d̂) − x̂·mean(d̂·x̂)) / σ` with `d̂ = γ·dy_pre`.
pub fn group_norm_input_grad(
    g: &GroupNormGeom,
    dy: &[f32],
    xhat: &[f32],
    inv_std: &[f32],
    silu: bool,
) -> KernelResult<Vec<f32>> {
    g.check("output gradient", dy.len())?;
    g.check("normalised input", xhat.len())?;
    check_len(
        "group norm",
        "saved statistics",
        inv_std.len(),
        g.b * g.groups,
    )?;
    let len = g.group_len();
    let mut dx = vec![0f32; dy.len()];
    if len == 0 {
        return Ok(dx);
    }
    dx.par_chunks_mut(len).enumerate().for_each(|(idx, dxc)| {
        let r = idx * len..(idx + 1) * len;
        let (dyc, xh) = (&dy[r.clone()], &xhat[r]);
        vectorised(
            #[inline(always)]
            || group_backward(g, idx, (dyc, xh), dxc, inv_std[idx], silu),
        );
    });
    Ok(dx)
}

/// Layer normalisation over the last axis of `x [rows, c]` (`γ`, `β` of length `c`), rows in
/// parallel; statistics accumulate in f64.
pub fn layer_norm(
    x: &[f32],
    c: usize,
    gamma: &[f32],
    beta: &[f32],
    eps: f64,
) -> KernelResult<Vec<f32>> {
    if c == 0 || !x.len().is_multiple_of(c) {
        return Err(KernelError::Rows {
            op: "layer norm",
            len: x.len(),
            row: c,
        });
    }
    check_len("layer norm", "gamma", gamma.len(), c)?;
    check_len("layer norm", "beta", beta.len(), c)?;
    let mut y = vec![0f32; x.len()];
    let rows_per = (1 << 14) / c + 1;
    y.par_chunks_mut(rows_per * c)
        .zip(x.par_chunks(rows_per * c))
        .for_each(|(yc, xc)| {
            for (yr, xr) in yc.chunks_exact_mut(c).zip(xc.chunks_exact(c)) {
                let mean = xr.iter().map(|&v| v as f64).sum::<f64>() / c as f64;
                let var = xr
                    .iter()
                    .map(|&v| (v as f64 - mean) * (v as f64 - mean))
                    .sum::<f64>()
                    / c as f64;
                let (m, inv) = (mean as f32, (1.0 / (var + eps).sqrt()) as f32);
                for (((o, &v), &g), &b) in yr.iter_mut().zip(xr).zip(gamma).zip(beta) {
                    *o = (v - m) * inv * g + b;
                }
            }
        });
    Ok(y)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rand(n: usize, seed: u64) -> Vec<f32> {
        crate::models::kernels::test_values(n, seed)
    }

    /// The scalar loss `Σ r ⊙ f(x)` and its finite-difference gradient.
    fn fd_check(silu: bool) {
        let (b, c, n, groups) = (2, 6, 5, 3);
        let gamma = rand(c, 1);
        let beta = rand(c, 2);
        let g = GroupNormGeom::new((b, c, n), groups, 1e-5, &gamma, &beta).unwrap();
        let x: Vec<f32> = rand(b * c * n, 3).iter().map(|v| v * 2.0 + 0.3).collect();
        let r = rand(b * c * n, 4);
        let loss = |x: &[f32]| -> f64 {
            let (y, _, _) = group_norm(&g, x, silu, false).unwrap();
            y.iter()
                .zip(&r)
                .map(|(a, b)| (*a as f64) * (*b as f64))
                .sum()
        };
        let (_, xhat, inv) = group_norm(&g, &x, silu, true).unwrap();
        let dx = group_norm_input_grad(&g, &r, &xhat.unwrap(), &inv, silu).unwrap();
        let h = 1e-2f32;
        for i in (0..x.len()).step_by(7) {
            let mut xp = x.clone();
            xp[i] += h;
            let mut xm = x.clone();
            xm[i] -= h;
            let fd = (loss(&xp) - loss(&xm)) / (2.0 * h as f64);
            assert!(
                (fd - dx[i] as f64).abs() < 2e-3 * (1.0 + fd.abs()),
                "silu {silu}, x[{i}]: finite difference {fd} vs {}",
                dx[i]
            );
        }
    }

    #[test]
    fn gradient_matches_finite_differences() {
        fd_check(false);
        fd_check(true);
    }

    #[test]
    fn forward_normalises_each_group() {
        let (b, c, n, groups) = (1, 4, 8, 2);
        let gamma = vec![1.0; c];
        let beta = vec![0.0; c];
        let g = GroupNormGeom::new((b, c, n), groups, 0.0, &gamma, &beta).unwrap();
        let x: Vec<f32> = (0..b * c * n).map(|i| (i * i) as f32 * 0.1).collect();
        let (y, _, _) = group_norm(&g, &x, false, false).unwrap();
        for grp in y.chunks(c / groups * n) {
            let mean: f32 = grp.iter().sum::<f32>() / grp.len() as f32;
            let var: f32 = grp.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / grp.len() as f32;
            assert!(
                mean.abs() < 1e-5 && (var - 1.0).abs() < 1e-4,
                "{mean} {var}"
            );
        }
        assert!(GroupNormGeom::new((1, 4, 8), 3, 1e-5, &gamma, &beta).is_err());
        assert!(group_norm(&g, &x[1..], false, false).is_err());
    }

    /// Groups longer than the 1 024-value blocks of the lane sums (with a remainder), offset
    /// far from zero, against the same formulas in f64.
    #[test]
    fn long_groups_match_an_f64_reference() {
        let (b, c, n, groups) = (2, 4, 3001, 2);
        let gamma = rand(c, 11);
        let beta = rand(c, 12);
        let g = GroupNormGeom::new((b, c, n), groups, 1e-6, &gamma, &beta).unwrap();
        let x: Vec<f32> = rand(b * c * n, 13).iter().map(|v| 50.0 + v).collect();
        let dy = rand(b * c * n, 14);
        let (y, xhat, inv) = group_norm(&g, &x, true, true).unwrap();
        let xhat = xhat.unwrap();
        let dx = group_norm_input_grad(&g, &dy, &xhat, &inv, true).unwrap();
        let len = c / groups * n;
        for (gi, r) in (0..b * groups).map(|gi| (gi, gi * len..(gi + 1) * len)) {
            let xs: Vec<f64> = x[r.clone()].iter().map(|&v| v as f64).collect();
            let mean = xs.iter().sum::<f64>() / len as f64;
            let var = xs.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / len as f64;
            let is = 1.0 / (var + 1e-6).sqrt();
            assert!((inv[gi] as f64 - is).abs() < 1e-5 * is);
            let ch0 = (gi % groups) * (c / groups);
            let mut dh = vec![0f64; len];
            for (k, i) in r.clone().enumerate() {
                let ch = ch0 + k / n;
                let (ga, be) = (gamma[ch] as f64, beta[ch] as f64);
                let xh = (xs[k] - mean) * is;
                let a = xh * ga + be;
                let sg = 1.0 / (1.0 + (-a).exp());
                assert!((y[i] as f64 - a * sg).abs() < 2e-5, "y[{i}]");
                dh[k] = dy[i] as f64 * sg * (1.0 + a * (1.0 - sg)) * ga;
            }
            let m1 = dh.iter().sum::<f64>() / len as f64;
            let m2 = dh
                .iter()
                .zip(&xhat[r.clone()])
                .map(|(d, &h)| d * h as f64)
                .sum::<f64>()
                / len as f64;
            for (k, i) in r.enumerate() {
                let want = (dh[k] - m1 - xhat[i] as f64 * m2) * is;
                assert!(
                    (dx[i] as f64 - want).abs() < 1e-4 * (1.0 + want.abs()),
                    "dx[{i}]"
                );
            }
        }
    }

    #[test]
    fn layer_norm_matches_the_definition() {
        let c = 48;
        let x = crate::models::kernels::test_values(7 * c, 3);
        let gamma = crate::models::kernels::test_values(c, 4);
        let beta = crate::models::kernels::test_values(c, 5);
        let y = layer_norm(&x, c, &gamma, &beta, 1e-5).unwrap();
        for r in 0..7 {
            let xr = &x[r * c..(r + 1) * c];
            let m = xr.iter().sum::<f32>() / c as f32;
            let v = xr.iter().map(|a| (a - m) * (a - m)).sum::<f32>() / c as f32;
            for j in 0..c {
                let want = (xr[j] - m) / (v + 1e-5).sqrt() * gamma[j] + beta[j];
                assert!((y[r * c + j] - want).abs() < 1e-5);
            }
        }
        assert!(layer_norm(&x[1..], c, &gamma, &beta, 1e-5).is_err());
        assert!(layer_norm(&x, c, &gamma[1..], &beta, 1e-5).is_err());
    }
}
