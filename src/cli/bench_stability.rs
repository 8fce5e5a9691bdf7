//! `vectorfusion bench stability`: where the methods fail. Runs seeds × method × style through
//! the executor every entry point shares ([`crate::pipeline::DefaultExecutor`]) with the analytic TEST teacher (built-in
//! targets, or `--teacher analytic:DIR`) or real weights (`--model DIR`), and reports per
//! method × style: failure rate (error/NaN, empty or collapsed SVG, oversaturation, diverged
//! loss), final quality spread (PSNR of the render against the nearest teacher target, analytic
//! teacher only) and seconds per run.

use super::CliError;
use super::generate::{cli_limits, spec_err};
use crate::image::{Image, psnr};
use crate::pipeline::{
    DefaultExecutor, Executor, JobContext, Method, ModelDirs, PlanRequest, Preset, RunInput, Tuning,
};
use crate::progress::CancelToken;
use crate::scene::{Rgba, Scene, Shape};
use crate::stages::styles::Style;
use crate::teacher::{AnalyticTeacher, AnalyticTeacherConfig};
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct BenchStabilityArgs {
    /// Seeds per method × style.
    #[arg(long, default_value_t = 4)]
    pub seeds: u64,
    /// Preset (draft, fast, balanced, paper): sampler and LIVE settings, and the defaults of
    /// the four options below.
    #[arg(long, default_value = "draft")]
    pub preset: String,
    /// SDS steps per run [default: 30 for draft, else the preset's].
    #[arg(long)]
    pub steps: Option<u32>,
    /// Teacher input size (px) [default: the preset's].
    #[arg(long)]
    pub size: Option<u32>,
    /// Samples K for sd_live* [default: the preset's].
    #[arg(long)]
    pub samples: Option<u32>,
    /// Paths (iconography) / strokes (sketch) [default: the preset's].
    #[arg(long)]
    pub paths: Option<usize>,
    /// `analytic:DIR` (PNG targets); default: built-in synthetic targets.
    #[arg(long, conflicts_with = "model")]
    pub teacher: Option<String>,
    /// Stable Diffusion directory (real weights) instead of the analytic teacher.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// CLIP scorer directory for reranking.
    #[arg(long)]
    pub scorer: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Write every run's final SVG and its render (`<method>-<style>-s<seed>.svg/.png`) here,
    /// and list the runs (with their failure kinds) in the report.
    #[arg(long)]
    pub save: Option<PathBuf>,
}

/// One run, listed in the report when `--save` is given.
#[derive(Clone, Debug, Serialize)]
pub struct StabilityRun {
    pub method: Method,
    pub style: Style,
    pub seed: u64,
    pub seconds: f64,
    pub paths: usize,
    pub psnr: Option<f64>,
    /// Failure kinds: `error`, `nan`, `collapsed`, `oversaturated`, `diverged` (empty = ok).
    pub failures: Vec<&'static str>,
    /// File stem under the `--save` directory (no file on error).
    pub file: Option<String>,
    pub error: Option<String>,
}

