//! `vectorfusion generate`: caption → SVG, through the executor the service uses: the request
//! is resolved into a [`crate::pipeline::RunPlan`] (printed in the JSON summary) and run.
//!
//! `--teacher analytic:DIR` uses the analytic TEST teacher (the exact denoiser of the PNG targets
//! in DIR; the caption is only recorded and may name a target). `--model DIR` loads a Stable
//! Diffusion diffusers directory (local files only) as the teacher. Without either (and without
//! `VECTORFUSION_MODELS_SD_DIR`), the embedded default model is used ([`default_model_dir`]:
//! `VF_DEFAULT_MODEL`, else `models/vf-icon`), with its `scorer/` as the default scorer.

use super::request_args::{ModelArgs, RequestArgs, cli_limits, parse_word};
use super::{CliError, ResultExt};
use crate::pipeline::{
    Aspect, CanvasRequest, DefaultExecutor, EncoderChoice, Executor, JobContext, Method, ModelDirs,
    PlanRequest, RunInput, SizeConditioningRequest, StartKind, default_model_dir,
};
use crate::progress::{CancelToken, Progress, Stage};
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
    #[arg(long, value_parser = parse_word::<Method>)]
    pub method: Option<Method>,
    /// CLIP scorer directory used to keep the best of the sampled images.
    #[arg(long)]
    pub scorer: Option<PathBuf>,
    /// Start from this PNG/JPEG: trace it with LIVE, then fine-tune it to the caption with SDS.
    #[arg(long, conflicts_with = "svg")]
    pub image: Option<PathBuf>,
    /// Start from this SVG: import it, then fine-tune it to the caption with SDS.
    #[arg(long)]
    pub svg: Option<PathBuf>,
    #[command(flatten)]
    pub model: ModelArgs,
    /// SDS encoder of Stable Diffusion models: vae, taesd or auto (TAESD when --taesd or a
    /// taesd/ folder in or beside the model exists and the preset is not paper). Pixel-space
    /// models ignore it.
    #[arg(long, default_value = "auto", value_parser = parse_word::<EncoderChoice>)]
    pub encoder: EncoderChoice,
    /// TAESD directory (`madebyollin/taesd` diffusers layout) for `--encoder taesd|auto`.
    #[arg(long)]
    pub taesd: Option<PathBuf>,
    #[command(flatten)]
    pub request: RequestArgs,
    #[command(flatten)]
    pub vector: super::vector_args::VectorArgs,
    #[command(flatten)]
    pub canvas: CanvasArgs,
    /// Output path: `.svg`, or `.pdf` (vector PDF) / `.png` (render) by extension.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write SVG snapshots here (`STAGE_STEP.svg`, every `--snapshot-every` steps).
    #[arg(long)]
    pub snapshots: Option<PathBuf>,
    /// Snapshot period of the LIVE and SDS stages [default: the preset's].
    #[arg(long)]
    pub snapshot_every: Option<u32>,
    /// Return the N best distinct results (1 to 6): the best N samples of the rerank, each
    /// traced and refined; with N > 1, `-o out.svg` writes out-1.svg ... out-N.svg.
    #[arg(long, default_value_t = 1)]
    pub variations: u32,
}

/// Where variation `i` (1-based) of `n` is written: `output` itself for a single result,
/// otherwise `output` with `-i` before its extension (`out.svg` → `out-2.svg`).
pub fn variation_path(output: &std::path::Path, i: usize, n: usize) -> PathBuf {
    if n <= 1 {
        return output.to_path_buf();
    }
    let stem = output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match output.extension() {
        Some(ext) => format!("{stem}-{i}.{}", ext.to_string_lossy()),
        None => format!("{stem}-{i}"),
    };
    output.with_file_name(name)
}

