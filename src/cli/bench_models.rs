//! `vectorfusion bench models`: full-size Stable Diffusion (1.5, 2.1, SDXL) / TAESD architectures with random
//! weights (compute does not depend on weight values), median wall time per component.

use super::request_args::parse_device;
use super::{CliError, ResultExt};
use crate::models::clip::{ClipTextConfig, ClipTextModel};
use crate::models::codec::Codec;
use crate::models::guided::size_time_ids;
use crate::models::loader::random_var_builder;
use crate::models::taesd::{Taesd, TaesdConfig};
use crate::models::unet::{AddedCond, Unet, UnetConfig};
use crate::models::vae::{AutoencoderKl, VaeConfig};
use crate::models::{ComputeDevice, ModelError, Precision};
use candle_core::{DType, Device, Tensor};
use std::time::Instant;

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Arch {
    Sd15,
    Sd21,
    /// The SDXL base UNet (with its pooled-text and size/crop conditioning) and VAE; the text
    /// encoders are not timed.
    Sdxl,
    Taesd,
}

/// Arguments of `bench models`.
#[derive(clap::Args, Debug)]
pub struct BenchModelsArgs {
    /// Architecture to build (random weights, full size).
    #[arg(long, value_enum, default_value = "sd15")]
    pub arch: Arch,
    /// Image size in pixels (latents are size/8).
    #[arg(long, default_value_t = 512)]
    pub size: usize,
    /// Timed repetitions of the fast components (median reported); one warm-up run first.
    #[arg(long, default_value_t = 3)]
    pub reps: usize,
    /// Timed repetitions of the guided UNet step (~20 s each at 512 on 2 cores).
    #[arg(long, default_value_t = 1)]
    pub unet_reps: usize,
    /// UNet precision (f32 or f16; bf16 is refused on CPU).
    #[arg(long, default_value = "f32")]
    pub unet_precision: Precision,
    /// Untimed warm-up runs before the timed ones.
    #[arg(long, default_value_t = 1)]
    pub warmup: usize,
    /// Only these components (comma separated: text,encoder,vjp,decoder,unet).
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<String>,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
    /// In-run baseline: candle's own CPU ops instead of our kernels (Winograd / im2col
    /// convolution, fused group norm, fused attention, linear layers with fused bias).
    #[arg(long)]
    pub candle_kernels: bool,
    /// Where the models run: cpu, cuda or cuda:N (CUDA needs a build with the `cuda` feature;
    /// each timed run ends with a device synchronisation).
    #[arg(long, default_value = "cpu", value_parser = parse_device)]
    pub device: ComputeDevice,
}

fn model_err(e: ModelError) -> CliError {
    CliError::Other(anyhow::anyhow!(e))
}

fn candle_err(e: candle_core::Error) -> CliError {
    CliError::Other(anyhow::anyhow!(e))
}

/// Peak resident memory since the last reset, in MiB (Linux; `None` elsewhere).
fn peak_rss_mb() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// User + system CPU time of this process in ms (Linux; `None` elsewhere). On a shared machine
/// this is steadier than wall time.
fn cpu_ms() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/stat").ok()?;
    // fields after the ")" of the command name: state is field 3, utime 14, stime 15
    let rest = s.rsplit_once(')')?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ut: f64 = f.get(11)?.parse().ok()?;
    let st: f64 = f.get(12)?.parse().ok()?;
    Some((ut + st) * 10.0) // USER_HZ = 100 on Linux
}

