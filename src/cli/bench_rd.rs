//! `vectorfusion bench vectorize --rd --images DIR`: rate–distortion of our LIVE tracing against
//! peer vectorisers, side by side in one run.
//!
//! `DIR` holds one sub-folder of PNGs per image set (`scripts/prepare_rd_set.sh DIR`: `emoji`,
//! `flat`, `mono`, `photo`; folders starting with `_` or `.` are skipped; PNGs directly in `DIR`
//! form one set named after it). On every image it runs:
//!
//! - **live**: `live::vectorize` at each `--paths` budget (and `auto` with `--auto`), written by
//!   [`crate::vector::write_svg`] as every run writes it (`--precision` is not used here);
//! - **vtracer** (the crate we link): spline/polygon × `--vt-speckle` × `--vt-precision`, on
//!   the RGBA image and (label suffix `white`) the image over white (`--vt-input`);
//! - **imagetracer** (npm `imagetracerjs`, through `node scripts/rd/imagetracer.js`): default
//!   options and a coarse preset (`ltres`/`qtres` 2, `pathomit` 16, whole-pixel coordinates) ×
//!   `--it-colors`, on the image over white;
//! - **potrace** (the Debian binary, black and white only) on the sets named by `--bw-sets`: the
//!   image over white thresholded at luma 0.5, piped in as PBM; `-t` 2/8 × corners only
//!   (`-a 0`) or curves (`-a 1`, `-O` 0.2/1).
//!
//! A peer that cannot run here prints a `SKIP` line and the run goes on without it.
//!
//! Each SVG is rendered back with resvg at the input size; PSNR and SSIM
//! ([`crate::image::ssim::ssim_over_white`]) are on RGB over white. Bytes are the SVG text as
//! the tool wrote it, raw and gzip-compressed (flate2, level 6 as `gzip` does). `paths` counts
//! `<path` elements (a vtracer, imagetracer or potrace path may hold many sub-paths and holes).
//! Seconds: the tracing only (imagetracer's are measured inside node, without its start-up;
//! potrace's are the wall time of the process).
//!
//! The R–D summary: per image set, tool and basis (raw or gzip KB, 1 KB = 1000 bytes), each
//! setting is one point (mean KB, mean PSNR over the set's images); a tool's *envelope* is its
//! upper Pareto frontier (the points no other point of the tool beats at fewer or equal bytes),
//! read between points by linear interpolation, flat after its largest point and undefined below
//! its smallest. "live − peer" at each `--kb` is the difference of the two envelopes there.

mod peers;
mod sets;
mod summary;
mod trace;

pub use peers::PeerError;
pub use summary::{Delta, Envelope, RdMean, RdSummary, envelope, envelope_at, means};

use super::bench_vectorize::{
    BenchVectorizeArgs, image_name, live_base, parse_budgets, with_budget,
};
use super::vectorize::load_input;
use super::{CliError, ResultExt};
use crate::retrieval::install::comma_list;
use crate::stages::live::{InitMode, LiveConfig, PathBudget};
use peers::{ImageTracer, probe_potrace};
use serde::Serialize;
use sets::{select_sets, spread};
use std::path::{Path, PathBuf};
use summary::{print_tables, summarise};
use trace::Target;

/// The peer tools `--peers` accepts.
const PEERS: [&str; 3] = ["vtracer", "imagetracer", "potrace"];

/// Flags of the rate–distortion mode (flattened into `bench vectorize`).
#[derive(clap::Args, Debug, Clone)]
pub struct RdArgs {
    /// Rate–distortion run: our budgets and each peer's settings on every image set of --images.
    #[arg(long)]
    pub rd: bool,
    /// Only these image sets (sub-folder names), comma-separated.
    #[arg(long)]
    pub sets: Option<String>,
    /// Peers to run (vtracer, imagetracer, potrace; `none` for ours only).
    #[arg(long, default_value = "vtracer,imagetracer,potrace")]
    pub peers: String,
    /// vtracer filter_speckle values of the grid.
    #[arg(long, default_value = "2,4,8,16,32")]
    pub vt_speckle: String,
    /// vtracer colour precisions (bits per channel, 1-8) of the grid.
    #[arg(long, default_value = "4,5,6,7")]
    pub vt_precision: String,
    /// What vtracer is given: the RGBA image (transparent pixels keyed out, as the crate does
    /// for its users), the image over white, or both as separate settings.
    #[arg(long, value_enum, default_value = "both")]
    pub vt_input: VtInput,
    /// imagetracerjs numberofcolors values of the grid.
    #[arg(long, default_value = "4,8,16,32")]
    pub it_colors: String,
    /// Folder whose node_modules holds imagetracerjs and pngjs (default: IMAGES/_tools).
    #[arg(long)]
    pub tools: Option<PathBuf>,
    /// The imagetracerjs driver script.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/rd/imagetracer.js"))]
    pub imagetracer_script: PathBuf,
    /// The node binary.
    #[arg(long, default_value = "node")]
    pub node: String,
    /// The potrace binary.
    #[arg(long, default_value = "potrace")]
    pub potrace: String,
    /// Image sets on which the black-and-white peer (potrace) runs.
    #[arg(long, default_value = "mono")]
    pub bw_sets: String,
    /// Print every setting's means, not only live's and the peers' envelope points.
    #[arg(long)]
    pub all_rows: bool,
    /// Also run ours under each of these byte budgets (`--max-bytes`, comma-separated), from
    /// the largest `--paths` budget; with `--vtracer-init` also started from vtracer's trace.
    #[arg(long)]
    pub max_bytes: Option<String>,
    /// Sizes (KB, raw or gzip) at which the summary compares envelopes.
    #[arg(long, default_value = "2,4,8,12,16")]
    pub kb: String,
}

