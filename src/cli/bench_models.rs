//! `vectorfusion bench models`: full-size Stable Diffusion / TAESD architectures with random
//! weights (compute does not depend on weight values), median wall time per component.

use super::CliError;
use crate::models::clip::{ClipTextConfig, ClipTextModel};
use crate::models::codec::Codec;
use crate::models::loader::random_var_builder;
use crate::models::taesd::{Taesd, TaesdConfig};
use crate::models::unet::{Unet, UnetConfig};
use crate::models::vae::{AutoencoderKl, VaeConfig};
use crate::models::{ModelError, Precision};
use candle_core::{DType, Device, Tensor};
use std::time::Instant;

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Arch {
    Sd15,
    Sd21,
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
    #[arg(long, default_value = "cpu")]
    pub device: String,
}

impl std::str::FromStr for Arch {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        <Self as clap::ValueEnum>::from_str(s, true)
    }
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
    fn cpu(&mut self, key: &str, cpu: Option<f64>) {
        if let Some(c) = cpu {
            self.cpu_ms.insert(key.to_string(), c);
        }
    }

    fn put(&mut self, key: &str, t: Timing) -> Option<f64> {
        self.cpu(key, t.cpu);
        Some(t.ms)
    }
}

/// Times one autoencoder's (VAE or TAESD) encoder forward, encoder VJP from scratch (taped
/// forward + pullback), the pullback alone and the decoder, each when selected by `--only`, on
/// `(image, latents)`, and records them (with CPU time and peak RSS) in `r`.
fn time_autoencoder(
    r: &mut Report,
    args: &BenchModelsArgs,
    want: &dyn Fn(&str) -> bool,
    say: &dyn Fn(&str),
    dev: &Device,
    codec: &Codec,
    (image, lat): (&Tensor, &Tensor),
) -> Result<(), CliError> {
    if want("encoder") {
        say("encoder forward");
        let Timing { ms, peak, cpu } = time_it(dev, args.warmup, args.reps, || {
            codec.encode(image).map(|_| ()).map_err(model_err)
        })?;
        r.encoder_fwd_ms = Some(ms);
        r.cpu("encoder_fwd", cpu);
        r.encoder_fwd_peak_rss_mb = peak;
    }
    if want("vjp") {
        say("encoder VJP");
        let Timing { ms, peak, cpu } = time_it(dev, args.warmup, args.reps, || {
            codec.encode_vjp(image, lat).map(|_| ()).map_err(model_err)
        })?;
        r.encoder_vjp_ms = Some(ms);
        r.cpu("encoder_vjp", cpu);
        r.encoder_vjp_peak_rss_mb = peak;
        say("encoder VJP backward (pullback of a recorded tape)");
        let tm = time_part(args.warmup, args.reps, || {
            let (_, tape) = codec.encode_t(image).map_err(model_err)?;
            sync(dev)?;
            let t0 = Instant::now();
            codec.encode_pullback(tape, lat).map_err(model_err)?;
            sync(dev)?;
            Ok(t0.elapsed().as_secs_f64() * 1e3)
        })?;
        r.encoder_bwd_ms = Some(tm.ms);
    }
    if want("decoder") {
        say("decoder");
        let tm = time_it(dev, args.warmup, args.reps, || {
            codec.decode(lat).map(|_| ()).map_err(model_err)
        })?;
        r.decoder_ms = r.put("decoder", tm);
    }
    Ok(())
}