/// The canvas and the negative prompt of a text run.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct CanvasArgs {
    /// Canvas aspect, width:height: 1:1, 4:3, 3:4, 16:9, 9:16, 3:2 or 2:3 (Stable Diffusion
    /// samples at it; a model that draws squares, like the embedded one, draws its square
    /// centred on the canvas) [default: the preset's square].
    #[arg(long, value_parser = parse_aspect)]
    pub aspect: Option<Aspect>,
    /// Canvas width in px (with --height, instead of --aspect; 64 to 2048; the drawing is
    /// scaled to fit and centred).
    #[arg(long)]
    pub width: Option<u32>,
    /// Canvas height in px (with --width).
    #[arg(long)]
    pub height: Option<u32>,
    /// What classifier-free guidance steers away from (sampling and SDS embed it as the
    /// unconditional prompt instead of "").
    #[arg(long)]
    pub negative_prompt: Option<String>,
    /// SDXL only: the original image size the drawing stands for, WIDTHxHEIGHT px (its size
    /// conditioning; SDXL draws sharper when told a large original, e.g. 1024x1024)
    /// [default: the drawn size].
    #[arg(long, value_name = "WxH", value_parser = parse_pair::<'x'>)]
    pub sdxl_original_size: Option<(u32, u32)>,
    /// SDXL only: the top-left corner of the crop within the original, LEFT,TOP px (its crop
    /// conditioning; 0,0 asks for a centred, uncropped subject) [default: 0,0].
    #[arg(long, value_name = "LEFT,TOP", value_parser = parse_pair::<','>)]
    pub sdxl_crop: Option<(u32, u32)>,
}

impl CanvasArgs {
    /// The SDXL size conditioning asked for (`None`: neither flag).
    pub fn size_conditioning(&self) -> Option<SizeConditioningRequest> {
        if self.sdxl_original_size.is_none() && self.sdxl_crop.is_none() {
            return None;
        }
        Some(SizeConditioningRequest {
            original_width: self.sdxl_original_size.map(|s| s.0),
            original_height: self.sdxl_original_size.map(|s| s.1),
            crop_left: self.sdxl_crop.map(|c| c.0),
            crop_top: self.sdxl_crop.map(|c| c.1),
        })
    }
}

fn parse_aspect(s: &str) -> Result<Aspect, String> {
    s.parse()
}

/// Two whole numbers separated by `SEP` (`1024x768`, `16,8`).
fn parse_pair<const SEP: char>(s: &str) -> Result<(u32, u32), String> {
    let number = |t: &str| {
        t.trim()
            .parse::<u32>()
            .map_err(|e| format!("{t:?} is not a whole number: {e}"))
    };
    let (a, b) = s
        .split_once(SEP)
        .ok_or_else(|| format!("expected two whole numbers separated by '{SEP}', got {s:?}"))?;
    Ok((number(a)?, number(b)?))
}