/// `--vt-input`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum VtInput {
    Rgba,
    White,
    Both,
}

/// Editability counts of one SVG (`crate::vector::check`'s `Editability`).
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct EditCounts {
    pub paths: usize,
    pub self_intersecting: usize,
    pub hidden: usize,
    pub slivers: usize,
    pub colors: usize,
}

/// ADAPTER to the shared checker, [`crate::vector::check::check_svg`] (`None` when it cannot
/// read the SVG). No checking of our own here.
fn editability(svg: &str) -> Option<EditCounts> {
    crate::vector::check::check_svg(svg)
        .ok()
        .map(|e| EditCounts {
            paths: e.paths,
            self_intersecting: e.self_intersecting,
            hidden: e.hidden,
            slivers: e.slivers,
            colors: e.colors,
        })
}

/// One tool at one setting on one image.
#[derive(Clone, Debug, Serialize)]
pub struct RdSample {
    pub set: String,
    pub image: String,
    pub tool: String,
    pub setting: String,
    pub paths: usize,
    pub psnr: f64,
    pub ssim: f64,
    pub svg_bytes: usize,
    pub svg_gz_bytes: usize,
    pub seconds: f64,
    /// `None` (null) when the checker cannot read the SVG.
    pub editability: Option<EditCounts>,
}

/// Comma-separated numbers, each checked by `ok`.
fn parse_list<T: std::str::FromStr>(
    flag: &str,
    text: &str,
    ok: impl Fn(&T) -> bool,
    what: &str,
) -> Result<Vec<T>, CliError> {
    let mut out = Vec::new();
    for part in comma_list(text) {
        match part.parse::<T>() {
            Ok(v) if ok(&v) => out.push(v),
            _ => {
                return Err(CliError::Usage(format!(
                    "{flag}: {part:?} is not {what} (a comma-separated list is expected)"
                )));
            }
        }
    }
    if out.is_empty() {
        return Err(CliError::Usage(format!("{flag}: the list is empty")));
    }
    Ok(out)
}

/// Our small-budget runs besides the plain `--paths` ones: each path budget started from
/// vtracer's trace (`--vtracer-init`), and each `--max-bytes` budget from the largest path
/// budget (from both starts with `--vtracer-init`).
fn small_runs(
    a: &BenchVectorizeArgs,
    base: &LiveConfig,
    budgets: &[usize],
    byte_budgets: &[usize],
) -> Vec<(String, LiveConfig)> {
    let mut inits = vec![("", base.init)];
    if a.vtracer_init && base.init != InitMode::Vtracer {
        inits.push(("vtracer-init ", InitMode::Vtracer));
    }
    let mut out = Vec::new();
    for &(prefix, init) in &inits {
        let start = LiveConfig {
            init,
            ..base.clone()
        };
        if !prefix.is_empty() {
            for &b in budgets {
                let cfg = with_budget(&start, PathBudget::fixed(b));
                out.push((format!("{prefix}paths {b}"), cfg));
            }
        }
        let most = budgets.iter().copied().max().unwrap_or(24);
        for &m in byte_budgets {
            let cfg = LiveConfig {
                max_bytes: Some(m),
                ..with_budget(&start, PathBudget::fixed(most))
            };
            out.push((format!("{prefix}bytes {m}"), cfg));
        }
    }
    out
}

