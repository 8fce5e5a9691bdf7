//! `vectorfusion generate`: caption → SVG by score distillation from scratch.
//!
//! `--teacher analytic:DIR` uses the analytic TEST teacher (the exact denoiser of the PNG targets
//! in DIR; the caption is only recorded and may name a target). `--model DIR` loads a Stable
//! Diffusion diffusers directory (local files only) as the teacher. Without either (and without
//! `VECTORFUSION_MODELS_SD_DIR`), the embedded default model is used ([`default_model_dir`]:
//! `VF_DEFAULT_MODEL`, else `models/vf-icon`), with its `scorer/` as the default scorer.
//! Pixel-space models always run the shared pipeline with their own presets.

use super::CliError;
use crate::pipeline::methods::{self, Models, Start, TextRequest};
use crate::pipeline::{
    EncoderChoice, Method, PipelineError, Preset, default_model_dir, is_small_model,
    resolve_encoder,
};
use crate::progress::{CancelToken, Progress};
use crate::stages::sds::{RasterBackend, SdsConfig, run_sds};
use crate::stages::styles::Style;
use crate::teacher::{AnalyticTeacher, AnalyticTeacherConfig, SdTeacher, Teacher, TeacherError};
use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use rand::SeedableRng;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct GenerateArgs {
    /// The caption (with the analytic test teacher it is only recorded).
    pub caption: String,
    /// Generation method: scratch, sd_live or sd_live_sds [default: sd_live_sds with a
    /// diffusion model (the paper's full pipeline), scratch with `--teacher`].
    #[arg(long)]
    pub method: Option<String>,
    /// Preset: draft, fast, balanced or paper (resolution, steps, paths, samples). Any of
    /// --preset, --scorer, --samples, --image, --svg or a method other than scratch runs the
    /// shared pipeline (the one the service runs).
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
    /// Style: iconography, pixel-art or sketch.
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
    /// Teacher input size in pixels (the SVG is written at this width) [default: the preset's,
    /// 64 for plain scratch].
    #[arg(long)]
    pub size: Option<u32>,
    /// SDS steps [default: the preset's, 500 for plain scratch].
    #[arg(long)]
    pub steps: Option<u32>,
    /// Number of paths (iconography, sketch; pixel art is always a 32x32 grid).
    #[arg(long)]
    pub paths: Option<usize>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// SDS classifier-free guidance scale [default: the model's (`_sds_guidance` in its
    /// model_index.json), 100 as in the paper for Stable Diffusion and the test teacher].
    #[arg(long)]
    pub guidance: Option<f32>,
    /// Sample from noise only: no retrieved training icons as starting points (the embedded
    /// model starts about half of its K samples from the icons nearest to the caption).
    #[arg(long)]
    pub no_retrieval: bool,
    /// Smallest timestep drawn.
    #[arg(long, default_value_t = 50)]
    pub t_min: usize,
    /// Largest timestep drawn (at the start, see `--t-max-end`).
    #[arg(long, default_value_t = 950)]
    pub t_max: usize,
    /// Anneal the largest timestep linearly to this value by the last step.
    #[arg(long)]
    pub t_max_end: Option<usize>,
    /// Clip each parameter group's gradient to this L2 norm.
    #[arg(long)]
    pub grad_clip: Option<f32>,
    /// Also re-initialise closed paths whose area is below this many px² (iconography).
    #[arg(long)]
    pub reinit_min_area: Option<f32>,
    /// Turn off the random perspective + crop augmentation.
    #[arg(long)]
    pub no_augment: bool,
    /// Output SVG path.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write an SVG snapshot here every `--snapshot-every` steps.
    #[arg(long)]
    pub snapshots: Option<PathBuf>,
    #[arg(long, default_value_t = 50)]
    pub snapshot_every: u32,
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

pub fn run(mut args: GenerateArgs) -> Result<(), CliError> {
    let method: Method = match &args.method {
        Some(m) => m.parse().map_err(CliError::Usage)?,
        None if args.teacher.is_some() => Method::Scratch,
        None => Method::SdLiveSds,
    };
    let encoder: EncoderChoice = args.encoder.parse().map_err(CliError::Usage)?;
    let (model, default_scorer) = model_and_scorer(&args)?;
    args.model = model;
    if args.scorer.is_none() {
        args.scorer = default_scorer;
    }
    let small = args.model.as_deref().is_some_and(is_small_model);
    if small
        || method != Method::Scratch
        || args.preset.is_some()
        || args.scorer.is_some()
        || args.samples.is_some()
        || args.image.is_some()
        || args.svg.is_some()
    {
        return run_pipeline(args, method, encoder, small);
    }
    let style: Style = args.style.parse().map_err(CliError::Usage)?;
    let size = args.size.unwrap_or(64);
    let steps = args.steps.unwrap_or(500);
    if !(8..=2048).contains(&size) {
        return Err(CliError::Usage(format!(
            "--size {size} out of range 8..=2048"
        )));
    }
    if steps == 0 {
        return Err(CliError::Usage("--steps must be positive".into()));
    }
    // The model's prompt/guidance defaults (the paper's for the analytic test teacher).
    let mut hints = crate::models::pipeline::ModelHints::default();
    let teacher: Box<dyn Teacher> = if let Some(dir) = &args.model {
        let taesd =
            resolve_encoder(encoder, true, dir, args.taesd.as_deref()).map_err(pipeline_err)?;
        let device = super::parse_device(&args.device)?;
        let t = SdTeacher::load_on(dir, size, taesd.as_deref(), device).map_err(|e| match e {
            TeacherError::Setup(m) => CliError::Usage(m),
            other => CliError::Other(anyhow::Error::new(other).context("loading the model")),
        })?;
        hints = t.model().hints;
        Box::new(t)
    } else {
        let spec = args.teacher.as_deref().ok_or_else(no_model)?;
        let dir = super::analytic_teacher_dir(spec)?;
        let pool = if size >= 64 && size % 64 == 0 {
            size / 64
        } else {
            1
        };
        Box::new(
            AnalyticTeacher::from_dir(
                dir,
                AnalyticTeacherConfig {
                    image_size: size,
                    pool,
                    num_train_timesteps: 1000,
                },
            )
            .map_err(|e| CliError::Usage(e.to_string()))?,
        )
    };
    eprintln!("teacher: {}", teacher.name());

    let mut cfg = SdsConfig::for_style(style, &args.caption, steps, size);
    cfg.prompt = style.prompt_with(&args.caption, hints.style_suffix);
    cfg.seed = args.seed;
    cfg.guidance = args.guidance.unwrap_or(hints.sds_guidance);
    cfg.snapshot_every = if args.snapshots.is_some() {
        args.snapshot_every
    } else {
        0
    };
    cfg.t_min = args.t_min;
    cfg.t_max = args.t_max;
    cfg.t_max_end = args.t_max_end;
    cfg.grad_clip = args.grad_clip;
    if let Some(r) = cfg.reinit.as_mut() {
        r.min_area = args.reinit_min_area;
    }
    if args.no_augment {
        cfg.augment = None;
    }
    let render = cfg.render_size(size);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed ^ 0x5eed_1a17);
    let paths = args.paths.unwrap_or(style.default_paths());
    if paths == 0 || paths > 4096 {
        return Err(CliError::Usage("--paths must be in 1..=4096".into()));
    }
    let scene = style
        .init_scene(render, paths, &mut rng)
        .context("initial scene")?;

    if let Some(d) = &args.snapshots {
        std::fs::create_dir_all(d)
            .with_context(|| format!("cannot create snapshot directory {}", d.display()))?;
    }
    let bar = ProgressBar::new(steps as u64);
    bar.set_style(
        ProgressStyle::with_template("sds [{bar:40}] {pos}/{len} {msg} ({eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let snap_dir = args.snapshots.clone();
    let snap_err = std::sync::Mutex::new(None::<String>);
    let sink = |p: Progress| {
        bar.set_position(p.step as u64);
        if let Some(l) = p.loss {
            bar.set_message(format!("loss {l:.4}"));
        }
        if let (Some(dir), Some(svg)) = (&snap_dir, &p.svg) {
            let path = dir.join(format!("step_{:05}.svg", p.step));
            if let Err(e) = std::fs::write(&path, svg)
                && let Ok(mut g) = snap_err.lock()
            {
                *g = Some(format!("{}: {e}", path.display()));
            }
        }
    };
    let out = run_sds(
        &RasterBackend,
        teacher.as_ref(),
        scene,
        &cfg,
        &sink,
        &CancelToken::new(),
    )
    .map_err(|e| match e {
        crate::stages::sds::SdsError::Config(m) => CliError::Usage(m),
        other => CliError::Other(anyhow::Error::new(other).context("score distillation")),
    })?;
    bar.finish();
    if let Ok(Some(e)) = snap_err.into_inner() {
        eprintln!("warning: could not write a snapshot: {e}");
    }
    let final_scene = out.scene.scaled_to_width(size);
    let svg = RasterBackend::svg_text(&final_scene);
    std::fs::write(&args.output, svg)
        .with_context(|| format!("cannot write {}", args.output.display()))?;
    eprintln!(
        "wrote {} ({} steps, {} skipped non-finite, {} lr halvings, {} re-inits)",
        args.output.display(),
        out.stats.steps_done,
        out.stats.skipped_nonfinite,
        out.stats.lr_halvings,
        out.stats.reinits
    );
    Ok(())
}

pub(crate) fn pipeline_err(e: PipelineError) -> CliError {
    match e {
        PipelineError::InvalidInput(m) | PipelineError::ModelsNotConfigured(m) => {
            CliError::Usage(m)
        }
        other => CliError::Other(anyhow::Error::new(other)),
    }
}

/// The shared pipeline ([`crate::pipeline::methods`]): every method, presets, starts from an
/// image or SVG, rerank, pruning.
fn run_pipeline(
    args: GenerateArgs,
    method: Method,
    encoder: EncoderChoice,
    small: bool,
) -> Result<(), CliError> {
    let style: Style = args.style.parse().map_err(CliError::Usage)?;
    let preset: Preset = match &args.preset {
        Some(p) => p.parse().map_err(CliError::Usage)?,
        None => Preset::default(),
    };
    let ps = preset.settings_for(small);
    let size = args.size.unwrap_or(ps.size);
    if !(8..=2048).contains(&size) {
        return Err(CliError::Usage(format!(
            "--size {size} out of range 8..=2048"
        )));
    }
    if args.steps == Some(0) || args.samples == Some(0) || args.paths == Some(0) {
        return Err(CliError::Usage(
            "--steps, --samples and --paths must be positive".into(),
        ));
    }
    let models = if let Some(dir) = &args.model {
        let taesd = resolve_encoder(encoder, ps.prefer_taesd, dir, args.taesd.as_deref())
            .map_err(pipeline_err)?;
        // The retrieval index is installed on first use, as the MiniLM weights are (the
        // service never downloads; `vectorfusion setup` does both up front).
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
        let device = super::parse_device(&args.device)?;
        Models::load_sd_with(dir, args.scorer.as_deref(), size, taesd.as_deref(), device)
            .map_err(pipeline_err)?
    } else {
        let spec = args.teacher.as_deref().ok_or_else(no_model)?;
        let dir = super::analytic_teacher_dir(spec)?;
        Models::load_analytic(dir, args.scorer.as_deref(), size).map_err(pipeline_err)?
    };
    eprintln!("teacher: {}", models.teacher().name());
    let start = if let Some(p) = &args.image {
        Start::Image(
            crate::image::Image::open(p)
                .map_err(|e| CliError::Usage(format!("{}: {e}", p.display())))?,
        )
    } else if let Some(p) = &args.svg {
        Start::Svg(
            crate::svg::load_scene(p)
                .map_err(|e| CliError::Usage(format!("{}: {e}", p.display())))?,
        )
    } else {
        Start::Method
    };
    let req = TextRequest {
        caption: args.caption.clone(),
        style,
        method,
        preset,
        paths: args.paths,
        steps: args.steps,
        samples: args.samples,
        seed: args.seed,
        guidance: args.guidance,
        retrieval: !args.no_retrieval,
        start,
    };
    if let Some(d) = &args.snapshots {
        std::fs::create_dir_all(d)
            .with_context(|| format!("cannot create snapshot directory {}", d.display()))?;
    }
    let snap_dir = args.snapshots.clone();
    let sink = |p: Progress| {
        if let Some(l) = p.loss
            && p.step % 10 == 0
        {
            eprintln!("{} {}/{} loss {l:.4}", p.stage, p.step, p.total);
        }
        if let Some(d) = &p.detail
            && p.stage == "rerank"
        {
            eprintln!("rerank: {d}");
        }
        if let (Some(dir), Some(svg)) = (&snap_dir, &p.svg) {
            let path = dir.join(format!("{}_{:05}.svg", p.stage, p.step));
            if let Err(e) = std::fs::write(&path, svg) {
                eprintln!("warning: could not write {}: {e}", path.display());
            }
        }
    };
    let out = methods::run_text(&models, &req, &sink, &CancelToken::new()).map_err(pipeline_err)?;
    std::fs::write(&args.output, &out.svg)
        .with_context(|| format!("cannot write {}", args.output.display()))?;
    eprintln!(
        "wrote {} ({} paths; detail {})",
        args.output.display(),
        out.paths,
        out.detail
    );
    Ok(())
}
