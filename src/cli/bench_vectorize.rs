//! `vectorfusion bench vectorize --images DIR --paths 16,32,64 [--json]`: LIVE against vtracer
//! (its defaults, polygon mode, and a setting tuned per image to land near each path count) on
//! every PNG in DIR. Every SVG is rendered back with resvg at the input size and compared with
//! the input on RGB over white.
//!
//! With `--rd`, a rate–distortion run over image sets against several peers instead
//! ([`super::bench_rd`]).

use super::vectorize::load_input;
use super::{CliError, ResultExt};
use crate::image::{Image, psnr};
use crate::pipeline::Preset;
use crate::progress::{CancelToken, NullSink};
use crate::stages::live::tracer::{TracerSetting, render_svg, trace};
use crate::stages::live::{self, InitMode, LiveConfig, PathBudget};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(clap::Args, Debug, Clone)]
pub struct BenchVectorizeArgs {
    /// Folder of PNG images (see scripts/prepare_fidelity_set.sh).
    #[arg(long)]
    pub images: PathBuf,
    /// Path budgets for LIVE and the tuned vtracer setting.
    #[arg(long, default_value = "16,32,64")]
    pub paths: String,
    /// LIVE settings of this preset (draft, fast, balanced, paper or cpu; `quality` is paper).
    #[arg(long, value_enum, default_value = "balanced")]
    pub preset: Preset,
    /// Also run `--paths auto`.
    #[arg(long)]
    pub auto: bool,
    /// `--rd`: LIVE's fill paints to run at each budget (comma-separated: flat, linear,
    /// radial); a gradient run's setting is named `paths N linear`.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "flat")]
    pub fills: Vec<crate::vector::fill::FillKind>,
    /// Also run LIVE started from vtracer's trace at each budget.
    #[arg(long)]
    pub vtracer_init: bool,
    /// Skip LIVE (vtracer rows only).
    #[arg(long)]
    pub no_live: bool,
    /// Only the first N images (name order).
    #[arg(long)]
    pub limit: Option<usize>,
    /// Decimal places in our SVGs (0 = whole pixels, enough at 256 px and the smallest files).
    #[arg(long, default_value_t = 0)]
    pub precision: u8,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Print one JSON object instead of a table; `--json FILE` writes it to FILE (with `--rd`,
    /// the table is still printed).
    #[arg(long, num_args = 0..=1, value_name = "FILE")]
    pub json: Option<Option<PathBuf>>,
    #[command(flatten)]
    pub rd: super::bench_rd::RdArgs,
}

/// One method on one image.
#[derive(Clone, Debug, Serialize)]
pub struct Sample {
    pub image: String,
    pub method: String,
    /// Requested budget (0 for untuned vtracer settings).
    pub budget: usize,
    /// Paths actually in the SVG.
    pub paths: usize,
    pub psnr: f64,
    pub seconds: f64,
    pub svg_bytes: usize,
}

/// Mean over images of one method and budget.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub method: String,
    /// Mean path count actually produced.
    pub paths: f64,
    pub budget: usize,
    pub psnr_mean: f64,
    pub seconds_mean: f64,
    pub svg_bytes_mean: f64,
}

/// Times `run` (an SVG and its path count) and scores its SVG against `target`.
fn measure<E: Into<anyhow::Error>>(
    name: &str,
    method: &str,
    budget: usize,
    target: &Image,
    run: impl FnOnce() -> Result<(String, usize), E>,
) -> Result<Sample, CliError> {
    let t0 = Instant::now();
    let (svg, paths) = run().failed(|| name.to_string())?;
    let seconds = t0.elapsed().as_secs_f64();
    let back =
        render_svg(&svg, target.width, target.height).failed(|| format!("{name}: {method}"))?;
    Ok(Sample {
        image: name.to_string(),
        method: method.to_string(),
        budget,
        paths,
        psnr: psnr(target, &back),
        seconds,
        svg_bytes: svg.len(),
    })
}

/// The vtracer settings searched for the tuned baseline.
fn tuning_grid() -> Vec<TracerSetting> {
    let mut out = Vec::new();
    for polygon in [true, false] {
        for color_precision in [6, 5, 4] {
            for filter_speckle in [4, 6, 8, 10, 12, 16, 20, 24, 32] {
                out.push(TracerSetting {
                    polygon,
                    filter_speckle,
                    color_precision,
                    layer_difference: 16,
                });
            }
        }
    }
    out
}