pub fn run(args: BenchModelsArgs) -> Result<(), CliError> {
    if args.size == 0 || args.size % 64 != 0 {
        return Err(CliError::Usage(format!(
            "--size must be a positive multiple of 64, got {}",
            args.size
        )));
    }
    let want = |c: &str| args.only.is_empty() || args.only.iter().any(|o| o == c);
    crate::models::kernels::set_enabled(!args.candle_kernels);
    let device = super::parse_device(&args.device)?;
    let dev = device.open().map_err(model_err)?;
    let s = args.size;
    let mut r = Report {
        arch: format!("{:?}", args.arch).to_lowercase(),
        size: s,
        unet_precision: format!("{:?}", args.unet_precision).to_lowercase(),
        device: device.to_string(),
        kernels: if args.candle_kernels {
            "candle"
        } else {
            "ours"
        }
        .into(),
        reps: args.reps,
        unet_reps: args.unet_reps,
        threads: candle_core::utils::get_num_threads(),
        ..Report::default()
    };
    let image = Tensor::rand(0f32, 1f32, (1, 3, s, s), &dev).map_err(candle_err)?;
    let lat = Tensor::randn(0f32, 1f32, (1, 4, s / 8, s / 8), &dev).map_err(candle_err)?;
    let say = |what: &str| {
        if !args.json {
            eprintln!("running {what} ...");
        }
    };

    match args.arch {
        Arch::Taesd => {
            let t = Taesd::new(random_var_builder(DType::F32, &dev), TaesdConfig::taesd())
                .map_err(candle_err)?;
            let codec = Codec::from(t);
            time_autoencoder(&mut r, &args, &want, &say, &dev, &codec, (&image, &lat))?;
        }
        Arch::Sd15 | Arch::Sd21 => {
            let sd21 = args.arch == Arch::Sd21;
            if want("encoder") || want("vjp") || want("decoder") {
                let vae = AutoencoderKl::new(random_var_builder(DType::F32, &dev), VaeConfig::sd())
                    .map_err(candle_err)?;
                let codec = Codec::from(vae);
                time_autoencoder(&mut r, &args, &want, &say, &dev, &codec, (&image, &lat))?;
            }
            let text_cfg: ClipTextConfig = if sd21 {
                serde_json::from_value(serde_json::json!({
                    "vocab_size": 49408, "hidden_size": 1024, "intermediate_size": 4096,
                    "num_hidden_layers": 23, "num_attention_heads": 16, "hidden_act": "gelu",
                    "projection_dim": 512
                }))
            } else {
                serde_json::from_value(serde_json::json!({
                    "vocab_size": 49408, "hidden_size": 768, "intermediate_size": 3072,
                    "num_hidden_layers": 12, "num_attention_heads": 12, "hidden_act": "quick_gelu",
                    "projection_dim": 768
                }))
            }
            .map_err(|e| CliError::Other(anyhow::anyhow!(e)))?;
            if want("text") {
                say("text encoder");
                let text = ClipTextModel::new(random_var_builder(DType::F32, &dev), &text_cfg)
                    .map_err(candle_err)?;
                let mut ids = vec![49407u32; 77];
                ids[0] = 49406;
                for (i, id) in ids.iter_mut().enumerate().take(9).skip(1) {
                    *id = 320 + i as u32;
                }
                let ids = Tensor::from_vec(ids, (1, 77), &dev).map_err(candle_err)?;
                let tm = time_it(&dev, args.warmup, args.reps, || {
                    text.forward(&ids).map(|_| ()).map_err(candle_err)
                })?;
                r.text_ms = r.put("text", tm);
            }
            if want("unet") {
                say("guided UNet step (batch 2)");
                let cfg = if sd21 {
                    UnetConfig::sd21()
                } else {
                    UnetConfig::sd15()
                };
                let cross = text_cfg.hidden_size;
                let unet = Unet::new(
                    random_var_builder(args.unet_precision.dtype(), &dev),
                    cfg,
                    std::path::Path::new("<random weights>"),
                )
                .map_err(model_err)?;
                let ctx = Tensor::randn(0f32, 1f32, (2, 77, cross), &dev).map_err(candle_err)?;
                let z2 = Tensor::cat(&[&lat, &lat], 0).map_err(candle_err)?;
                let tm = time_it(&dev, args.warmup, args.unet_reps, || {
                    let out = unet.forward(&z2, 500.0, &ctx).map_err(model_err)?;
                    // the guidance combination itself
                    let u = out.narrow(0, 0, 1).map_err(candle_err)?;
                    let c = out.narrow(0, 1, 1).map_err(candle_err)?;
                    let _ = (&u + ((c - &u).map_err(candle_err)? * 7.5).map_err(candle_err)?)
                        .map_err(candle_err)?;
                    Ok(())
                })?;
                r.unet_cfg_ms = r.put("unet_cfg", tm);
            }
        }
    }

    if args.json {
        println!(
            "{}",
            serde_json::to_string(&r).map_err(|e| CliError::Other(anyhow::anyhow!(e)))?
        );
    } else {
        let f = |v: Option<f64>| v.map_or("-".to_string(), |x| format!("{x:.0}"));
        println!(
            "bench models  arch={} size={} unet={} kernels={} threads={} (median of {} / unet {})",
            r.arch, r.size, r.unet_precision, r.kernels, r.threads, r.reps, r.unet_reps
        );
        println!("  unet_cfg_ms     {}", f(r.unet_cfg_ms));
        println!("  encoder_fwd_ms  {}", f(r.encoder_fwd_ms));
        println!("  encoder_vjp_ms  {}", f(r.encoder_vjp_ms));
        println!("  encoder_bwd_ms  {}", f(r.encoder_bwd_ms));
        println!("  decoder_ms      {}", f(r.decoder_ms));
        println!("  text_ms         {}", f(r.text_ms));
        println!("  cpu ms per run  {:?}", r.cpu_ms);
        println!(
            "  peak RSS MiB    encoder fwd {} / vjp {}",
            f(r.encoder_fwd_peak_rss_mb),
            f(r.encoder_vjp_peak_rss_mb)
        );
    }
    Ok(())
}