/// Entry point of `bench vectorize --rd`.
pub fn run(a: &BenchVectorizeArgs) -> Result<(), CliError> {
    let budgets = parse_budgets(&a.paths)?;
    let grid = Grid::parse(&a.rd)?;
    if a.limit == Some(0) {
        return Err(CliError::Usage("--limit: must be at least 1".into()));
    }
    let sets = select_sets(a)?;
    let byte_budgets = match &a.rd.max_bytes {
        Some(text) => parse_list(
            "--max-bytes",
            text,
            |&v| crate::vector::check_max_bytes(v).is_ok(),
            "a byte budget the vector stage accepts",
        )?,
        None => Vec::new(),
    };
    let tools = Tools::probe(a, &grid, &sets, &budgets, &byte_budgets);
    let mut samples: Vec<RdSample> = Vec::new();
    let mut set_sizes: Vec<(String, usize)> = Vec::new();
    for (set, files) in sets {
        let files = spread(files, a.limit);
        set_sizes.push((set.clone(), files.len()));
        for file in &files {
            samples.extend(tools.trace_image(&grid, &set, file)?);
        }
    }
    if let Some(t) = &tools.imagetracer {
        t.remove_scratch();
    }
    let means = means(&samples);
    let summaries = summarise(&means, &set_sizes, &grid.kbs);
    let tables = || {
        print_tables(
            &set_sizes,
            &means,
            &summaries,
            &tools.skipped,
            a.rd.all_rows,
        )
    };
    let json_out = serde_json::json!({
        "images": set_sizes.iter().map(|(_, n)| n).sum::<usize>(),
        "sets": set_sizes.iter().map(|(s, n)| serde_json::json!({"set": s, "images": n})).collect::<Vec<_>>(),
        "preset": format!("{:?}", a.preset).to_lowercase(),
        "precision": "auto (vector::write_svg)",
        "seed": a.seed,
        "skipped": tools.skipped.iter().map(|(t, w)| serde_json::json!({"tool": t, "why": w})).collect::<Vec<_>>(),
        "editability_checker": editability("<svg xmlns=\"http://www.w3.org/2000/svg\"/>").is_some(),
        "means": means,
        "rd": summaries,
        "samples": samples,
    });
    match &a.json {
        Some(Some(path)) => {
            let text =
                serde_json::to_string_pretty(&json_out).failed(|| "cannot encode JSON".into())?;
            std::fs::write(path, text + "\n")
                .failed(|| format!("cannot write {}", path.display()))?;
            tables();
            eprintln!("wrote {}", path.display());
        }
        Some(None) => println!("{json_out}"),
        None => tables(),
    }
    Ok(())
}

/// The peers' settings grid and the summary's sizes, parsed from the flags.
struct Grid {
    speckles: Vec<usize>,
    precisions: Vec<i32>,
    it_colors: Vec<usize>,
    kbs: Vec<f64>,
    /// The peers asked for (checked names; empty for `none`).
    peers: Vec<String>,
    bw_sets: Vec<String>,
    vt_input: VtInput,
    potrace: String,
}

impl Grid {
    fn parse(r: &RdArgs) -> Result<Self, CliError> {
        let mut peers = comma_list(&r.peers);
        if peers == ["none"] {
            peers.clear();
        }
        if let Some(p) = peers.iter().find(|p| !PEERS.contains(&p.as_str())) {
            return Err(CliError::Usage(format!(
                "--peers: unknown peer {p:?} (known: {}, or none)",
                PEERS.join(", ")
            )));
        }
        Ok(Grid {
            speckles: parse_list("--vt-speckle", &r.vt_speckle, |&v| v <= 256, "0..=256")?,
            precisions: parse_list(
                "--vt-precision",
                &r.vt_precision,
                |v| (1..=8).contains(v),
                "a colour precision in 1..=8",
            )?,
            it_colors: parse_list(
                "--it-colors",
                &r.it_colors,
                |v| (2..=256).contains(v),
                "a colour count in 2..=256",
            )?,
            kbs: parse_list(
                "--kb",
                &r.kb,
                |v: &f64| v.is_finite() && *v > 0.0,
                "a positive size in KB",
            )?,
            peers,
            bw_sets: comma_list(&r.bw_sets),
            vt_input: r.vt_input,
            potrace: r.potrace.clone(),
        })
    }

    fn wants(&self, peer: &str) -> bool {
        self.peers.iter().any(|p| p == peer)
    }
}

/// The tools that run here: the peers that were asked for and answer, and our LIVE runs.
struct Tools {
    vtracer: bool,
    imagetracer: Option<ImageTracer>,
    potrace: bool,
    /// Peers asked for that cannot run here: `(tool, why)`.
    skipped: Vec<(String, String)>,
    live_runs: Vec<(String, LiveConfig)>,
}