fn reset_peak_rss() {
    // "5" resets the peak RSS counter (Linux >= 4.0); harmless if unavailable
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

/// Waits for the work queued on `dev` (a no-op on the CPU), so wall times cover GPU work.
fn sync(dev: &Device) -> Result<(), CliError> {
    dev.synchronize().map_err(candle_err)
}

/// Runs `f` `warmup` times untimed, then `reps` timed times, each ending with a [`sync`] of
/// `dev`; returns the median wall ms, the peak RSS (MiB) seen during the timed runs and the
/// mean process CPU ms per run.
fn time_it<F>(dev: &Device, warmup: usize, reps: usize, mut f: F) -> Result<Timing, CliError>
where
    F: FnMut() -> Result<(), CliError>,
{
    time_part(warmup, reps, || {
        let t0 = Instant::now();
        f()?;
        sync(dev)?;
        Ok(t0.elapsed().as_secs_f64() * 1e3)
    })
}

/// [`time_it`] for a run whose timed part `f` measures itself (it returns that part's wall ms,
/// after untimed setup such as recording a tape). CPU time covers the whole run.
fn time_part<F>(warmup: usize, reps: usize, mut f: F) -> Result<Timing, CliError>
where
    F: FnMut() -> Result<f64, CliError>,
{
    for _ in 0..warmup {
        f()?;
    }
    reset_peak_rss();
    let c0 = cpu_ms();
    let mut ts = Vec::with_capacity(reps.max(1));
    for _ in 0..reps.max(1) {
        ts.push(f()?);
    }
    let cpu = match (c0, cpu_ms()) {
        (Some(a), Some(b)) => Some((b - a) / reps.max(1) as f64),
        _ => None,
    };
    Ok(Timing {
        ms: super::bench::median(ts),
        peak: peak_rss_mb(),
        cpu,
    })
}

/// One component's measurement.
struct Timing {
    ms: f64,
    peak: Option<f64>,
    cpu: Option<f64>,
}

#[derive(Debug, Default, serde::Serialize)]
struct Report {
    /// the CPU and the SIMD paths the kernels take on it
    cpu: crate::models::kernels::cpu::CpuReport,
    /// process CPU ms per run (user + system), per component
    cpu_ms: std::collections::BTreeMap<String, f64>,
    arch: String,
    size: usize,
    unet_precision: String,
    /// "cpu" or "cuda:N"
    device: String,
    /// "ours" or "candle" (the `--candle-kernels` baseline)
    kernels: String,
    reps: usize,
    unet_reps: usize,
    threads: usize,
    unet_cfg_ms: Option<f64>,
    encoder_fwd_ms: Option<f64>,
    encoder_vjp_ms: Option<f64>,
    /// the VJP's backward alone: the pullback of a tape recorded by an untimed forward (what an
    /// SDS step adds to the encode it needs anyway)
    encoder_bwd_ms: Option<f64>,
    decoder_ms: Option<f64>,
    text_ms: Option<f64>,
    encoder_fwd_peak_rss_mb: Option<f64>,
    encoder_vjp_peak_rss_mb: Option<f64>,
}

impl Report {
    /// The report's header of a run with `args`, no component timed yet.
    fn new(args: &BenchModelsArgs) -> Self {
        Report {
            arch: format!("{:?}", args.arch).to_lowercase(),
            size: args.size,
            unet_precision: format!("{:?}", args.unet_precision).to_lowercase(),
            device: args.device.to_string(),
            kernels: if args.candle_kernels {
                "candle"
            } else {
                "ours"
            }
            .into(),
            reps: args.reps,
            unet_reps: args.unet_reps,
            threads: candle_core::utils::get_num_threads(),
            cpu: crate::models::kernels::cpu::CpuReport::detect(),
            ..Report::default()
        }
    }

    /// Records `key`'s CPU time; its median wall ms, to be stored in its field.
    fn put(&mut self, key: &str, t: Timing) -> Option<f64> {
        if let Some(c) = t.cpu {
            self.cpu_ms.insert(key.to_string(), c);
        }
        Some(t.ms)
    }

    /// The text report.
    fn print(&self) {
        let f = |v: Option<f64>| v.map_or("-".to_string(), |x| format!("{x:.0}"));
        println!(
            "bench models  arch={} size={} unet={} kernels={} threads={} (median of {} / unet {})",
            self.arch,
            self.size,
            self.unet_precision,
            self.kernels,
            self.threads,
            self.reps,
            self.unet_reps
        );
        println!(
            "  cpu             {} [{}]; gemm {}, element-wise {}",
            self.cpu.model,
            self.cpu.features.join(" "),
            self.cpu.gemm,
            self.cpu.elementwise
        );
        println!("  unet_cfg_ms     {}", f(self.unet_cfg_ms));
        println!("  encoder_fwd_ms  {}", f(self.encoder_fwd_ms));
        println!("  encoder_vjp_ms  {}", f(self.encoder_vjp_ms));
        println!("  encoder_bwd_ms  {}", f(self.encoder_bwd_ms));
        println!("  decoder_ms      {}", f(self.decoder_ms));
        println!("  text_ms         {}", f(self.text_ms));
        println!("  cpu ms per run  {:?}", self.cpu_ms);
        println!(
            "  peak RSS MiB    encoder fwd {} / vjp {}",
            f(self.encoder_fwd_peak_rss_mb),
            f(self.encoder_vjp_peak_rss_mb)
        );
    }
}

/// What a benchmark run shares: its flags and the opened device.
struct Bench<'a> {
    args: &'a BenchModelsArgs,
    dev: Device,
}

