//! **Test teacher**: the exact optimal denoiser of a small fixed set of target images.
//!
//! This is not a generative model. It exists so that score distillation can be tested end to end
//! without pretrained weights: for a data distribution that is a uniform mixture of point masses
//! at the encoded targets `z_k`, the MMSE denoiser is known in closed form,
//!
//! ```text
//! z_t = √ᾱ_t z_0 + √(1−ᾱ_t) ε
//! w_k = softmax_k( −|z_t − √ᾱ_t z_k|² / (2 (1−ᾱ_t)) )
//! x̂_0 = Σ_k w_k z_k,    ε̂ = (z_t − √ᾱ_t x̂_0) / √(1−ᾱ_t)
//! ```
//!
//! so SDS with it pulls the render towards the nearest target, which tests can measure (PSNR).
//!
//! The "encoder" maps pixels to `[-1, 1]`: the image is composited over white, average-pooled by
//! `pool` (1 = identity) and scaled `z = 2·x − 1`. Its VJP is exact.
//!
//! Conditioning: targets whose file stem (name) appears in the caption form the conditional
//! mixture; the unconditional mixture is all targets. With no name in the caption both coincide
//! and guidance has no effect.

#![allow(clippy::needless_range_loop)] // index loops read clearest in pixel code

use super::{
    Conditioning, Latent, SampleConfig, SampleError, Teacher, TeacherError, sd_alphas_cumprod,
};
use crate::image::Image;
use crate::progress::{CancelToken, Progress, ProgressSink};
use std::path::Path;

/// Settings of the analytic test teacher.
#[derive(Clone, Debug, PartialEq)]
pub struct AnalyticTeacherConfig {
    /// Side of the (square) images the encoder takes.
    pub image_size: u32,
    /// Average-pool factor of the encoder (must divide `image_size`); 1 = identity.
    pub pool: u32,
    /// Number of diffusion training timesteps (SD's scaled-linear schedule).
    pub num_train_timesteps: usize,
}

impl Default for AnalyticTeacherConfig {
    fn default() -> Self {
        Self {
            image_size: 64,
            pool: 1,
            num_train_timesteps: 1000,
        }
    }
}

/// The analytic **test teacher** (see the module docs).
#[derive(Clone, Debug)]
pub struct AnalyticTeacher {
    config: AnalyticTeacherConfig,
    names: Vec<String>,
    targets: Vec<Image>,
    /// Encoded targets, f64.
    latents: Vec<Vec<f64>>,
    alphas: Vec<f32>,
}

impl AnalyticTeacher {
    /// Builds the teacher from named target images, each resized (bilinear) to `image_size`.
    pub fn new(
        config: AnalyticTeacherConfig,
        targets: Vec<(String, Image)>,
    ) -> Result<Self, TeacherError> {
        if targets.is_empty() {
            return Err(TeacherError::Setup(
                "the analytic test teacher needs at least one target image".into(),
            ));
        }
        if config.image_size == 0
            || config.pool == 0
            || !config.image_size.is_multiple_of(config.pool)
        {
            return Err(TeacherError::Setup(format!(
                "pool factor {} must be positive and divide the image size {}",
                config.pool, config.image_size
            )));
        }
        if config.num_train_timesteps < 2 {
            return Err(TeacherError::Setup("need at least 2 timesteps".into()));
        }
        let mut names = Vec::new();
        let mut images = Vec::new();
        for (name, im) in targets {
            if im.width == 0 || im.height == 0 {
                return Err(TeacherError::Setup(format!("target {name} is empty")));
            }
            images.push(resize_bilinear(&im, config.image_size, config.image_size));
            names.push(name);
        }
        let alphas = sd_alphas_cumprod(config.num_train_timesteps)?;
        let mut t = Self {
            config,
            names,
            targets: images,
            latents: Vec::new(),
            alphas,
        };
        t.latents = t
            .targets
            .iter()
            .map(|im| t.encode_f64(im))
            .collect::<Result<_, _>>()?;
        Ok(t)
    }

