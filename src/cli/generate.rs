//! `vectorfusion generate`: caption → SVG, through the executor the service uses: the request
//! is resolved into a [`crate::pipeline::RunPlan`] (printed in the JSON summary) and run.
//!
//! `--teacher analytic:DIR` uses the analytic TEST teacher (the exact denoiser of the PNG targets
//! in DIR; the caption is only recorded and may name a target). `--model DIR` loads a Stable
//! Diffusion diffusers directory (local files only) as the teacher. Without either (and without
//! `VECTORFUSION_MODELS_SD_DIR`), the embedded default model is used ([`default_model_dir`]:
//! `VF_DEFAULT_MODEL`, else `models/vf-icon`), with its `scorer/` as the default scorer.

use super::CliError;
use super::tuning::SdsTuningArgs;
use crate::pipeline::{
    DefaultExecutor, EncoderChoice, Executor, JobContext, JobKind, Limits, Method, ModelDirs,
    PipelineError, PlanRequest, Preset, RunInput, SpecError, StartKind, Style, default_model_dir,
};
use crate::progress::{CancelToken, Progress, Stage};
use crate::scene::MAX_PATHS;
use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

#[derive(clap::Args, Debug)]
pub struct GenerateArgs {
    /// The caption (with the analytic test teacher it is only recorded).
    pub caption: String,
    /// Generation method: scratch, sd_live or sd_live_sds [default: sd_live_sds with a
    /// diffusion model (the paper's full pipeline), scratch with `--teacher`].
    #[arg(long)]
    pub method: Option<String>,
    /// Preset: draft, fast, balanced or paper (resolution, steps, paths, samples, sampler
    /// steps, LIVE iterations; `default` and `quality` are older names of balanced and paper)
    /// [default: balanced].
    #[arg(long)]
    pub preset: Option<String>,
    /// CLIP scorer directory used to keep the best of the sampled images.
    #[arg(long)]
    pub scorer: Option<PathBuf>,
    /// Images sampled for sd_live / sd_live_sds (K).
    #[arg(long)]
    pub samples: Option<u32>,
    /// Start from this PNG/JPEG: trace it with LIVE, then fine-tune it to the caption with SDS.
    #[arg(long, conflicts_with = "svg")]
    pub image: Option<PathBuf>,
    /// Start from this SVG: import it, then fine-tune it to the caption with SDS.
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// Style: iconography, pixel_art, sketch, low_poly or painting (`pixel-art`, `low-poly`,
    /// `icon`, `line` are accepted too).
    #[arg(long, default_value = "iconography")]
    pub style: String,
    /// Stable Diffusion model directory (diffusers layout).
    #[arg(long, conflicts_with = "teacher")]
    pub model: Option<PathBuf>,
    /// `analytic:DIR`: the analytic TEST teacher built from the PNG targets in DIR.
    #[arg(long)]
    pub teacher: Option<String>,
    /// SDS encoder of Stable Diffusion models: vae, taesd or auto (TAESD when --taesd or a
    /// taesd/ folder in or beside the model exists and the preset is not paper). Pixel-space
    /// models ignore it.
    #[arg(long, default_value = "auto")]
    pub encoder: String,
    /// TAESD directory (`madebyollin/taesd` diffusers layout) for `--encoder taesd|auto`.
    #[arg(long)]
    pub taesd: Option<PathBuf>,
    /// Where the diffusion model runs: cpu, cuda or cuda:N (CUDA needs a build with the `cuda`
    /// feature).
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// SDS steps [default: the preset's].
    #[arg(long)]
    pub steps: Option<u32>,
    /// Number of paths or strokes (pixel art is always a 32x32 grid) [default: the preset's].
    #[arg(long)]
    pub paths: Option<u32>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Sample from noise only: no retrieved training icons as starting points (the embedded
    /// model starts a share of its K samples, `_retrieval_share`, from the icons nearest to the
    /// caption).
    #[arg(long)]
    pub no_retrieval: bool,
    #[command(flatten)]
    pub tuning: SdsTuningArgs,
    #[command(flatten)]
    pub vector: super::vector_args::VectorArgs,
    /// Output SVG path.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write SVG snapshots here (`STAGE_STEP.svg`, every `--snapshot-every` steps).
    #[arg(long)]
    pub snapshots: Option<PathBuf>,
    /// Snapshot period of the LIVE and SDS stages [default: the preset's].
    #[arg(long)]
    pub snapshot_every: Option<u32>,
}

/// `--model`, else `VECTORFUSION_MODELS_SD_DIR` (and `..._CLIP_DIR` as the scorer), else the
/// embedded default model (with its `scorer/`), unless `--teacher` is given. Returns the model
/// directory and the default scorer that goes with it.
fn model_and_scorer(args: &GenerateArgs) -> Result<(Option<PathBuf>, Option<PathBuf>), CliError> {
    if args.model.is_some() || args.teacher.is_some() {
        return Ok((args.model.clone(), None));
    }
    let cfg = crate::config::Config::load(None).map_err(|e| CliError::Usage(e.to_string()))?;
    let mut dirs = cfg.model_dirs();
    if dirs.sd_dir.is_none() {
        dirs = dirs.or_default_model(default_model_dir().map_err(CliError::Usage)?);
    }
    Ok((dirs.sd_dir, dirs.clip_dir))
}

fn no_model() -> CliError {
    CliError::Usage(format!(
        "give --model DIR or --teacher analytic:DIR (the embedded default model {} was not \
         found here or in the source tree; set {} to its directory)",
        crate::pipeline::EMBEDDED_MODEL,
        crate::pipeline::DEFAULT_MODEL_ENV
    ))
}

pub(crate) fn pipeline_err(e: PipelineError) -> CliError {
    match e {
        PipelineError::InvalidInput(m) | PipelineError::ModelsNotConfigured(m) => {
            CliError::Usage(m)
        }
        other => CliError::Other(anyhow::Error::new(other)),
    }
}

pub(crate) fn spec_err(e: SpecError) -> CliError {
    CliError::Usage(format!("--{}: {}", e.field.replace('_', "-"), e.reason))
}

/// Limits of a command-line run: only what the stages themselves cap.
pub(crate) fn cli_limits() -> Limits {
    Limits {
        max_paths: MAX_PATHS as u32,
        max_steps: u32::MAX,
        max_samples: u32::MAX,
        ..Limits::default()
    }
}

/// The model directories of a command-line run (`--model`/`--teacher`, `--scorer`, `--taesd`,
/// `--encoder`, `--device`, else the configured or embedded model).
fn model_dirs(args: &GenerateArgs) -> Result<ModelDirs, CliError> {
    let encoder: EncoderChoice = args.encoder.parse().map_err(CliError::Usage)?;
    let (model, default_scorer) = model_and_scorer(args)?;
    let analytic_dir = match (&model, &args.teacher) {
        (Some(_), _) => None,
        (None, Some(spec)) => Some(super::analytic_teacher_dir(spec)?.to_path_buf()),
        (None, None) => return Err(no_model()),
    };
    Ok(ModelDirs {
        sd_dir: model,
        clip_dir: args.scorer.clone().or(default_scorer),
        taesd_dir: args.taesd.clone(),
        encoder,
        device: super::parse_device(&args.device)?,
        analytic_dir,
    })
}

/// A progress bar per stage on stderr; snapshots written to `snap_dir`.
fn progress_sink(snap_dir: Option<PathBuf>) -> (ProgressBar, impl Fn(Progress) + Send + Sync) {
    let bar = ProgressBar::new(1);
    bar.set_style(
        ProgressStyle::with_template("{msg:>8} [{bar:40}] {pos}/{len} ({eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let stage = Mutex::new(None);
    let b = bar.clone();
    let sink = move |p: Progress| {
        if let Ok(mut s) = stage.lock()
            && *s != Some(p.stage)
        {
            *s = Some(p.stage);
            b.reset();
            b.set_message(p.stage.as_str());
        }
        b.set_length(u64::from(p.total));
        b.set_position(u64::from(p.step));
        if let (Some(d), Stage::Rerank) = (&p.detail, p.stage) {
            b.suspend(|| eprintln!("rerank: {d}"));
        }
        if let (Some(dir), Some(svg)) = (&snap_dir, &p.svg) {
            let path = dir.join(format!("{}_{:05}.svg", p.stage.as_str(), p.step));
            if let Err(e) = std::fs::write(&path, svg) {
                b.suspend(|| eprintln!("warning: could not write {}: {e}", path.display()));
            }
        }
    };
    (bar, sink)
}

pub fn run(args: GenerateArgs) -> Result<(), CliError> {
    let method: Method = match &args.method {
        Some(m) => m.parse().map_err(CliError::Usage)?,
        None if args.teacher.is_some() => Method::Scratch,
        None => Method::SdLiveSds,
    };
    let style: Style = args.style.parse().map_err(CliError::Usage)?;
    let preset: Preset = match &args.preset {
        Some(p) => p.parse().map_err(CliError::Usage)?,
        None => Preset::default(),
    };
    let dirs = model_dirs(&args)?;
    // The retrieval index is installed on first use, as the MiniLM weights are (the service
    // never downloads; `vectorfusion setup` does both up front).
    if let Some(dir) = &dirs.sd_dir {
        let rloc = crate::retrieval::RetrievalLocations::from_env();
        if !args.no_retrieval
            && method != Method::Scratch
            && matches!(crate::retrieval::pinned_packages(dir), Ok(Some(_)))
            && rloc.load(dir).is_err()
            && !rloc.offline
            && let Err(e) = super::setup::install_retrieval(dir, &rloc)
        {
            eprintln!("warning: no retrieval index ({e}); sampling from noise only");
        }
    }
    let (start, image, svg) = if let Some(p) = &args.image {
        let im = crate::image::Image::open(p)
            .map_err(|e| CliError::Usage(format!("{}: {e}", p.display())))?;
        (StartKind::Image, Some(im), None)
    } else if let Some(p) = &args.svg {
        let sc = crate::svg::load_scene(p)
            .map_err(|e| CliError::Usage(format!("{}: {e}", p.display())))?;
        (StartKind::Svg, None, Some(sc))
    } else {
        (StartKind::Method, None, None)
    };
    let request = PlanRequest {
        kind: JobKind::Text,
        caption: Some(args.caption.clone()),
        start,
        style,
        method,
        preset,
        paths: args.paths,
        steps: args.steps,
        samples: args.samples,
        seed: args.seed,
        retrieval: !args.no_retrieval,
        vector: crate::vector::VectorOptions {
            colors: args.vector.color_plan()?,
            ..Default::default()
        },
        tuning: args.tuning.tuning(args.snapshot_every),
    };
    let exec = DefaultExecutor::with_downloads(dirs);
    let plan = exec.plan(&request, &cli_limits()).map_err(spec_err)?;
    let text = plan
        .text
        .as_ref()
        .ok_or_else(|| CliError::Usage("the request resolved to no text run".into()))?;
    let models = exec.load_models(text).map_err(pipeline_err)?;
    eprintln!("teacher: {}", models.teacher().name());
    if let Some(d) = &args.snapshots {
        std::fs::create_dir_all(d)
            .with_context(|| format!("cannot create snapshot directory {}", d.display()))?;
    }
    let (bar, sink) = progress_sink(args.snapshots.clone());
    let ctx = JobContext::new(
        Arc::new(sink),
        CancelToken::new(),
        u32::MAX,
        Box::new(|_| Ok(())),
        None,
    );
    let input = RunInput {
        caption: Some(args.caption.clone()),
        image,
        svg,
    };
    let out = exec.run_plan(&plan, &input, &ctx).map_err(pipeline_err)?;
    bar.finish_and_clear();
    std::fs::write(&args.output, &out.svg)
        .with_context(|| format!("cannot write {}", args.output.display()))?;
    eprintln!("wrote {} ({} paths)", args.output.display(), out.paths);
    let summary = serde_json::json!({
        "output": args.output,
        "paths": out.paths,
        "plan": plan,
        "detail": out.report,
    });
    println!("{summary}");
    Ok(())
}