impl Tools {
    /// Probes the peers of `grid` (a peer that cannot run is skipped, loudly) and lists the
    /// LIVE runs (each budget, `auto` with `--auto`; none with `--no-live`).
    fn probe(
        a: &BenchVectorizeArgs,
        grid: &Grid,
        sets: &[(String, Vec<PathBuf>)],
        budgets: &[usize],
        byte_budgets: &[usize],
    ) -> Self {
        let mut skipped: Vec<(String, String)> = Vec::new();
        let imagetracer = grid
            .wants("imagetracer")
            .then(|| ImageTracer::probe(&a.rd, &a.images))
            .and_then(|probe| {
                probe
                    .map_err(|why| skipped.push(("imagetracer".into(), why.to_string())))
                    .ok()
            });
        let potrace = grid.wants("potrace")
            && probe_potrace(&grid.potrace)
                .map_err(|why| skipped.push(("potrace".into(), why.to_string())))
                .is_ok();
        if potrace && !sets.iter().any(|(n, _)| grid.bw_sets.contains(n)) {
            let why = format!(
                "no image set named in --bw-sets ({})",
                grid.bw_sets.join(",")
            );
            skipped.push(("potrace".into(), why));
        }
        for (tool, why) in &skipped {
            eprintln!("SKIP {tool}: {why}");
        }
        let base = live_base(a);
        let mut live_runs: Vec<(String, LiveConfig)> = Vec::new();
        for &fill in &a.fills {
            let base = LiveConfig {
                fill,
                ..base.clone()
            };
            let suffix = if fill.is_flat() { "" } else { fill.name() };
            for &b in budgets {
                let label = format!("paths {b} {suffix}").trim_end().to_string();
                live_runs.push((label, with_budget(&base, PathBudget::fixed(b))));
            }
        }
        live_runs.extend(small_runs(a, &base, budgets, byte_budgets));
        if a.auto {
            live_runs.push(("auto".into(), with_budget(&base, PathBudget::auto())));
        }
        if a.no_live {
            live_runs.clear();
        }
        Tools {
            vtracer: grid.wants("vtracer"),
            imagetracer,
            potrace,
            skipped,
            live_runs,
        }
    }

    /// Every tool's samples on one image of `set`: the peers' grids, then our budgets.
    fn trace_image(&self, grid: &Grid, set: &str, file: &Path) -> Result<Vec<RdSample>, CliError> {
        let target = load_input(file)?;
        let t = Target {
            set,
            image: image_name(file),
            target: &target,
        };
        let mut samples = Vec::new();
        if self.vtracer {
            samples.extend(t.vtracer(grid)?);
        }
        if let Some(tracer) = &self.imagetracer {
            samples.extend(t.imagetracer(tracer, file, &grid.it_colors)?);
        }
        if self.potrace && grid.bw_sets.iter().any(|s| s == set) {
            samples.extend(t.potrace(&grid.potrace)?);
        }
        if !samples.is_empty() {
            let best = samples
                .iter()
                .map(|s| s.psnr.min(100.0))
                .fold(f64::NEG_INFINITY, f64::max);
            eprintln!(
                "{set}/{}: {} peer settings, best PSNR {best:.2} dB",
                t.image,
                samples.len()
            );
        }
        for (label, cfg) in &self.live_runs {
            samples.push(t.live(label, cfg)?);
        }
        Ok(samples)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::bench::BenchCommand as BenchCommandAlias;

    #[test]
    fn small_runs_start_from_both_inits_and_trim_to_each_byte_budget() {
        use clap::Parser;
        let argv = [
            "vectorfusion",
            "bench",
            "vectorize",
            "--rd",
            "--images",
            "x",
            "--vtracer-init",
        ];
        let cmd = crate::cli::Cli::parse_from(argv).command;
        let crate::cli::Command::Bench(BenchCommandAlias::Vectorize(a)) = cmd else {
            panic!("not bench vectorize");
        };
        let base = live_base(&a);
        let runs = small_runs(&a, &base, &[8, 16], &[2048]);
        let labels: Vec<&str> = runs.iter().map(|(l, _)| l.as_str()).collect();
        let want = [
            "bytes 2048",
            "vtracer-init paths 8",
            "vtracer-init paths 16",
            "vtracer-init bytes 2048",
        ];
        assert_eq!(labels, want);
        let (_, last) = &runs[3];
        assert_eq!(last.init, InitMode::Vtracer);
        assert_eq!((last.max_bytes, last.budget.max_paths()), (Some(2048), 16));
        assert_eq!(runs[0].1.init, base.init);
        assert!(small_runs(&a, &base, &[8], &[]).len() == 1);
    }

    #[test]
    fn lists_are_checked() {
        assert_eq!(
            parse_list::<usize>("--x", "2, 4,8", |_| true, "n").ok(),
            Some(vec![2, 4, 8])
        );
        assert!(matches!(
            parse_list::<usize>("--x", "2,a", |_| true, "n"),
            Err(CliError::Usage(_))
        ));
        assert!(matches!(
            parse_list::<i32>("--x", "9", |v| (1..=8).contains(v), "n"),
            Err(CliError::Usage(_))
        ));
        assert!(matches!(
            parse_list::<usize>("--x", "", |_| true, "n"),
            Err(CliError::Usage(_))
        ));
    }
}
