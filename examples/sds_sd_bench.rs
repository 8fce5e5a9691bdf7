//! Per-step time of SDS with the full-size Stable Diffusion 1.5 architecture (random weights:
//! compute does not depend on weight values) on this machine, next to an in-run baseline of the
//! same loop with the analytic test teacher (everything but the model).
//!
//! `cargo run --release --example sds_sd_bench [STEPS] [SIZE] [vae|taesd] [recompute]`
//! (defaults 3, 512, vae): the encoder SDS backpropagates through, the full VAE (the paper's) or
//! TAESD (the `fast` preset's). After the SD steps, `recompute` also times the steps the way
//! they ran before the taped encoder was shared: an untaped encode, then the VJP from scratch.

use candle_core::{DType, Device, Tensor};
use std::path::Path;
use std::sync::Mutex;
use std::time::Instant;
use vectorfusion::image::Image;
use vectorfusion::models::StableDiffusion;
use vectorfusion::models::loader::random_var_builder;
use vectorfusion::models::scheduler::SchedulerConfig;
use vectorfusion::models::taesd::{Taesd, TaesdConfig};
use vectorfusion::models::unet::{Unet, UnetConfig};
use vectorfusion::models::vae::{AutoencoderKl, VaeConfig};
use vectorfusion::progress::{CancelToken, Progress};
use vectorfusion::stages::sds::{RasterBackend, SdsConfig, run_sds};
use vectorfusion::stages::styles::Style;
use vectorfusion::teacher::{
    AnalyticTeacher, AnalyticTeacherConfig, Conditioning, Latent, Pullback, SdTeacher, Teacher,
    TeacherError, linearise_by_recomputing,
};

/// SD with random weights has no text encoder: condition on random embeddings. With `share`
/// off, the SDS step encodes and then runs the VJP from scratch (the trait's default).
struct RandomText(SdTeacher, bool);