impl Bench<'_> {
    /// Whether `--only` selects `component` (everything without `--only`).
    fn want(&self, component: &str) -> bool {
        self.args.only.is_empty() || self.args.only.iter().any(|o| o == component)
    }

    /// Says on stderr what runs next (not with `--json`).
    fn say(&self, what: &str) {
        if !self.args.json {
            eprintln!("running {what} ...");
        }
    }

    /// [`time_it`] on this device with `--warmup` and `reps` timed runs.
    fn time<F>(&self, reps: usize, f: F) -> Result<Timing, CliError>
    where
        F: FnMut() -> Result<(), CliError>,
    {
        time_it(&self.dev, self.args.warmup, reps, f)
    }

    /// Times one autoencoder's (VAE or TAESD) encoder forward, encoder VJP from scratch
    /// (taped forward + pullback), the pullback alone and the decoder, each when selected by
    /// `--only`, on `(image, latents)`, and records them (with CPU time and peak RSS) in `r`.
    fn autoencoder(
        &self,
        r: &mut Report,
        codec: &Codec,
        (image, lat): (&Tensor, &Tensor),
    ) -> Result<(), CliError> {
        let reps = self.args.reps;
        if self.want("encoder") {
            self.say("encoder forward");
            let tm = self.time(reps, || codec.encode(image).map(|_| ()).map_err(model_err))?;
            r.encoder_fwd_peak_rss_mb = tm.peak;
            r.encoder_fwd_ms = r.put("encoder_fwd", tm);
        }
        if self.want("vjp") {
            self.say("encoder VJP");
            let tm = self.time(reps, || {
                codec.encode_vjp(image, lat).map(|_| ()).map_err(model_err)
            })?;
            r.encoder_vjp_peak_rss_mb = tm.peak;
            r.encoder_vjp_ms = r.put("encoder_vjp", tm);
            self.say("encoder VJP backward (pullback of a recorded tape)");
            let tm = time_part(self.args.warmup, reps, || {
                let (_, tape) = codec.encode_t(image).map_err(model_err)?;
                sync(&self.dev)?;
                let t0 = Instant::now();
                codec.encode_pullback(tape, lat).map_err(model_err)?;
                sync(&self.dev)?;
                Ok(t0.elapsed().as_secs_f64() * 1e3)
            })?;
            r.encoder_bwd_ms = Some(tm.ms);
        }
        if self.want("decoder") {
            self.say("decoder");
            let tm = self.time(reps, || codec.decode(lat).map(|_| ()).map_err(model_err))?;
            r.decoder_ms = r.put("decoder", tm);
        }
        Ok(())
    }

    /// Stable Diffusion 1.5, 2.1 or SDXL: its VAE (SDXL's has SD's architecture), CLIP text
    /// encoder (not SDXL's two) and a guided UNet step.
    fn stable_diffusion(
        &self,
        r: &mut Report,
        image: &Tensor,
        lat: &Tensor,
    ) -> Result<(), CliError> {
        let arch = self.args.arch;
        if self.want("encoder") || self.want("vjp") || self.want("decoder") {
            let vae =
                AutoencoderKl::new(random_var_builder(DType::F32, &self.dev), VaeConfig::sd())
                    .map_err(candle_err)?;
            self.autoencoder(r, &Codec::from(vae), (image, lat))?;
        }
        if self.want("text") && arch != Arch::Sdxl {
            self.say("text encoder");
            r.text_ms = self.text_encoder(r, &text_config(arch == Arch::Sd21)?)?;
        }
        if self.want("unet") {
            self.say("guided UNet step (batch 2)");
            let cfg = match arch {
                Arch::Sd21 => UnetConfig::sd21(),
                Arch::Sdxl => UnetConfig::sdxl(),
                _ => UnetConfig::sd15(),
            };
            r.unet_cfg_ms = self.guided_unet(r, cfg, lat)?;
        }
        Ok(())
    }

    /// The CLIP text encoder on one 77-token caption.
    fn text_encoder(&self, r: &mut Report, cfg: &ClipTextConfig) -> Result<Option<f64>, CliError> {
        let text = ClipTextModel::new(random_var_builder(DType::F32, &self.dev), cfg)
            .map_err(candle_err)?;
        let mut ids = vec![49407u32; 77];
        ids[0] = 49406;
        for (i, id) in ids.iter_mut().enumerate().take(9).skip(1) {
            *id = 320 + i as u32;
        }
        let ids = Tensor::from_vec(ids, (1, 77), &self.dev).map_err(candle_err)?;
        let tm = self.time(self.args.reps, || {
            text.forward(&ids).map(|_| ()).map_err(candle_err)
        })?;
        Ok(r.put("text", tm))
    }

    /// One classifier-free-guided UNet step: a batch of 2 at `--unet-precision` (SDXL: with
    /// random pooled embeddings and the size time ids of `--size`), then the guidance
    /// combination.
    fn guided_unet(
        &self,
        r: &mut Report,
        cfg: UnetConfig,
        lat: &Tensor,
    ) -> Result<Option<f64>, CliError> {
        let unet = Unet::new(
            random_var_builder(self.args.unet_precision.dtype(), &self.dev),
            cfg,
            std::path::Path::new("<random weights>"),
        )
        .map_err(model_err)?;
        let cross = unet.arch.cross_attention_dim;
        let ctx = Tensor::randn(0f32, 1f32, (2, 77, cross), &self.dev).map_err(candle_err)?;
        let added = match unet.arch.text_time {
            Some(tt) => {
                let side = self.args.size as u32;
                let ids = size_time_ids(side, side, &self.dev).map_err(model_err)?;
                Some(AddedCond {
                    text_embeds: Tensor::randn(0f32, 1f32, (2, tt.pooled_dim()), &self.dev)
                        .map_err(candle_err)?,
                    time_ids: Tensor::cat(&[&ids, &ids], 0).map_err(candle_err)?,
                })
            }
            None => None,
        };
        let z2 = Tensor::cat(&[lat, lat], 0).map_err(candle_err)?;
        let tm = self.time(self.args.unet_reps, || {
            let out = unet
                .forward_added(&z2, 500.0, &ctx, added.as_ref())
                .map_err(model_err)?;
            // the guidance combination itself
            let u = out.narrow(0, 0, 1).map_err(candle_err)?;
            let c = out.narrow(0, 1, 1).map_err(candle_err)?;
            let _ = (&u + ((c - &u).map_err(candle_err)? * 7.5).map_err(candle_err)?)
                .map_err(candle_err)?;
            Ok(())
        })?;
        Ok(r.put("unet_cfg", tm))
    }
}