pub fn run(a: BenchVectorizeArgs) -> Result<(), CliError> {
    if a.rd.rd {
        return super::bench_rd::run(&a);
    }
    let budgets = parse_budgets(&a.paths)?;
    let files = list_images(&a)?;
    let mut samples = Vec::new();
    for file in &files {
        let name = image_name(file);
        let target = load_input(file)?;
        samples.extend(vtracer_samples(&name, &target, &budgets)?);
        if !a.no_live {
            samples.extend(live_samples(&a, &name, &target, &budgets)?);
        }
    }
    let rows = summarise(&samples);
    match &a.json {
        Some(out) => write_json(out.as_deref(), files.len(), &rows, &samples),
        None => {
            print_rows(files.len(), &rows);
            Ok(())
        }
    }
}

/// `--paths`: a list of independent budgets, each at most the per-run path limit.
pub(super) fn parse_budgets(paths: &str) -> Result<Vec<usize>, CliError> {
    let budgets = live::schedule::parse_schedule(paths, usize::MAX)
        .map_err(|e| CliError::Usage(format!("--paths: {e}")))?;
    if let Some(b) = budgets.iter().find(|&&b| b > live::MAX_PATHS) {
        return Err(CliError::Usage(format!(
            "--paths: budget {b} exceeds the limit of {} paths",
            live::MAX_PATHS
        )));
    }
    Ok(budgets)
}

/// An image's name in the reports: its file stem.
pub(super) fn image_name(file: &Path) -> String {
    file.file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("?")
        .to_string()
}

/// LIVE's settings of `--preset` and `--seed`, without snapshots.
pub(super) fn live_base(a: &BenchVectorizeArgs) -> LiveConfig {
    LiveConfig {
        seed: a.seed,
        snapshot_every: 0,
        ..a.preset.live_config()
    }
}

/// `base` with the path budget `budget`.
pub(super) fn with_budget(base: &LiveConfig, budget: PathBudget) -> LiveConfig {
    LiveConfig {
        budget,
        ..base.clone()
    }
}

/// The PNGs of `--images` in name order (the first `--limit`); none is a usage error.
fn list_images(a: &BenchVectorizeArgs) -> Result<Vec<PathBuf>, CliError> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(&a.images)
        .bad_input(|| format!("cannot read {}", a.images.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("png")))
        .collect();
    files.sort();
    if let Some(n) = a.limit {
        files.truncate(n);
    }
    if files.is_empty() {
        return Err(CliError::Usage(format!(
            "no PNG files in {} (run scripts/prepare_fidelity_set.sh)",
            a.images.display()
        )));
    }
    Ok(files)
}

/// vtracer's defaults, its polygon mode, and the grid setting tuned per budget.
fn vtracer_samples(name: &str, target: &Image, budgets: &[usize]) -> Result<Vec<Sample>, CliError> {
    let vt = |s: TracerSetting| {
        move || {
            trace(target, &s)
                .map(|t| (t.path_count(), t.svg))
                .map(|(n, s)| (s, n))
                .map_err(anyhow::Error::msg)
        }
    };
    let polygon = TracerSetting {
        polygon: true,
        ..TracerSetting::default()
    };
    let mut out = vec![
        measure(
            name,
            "vtracer-default",
            0,
            target,
            vt(TracerSetting::default()),
        )?,
        measure(name, "vtracer-polygon", 0, target, vt(polygon))?,
    ];
    // Tuned: per image and budget, the grid setting with the best PSNR among those with at
    // most `budget` paths (or the fewest paths if none fits). Seconds are for that single
    // trace, not the search.
    let grid: Vec<Sample> = tuning_grid()
        .into_iter()
        .map(|s| measure(name, &s.label(), 0, target, vt(s)))
        .collect::<Result<_, _>>()?;
    for &b in budgets {
        let best = grid
            .iter()
            .filter(|s| s.paths <= b)
            .max_by(|x, y| x.psnr.total_cmp(&y.psnr))
            .or_else(|| grid.iter().min_by_key(|s| s.paths));
        if let Some(best) = best {
            out.push(Sample {
                method: "vtracer-tuned".into(),
                budget: b,
                ..best.clone()
            });
        }
    }
    Ok(out)
}