impl Teacher for RandomText {
    fn name(&self) -> String {
        self.0.name()
    }
    fn image_size(&self) -> u32 {
        self.0.image_size()
    }
    fn latent_shape(&self) -> [usize; 3] {
        self.0.latent_shape()
    }
    fn alphas_cumprod(&self) -> &[f32] {
        self.0.alphas_cumprod()
    }
    fn condition(&self, p: &str, n: &str) -> Result<Conditioning, TeacherError> {
        let r = |s| {
            Tensor::randn(0f32, 1.0, (1, 77, 768), &Device::Cpu)
                .and_then(|t| t.flatten_all())
                .and_then(|t| t.to_vec1::<f32>())
                .map_err(|e| TeacherError::Model(format!("{e} {s}")))
        };
        Ok(Conditioning {
            prompt: p.into(),
            negative_prompt: n.into(),
            embed_shape: vec![1, 77, 768],
            cond: r("c")?,
            uncond: r("u")?,
            added: None,
        })
    }
    fn encode(&self, im: &Image) -> Result<Latent, TeacherError> {
        self.0.encode(im)
    }
    fn encode_vjp(&self, im: &Image, d: &Latent) -> Result<Vec<f32>, TeacherError> {
        self.0.encode_vjp(im, d)
    }
    fn encode_linearised<'a>(&'a self, im: &Image) -> Result<(Latent, Pullback<'a>), TeacherError> {
        if self.1 {
            self.0.encode_linearised(im)
        } else {
            linearise_by_recomputing(self, im)
        }
    }
    fn predict_noise(
        &self,
        z: &Latent,
        t: usize,
        c: &Conditioning,
        g: f32,
    ) -> Result<Latent, TeacherError> {
        self.0.predict_noise(z, t, c, g)
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn step_times(teacher: &dyn Teacher, steps: u32, size: u32) -> Vec<f64> {
    let mut cfg = SdsConfig::for_style(Style::Iconography, "a cat", steps, size);
    cfg.snapshot_every = 0;
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(1);
    let scene = Style::Iconography
        .init_scene(cfg.render_size(size), 64, &mut rng)
        .unwrap();
    let stamps = Mutex::new(vec![Instant::now()]);
    let sink = |_: Progress| stamps.lock().unwrap().push(Instant::now());
    run_sds(
        &RasterBackend,
        teacher,
        scene,
        &cfg,
        &sink,
        &CancelToken::new(),
    )
    .unwrap();
    let s = stamps.into_inner().unwrap();
    // The last event is the final summary, not a step.
    s.windows(2)
        .take(steps as usize)
        .map(|w| (w[1] - w[0]).as_secs_f64())
        .collect()
}

fn main() {
    vectorfusion::alloc::tune();
    let args: Vec<String> = std::env::args().collect();
    let steps: u32 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(3);
    let size: u32 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(512);
    let dev = Device::Cpu;
    let t0 = Instant::now();
    let unet = Unet::new(
        random_var_builder(DType::F32, &dev),
        UnetConfig::sd15(),
        Path::new("random-sd15-unet"),
    )
    .unwrap();
    let encoder = args.get(3).map(String::as_str).unwrap_or("vae");
    let vb = random_var_builder(DType::F32, &dev);
    let sd = match encoder {
        "vae" => StableDiffusion::from_parts(
            unet,
            AutoencoderKl::new(vb, VaeConfig::sd()).unwrap(),
            SchedulerConfig::sd(),
            dev.clone(),
        ),
        "taesd" => StableDiffusion::from_parts(
            unet,
            Taesd::new(vb, TaesdConfig::taesd()).unwrap(),
            SchedulerConfig::sd(),
            dev.clone(),
        ),
        other => {
            eprintln!("encoder must be vae or taesd, got {other:?}");
            std::process::exit(2);
        }
    }
    .unwrap();
    let mut teacher = RandomText(SdTeacher::new(sd, size).unwrap(), true);
    println!(
        "built random SD 1.5 (SDS encoder: {encoder}) in {:.1} s",
        t0.elapsed().as_secs_f64()
    );

    // Component breakdown (one call each).
    let im = Image::filled(size, size, [0.5, 0.5, 0.5, 1.0]);
    let t = Instant::now();
    let z = teacher.encode(&im).unwrap();
    let enc = t.elapsed().as_secs_f64();
    let t = Instant::now();
    teacher.encode_vjp(&im, &z).unwrap();
    let vjp = t.elapsed().as_secs_f64();
    // What an SDS step runs: one taped forward, then the pullback.
    let t = Instant::now();
    let (_, pullback) = teacher.encode_linearised(&im).unwrap();
    let taped = t.elapsed().as_secs_f64();
    let t = Instant::now();
    pullback(&z).unwrap();
    let back = t.elapsed().as_secs_f64();
    let c = teacher.condition("a cat", "").unwrap();
    let t = Instant::now();
    teacher.predict_noise(&z, 500, &c, 100.0).unwrap();
    let unet = t.elapsed().as_secs_f64();
    println!(
        "{encoder} encode {enc:.2} s, encoder VJP from scratch {vjp:.2} s (taped encode {taped:.2} s + pullback {back:.2} s), UNet with CFG (batch 2) {unet:.2} s"
    );

    let base = AnalyticTeacher::new(
        AnalyticTeacherConfig {
            image_size: size,
            pool: (size / 64).max(1),
            num_train_timesteps: 1000,
        },
        vec![("t".into(), Image::filled(size, size, [1.0; 4]))],
    )
    .unwrap();
    let b = step_times(&base, 10, size);
    println!(
        "baseline (analytic test teacher) per step: median {:.3} s over {} steps",
        median(b.clone()),
        b.len()
    );
    let s = step_times(&teacher, steps, size);
    println!(
        "SD 1.5 (random weights) per step: median {:.2} s over {} steps {:?}",
        median(s.clone()),
        s.len(),
        s
    );
    if args.get(4).map(String::as_str) == Some("recompute") {
        teacher.1 = false;
        let s = step_times(&teacher, steps, size);
        println!(
            "same, encode then VJP from scratch (before the shared tape): median {:.2} s {:?}",
            median(s.clone()),
            s
        );
    }
}
