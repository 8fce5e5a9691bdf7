//! `vectorfusion vectorize INPUT.png -o OUT.svg`: trace a raster image into closed cubic paths
//! with LIVE.

use super::{CliError, ResultExt};
use crate::image::Image;
use crate::pipeline::{
    DefaultExecutor, Executor, JobContext, JobKind, PlanRequest, RunInput, Tuning,
};
use crate::progress::{CancelToken, Progress};
use crate::stages::live::{self, InitMode, LiveConfig, PathBudget};
use std::path::{Path, PathBuf};

/// Largest input side the command accepts (larger images are refused before decoding).
pub const MAX_INPUT_SIDE: u32 = 4096;

#[derive(clap::Args, Debug, Clone)]
pub struct VectorizeArgs {
    /// Input image (PNG or JPEG).
    pub input: PathBuf,
    /// Output path: `.svg`, or `.pdf` (vector PDF) / `.png` (render) by extension.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Number of paths, or `auto` (add stages while they pay off, then prune).
    #[arg(long, default_value = "64")]
    pub paths: String,
    /// Custom stage schedule, e.g. `8,8,16,16,16` (overrides --paths N).
    #[arg(long)]
    pub schedule: Option<String>,
    /// Working side in pixels: the optimisation runs on the image scaled to the area of a square
    /// of this side (never enlarged); the preset's by default.
    #[arg(long)]
    pub size: Option<u32>,
    /// Adam iterations per stage; the preset's by default.
    #[arg(long)]
    pub iters: Option<u32>,
    #[arg(long, default_value_t = 0, value_parser = crate::pipeline::parse_seed)]
    pub seed: u64,
    /// Preset: draft, fast, balanced, paper or cpu (`quality` is an older name of paper; cpu
    /// traces as balanced): the working size and iterations; the same vocabulary as `generate`
    /// and the service.
    #[arg(long, default_value = "balanced")]
    pub preset: String,
    /// Where the paths come from: LIVE's circles, vtracer's trace (refined), or `pixels`: no
    /// tracing, a square per pixel merged per region of a colour (pixel art, up to 256 px).
    #[arg(long, value_enum, default_value = "circles")]
    pub init: InitArg,
    /// Weight of the self-intersection (Xing) loss.
    #[arg(long)]
    pub xing_weight: Option<f32>,
    #[command(flatten)]
    pub vector: super::vector_args::VectorArgs,
    /// Stop adding paths once the PSNR (dB, over white) reaches this.
    #[arg(long)]
    pub target_psnr: Option<f64>,
    /// Keep the SVG at most this many bytes: stop adding paths, then drop the paths whose
    /// removal costs least (one path always stays, even where it alone is larger).
    #[arg(long)]
    pub max_bytes: Option<usize>,
    /// End each stage early once 20 steps improve the loss by less than this fraction of the
    /// previous 20's (e.g. 0.002: about 2× faster, 1.7 dB lower at 24 paths on icons) [default:
    /// 0, every step].
    #[arg(long)]
    pub converge: Option<f32>,
    /// Decimal places in the SVG, in pixel units [default: integers on the coarsest grid (1 to
    /// 1/1000 px, the viewBox scaled to it) that keeps the render within 0.5/255 and every
    /// outline simple].
    #[arg(long)]
    pub precision: Option<u8>,
    /// Also write our render of the result as PNG.
    #[arg(long)]
    pub preview: Option<PathBuf>,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
    /// Print a JSON summary on stdout (the plan, paths, PSNR, bytes, editability, seconds).
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum InitArg {
    Circles,
    Vtracer,
    /// A square per pixel, merged per region of a colour: pixel art copied exactly.
    Pixels,
}

/// Reads an image, refusing unreadable files and images over [`MAX_INPUT_SIDE`] with a clear
/// message before decoding them fully.
pub fn load_input(path: &Path) -> Result<Image, CliError> {
    let dims = image::ImageReader::open(path)
        .bad_input(|| format!("cannot open {}", path.display()))?
        .with_guessed_format()
        .bad_input(|| format!("cannot read {}", path.display()))?
        .into_dimensions()
        .bad_input(|| format!("{} is not a readable PNG/JPEG image", path.display()))?;
    if dims.0 > MAX_INPUT_SIDE || dims.1 > MAX_INPUT_SIDE {
        return Err(CliError::Usage(format!(
            "{} is {}x{}; images larger than {MAX_INPUT_SIDE} px per side are refused \
             (downscale it first)",
            path.display(),
            dims.0,
            dims.1
        )));
    }
    Image::open(path).bad_input(|| path.display().to_string())
}

/// Builds the LIVE configuration from the command-line options.
pub fn config_from_args(a: &VectorizeArgs) -> Result<LiveConfig, CliError> {
    let preset: crate::pipeline::Preset = a.preset.parse().map_err(CliError::Usage)?;
    let mut cfg = preset.live_config();
    cfg.budget = if let Some(s) = &a.schedule {
        PathBudget::Schedule {
            stages: live::schedule::parse_schedule(s, live::MAX_PATHS)
                .map_err(|e| CliError::Usage(e.to_string()))?,
        }
    } else if a.paths.trim() == "auto" {
        PathBudget::auto()
    } else {
        let n: usize = a.paths.trim().parse().map_err(|_| {
            CliError::Usage(format!(
                "--paths must be a number or `auto`, got {:?}",
                a.paths
            ))
        })?;
        if n == 0 || n > live::MAX_PATHS {
            return Err(CliError::Usage(format!(
                "--paths must be in 1..={}",
                live::MAX_PATHS
            )));
        }
        PathBudget::fixed(n)
    };
    if let Some(s) = a.size {
        cfg.size = s;
    }
    if let Some(i) = a.iters {
        cfg.iters_per_stage = i;
    }
    if let Some(x) = a.xing_weight {
        cfg.xing_weight = x;
    }
    cfg.seed = a.seed;
    cfg.colors = a.vector.color_plan()?;
    cfg.fill = a.vector.fill()?;
    cfg.target_psnr = a
        .target_psnr
        .map(crate::vector::check_target_psnr)
        .transpose()
        .map_err(|e| CliError::Usage(format!("--target-psnr: {e}")))?;
    cfg.max_bytes = a
        .max_bytes
        .map(crate::vector::check_max_bytes)
        .transpose()
        .map_err(|e| CliError::Usage(format!("--max-bytes: {e}")))?;
    if let Some(c) = a.converge {
        if !(0.0..1.0).contains(&c) {
            return Err(CliError::Usage(format!(
                "--converge must be at least 0 and below 1, got {c}"
            )));
        }
        cfg.converge_tol = c;
    }
    cfg.init = match a.init {
        InitArg::Circles => InitMode::Circles,
        InitArg::Vtracer => InitMode::Vtracer,
        InitArg::Pixels => InitMode::Pixels,
    };
    cfg.validate().map_err(|e| CliError::Usage(e.to_string()))?;
    Ok(cfg)
}

pub fn run(a: VectorizeArgs) -> Result<(), CliError> {
    let cfg = config_from_args(&a)?;
    let group = cfg.colors.group;
    let target = load_input(&a.input)?;
    let t0 = std::time::Instant::now();
    let (plan, result) = trace(&a, cfg, target)?;
    // The run's SVG (the fewest decimals that keep the picture and simple outlines), or the
    // scene at the decimals asked for.
    let svg = match a.precision {
        None => result.svg.clone(),
        Some(precision) => crate::svg::to_svg(
            &result.scene,
            &crate::svg::SvgOptions {
                precision,
                ..group.svg_options()
            },
        ),
    };
    super::write_result(&a.output, &svg)?;
    if let Some(p) = &a.preview {
        crate::raster::render(&result.scene)
            .save_png(p)
            .failed(|| "preview".into())?;
    }
    let e = crate::vector::check::check_svg(&svg).unwrap_or_default();
    eprintln!(
        "{}: {} paths{}, PSNR {:.2} dB, {} bytes, {} colours, {} self-intersecting, {} hidden, \
         {} slivers, {:.1} s",
        a.output.display(),
        result.paths,
        match result.report.paths_pruned {
            Some(n) if n > 0 => format!(" ({n} pruned)"),
            _ => String::new(),
        },
        result.report.psnr.unwrap_or(f64::NAN),
        svg.len(),
        e.colors,
        e.self_intersecting,
        e.hidden,
        e.slivers,
        t0.elapsed().as_secs_f64()
    );
    if a.json {
        let summary = serde_json::json!({
            "output": a.output,
            "paths": result.paths,
            "bytes": svg.len(),
            "editability": e,
            "seconds": t0.elapsed().as_secs_f64(),
            "plan": plan,
            "detail": result.report,
        });
        println!("{summary}");
    }
    Ok(())
}

/// Traces `target` with `cfg` through the executor and plan the service's vectorize jobs use
/// (this command's LIVE configuration as the plan), with a progress bar unless `--quiet`.
fn trace(
    a: &VectorizeArgs,
    cfg: LiveConfig,
    target: Image,
) -> Result<(crate::pipeline::RunPlan, crate::pipeline::RunOutput), CliError> {
    let bar = if a.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(1)
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} {msg}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let sink = {
        let bar = bar.clone();
        move |p: Progress| {
            bar.set_length(p.total as u64);
            bar.set_position(p.step as u64);
            let paths = p
                .detail
                .as_ref()
                .and_then(|d| d.get("paths"))
                .and_then(|v| v.as_u64())
                .unwrap_or(0);
            if let Some(l) = p.loss {
                bar.set_message(format!("paths {paths} loss {l:.5}"));
            }
        }
    };
    // The same executor and plan as the service's vectorize jobs, with this command's LIVE
    // configuration as the plan.
    let exec = DefaultExecutor::default();
    let request = PlanRequest {
        kind: JobKind::Vectorize,
        caption: None,
        seed: a.seed,
        tuning: Tuning {
            live: Some(cfg),
            ..Tuning::default()
        },
        ..PlanRequest::text("")
    };
    let plan = exec.plan(&request, &super::request_args::cli_limits())?;
    let ctx = JobContext::new(
        std::sync::Arc::new(sink),
        CancelToken::new(),
        u32::MAX,
        Box::new(|_| Ok(())),
        None,
    );
    let input = RunInput {
        image: Some(target),
        ..RunInput::default()
    };
    // Bad input or settings (a refused image or configuration) exit 2, other failures 1.
    let result = exec.run_plan(&plan, &input, &ctx)?;
    bar.finish_and_clear();
    Ok((plan, result))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::Preset;
    use clap::Parser;