/// LIVE at each budget (and from vtracer's trace with `--vtracer-init`, `auto` with `--auto`).
fn live_samples(
    a: &BenchVectorizeArgs,
    name: &str,
    target: &Image,
    budgets: &[usize],
) -> Result<Vec<Sample>, CliError> {
    let base = live_base(a);
    let mut runs: Vec<(&str, usize, LiveConfig)> = Vec::new();
    for &b in budgets {
        let fixed = with_budget(&base, PathBudget::fixed(b));
        runs.push(("live", b, fixed.clone()));
        if a.vtracer_init {
            let init = LiveConfig {
                init: InitMode::Vtracer,
                ..fixed
            };
            runs.push(("live-vtracer-init", b, init));
        }
    }
    if a.auto {
        runs.push(("live-auto", 0, with_budget(&base, PathBudget::auto())));
    }
    let svg_opts = crate::svg::SvgOptions {
        precision: a.precision,
        ..Default::default()
    };
    let mut out = Vec::new();
    for (method, b, cfg) in runs {
        let s = measure(name, method, b, target, || {
            live::vectorize(target, &cfg, &NullSink, &CancelToken::new())
                .map(|r| (crate::svg::to_svg(&r.scene, &svg_opts), r.paths))
        })?;
        if a.json.is_none() {
            eprintln!(
                "{name:50} {method:18} budget {b:3} paths {:3} psnr {:6.2} bytes {:6} {:.2} s",
                s.paths, s.psnr, s.svg_bytes, s.seconds
            );
        }
        out.push(s);
    }
    Ok(out)
}

/// The JSON report, on stdout or written to `path`.
fn write_json(
    path: Option<&Path>,
    images: usize,
    rows: &[Row],
    samples: &[Sample],
) -> Result<(), CliError> {
    let out = serde_json::json!({
        "images": images,
        "rows": rows.iter().map(|r| serde_json::json!({
            "method": r.method,
            "paths": if r.budget > 0 { r.budget } else { r.paths.round() as usize },
            "paths_mean": r.paths,
            "psnr_mean": r.psnr_mean,
            "seconds_mean": r.seconds_mean,
            "svg_bytes_mean": r.svg_bytes_mean,
        })).collect::<Vec<_>>(),
        "per_image": samples,
    });
    match path {
        Some(path) => std::fs::write(path, format!("{out}\n"))
            .failed(|| format!("cannot write {}", path.display())),
        None => {
            println!("{out}");
            Ok(())
        }
    }
}

/// The text table: one row per method and budget.
fn print_rows(images: usize, rows: &[Row]) {
    println!("{images} images");
    println!(
        "{:20} {:>6} {:>10} {:>9} {:>10} {:>12}",
        "method", "budget", "paths_mean", "psnr_dB", "seconds", "svg_bytes"
    );
    for r in rows {
        println!(
            "{:20} {:>6} {:>10.1} {:>9.2} {:>10.3} {:>12.0}",
            r.method, r.budget, r.paths, r.psnr_mean, r.seconds_mean, r.svg_bytes_mean
        );
    }
}

/// Groups samples by (method, budget) in first-seen order and averages them.
pub fn summarise(samples: &[Sample]) -> Vec<Row> {
    let mut keys: Vec<(String, usize)> = Vec::new();
    for s in samples {
        let k = (s.method.clone(), s.budget);
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    keys.into_iter()
        .map(|(method, budget)| {
            let g: Vec<&Sample> = samples
                .iter()
                .filter(|s| s.method == method && s.budget == budget)
                .collect();
            let n = g.len().max(1) as f64;
            let mean = |f: &dyn Fn(&Sample) -> f64| g.iter().map(|s| f(s)).sum::<f64>() / n;
            Row {
                paths: mean(&|s| s.paths as f64),
                psnr_mean: mean(&|s| s.psnr.min(100.0)),
                seconds_mean: mean(&|s| s.seconds),
                svg_bytes_mean: mean(&|s| s.svg_bytes as f64),
                method,
                budget,
            }
        })
        .collect()
}
