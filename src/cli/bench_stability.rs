//! `vectorfusion bench stability`: where the methods fail. Runs seeds × method × style through
//! the executor every entry point shares ([`crate::pipeline::DefaultExecutor`]) with the analytic TEST teacher (built-in
//! targets, or `--teacher analytic:DIR`) or real weights (`--model DIR`), and reports per
//! method × style: failure rate (error/NaN, empty or collapsed SVG, oversaturation, diverged
//! loss), final quality spread (PSNR of the render against the nearest teacher target, analytic
//! teacher only) and seconds per run.

use super::request_args::{BudgetArgs, ModelArgs, cli_limits, parse_word};
use super::{CliError, ResultExt};
use crate::image::{Image, psnr};
use crate::pipeline::{
    DefaultExecutor, Executor, JobContext, Method, ModelDirs, PlanRequest, Preset, RunInput,
    RunOutput, Tuning,
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
    /// the budget and `--size` (draft runs 30 SDS steps unless `--steps` says otherwise).
    #[arg(long, default_value = "draft", value_parser = parse_word::<Preset>)]
    pub preset: Preset,
    #[command(flatten)]
    pub budget: BudgetArgs,
    /// Teacher input size (px) [default: the preset's].
    #[arg(long)]
    pub size: Option<u32>,
    /// The teacher (default: the analytic teacher over built-in synthetic targets).
    #[command(flatten)]
    pub model: ModelArgs,
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

/// The benchmark's settings, the preset's filled in and checked.
struct Resolved {
    preset: Preset,
    seeds: u64,
    steps: u32,
    size: u32,
    samples: u32,
    paths: u32,
    model: ModelArgs,
    scorer: Option<PathBuf>,
    json: bool,
    save: Option<PathBuf>,
}

/// The caption of every run (the analytic teacher ignores it).
const CAPTION: &str = "an icon";

impl Resolved {
    /// `args` with the preset's budget where a flag is omitted; zero counts and sizes outside
    /// 8..=512 are usage errors.
    fn new(args: BenchStabilityArgs) -> Result<Self, CliError> {
        let preset = args.preset;
        // Small priors (the embedded model) have their own presets.
        let small = args
            .model
            .model
            .as_deref()
            .is_some_and(crate::pipeline::is_small_model);
        let ps = preset.settings_for(small);
        let draft_steps = if preset == Preset::Draft {
            30
        } else {
            ps.steps
        };
        let a = Resolved {
            preset,
            seeds: args.seeds,
            steps: args.budget.steps.unwrap_or(draft_steps),
            size: args.size.unwrap_or(ps.size),
            samples: args.budget.samples.unwrap_or(ps.samples),
            paths: args.budget.paths.unwrap_or(ps.paths as u32),
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
        Ok(a)
    }

    /// The request of one run (no retrieval: every sample starts from noise).
    fn request(&self, method: Method, style: Style, seed: u64) -> PlanRequest {
        PlanRequest {
            style,
            method,
            preset: self.preset,
            paths: Some(self.paths),
            steps: Some(self.steps),
            samples: Some(self.samples),
            seed,
            retrieval: false,
            tuning: Tuning {
                size: Some(self.size),
                ..Tuning::default()
            },
            ..PlanRequest::text(CAPTION)
        }
    }
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
        std::fs::create_dir_all(&dir).failed(|| dir.display().to_string())?;
        Ok(TempDir(dir))
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

pub fn run(args: BenchStabilityArgs) -> Result<(), CliError> {
    let a = Resolved::new(args)?;
    let teacher = Teacher::new(&a)?;
    let exec = DefaultExecutor::with_downloads(ModelDirs {
        analytic_dir: teacher.analytic_dir.clone(),
        ..a.model.model_dirs(a.scorer.clone())
    });
    if let Some(dir) = &a.save {
        std::fs::create_dir_all(dir).bad_input(|| format!("--save {}", dir.display()))?;
    }
    let mut report = StabilityReport {
        teacher: String::new(),
        preset: a.preset,
        seeds: a.seeds,
        steps: a.steps,
        size: a.size,
        cells: Vec::new(),
        runs: Vec::new(),
    };
    for method in Method::ALL {
        for style in Style::ALL {
            let cell = run_cell(&exec, &a, &teacher.targets, *method, style, &mut report)?;
            if !a.json {
                print_cell(&cell);
            }
            report.cells.push(cell);
        }
    }
    if a.json {
        let text = serde_json::to_string_pretty(&report).failed(|| "encoding the report".into())?;
        println!("{text}");
    }
    Ok(())
}

/// The analytic teacher's targets (none with `--model`): a `--teacher` directory's PNGs, or
/// the built-in targets written to a temporary directory the executor reads them from.
struct Teacher {
    analytic_dir: Option<PathBuf>,
    /// What a render is scored against.
    targets: Vec<Image>,
    /// Holds the built-in targets' directory until the benchmark ends.
    _builtin: Option<TempDir>,
}

impl Teacher {
    fn new(a: &Resolved) -> Result<Self, CliError> {
        if a.model.model.is_some() {
            return Ok(Teacher {
                analytic_dir: None,
                targets: Vec::new(),
                _builtin: None,
            });
        }
        if let Some(dir) = &a.model.teacher {
            let config = AnalyticTeacherConfig {
                image_size: a.size,
                pool: 1,
                num_train_timesteps: 1000,
            };
            let t = AnalyticTeacher::from_dir(dir, config)
                .bad_input(|| format!("--teacher analytic:{}", dir.display()))?;
            return Ok(Teacher {
                analytic_dir: Some(dir.clone()),
                targets: t.targets().to_vec(),
                _builtin: None,
            });
        }
        let builtin = TempDir::new("vf-stability-targets")?;
        let mut targets = Vec::new();
        for (name, t) in builtin_targets(a.size)? {
            // Scored against what the teacher reads back (8-bit PNG), not the f32 original.
            let path = builtin.0.join(format!("{name}.png"));
            let back = t.save_png(&path).and_then(|()| Image::open(&path));
            targets.push(back.failed(|| "built-in targets".into())?);
        }
        Ok(Teacher {
            analytic_dir: Some(builtin.0.clone()),
            targets,
            _builtin: Some(builtin),
        })
    }
}

/// Every seed of one method × style; the runs are added to `report` with `--save`, and the
/// teacher's name as the runs report it.
fn run_cell(
    exec: &DefaultExecutor,
    a: &Resolved,
    targets: &[Image],
    method: Method,
    style: Style,
    report: &mut StabilityReport,
) -> Result<StabilityCell, CliError> {
    let mut runs = Vec::new();
    for seed in 0..a.seeds {
        let (run, teacher) = run_seed(exec, a, targets, method, style, seed)?;
        if let Some(t) = teacher {
            report.teacher = t;
        }
        runs.push(run);
    }
    let cell = StabilityCell::of(method, style, &runs);
    if a.save.is_some() {
        report.runs.extend(runs);
    }
    Ok(cell)
}

impl StabilityCell {
    /// The counts and medians of one method × style's runs.
    fn of(method: Method, style: Style, runs: &[StabilityRun]) -> Self {
        let count = |kind: &str| runs.iter().filter(|r| r.failures.contains(&kind)).count() as u64;
        let failed = runs.iter().filter(|r| !r.failures.is_empty()).count() as u64;
        let ran: Vec<&StabilityRun> = runs.iter().filter(|r| r.error.is_none()).collect();
        let psnrs: Vec<f64> = ran.iter().filter_map(|r| r.psnr).collect();
        StabilityCell {
            method,
            style,
            runs: runs.len() as u64,
            errors: count("error"),
            nan: count("nan"),
            collapsed: count("collapsed"),
            oversaturated: count("oversaturated"),
            diverged: count("diverged"),
            failed,
            failure_rate: failed as f64 / runs.len() as f64,
            psnr_min: psnrs.iter().copied().min_by(f64::total_cmp),
            psnr_max: psnrs.iter().copied().max_by(f64::total_cmp),
            psnr_median: median(psnrs),
            seconds_median: median(runs.iter().map(|r| r.seconds).collect()).unwrap_or(f64::NAN),
            paths_needed_median: median(ran.iter().map(|r| r.paths as f64).collect())
                .unwrap_or(0.0),
        }
    }
}

/// One seed's run with its failure kinds and quality; the teacher's name when it ran. A run
/// that fails is an `error` run, not an error of the benchmark.
fn run_seed(
    exec: &DefaultExecutor,
    a: &Resolved,
    targets: &[Image],
    method: Method,
    style: Style,
    seed: u64,
) -> Result<(StabilityRun, Option<String>), CliError> {
    let plan = exec.plan(&a.request(method, style, seed), &cli_limits())?;
    let t0 = Instant::now();
    let input = RunInput {
        caption: Some(CAPTION.into()),
        ..RunInput::default()
    };
    let result = exec.run_plan(&plan, &input, &JobContext::detached(CancelToken::new()));
    let mut run = StabilityRun {
        method,
        style,
        seed,
        seconds: t0.elapsed().as_secs_f64(),
        paths: 0,
        psnr: None,
        failures: Vec::new(),
        file: None,
        error: None,
    };
    let out = match result {
        Ok(out) => out,
        Err(e) => {
            eprintln!("{method:?} {style} seed {seed}: error: {e}");
            run.failures.push("error");
            run.error = Some(e.to_string());
            return Ok((run, None));
        }
    };
    let img = crate::raster::render(&out.scene);
    run.failures = failures(&out, &img, a.steps);
    run.paths = out.paths;
    run.psnr = targets
        .iter()
        .filter(|t| t.width == img.width && t.height == img.height)
        .map(|t| psnr(&img, t).min(PSNR_CAP))
        .max_by(f64::total_cmp);
    if let Some(dir) = &a.save {
        let stem = format!("{}-{style}-s{seed}", method.as_str());
        let svg = dir.join(format!("{stem}.svg"));
        std::fs::write(&svg, &out.svg).failed(|| format!("cannot write {}", svg.display()))?;
        let png = dir.join(format!("{stem}.png"));
        img.save_png(&png)
            .failed(|| format!("cannot write {}", png.display()))?;
        run.file = Some(stem);
    }
    Ok((run, out.report.teacher))
}

/// The failure kinds of a finished run (`nan`, `collapsed`, `oversaturated`, `diverged`) from
/// its output, its render and the SDS steps it was given.
fn failures(out: &RunOutput, img: &Image, steps: u32) -> Vec<&'static str> {
    let nan = out.svg.contains("NaN") || img.data.iter().any(|v| !v.is_finite());
    let collapsed = out.paths == 0 || spread(img) < COLLAPSED_SPREAD;
    let over = chroma(img) > OVERSATURATED_CHROMA;
    let diverged = out.report.sds.as_ref().is_some_and(|sds| {
        let s = &sds.stats;
        s.lr_halvings > 0
            || !s.last_loss.is_finite()
            || u64::from(s.skipped_nonfinite) > u64::from(steps / 4)
    });
    [
        (nan, "nan"),
        (collapsed, "collapsed"),
        (over, "oversaturated"),
        (diverged, "diverged"),
    ]
    .into_iter()
    .filter_map(|(hit, kind)| hit.then_some(kind))
    .collect()
}

/// One line of the text report.
fn print_cell(cell: &StabilityCell) {
    println!(
        "{:<12} {:<12} fail {}/{} (err {} nan {} collapsed {} oversat {} diverged {})  psnr {} / {} / {}  {:.2}s  paths {}",
        format!("{:?}", cell.method),
        cell.style.to_string(),
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

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or_else(|| "-".into(), |x| format!("{x:.1}"))
}