    /// Loads every `*.png` in `dir` (sorted by name) as a target; names are the file stems.
    pub fn from_dir(dir: &Path, config: AnalyticTeacherConfig) -> Result<Self, TeacherError> {
        let rd = std::fs::read_dir(dir)
            .map_err(|e| TeacherError::Io(format!("cannot read {}: {e}", dir.display())))?;
        let mut paths: Vec<_> = rd
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.extension()
                    .and_then(|e| e.to_str())
                    .is_some_and(|e| e.eq_ignore_ascii_case("png"))
            })
            .collect();
        paths.sort();
        if paths.is_empty() {
            return Err(TeacherError::Setup(format!(
                "no .png target images in {}",
                dir.display()
            )));
        }
        let mut targets = Vec::new();
        for p in paths {
            let im = Image::open(&p).map_err(|e| TeacherError::Io(e.to_string()))?;
            let name = p
                .file_stem()
                .and_then(|s| s.to_str())
                .unwrap_or("target")
                .to_string();
            targets.push((name, im));
        }
        Self::new(config, targets)
    }

    /// The target images, resized to the teacher's image size.
    pub fn targets(&self) -> &[Image] {
        &self.targets
    }

    pub fn target_names(&self) -> &[String] {
        &self.names
    }

    pub fn config(&self) -> &AnalyticTeacherConfig {
        &self.config
    }

    fn check_image(&self, image: &Image) -> Result<(), TeacherError> {
        let s = self.config.image_size;
        if image.width != s || image.height != s || image.data.len() != 4 * (s * s) as usize {
            return Err(TeacherError::ImageSize {
                got_w: image.width,
                got_h: image.height,
                want_w: s,
                want_h: s,
            });
        }
        Ok(())
    }

    fn encode_f64(&self, image: &Image) -> Result<Vec<f64>, TeacherError> {
        self.check_image(image)?;
        let [c, h, w] = self.latent_shape();
        let f = self.config.pool as usize;
        let side = self.config.image_size as usize;
        let scale = 2.0 / (f * f) as f64;
        let mut z = vec![0.0f64; c * h * w];
        for y in 0..side {
            for x in 0..side {
                let p = &image.data[4 * (y * side + x)..4 * (y * side + x) + 4];
                let o = (y / f) * w + x / f;
                for ch in 0..3 {
                    z[ch * h * w + o] += scale * (p[ch] as f64 + 1.0 - p[3] as f64);
                }
            }
        }
        for v in &mut z {
            *v -= 1.0;
        }
        Ok(z)
    }

    fn check_latent(&self, z: &Latent) -> Result<(), TeacherError> {
        let want = self.latent_shape();
        if z.shape != want || z.data.len() != want.iter().product::<usize>() {
            return Err(TeacherError::LatentShape { got: z.shape, want });
        }
        Ok(())
    }

    /// Indices of targets whose name appears in the prompt (case-insensitive).
    fn selected(&self, prompt: &str) -> Vec<usize> {
        let p = prompt.to_lowercase();
        self.names
            .iter()
            .enumerate()
            .filter(|(_, n)| !n.is_empty() && p.contains(&n.to_lowercase()))
            .map(|(i, _)| i)
            .collect()
    }

    /// Posterior mean `E[z_0 | z_t]` over the targets in `subset`, in f64.
    fn posterior_mean(&self, z_t: &[f32], t: usize, subset: &[usize]) -> Vec<f64> {
        let ab = self.alphas[t] as f64;
        let (sa, var) = (ab.sqrt(), 1.0 - ab);
        let logits: Vec<f64> = subset
            .iter()
            .map(|&k| {
                let d2: f64 = z_t
                    .iter()
                    .zip(&self.latents[k])
                    .map(|(&a, &b)| {
                        let d = a as f64 - sa * b;
                        d * d
                    })
                    .sum();
                -d2 / (2.0 * var)
            })
            .collect();
        let m = logits.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        let ws: Vec<f64> = logits.iter().map(|l| (l - m).exp()).collect();
        let sum: f64 = ws.iter().sum();
        let mut x0 = vec![0.0f64; z_t.len()];
        for (w, &k) in ws.iter().zip(subset) {
            let w = w / sum;
            for (o, v) in x0.iter_mut().zip(&self.latents[k]) {
                *o += w * v;
            }
        }
        x0
    }

    fn eps_from_x0(&self, z_t: &[f32], t: usize, x0: &[f64]) -> Vec<f64> {
        let ab = self.alphas[t] as f64;
        let (sa, s) = (ab.sqrt(), (1.0 - ab).sqrt());
        z_t.iter()
            .zip(x0)
            .map(|(&z, &x)| (z as f64 - sa * x) / s)
            .collect()
    }
}