/// `--model`, else `VECTORFUSION_MODELS_SD_DIR` (and `..._CLIP_DIR` as the scorer), else the
/// embedded default model (with its `scorer/`), unless `--teacher` is given. Returns the model
/// directory and the default scorer that goes with it.
fn model_and_scorer(args: &GenerateArgs) -> Result<(Option<PathBuf>, Option<PathBuf>), CliError> {
    if args.model.model.is_some() || args.model.teacher.is_some() {
        return Ok((args.model.model.clone(), None));
    }
    let cfg = crate::config::Config::load(None).map_err(|e| CliError::Usage(e.to_string()))?;
    let mut dirs = cfg.model_dirs();
    if dirs.sd_dir.is_none() {
        let default = default_model_dir().map_err(|e| CliError::Usage(e.to_string()))?;
        dirs = dirs.or_default_model(default);
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

/// The model directories of a command-line run (`--model`/`--teacher`, `--scorer`, `--taesd`,
/// `--encoder`, `--device`, else the configured or embedded model).
fn model_dirs(args: &GenerateArgs) -> Result<ModelDirs, CliError> {
    let (model, default_scorer) = model_and_scorer(args)?;
    if model.is_none() && args.model.teacher.is_none() {
        return Err(no_model());
    }
    Ok(ModelDirs {
        sd_dir: model.clone(),
        taesd_dir: args.taesd.clone(),
        encoder: args.encoder,
        // A model (given or configured) is the teacher; the test teacher only without one.
        analytic_dir: model
            .is_none()
            .then(|| args.model.teacher.clone())
            .flatten(),
        ..args
            .model
            .model_dirs(args.scorer.clone().or(default_scorer))
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
    let method = args.method.unwrap_or(if args.model.teacher.is_some() {
        Method::Scratch
    } else {
        Method::SdLiveSds
    });
    let dirs = model_dirs(&args)?;
    if !args.request.no_retrieval && method != Method::Scratch {
        install_retrieval(&dirs);
    }
    let (request, input, warnings) = request_and_input(&args, method)?;
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    let exec = DefaultExecutor::with_downloads(dirs);
    let plan = exec.plan(&request, &cli_limits())?;
    let text = plan
        .text
        .as_ref()
        .ok_or_else(|| CliError::Usage("the request resolved to no text run".into()))?;
    let models = exec.load_models(text)?;
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
    let mut out = exec.run_plan(&plan, &input, &ctx)?;
    out.report.import_warnings = warnings;
    bar.finish_and_clear();
    let n = out.variations.len() + 1;
    let mut outputs = Vec::with_capacity(n);
    for (i, (svg, paths)) in std::iter::once(&out)
        .chain(&out.variations)
        .map(|o| (&o.svg, o.paths))
        .enumerate()
    {
        let path = variation_path(&args.output, i + 1, n);
        super::write_result(&path, svg)?;
        eprintln!("wrote {} ({paths} paths)", path.display());
        outputs.push(path);
    }
    let mut summary = serde_json::json!({
        "output": outputs[0],
        "paths": out.paths,
        "plan": plan,
        "detail": out.report,
    });
    if n > 1 {
        summary["outputs"] = serde_json::json!(outputs);
    }
    println!("{summary}");
    Ok(())
}

/// Installs the retrieval index of a model that pins one and has none yet, on first use as
/// the MiniLM weights are (the service never downloads; `vectorfusion setup` does both up
/// front). Without it the run samples from noise only.
fn install_retrieval(dirs: &ModelDirs) {
    let Some(dir) = &dirs.sd_dir else {
        return;
    };
    let rloc = crate::retrieval::RetrievalLocations::from_env();
    if matches!(crate::retrieval::pinned_packages(dir), Ok(Some(_)))
        && rloc.load(dir).is_err()
        && !rloc.offline
        && let Err(e) = super::setup::install_retrieval(dir, &rloc)
    {
        eprintln!("warning: no retrieval index ({e}); sampling from noise only");
    }
}

/// The request of a run by `method` and its input: the caption, and the `--image` or `--svg`
/// it starts from (a file that cannot be read is bad input), and the SVG import's warnings.
fn request_and_input(
    args: &GenerateArgs,
    method: Method,
) -> Result<(PlanRequest, RunInput, Vec<String>), CliError> {
    let mut input = RunInput {
        caption: Some(args.caption.clone()),
        ..RunInput::default()
    };
    let mut warnings = Vec::new();
    let start = if let Some(p) = &args.image {
        input.image = Some(crate::image::Image::open(p).bad_input(|| p.display().to_string())?);
        StartKind::Image
    } else if let Some(p) = &args.svg {
        let import = crate::svg::load_import(p).bad_input(|| p.display().to_string())?;
        input.svg = Some(import.scene);
        warnings = import.warnings;
        StartKind::Svg
    } else {
        StartKind::Method
    };
    let request = PlanRequest {
        start,
        vector: crate::vector::VectorOptions {
            colors: args.vector.color_plan()?,
            fill: args.vector.fill()?,
            ..Default::default()
        },
        tuning: args.request.tuning.tuning(args.snapshot_every),
        variations: args.variations,
        canvas: CanvasRequest {
            aspect: args.canvas.aspect,
            width: args.canvas.width,
            height: args.canvas.height,
        },
        negative_prompt: args.canvas.negative_prompt.clone(),
        size_conditioning: args.canvas.size_conditioning(),
        ..args.request.plan_request(&args.caption, method)
    };
    Ok((request, input, warnings))
}
