//! Convolution and group-norm kernels against candle's own CPU ops, on the layer shapes of the
//! SD VAE and TAESD (f32, batch 1, random values).
//!
//! `cargo bench --bench conv_kernels [-- REPS]` prints, per shape, the median wall milliseconds
//! and GFLOP/s (direct-convolution FLOPs, so Winograd shows as more than the machine's GEMM
//! rate) of: our conv forward (Winograd for 3×3 stride 1), our im2col GEMM forward, candle's
//! `conv2d`, our input gradient (adjoint), and the group norm + SiLU (ours fused vs candle op
//! by op).

use candle_core::{Device, Tensor};
use std::time::Instant;
use vectorfusion::models::kernels::{self, conv, norm, winograd};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn time<T>(reps: usize, mut f: impl FnMut() -> T) -> f64 {
    std::hint::black_box(f());
    median(
        (0..reps)
            .map(|_| {
                let t = Instant::now();
                std::hint::black_box(f());
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect(),
    )
}

fn main() -> candle_core::Result<()> {
    let reps: usize = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(5);
    let dev = Device::Cpu;
    println!(
        "threads {} | reps {reps} | ms (GFLOP/s)",
        candle_core::utils::get_num_threads()
    );
    println!(
        "{:<28} {:>16} {:>16} {:>16} {:>16}",
        "conv (ci→co @ h, k, s)", "ours fwd", "ours im2col fwd", "candle fwd", "ours adjoint"
    );
    for &(ci, co, h, k, s) in &[
        (64, 64, 256, 3, 1),   // TAESD encoder blocks at 512 px
        (64, 64, 512, 3, 1),   // TAESD first block / decoder top
        (128, 128, 256, 3, 1), // SD VAE at 256 px, top level
        (256, 256, 128, 3, 1),
        (512, 512, 64, 3, 1),
        (512, 512, 32, 3, 1),
        (128, 128, 256, 3, 2), // downsampler (stride 2)
        (256, 512, 64, 1, 1),  // shortcut 1×1
    ] {
        let pad = if k == 3 { [1; 4] } else { [0; 4] };
        let g = conv::ConvGeom::new(1, ci, h, h, co, k, s, pad).map_err(kernels::err)?;
        let (ho, wo) = g.out_hw();
        let x = Tensor::randn(0f32, 1.0, (1, ci, h, h), &dev)?;
        let w = Tensor::randn(0f32, 0.05, (co, ci, k, k), &dev)?;
        let dy = Tensor::randn(0f32, 1.0, (1, co, ho, wo), &dev)?;
        let (xs, ws, dys) = (
            x.flatten_all()?.to_vec1::<f32>()?,
            w.flatten_all()?.to_vec1::<f32>()?,
            dy.flatten_all()?.to_vec1::<f32>()?,
        );
        let gflop = 2.0 * (ci * co * k * k * ho * wo) as f64 / 1e9;
        // the layers cache the Winograd transforms; so does this bench
        let wino = (k == 3 && s == 1).then(|| winograd::transform_kernel(&ws, co, ci));
        let wino_t = (k == 3 && s == 1)
            .then(|| winograd::transform_kernel(&conv::flip_transpose(&ws, co, ci, k), ci, co));
        let ours = time(reps, || {
            conv::conv2d_prepared(&g, &xs, &ws, wino.as_deref(), None)
        });
        let im2col = time(reps, || conv::conv2d_im2col(&g, &xs, &ws, None));
        let cand = time(reps, || x.conv2d(&w, pad[0], s, 1, 1));
        let adj = time(reps, || {
            conv::conv2d_input_grad_prepared(&g, &dys, &ws, wino_t.as_deref())
        });
        let f = |ms: f64| format!("{ms:8.1} ({:5.1})", gflop / ms * 1e3);
        println!(
            "{:<28} {:>16} {:>16} {:>16} {:>16}",
            format!("{ci}→{co} @ {h}, {k}x{k}, s{s}"),
            f(ours),
            f(im2col),
            f(cand),
            f(adj)
        );
    }
    println!(
        "\n{:<28} {:>16} {:>16}",
        "group norm + SiLU (c @ h)", "ours fused", "candle ops"
    );
    for &(c, h) in &[(128, 512), (128, 256), (512, 64)] {
        let x = Tensor::randn(0f32, 1.0, (1, c, h, h), &dev)?;
        let gamma = vec![1.1f32; c];
        let beta = vec![0.1f32; c];
        let xs = x.flatten_all()?.to_vec1::<f32>()?;
        let g = norm::GroupNormGeom::new((1, c, h * h), 32, 1e-6, &gamma, &beta)
            .map_err(kernels::err)?;
        let ours = time(reps, || norm::group_norm(&g, &xs, true, false));
        let gt = Tensor::new(gamma.as_slice(), &dev)?.reshape((1, c, 1, 1))?;
        let bt = Tensor::new(beta.as_slice(), &dev)?.reshape((1, c, 1, 1))?;
        let cand = time(reps, || -> candle_core::Result<Tensor> {
            let xg = x.reshape((1, 32, ()))?;
            let mean = xg.mean_keepdim(2)?;
            let xc = xg.broadcast_sub(&mean)?;
            let var = xc.sqr()?.mean_keepdim(2)?;
            let xh = xc.broadcast_div(&(var + 1e-6)?.sqrt()?)?;
            xh.reshape((1, c, h, h))?
                .broadcast_mul(&gt)?
                .broadcast_add(&bt)?
                .silu()
        });
        println!(
            "{:<28} {:>13.1} ms {:>13.1} ms",
            format!("{c} @ {h}"),
            ours,
            cand
        );
    }
    Ok(())
}
