use super::*;
use crate::models::kernels::{max_abs_diff, test_values};

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
                                if yi < 0 || xi < 0 || yi >= g.h as isize || xi >= g.w as isize {
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
    test_values(n, seed.wrapping_add(0x5eed))
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
                let err = max_abs_diff(&got, &want);
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
            let d = max_abs_diff(&atv, &prepared);
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