/// The CLIP text encoder of Stable Diffusion 2.1 (OpenCLIP ViT-H) or 1.5 (ViT-L).
fn text_config(sd21: bool) -> Result<ClipTextConfig, CliError> {
    let json = if sd21 {
        serde_json::json!({
            "vocab_size": 49408, "hidden_size": 1024, "intermediate_size": 4096,
            "num_hidden_layers": 23, "num_attention_heads": 16, "hidden_act": "gelu",
            "projection_dim": 512
        })
    } else {
        serde_json::json!({
            "vocab_size": 49408, "hidden_size": 768, "intermediate_size": 3072,
            "num_hidden_layers": 12, "num_attention_heads": 12, "hidden_act": "quick_gelu",
            "projection_dim": 768
        })
    };
    serde_json::from_value(json).failed(|| "text encoder configuration".into())
}

pub fn run(args: BenchModelsArgs) -> Result<(), CliError> {
    if args.size == 0 || !args.size.is_multiple_of(64) {
        return Err(CliError::Usage(format!(
            "--size must be a positive multiple of 64, got {}",
            args.size
        )));
    }
    crate::models::kernels::set_enabled(!args.candle_kernels);
    let bench = Bench {
        args: &args,
        dev: args.device.open().map_err(model_err)?,
    };
    let mut r = Report::new(&args);
    let s = args.size;
    let image = Tensor::rand(0f32, 1f32, (1, 3, s, s), &bench.dev).map_err(candle_err)?;
    let lat = Tensor::randn(0f32, 1f32, (1, 4, s / 8, s / 8), &bench.dev).map_err(candle_err)?;
    match args.arch {
        Arch::Taesd => {
            let t = Taesd::new(
                random_var_builder(DType::F32, &bench.dev),
                TaesdConfig::taesd(),
            )
            .map_err(candle_err)?;
            bench.autoencoder(&mut r, &Codec::from(t), (&image, &lat))?;
        }
        Arch::Sd15 | Arch::Sd21 | Arch::Sdxl => bench.stable_diffusion(&mut r, &image, &lat)?,
    }
    if args.json {
        let text = serde_json::to_string(&r).failed(|| "encoding the report".into())?;
        println!("{text}");
    } else {
        r.print();
    }
    Ok(())
}