impl Teacher for AnalyticTeacher {
    /// Its exact distribution is uniform over the targets, so a sample is a target drawn at
    /// random (`starts` are ignored: a test teacher has no retrieval).
    fn sample(
        &self,
        _prompt: &str,
        _starts: &[Image],
        cfg: &SampleConfig,
        sink: &dyn ProgressSink,
        _cancel: &CancelToken,
    ) -> Result<Vec<Image>, SampleError> {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x5a3b_1e00);
        if self.targets.is_empty() {
            return Err(SampleError::Failed(
                "sampling: the test teacher has no targets".into(),
            ));
        }
        let mut out = Vec::with_capacity(cfg.k as usize);
        for i in 0..cfg.k {
            let j = rng.random_range(0..self.targets.len());
            out.push(self.targets[j].clone());
            sink.report(Progress::new(crate::progress::Stage::Sample, i + 1, cfg.k));
        }
        Ok(out)
    }

    fn name(&self) -> String {
        format!(
            "analytic TEST teacher (exact denoiser of {} target image(s); not a generative model)",
            self.targets.len()
        )
    }

    fn is_test_teacher(&self) -> bool {
        true
    }

    fn image_size(&self) -> u32 {
        self.config.image_size
    }

    fn latent_shape(&self) -> [usize; 3] {
        let s = (self.config.image_size / self.config.pool) as usize;
        [3, s, s]
    }

    fn alphas_cumprod(&self) -> &[f32] {
        &self.alphas
    }

    fn condition(&self, prompt: &str, negative_prompt: &str) -> Result<Conditioning, TeacherError> {
        Ok(Conditioning {
            prompt: prompt.to_string(),
            negative_prompt: negative_prompt.to_string(),
            ..Conditioning::default()
        })
    }

    fn encode(&self, image: &Image) -> Result<Latent, TeacherError> {
        let z = self.encode_f64(image)?;
        Ok(Latent {
            shape: self.latent_shape(),
            data: z.into_iter().map(|v| v as f32).collect(),
        })
    }

    fn encode_vjp(&self, image: &Image, d_latent: &Latent) -> Result<Vec<f32>, TeacherError> {
        self.check_image(image)?;
        self.check_latent(d_latent)?;
        let [_, h, w] = self.latent_shape();
        let f = self.config.pool as usize;
        let side = self.config.image_size as usize;
        let scale = 2.0 / (f * f) as f32;
        let mut d = vec![0.0f32; 4 * side * side];
        for y in 0..side {
            for x in 0..side {
                let o = (y / f) * w + x / f;
                let px = &mut d[4 * (y * side + x)..4 * (y * side + x) + 4];
                let mut da = 0.0;
                for (ch, dp) in px.iter_mut().take(3).enumerate() {
                    let g = scale * d_latent.data[ch * h * w + o];
                    *dp = g;
                    da -= g;
                }
                px[3] = da;
            }
        }
        Ok(d)
    }

    fn predict_noise(
        &self,
        z_t: &Latent,
        t: usize,
        cond: &Conditioning,
        guidance: f32,
    ) -> Result<Latent, TeacherError> {
        self.check_latent(z_t)?;
        super::check_timestep(t, self.alphas.len())?;
        let all: Vec<usize> = (0..self.targets.len()).collect();
        let sel = self.selected(&cond.prompt);
        let eps_u = self.eps_from_x0(&z_t.data, t, &self.posterior_mean(&z_t.data, t, &all));
        let data = if sel.is_empty() || sel.len() == all.len() {
            eps_u.into_iter().map(|v| v as f32).collect()
        } else {
            let eps_c = self.eps_from_x0(&z_t.data, t, &self.posterior_mean(&z_t.data, t, &sel));
            let g = guidance as f64;
            eps_u
                .iter()
                .zip(&eps_c)
                .map(|(u, c)| (u + g * (c - u)) as f32)
                .collect()
        };
        Ok(Latent {
            shape: z_t.shape,
            data,
        })
    }
}