/// One method × style cell.
#[derive(Clone, Debug, Serialize)]
pub struct StabilityCell {
    pub method: Method,
    pub style: Style,
    pub runs: u64,
    pub errors: u64,
    pub nan: u64,
    pub collapsed: u64,
    pub oversaturated: u64,
    pub diverged: u64,
    /// Runs with any failure.
    pub failed: u64,
    pub failure_rate: f64,
    /// PSNR (dB) of the final render against the nearest target: min, median, max.
    pub psnr_min: Option<f64>,
    pub psnr_median: Option<f64>,
    pub psnr_max: Option<f64>,
    pub seconds_median: f64,
    pub paths_needed_median: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct StabilityReport {
    pub teacher: String,
    pub preset: Preset,
    pub seeds: u64,
    pub steps: u32,
    pub size: u32,
    pub cells: Vec<StabilityCell>,
    /// Every run, when `--save` was given.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub runs: Vec<StabilityRun>,
}

struct Resolved {
    seeds: u64,
    steps: u32,
    size: u32,
    samples: u32,
    paths: usize,
    teacher: Option<String>,
    model: Option<PathBuf>,
    scorer: Option<PathBuf>,
    json: bool,
    save: Option<PathBuf>,
}

/// Two flat icons on white (a red disc, a blue square) as analytic-teacher targets.
pub fn builtin_targets(size: u32) -> Result<Vec<(String, Image)>, CliError> {
    let s = size as f32;
    let mk = |shape: Result<Shape, crate::scene::SceneError>| -> Result<Image, CliError> {
        let mut scene =
            Scene::new(size, size, Rgba::WHITE).map_err(|e| CliError::Other(e.into()))?;
        scene
            .shapes
            .push(shape.map_err(|e| CliError::Other(e.into()))?);
        Ok(crate::raster::render(&scene))
    };
    Ok(vec![
        (
            "disc".into(),
            mk(Shape::circle(
                0.5 * s,
                0.5 * s,
                0.3 * s,
                8,
                Rgba::new(0.9, 0.2, 0.1, 1.0),
            ))?,
        ),
        (
            "square".into(),
            mk(Shape::square(
                0.25 * s,
                0.25 * s,
                0.5 * s,
                Rgba::new(0.1, 0.3, 0.8, 1.0),
            ))?,
        ),
    ])
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| x.is_finite());
    v.sort_by(f64::total_cmp);
    let n = v.len();
    (n > 0).then(|| {
        if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        }
    })
}

/// Render over white: mean absolute deviation from its mean colour (0 = one flat colour).
fn spread(im: &Image) -> f64 {
    let o = im.over([1.0, 1.0, 1.0]);
    let n = o.len_pixels().max(1) as f64;
    let mut mean = [0.0f64; 3];
    for p in o.data.chunks_exact(4) {
        for c in 0..3 {
            mean[c] += p[c] as f64 / n;
        }
    }
    o.data
        .chunks_exact(4)
        .map(|p| (0..3).map(|c| (p[c] as f64 - mean[c]).abs()).sum::<f64>() / 3.0)
        .sum::<f64>()
        / n
}

/// Mean chroma `max(rgb) − min(rgb)` over white.
fn chroma(im: &Image) -> f64 {
    let o = im.over([1.0, 1.0, 1.0]);
    let n = o.len_pixels().max(1) as f64;
    o.data
        .chunks_exact(4)
        .map(|p| (p[0].max(p[1]).max(p[2]) - p[0].min(p[1]).min(p[2])) as f64)
        .sum::<f64>()
        / n
}

/// Oversaturated: mean chroma above this (flat icons on white stay far below).
pub const OVERSATURATED_CHROMA: f64 = 0.6;
/// PSNR of identical images is reported as this (dB).
pub const PSNR_CAP: f64 = 99.0;
/// Collapsed: the render is (nearly) one flat colour.
pub const COLLAPSED_SPREAD: f64 = 0.01;

/// A directory removed when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new(prefix: &str) -> Result<Self, CliError> {
        let dir = std::env::temp_dir().join(format!("{prefix}-{}", std::process::id()));
        std::fs::create_dir_all(&dir)
            .map_err(|e| CliError::Other(anyhow::anyhow!("{}: {e}", dir.display())))?;
        Ok(TempDir(dir))
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