    fn parse(extra: &[&str]) -> VectorizeArgs {
        let mut argv = vec!["vectorfusion", "vectorize", "in.png", "-o", "out.svg"];
        argv.extend_from_slice(extra);
        match crate::cli::Cli::parse_from(argv).command {
            crate::cli::Command::Vectorize(a) => a,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn options_map_to_config() {
        let c = config_from_args(&parse(&[])).unwrap();
        assert_eq!(c, Preset::Balanced.live_config());
        // One preset vocabulary: `quality` is paper's older name, draft cuts the work.
        let q = config_from_args(&parse(&["--preset", "quality"])).unwrap();
        assert_eq!(q.size, Preset::Paper.live_config().size);
        let d = config_from_args(&parse(&["--preset", "draft"])).unwrap();
        assert_eq!((d.size, d.iters_per_stage), (64, 20));
        assert!(config_from_args(&parse(&["--preset", "best"])).is_err());
        let c = config_from_args(&parse(&["--paths", "auto", "--seed", "7"])).unwrap();
        assert!(matches!(c.budget, PathBudget::Auto { .. }));
        assert_eq!(c.seed, 7);
        let c = config_from_args(&parse(&[
            "--paths", "16", "--preset", "fast", "--size", "96", "--iters", "12", "--init",
            "vtracer",
        ]))
        .unwrap();
        assert_eq!(c.budget, PathBudget::fixed(16));
        assert_eq!((c.size, c.iters_per_stage), (96, 12));
        assert_eq!(c.init, InitMode::Vtracer);
        let c = config_from_args(&parse(&["--schedule", "4,4,8", "--paths", "99"])).unwrap();
        assert_eq!(
            c.budget,
            PathBudget::Schedule {
                stages: vec![4, 4, 8]
            }
        );
        for bad in [
            &["--paths", "0"][..],
            &["--paths", "x"],
            &["--schedule", "4,,8"],
            &["--size", "2"],
        ] {
            assert!(matches!(
                config_from_args(&parse(bad)),
                Err(CliError::Usage(_))
            ));
        }
    }
}