/// Bilinear resize of a premultiplied image (pixel centres aligned, edges clamped).
pub fn resize_bilinear(im: &Image, w: u32, h: u32) -> Image {
    if im.width == w && im.height == h {
        return im.clone();
    }
    let mut out = Image::new(w, h);
    let (sw, sh) = (im.width as usize, im.height as usize);
    let (fx, fy) = (sw as f32 / w as f32, sh as f32 / h as f32);
    for y in 0..h as usize {
        let sy = ((y as f32 + 0.5) * fy - 0.5).clamp(0.0, (sh - 1) as f32);
        let (y0, ty) = (sy.floor() as usize, sy - sy.floor());
        let y1 = (y0 + 1).min(sh - 1);
        for x in 0..w as usize {
            let sx = ((x as f32 + 0.5) * fx - 0.5).clamp(0.0, (sw - 1) as f32);
            let (x0, tx) = (sx.floor() as usize, sx - sx.floor());
            let x1 = (x0 + 1).min(sw - 1);
            for c in 0..4 {
                let g = |xx: usize, yy: usize| im.data[4 * (yy * sw + xx) + c];
                let v = (1.0 - ty) * ((1.0 - tx) * g(x0, y0) + tx * g(x1, y0))
                    + ty * ((1.0 - tx) * g(x0, y1) + tx * g(x1, y1));
                out.data[4 * (y * w as usize + x) + c] = v;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_image(rng: &mut ChaCha8Rng, s: u32) -> Image {
        let mut im = Image::new(s, s);
        for px in im.data.chunks_exact_mut(4) {
            let a: f32 = rng.random_range(0.2..1.0);
            for c in 0..3 {
                px[c] = a * rng.random_range(0.0..1.0f32);
            }
            px[3] = a;
        }
        im
    }

    fn teacher(k: usize, s: u32, pool: u32, seed: u64) -> AnalyticTeacher {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let targets = (0..k)
            .map(|i| (format!("t{i}"), random_image(&mut rng, s)))
            .collect();
        AnalyticTeacher::new(
            AnalyticTeacherConfig {
                image_size: s,
                pool,
                num_train_timesteps: 1000,
            },
            targets,
        )
        .unwrap()
    }

    #[test]
    fn single_target_x0_is_recovered_exactly() {
        let te = teacher(1, 8, 2, 1);
        let z0 = te.encode(&te.targets()[0]).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for &t in &[10usize, 300, 900] {
            // Any z_t: with one target the posterior mean is that target.
            let zt = Latent {
                shape: z0.shape,
                data: (0..z0.len())
                    .map(|_| rng.random_range(-2.0..2.0f32))
                    .collect(),
            };
            let eps = te
                .predict_noise(&zt, t, &Conditioning::default(), 7.5)
                .unwrap();
            let ab = te.alphas_cumprod()[t] as f64;
            for i in 0..zt.len() {
                let x0 = (zt.data[i] as f64 - (1.0 - ab).sqrt() * eps.data[i] as f64) / ab.sqrt();
                assert!((x0 - z0.data[i] as f64).abs() < 1e-4, "t={t} i={i}");
            }
        }
    }

    #[test]
    fn encode_vjp_matches_finite_differences() {
        let te = teacher(2, 8, 2, 2);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let im = random_image(&mut rng, 8);
        let dz = Latent {
            shape: te.latent_shape(),
            data: (0..te.latent_shape().iter().product::<usize>())
                .map(|_| rng.random_range(-1.0..1.0f32))
                .collect(),
        };
        let g = te.encode_vjp(&im, &dz).unwrap();
        let f = |im: &Image| -> f64 {
            let z = te.encode_f64(im).unwrap();
            z.iter().zip(&dz.data).map(|(a, b)| a * *b as f64).sum()
        };
        for i in (0..im.data.len()).step_by(5) {
            let fd = crate::image::central_difference(&im, i, 1e-3, f);
            assert!((fd - g[i] as f64).abs() < 1e-3, "i={i} fd={fd} an={}", g[i]);
        }
    }

    #[test]
    fn mixture_matches_brute_force_f64() {
        let te = teacher(3, 4, 1, 4);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let n = te.latent_shape().iter().product::<usize>();
        // Start near target 1 so the weights are not all one-hot.
        let t = 700;
        let ab = te.alphas_cumprod()[t] as f64;
        let zt = Latent {
            shape: te.latent_shape(),
            data: (0..n)
                .map(|i| {
                    (ab.sqrt() * te.latents[1][i]
                        + (1.0 - ab).sqrt() * rng.random_range(-1.5..1.5f64))
                        as f32
                })
                .collect(),
        };
        let eps = te
            .predict_noise(&zt, t, &Conditioning::default(), 1.0)
            .unwrap();
        // Independent brute force: Gaussian likelihoods p(z_t | k) without log-sum-exp tricks.
        let var = 1.0 - ab;
        let lik: Vec<f64> = (0..3)
            .map(|k| {
                let mut d2 = 0.0;
                for i in 0..n {
                    let d = zt.data[i] as f64 - ab.sqrt() * te.latents[k][i];
                    d2 += d * d;
                }
                (-d2 / (2.0 * var)).exp()
            })
            .collect();
        let z: f64 = lik.iter().sum();
        assert!(
            lik.iter().filter(|l| **l / z > 1e-3).count() >= 2,
            "{lik:?}"
        );
        for i in 0..n {
            let x0: f64 = (0..3).map(|k| lik[k] / z * te.latents[k][i]).sum();
            let e = (zt.data[i] as f64 - ab.sqrt() * x0) / var.sqrt();
            assert!((e - eps.data[i] as f64).abs() < 1e-4, "i={i}");
        }
    }

    #[test]
    fn guidance_uses_caption_selected_targets() {
        let te = teacher(2, 4, 1, 6);
        let n = te.latent_shape().iter().product::<usize>();
        let zt = Latent {
            shape: te.latent_shape(),
            data: vec![0.1; n],
        };
        let t = 950;
        let c = te.condition("a picture of t1", "").unwrap();
        let e1 = te.predict_noise(&zt, t, &c, 1.0).unwrap();
        // guidance 1 = purely conditional = single-target denoiser of t1.
        let ab = te.alphas_cumprod()[t] as f64;
        for i in 0..n {
            let want = (zt.data[i] as f64 - ab.sqrt() * te.latents[1][i]) / (1.0 - ab).sqrt();
            assert!((want - e1.data[i] as f64).abs() < 1e-4);
        }
        let e0 = te.predict_noise(&zt, t, &c, 0.0).unwrap();
        let eu = te
            .predict_noise(&zt, t, &Conditioning::default(), 5.0)
            .unwrap();
        assert_eq!(e0, eu);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let te = teacher(1, 8, 2, 7);
        assert!(te.encode(&Image::new(4, 4)).is_err());
        let z = Latent::zeros([3, 2, 2]);
        assert!(
            te.predict_noise(&z, 0, &Conditioning::default(), 1.0)
                .is_err()
        );
        let z = Latent::zeros(te.latent_shape());
        assert!(
            te.predict_noise(&z, 1000, &Conditioning::default(), 1.0)
                .is_err()
        );
        assert!(AnalyticTeacher::new(AnalyticTeacherConfig::default(), vec![]).is_err());
    }
}