pub fn run(args: BenchStabilityArgs) -> Result<(), CliError> {
    let preset: Preset = args.preset.parse().map_err(CliError::Usage)?;
    // Small priors (the embedded model) have their own presets.
    let small = args
        .model
        .as_deref()
        .is_some_and(crate::pipeline::is_small_model);
    let ps = preset.settings_for(small);
    let a = Resolved {
        seeds: args.seeds,
        steps: args.steps.unwrap_or(if preset == Preset::Draft {
            30
        } else {
            ps.steps
        }),
        size: args.size.unwrap_or(ps.size),
        samples: args.samples.unwrap_or(ps.samples),
        paths: args.paths.unwrap_or(ps.paths),
        teacher: args.teacher,
        model: args.model,
        scorer: args.scorer,
        json: args.json,
        save: args.save,
    };
    if a.seeds == 0 || a.steps == 0 || a.samples == 0 || a.paths == 0 {
        return Err(CliError::Usage(
            "--seeds, --steps, --samples and --paths must be positive".into(),
        ));
    }
    if !(8..=512).contains(&a.size) {
        return Err(CliError::Usage("--size must be in 8..=512".into()));
    }
    // The built-in targets reach the executor as the analytic teacher's PNG directory.
    let builtin_dir;
    let (analytic_dir, targets) = match (&a.model, &a.teacher) {
        (Some(_), _) => (None, Vec::new()),
        (None, Some(spec)) => {
            let dir = super::analytic_teacher_dir(spec)?.to_path_buf();
            let t = AnalyticTeacher::from_dir(
                &dir,
                AnalyticTeacherConfig {
                    image_size: a.size,
                    pool: 1,
                    num_train_timesteps: 1000,
                },
            )
            .map_err(|e| CliError::Usage(e.to_string()))?;
            (Some(dir), t.targets().to_vec())
        }
        (None, None) => {
            builtin_dir = TempDir::new("vf-stability-targets")?;
            let mut targets = Vec::new();
            for (name, t) in builtin_targets(a.size)? {
                // Scored against what the teacher reads back (8-bit PNG), not the f32 original.
                let path = builtin_dir.0.join(format!("{name}.png"));
                t.save_png(&path)
                    .and_then(|()| Image::open(&path))
                    .map(|t| targets.push(t))
                    .map_err(|e| CliError::Other(anyhow::anyhow!("built-in targets: {e}")))?;
            }
            (Some(builtin_dir.0.clone()), targets)
        }
    };
    let exec = DefaultExecutor::with_downloads(ModelDirs {
        sd_dir: a.model.clone(),
        clip_dir: a.scorer.clone(),
        analytic_dir,
        ..ModelDirs::default()
    });
    if let Some(dir) = &a.save {
        std::fs::create_dir_all(dir)
            .map_err(|e| CliError::Usage(format!("--save {}: {e}", dir.display())))?;
    }
    let mut teacher = String::new();
    let mut cells = Vec::new();
    let mut runs = Vec::new();
    for method in Method::ALL {
        for style in Style::ALL {
            let mut cell = StabilityCell {
                method: *method,
                style,
                runs: a.seeds,
                errors: 0,
                nan: 0,
                collapsed: 0,
                oversaturated: 0,
                diverged: 0,
                failed: 0,
                failure_rate: 0.0,
                psnr_min: None,
                psnr_median: None,
                psnr_max: None,
                seconds_median: 0.0,
                paths_needed_median: 0.0,
            };
            let (mut psnrs, mut secs, mut paths) = (Vec::new(), Vec::new(), Vec::new());
            for seed in 0..a.seeds {
                let req = PlanRequest {
                    style,
                    method: *method,
                    preset,
                    paths: Some(a.paths as u32),
                    steps: Some(a.steps),
                    samples: Some(a.samples),
                    seed,
                    retrieval: false,
                    tuning: Tuning {
                        size: Some(a.size),
                        ..Tuning::default()
                    },
                    ..PlanRequest::text("an icon")
                };
                let plan = exec.plan(&req, &cli_limits()).map_err(spec_err)?;
                let t0 = Instant::now();
                let input = RunInput {
                    caption: Some("an icon".into()),
                    ..RunInput::default()
                };
                let r = exec.run_plan(&plan, &input, &JobContext::detached(CancelToken::new()));
                let seconds = t0.elapsed().as_secs_f64();
                secs.push(seconds);
                let mut run = StabilityRun {
                    method: *method,
                    style,
                    seed,
                    seconds,
                    paths: 0,
                    psnr: None,
                    failures: Vec::new(),
                    file: None,
                    error: None,
                };
                let out = match r {
                    Ok(o) => o,
                    Err(e) => {
                        eprintln!("{method:?} {style} seed {seed}: error: {e}");
                        cell.errors += 1;
                        cell.failed += 1;
                        if a.save.is_some() {
                            run.failures.push("error");
                            run.error = Some(e.to_string());
                            runs.push(run);
                        }
                        continue;
                    }
                };
                if let Some(t) = &out.report.teacher {
                    t.clone_into(&mut teacher);
                }
                let img = crate::raster::render(&out.scene);
                let nan = out.svg.contains("NaN") || img.data.iter().any(|v| !v.is_finite());
                let collapsed = out.paths == 0 || spread(&img) < COLLAPSED_SPREAD;
                let over = chroma(&img) > OVERSATURATED_CHROMA;
                let diverged = out.report.sds.as_ref().is_some_and(|sds| {
                    let s = &sds.stats;
                    s.lr_halvings > 0
                        || !s.last_loss.is_finite()
                        || u64::from(s.skipped_nonfinite) > (a.steps / 4) as u64
                });
                cell.nan += nan as u64;
                cell.collapsed += collapsed as u64;
                cell.oversaturated += over as u64;
                cell.diverged += diverged as u64;
                cell.failed += (nan || collapsed || over || diverged) as u64;
                paths.push(out.paths as f64);
                let best = targets
                    .iter()
                    .filter(|t| t.width == img.width && t.height == img.height)
                    .map(|t| psnr(&img, t).min(PSNR_CAP))
                    .max_by(f64::total_cmp);
                psnrs.extend(best);
                if let Some(dir) = &a.save {
                    let stem = format!("{}-{style}-s{seed}", method.as_str());
                    let io = |e: std::io::Error| CliError::Other(e.into());
                    std::fs::write(dir.join(format!("{stem}.svg")), &out.svg).map_err(io)?;
                    img.save_png(&dir.join(format!("{stem}.png")))
                        .map_err(|e| CliError::Other(e.into()))?;
                    for (hit, kind) in [
                        (nan, "nan"),
                        (collapsed, "collapsed"),
                        (over, "oversaturated"),
                        (diverged, "diverged"),
                    ] {
                        if hit {
                            run.failures.push(kind);
                        }
                    }
                    run.paths = out.paths;
                    run.psnr = best;
                    run.file = Some(stem);
                    runs.push(run);
                }
            }
            cell.failure_rate = cell.failed as f64 / a.seeds as f64;
            cell.psnr_min = psnrs.iter().copied().min_by(f64::total_cmp);
            cell.psnr_max = psnrs.iter().copied().max_by(f64::total_cmp);
            cell.psnr_median = median(psnrs);
            cell.seconds_median = median(secs).unwrap_or(f64::NAN);
            cell.paths_needed_median = median(paths).unwrap_or(0.0);
            if !a.json {
                println!(
                    "{:<12} {:<12} fail {}/{} (err {} nan {} collapsed {} oversat {} diverged {})  psnr {} / {} / {}  {:.2}s  paths {}",
                    format!("{method:?}"),
                    style.to_string(),
                    cell.failed,
                    cell.runs,
                    cell.errors,
                    cell.nan,
                    cell.collapsed,
                    cell.oversaturated,
                    cell.diverged,
                    fmt_opt(cell.psnr_min),
                    fmt_opt(cell.psnr_median),
                    fmt_opt(cell.psnr_max),
                    cell.seconds_median,
                    cell.paths_needed_median
                );
            }
            cells.push(cell);
        }
    }
    let report = StabilityReport {
        teacher,
        preset,
        seeds: a.seeds,
        steps: a.steps,
        size: a.size,
        cells,
        runs,
    };
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&report).map_err(|e| CliError::Other(e.into()))?
        );
    }
    Ok(())
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or_else(|| "-".into(), |x| format!("{x:.1}"))
}
