//! The SDS image-space gradient with the analytic TEST teacher equals an independent brute-force
//! f64 computation: `dL/dx = J_encᵀ · w(t)(ε̂ − ε)` with the encoder Jacobian taken column by
//! column by finite differences and `ε̂` from the Gaussian likelihoods of every target.

#![allow(clippy::needless_range_loop)] // index loops read clearest in pixel code

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use vectorfusion::image::Image;
use vectorfusion::stages::sds::{Weighting, gaussian, sds_image_grad};
use vectorfusion::teacher::{AnalyticTeacher, AnalyticTeacherConfig, Teacher};

fn random_image(rng: &mut ChaCha8Rng, s: u32) -> Image {
    let mut im = Image::new(s, s);
    for px in im.data.chunks_exact_mut(4) {
        let a: f32 = rng.random_range(0.3..1.0);
        for c in 0..3 {
            px[c] = a * rng.random::<f32>();
        }
        px[3] = a;
    }
    im
}

#[test]
fn sds_image_gradient_equals_brute_force() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let s = 8u32;
    let targets: Vec<_> = (0..3)
        .map(|i| (format!("target{i}"), random_image(&mut rng, s)))
        .collect();
    let te = AnalyticTeacher::new(
        AnalyticTeacherConfig {
            image_size: s,
            pool: 2,
            num_train_timesteps: 1000,
        },
        targets,
    )
    .unwrap();
    let n = te.latent_shape().iter().product::<usize>();
    // Encoded targets via the public encoder, in f64.
    let zk: Vec<Vec<f64>> = te
        .targets()
        .iter()
        .map(|im| {
            te.encode(im)
                .unwrap()
                .data
                .iter()
                .map(|v| *v as f64)
                .collect()
        })
        .collect();
    for (case, &(t, weighting, guidance, prompt)) in [
        (800usize, Weighting::OneMinusAlpha, 1.0f32, "anything"),
        (400, Weighting::Uniform, 1.0, "no names"),
        (950, Weighting::SqrtAlphaSigma, 7.5, "a target1 please"),
    ]
    .iter()
    .enumerate()
    {
        // Start near target 0 so that several mixture weights matter at large t.
        let mut x = te.targets()[0].clone();
        for v in &mut x.data {
            *v = (*v + rng.random_range(-0.2..0.2f32)).clamp(0.0, 1.0);
        }
        for px in x.data.chunks_exact_mut(4) {
            for c in 0..3 {
                px[c] = px[c].min(px[3]);
            }
        }
        let noise: Vec<f32> = (0..n).map(|_| gaussian(&mut rng)).collect();
        let cond = te.condition(prompt, "").unwrap();
        let (g, _) = sds_image_grad(&te, &x, t, &noise, &cond, guidance, weighting).unwrap();

        // Brute force.
        let ab = te.alphas_cumprod()[t] as f64;
        let (sa, sig) = (ab.sqrt(), (1.0 - ab).sqrt());
        let z: Vec<f64> = te
            .encode(&x)
            .unwrap()
            .data
            .iter()
            .map(|v| *v as f64)
            .collect();
        let zt: Vec<f64> = (0..n).map(|i| sa * z[i] + sig * noise[i] as f64).collect();
        let eps_for = |set: &[usize]| -> Vec<f64> {
            let lik: Vec<f64> = set
                .iter()
                .map(|&k| {
                    let d2: f64 = (0..n).map(|i| (zt[i] - sa * zk[k][i]).powi(2)).sum();
                    (-d2 / (2.0 * sig * sig)).exp()
                })
                .collect();
            let tot: f64 = lik.iter().sum();
            (0..n)
                .map(|i| {
                    let x0: f64 = set.iter().zip(&lik).map(|(&k, l)| l / tot * zk[k][i]).sum();
                    (zt[i] - sa * x0) / sig
                })
                .collect()
        };
        let eu = eps_for(&[0, 1, 2]);
        let eps_hat: Vec<f64> = if prompt.contains("target1") {
            let ec = eps_for(&[1]);
            (0..n)
                .map(|i| eu[i] + guidance as f64 * (ec[i] - eu[i]))
                .collect()
        } else {
            eu
        };
        let w = match weighting {
            Weighting::OneMinusAlpha => 1.0 - ab,
            Weighting::Uniform => 1.0,
            Weighting::SqrtAlphaSigma => (ab * (1.0 - ab)).sqrt(),
        };
        let gz: Vec<f64> = (0..n).map(|i| w * (eps_hat[i] - noise[i] as f64)).collect();
        let h = 1e-2f32;
        let mut max_err = 0.0f64;
        let mut max_mag = 0.0f64;
        for i in 0..x.data.len() {
            let (mut p, mut m) = (x.clone(), x.clone());
            p.data[i] += h;
            m.data[i] -= h;
            let (zp, zm) = (te.encode(&p).unwrap(), te.encode(&m).unwrap());
            let want: f64 = (0..n)
                .map(|j| (zp.data[j] as f64 - zm.data[j] as f64) / (2.0 * h as f64) * gz[j])
                .sum();
            max_err = max_err.max((want - g[i] as f64).abs());
            max_mag = max_mag.max(want.abs());
        }
        assert!(max_mag > 1e-3, "case {case}: gradient is trivially zero");
        assert!(
            max_err < 1e-3 * max_mag.max(1.0),
            "case {case}: max error {max_err} (scale {max_mag})"
        );
    }
}
