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

use super::CliError;
use super::bench_vectorize::BenchVectorizeArgs;
use super::vectorize::load_input;
use crate::image::ssim::ssim_over_white;
use crate::image::{Image, psnr};
use crate::progress::{CancelToken, NullSink};
use crate::stages::live::tracer::{TracerSetting, render_svg, trace};
use crate::stages::live::{self, LiveConfig, PathBudget};
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

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

/// Means of one tool and setting over one set's images.
#[derive(Clone, Debug, Serialize)]
pub struct RdMean {
    pub set: String,
    pub tool: String,
    pub setting: String,
    pub images: usize,
    pub paths: f64,
    pub psnr: f64,
    pub ssim: f64,
    pub svg_bytes: f64,
    pub svg_gz_bytes: f64,
    pub seconds: f64,
    /// Means of the editability counts over the images that have them.
    pub self_intersecting: Option<f64>,
    pub hidden: Option<f64>,
    pub slivers: Option<f64>,
    pub colors: Option<f64>,
}

/// One tool's envelope on one set and basis: `(KB, PSNR)` points, KB ascending.
#[derive(Clone, Debug, Serialize)]
pub struct Envelope {
    pub tool: String,
    pub points: Vec<(f64, f64)>,
    /// The setting of each point.
    pub settings: Vec<String>,
}

/// `live − peer` at one size.
#[derive(Clone, Debug, Serialize)]
pub struct Delta {
    pub peer: String,
    pub kb: f64,
    pub live: Option<f64>,
    pub peer_psnr: Option<f64>,
    pub delta_db: Option<f64>,
    /// `kb` lies past the largest point of either envelope (read flat there).
    pub beyond: bool,
}

/// The R–D summary of one set on one basis.
#[derive(Clone, Debug, Serialize)]
pub struct RdSummary {
    pub set: String,
    /// `raw` or `gzip`.
    pub basis: String,
    pub envelopes: Vec<Envelope>,
    pub deltas: Vec<Delta>,
}

/// Comma-separated numbers, each checked by `ok`.
fn parse_list<T: std::str::FromStr>(
    flag: &str,
    text: &str,
    ok: impl Fn(&T) -> bool,
    what: &str,
) -> Result<Vec<T>, CliError> {
    let mut out = Vec::new();
    for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
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

fn names(text: &str) -> Vec<String> {
    text.split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(String::from)
        .collect()
}

/// The image sets under `dir`: `(name, PNG files in name order)`.
fn discover_sets(dir: &Path) -> Result<Vec<(String, Vec<PathBuf>)>, CliError> {
    let pngs = |d: &Path| -> Result<Vec<PathBuf>, CliError> {
        let mut v: Vec<PathBuf> = std::fs::read_dir(d)
            .map_err(|e| CliError::Usage(format!("cannot read {}: {e}", d.display())))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file() && p.extension().is_some_and(|x| x.eq_ignore_ascii_case("png")))
            .collect();
        v.sort();
        Ok(v)
    };
    let mut sets = Vec::new();
    let top = pngs(dir)?;
    if !top.is_empty() {
        let name = dir
            .file_name()
            .and_then(|s| s.to_str())
            .unwrap_or("images")
            .to_string();
        sets.push((name, top));
    }
    let mut subs: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| CliError::Usage(format!("cannot read {}: {e}", dir.display())))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    subs.sort();
    for sub in subs {
        let Some(name) = sub.file_name().and_then(|s| s.to_str()) else {
            continue;
        };
        if name.starts_with('_') || name.starts_with('.') {
            continue;
        }
        let files = pngs(&sub)?;
        if !files.is_empty() {
            sets.push((name.to_string(), files));
        }
    }
    Ok(sets)
}

/// `n` files evenly spaced in name order (all of them when `n` is at least their number).
fn spread(files: Vec<PathBuf>, n: Option<usize>) -> Vec<PathBuf> {
    match n {
        Some(n) if n < files.len() => {
            let len = files.len();
            (0..n).map(|i| files[i * len / n].clone()).collect()
        }
        _ => files,
    }
}

fn gzip_len(text: &str) -> usize {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    // Writing to a Vec cannot fail.
    let _ = enc.write_all(text.as_bytes());
    enc.finish().map(|v| v.len()).unwrap_or(0)
}

/// Scores one SVG against its target.
fn score(
    set: &str,
    image: &str,
    tool: &str,
    setting: &str,
    target: &Image,
    svg: &str,
    seconds: f64,
) -> Result<RdSample, CliError> {
    let back = render_svg(svg, target.width, target.height).map_err(|e| {
        CliError::Other(anyhow::anyhow!(
            "{image}: {tool} {setting}: cannot render: {e}"
        ))
    })?;
    Ok(RdSample {
        set: set.to_string(),
        image: image.to_string(),
        tool: tool.to_string(),
        setting: setting.to_string(),
        paths: svg.matches("<path").count(),
        psnr: psnr(target, &back),
        ssim: ssim_over_white(target, &back),
        svg_bytes: svg.len(),
        svg_gz_bytes: gzip_len(svg),
        seconds,
        editability: editability(svg),
    })
}

/// Where the imagetracer peer runs from, or why it cannot.
struct ImageTracer {
    node: String,
    script: PathBuf,
    node_path: PathBuf,
    scratch: PathBuf,
}

fn probe_imagetracer(a: &RdArgs, images: &Path) -> Result<ImageTracer, String> {
    let tools = a.tools.clone().unwrap_or_else(|| images.join("_tools"));
    let node_path = tools.join("node_modules");
    for pkg in ["imagetracerjs", "pngjs"] {
        if !node_path.join(pkg).is_dir() {
            return Err(format!(
                "{} has no {pkg} (scripts/prepare_rd_set.sh installs it; or --tools DIR)",
                node_path.display()
            ));
        }
    }
    if !a.imagetracer_script.is_file() {
        return Err(format!(
            "no driver script at {} (--imagetracer-script)",
            a.imagetracer_script.display()
        ));
    }
    let ok = Command::new(&a.node)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    if !ok {
        return Err(format!("cannot run `{} --version`", a.node));
    }
    let scratch = std::env::temp_dir().join(format!("vf-rd-{}", std::process::id()));
    std::fs::create_dir_all(&scratch)
        .map_err(|e| format!("cannot create {}: {e}", scratch.display()))?;
    Ok(ImageTracer {
        node: a.node.clone(),
        script: a.imagetracer_script.clone(),
        node_path,
        scratch,
    })
}

/// The imagetracer grid: `(label, options JSON)`.
fn imagetracer_grid(colors: &[usize]) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for &n in colors {
        out.push((
            format!("n{n}"),
            format!(r#"{{"numberofcolors":{n},"over_white":true}}"#),
        ));
        out.push((
            format!("n{n} coarse"),
            format!(
                r#"{{"numberofcolors":{n},"ltres":2,"qtres":2,"pathomit":16,"roundcoords":0,"over_white":true}}"#
            ),
        ));
    }
    out
}

/// Runs the imagetracer driver: `(svg, seconds)`.
fn run_imagetracer(t: &ImageTracer, png: &Path, options: &str) -> Result<(String, f64), String> {
    let out_svg = t.scratch.join("imagetracer.svg");
    let out = Command::new(&t.node)
        .env("NODE_PATH", &t.node_path)
        .arg(&t.script)
        .arg(png)
        .arg(&out_svg)
        .arg(options)
        .output()
        .map_err(|e| format!("cannot run {}: {e}", t.node))?;
    if !out.status.success() {
        return Err(format!(
            "imagetracer failed: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    let report: serde_json::Value = serde_json::from_slice(&out.stdout)
        .map_err(|e| format!("imagetracer printed no JSON report: {e}"))?;
    let seconds = report["seconds"].as_f64().unwrap_or(f64::NAN);
    let svg = std::fs::read_to_string(&out_svg)
        .map_err(|e| format!("cannot read {}: {e}", out_svg.display()))?;
    Ok((svg, seconds))
}

fn probe_potrace(bin: &str) -> Result<(), String> {
    let ok = Command::new(bin)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    if ok {
        Ok(())
    } else {
        Err(format!(
            "cannot run `{bin} --version` (Debian: apt-get install potrace)"
        ))
    }
}

/// The potrace grid: `(label, arguments)`.
fn potrace_grid() -> Vec<(String, Vec<String>)> {
    let mut out = Vec::new();
    for t in [2, 8] {
        let mut push = |label: String, extra: &[&str]| {
            let mut args = vec!["-t".to_string(), t.to_string()];
            args.extend(extra.iter().map(|s| s.to_string()));
            out.push((label, args));
        };
        push(format!("t{t} a0"), &["-a", "0"]);
        push(format!("t{t} a1 O0.2"), &["-a", "1", "-O", "0.2"]);
        push(format!("t{t} a1 O1"), &["-a", "1", "-O", "1"]);
    }
    out
}

/// The image over white thresholded at luma (Rec. 601) 0.5, as binary PBM (1 = black).
fn to_pbm(im: &Image) -> Vec<u8> {
    let (w, h) = (im.width as usize, im.height as usize);
    let mut out = format!("P4\n{w} {h}\n").into_bytes();
    let row_bytes = w.div_ceil(8);
    for y in 0..h {
        let mut row = vec![0u8; row_bytes];
        for x in 0..w {
            let i = 4 * (y * w + x);
            let p = &im.data[i..i + 4];
            let white = 1.0 - p[3];
            let luma = 0.299 * (p[0] + white) + 0.587 * (p[1] + white) + 0.114 * (p[2] + white);
            if luma < 0.5 {
                row[x / 8] |= 0x80 >> (x % 8);
            }
        }
        out.extend_from_slice(&row);
    }
    out
}

/// Runs potrace on PBM bytes: `(svg, seconds)`.
fn run_potrace(bin: &str, pbm: &[u8], args: &[String]) -> Result<(String, f64), String> {
    let t0 = Instant::now();
    let mut child = Command::new(bin)
        .args(["-s", "-o", "-"])
        .args(args)
        .arg("-")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot run {bin}: {e}"))?;
    if let Some(mut stdin) = child.stdin.take() {
        stdin
            .write_all(pbm)
            .map_err(|e| format!("cannot write to {bin}: {e}"))?;
    }
    let out = child
        .wait_with_output()
        .map_err(|e| format!("{bin} failed: {e}"))?;
    let seconds = t0.elapsed().as_secs_f64();
    if !out.status.success() {
        return Err(format!(
            "{bin} failed: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    let svg = String::from_utf8(out.stdout).map_err(|e| format!("{bin}: not UTF-8: {e}"))?;
    Ok((svg, seconds))
}

/// Entry point of `bench vectorize --rd`.
pub fn run(a: &BenchVectorizeArgs) -> Result<(), CliError> {
    let r = &a.rd;
    let budgets = live::schedule::parse_schedule(&a.paths, usize::MAX)
        .map_err(|e| CliError::Usage(format!("--paths: {e}")))?;
    if let Some(b) = budgets.iter().find(|&&b| b > live::MAX_PATHS) {
        return Err(CliError::Usage(format!(
            "--paths: budget {b} exceeds the limit of {} paths",
            live::MAX_PATHS
        )));
    }
    let speckles = parse_list::<usize>("--vt-speckle", &r.vt_speckle, |&v| v <= 256, "0..=256")?;
    let precisions = parse_list::<i32>(
        "--vt-precision",
        &r.vt_precision,
        |v| (1..=8).contains(v),
        "a colour precision in 1..=8",
    )?;
    let it_colors = parse_list::<usize>(
        "--it-colors",
        &r.it_colors,
        |v| (2..=256).contains(v),
        "a colour count in 2..=256",
    )?;
    let kbs = parse_list::<f64>(
        "--kb",
        &r.kb,
        |v| v.is_finite() && *v > 0.0,
        "a positive size in KB",
    )?;
    let mut peers = names(&r.peers);
    if peers == ["none"] {
        peers.clear();
    }
    if let Some(p) = peers.iter().find(|p| !PEERS.contains(&p.as_str())) {
        return Err(CliError::Usage(format!(
            "--peers: unknown peer {p:?} (known: {}, or none)",
            PEERS.join(", ")
        )));
    }
    if a.limit == Some(0) {
        return Err(CliError::Usage("--limit: must be at least 1".into()));
    }
    let bw_sets = names(&r.bw_sets);
    let mut sets = discover_sets(&a.images)?;
    if let Some(only) = &r.sets {
        let only = names(only);
        if let Some(missing) = only.iter().find(|s| !sets.iter().any(|(n, _)| n == *s)) {
            return Err(CliError::Usage(format!(
                "--sets: no image set {missing:?} in {} (found: {})",
                a.images.display(),
                sets.iter()
                    .map(|(n, _)| n.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
        sets.retain(|(n, _)| only.contains(n));
    }
    if sets.is_empty() {
        return Err(CliError::Usage(format!(
            "no PNG files in {} or its sub-folders (run scripts/prepare_rd_set.sh {})",
            a.images.display(),
            a.images.display()
        )));
    }

    // Peers that cannot run here are skipped, loudly.
    let mut skipped: Vec<(String, String)> = Vec::new();
    let imagetracer = if peers.iter().any(|p| p == "imagetracer") {
        match probe_imagetracer(r, &a.images) {
            Ok(t) => Some(t),
            Err(why) => {
                skipped.push(("imagetracer".into(), why));
                None
            }
        }
    } else {
        None
    };
    let potrace = peers.iter().any(|p| p == "potrace")
        && match probe_potrace(&r.potrace) {
            Ok(()) => true,
            Err(why) => {
                skipped.push(("potrace".into(), why));
                false
            }
        };
    if potrace && !sets.iter().any(|(n, _)| bw_sets.contains(n)) {
        skipped.push((
            "potrace".into(),
            format!("no image set named in --bw-sets ({})", bw_sets.join(",")),
        ));
    }
    for (tool, why) in &skipped {
        eprintln!("SKIP {tool}: {why}");
    }
    let vtracer = peers.iter().any(|p| p == "vtracer");

    let base = LiveConfig {
        seed: a.seed,
        snapshot_every: 0,
        ..LiveConfig::preset(a.preset)
    };
    let mut live_runs: Vec<(String, LiveConfig)> = budgets
        .iter()
        .map(|&b| {
            (
                format!("paths {b}"),
                LiveConfig {
                    budget: PathBudget::fixed(b),
                    ..base.clone()
                },
            )
        })
        .collect();
    if a.auto {
        live_runs.push((
            "auto".into(),
            LiveConfig {
                budget: PathBudget::auto(),
                ..base.clone()
            },
        ));
    }
    if a.no_live {
        live_runs.clear();
    }

    let mut samples: Vec<RdSample> = Vec::new();
    let mut set_sizes: Vec<(String, usize)> = Vec::new();
    for (set, files) in sets {
        let files = spread(files, a.limit);
        set_sizes.push((set.clone(), files.len()));
        for file in &files {
            let image = file
                .file_stem()
                .and_then(|s| s.to_str())
                .unwrap_or("?")
                .to_string();
            let target = load_input(file)?;
            let first = samples.len();
            if vtracer {
                let white = target.over([1.0, 1.0, 1.0]);
                let mut inputs: Vec<(&Image, &str)> = Vec::new();
                if r.vt_input != VtInput::White {
                    inputs.push((&target, ""));
                }
                if r.vt_input != VtInput::Rgba {
                    inputs.push((&white, " white"));
                }
                for (input, suffix) in inputs {
                    for polygon in [false, true] {
                        for &filter_speckle in &speckles {
                            for &color_precision in &precisions {
                                let s = TracerSetting {
                                    polygon,
                                    filter_speckle,
                                    color_precision,
                                    ..TracerSetting::default()
                                };
                                let t0 = Instant::now();
                                let svg = trace(input, &s)
                                    .map_err(|e| {
                                        CliError::Other(anyhow::anyhow!("{image}: vtracer: {e}"))
                                    })?
                                    .svg;
                                let secs = t0.elapsed().as_secs_f64();
                                let label = format!("{}{suffix}", s.label());
                                samples.push(score(
                                    &set, &image, "vtracer", &label, &target, &svg, secs,
                                )?);
                            }
                        }
                    }
                }
            }
            if let Some(t) = &imagetracer {
                for (label, options) in imagetracer_grid(&it_colors) {
                    let (svg, secs) = run_imagetracer(t, file, &options)
                        .map_err(|e| CliError::Other(anyhow::anyhow!("{image}: {label}: {e}")))?;
                    samples.push(score(
                        &set,
                        &image,
                        "imagetracer",
                        &label,
                        &target,
                        &svg,
                        secs,
                    )?);
                }
            }
            if potrace && bw_sets.contains(&set) {
                let pbm = to_pbm(&target);
                for (label, args) in potrace_grid() {
                    let (svg, secs) = run_potrace(&r.potrace, &pbm, &args).map_err(|e| {
                        CliError::Other(anyhow::anyhow!("{image}: potrace {label}: {e}"))
                    })?;
                    samples.push(score(&set, &image, "potrace", &label, &target, &svg, secs)?);
                }
            }
            if first < samples.len() {
                eprintln!(
                    "{set}/{image}: {} peer settings, best PSNR {:.2} dB",
                    samples.len() - first,
                    samples[first..]
                        .iter()
                        .map(|s| s.psnr.min(100.0))
                        .fold(f64::NEG_INFINITY, f64::max)
                );
            }
            for (label, cfg) in &live_runs {
                let t0 = Instant::now();
                let res = live::vectorize(&target, cfg, &NullSink, &CancelToken::new())
                    .map_err(|e| CliError::Other(anyhow::anyhow!("{image}: live {label}: {e}")))?;
                // Our output as every run writes it (fewest decimals within the render
                // tolerance, simple outlines), timed with the tracing.
                let svg = crate::vector::write_svg(&res.scene, &cfg.colors);
                let secs = t0.elapsed().as_secs_f64();
                let s = score(&set, &image, "live", label, &target, &svg, secs)?;
                eprintln!(
                    "{set}/{image}: live {label:9} paths {:3} psnr {:6.2} ssim {:.4} bytes {:6} gz {:5} {:.2} s",
                    s.paths, s.psnr, s.ssim, s.svg_bytes, s.svg_gz_bytes, s.seconds
                );
                samples.push(s);
            }
        }
    }
    if let Some(t) = &imagetracer {
        let _ = std::fs::remove_dir_all(&t.scratch);
    }

    let means = means(&samples);
    let mut summaries = Vec::new();
    for (set, _) in &set_sizes {
        for basis in ["raw", "gzip"] {
            summaries.push(summarise_set(&means, set, basis, &kbs));
        }
    }

    let json_out = serde_json::json!({
        "images": set_sizes.iter().map(|(_, n)| n).sum::<usize>(),
        "sets": set_sizes.iter().map(|(s, n)| serde_json::json!({"set": s, "images": n})).collect::<Vec<_>>(),
        "preset": format!("{:?}", a.preset).to_lowercase(),
        "precision": "auto (vector::write_svg)",
        "seed": a.seed,
        "skipped": skipped.iter().map(|(t, w)| serde_json::json!({"tool": t, "why": w})).collect::<Vec<_>>(),
        "editability_checker": editability("<svg xmlns=\"http://www.w3.org/2000/svg\"/>").is_some(),
        "means": means,
        "rd": summaries,
        "samples": samples,
    });
    match &a.json {
        Some(Some(path)) => {
            let text = serde_json::to_string_pretty(&json_out)
                .map_err(|e| CliError::Other(anyhow::anyhow!("cannot encode JSON: {e}")))?;
            std::fs::write(path, text + "\n").map_err(|e| {
                CliError::Other(anyhow::anyhow!("cannot write {}: {e}", path.display()))
            })?;
            print_tables(&set_sizes, &means, &summaries, &skipped, r.all_rows);
            eprintln!("wrote {}", path.display());
        }
        Some(None) => println!("{json_out}"),
        None => print_tables(&set_sizes, &means, &summaries, &skipped, r.all_rows),
    }
    Ok(())
}

/// Means per (set, tool, setting), in first-seen order.
pub fn means(samples: &[RdSample]) -> Vec<RdMean> {
    let mut keys: Vec<(&str, &str, &str)> = Vec::new();
    for s in samples {
        let k = (s.set.as_str(), s.tool.as_str(), s.setting.as_str());
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    keys.into_iter()
        .map(|(set, tool, setting)| {
            let g: Vec<&RdSample> = samples
                .iter()
                .filter(|s| s.set == set && s.tool == tool && s.setting == setting)
                .collect();
            let n = g.len().max(1) as f64;
            let mean = |f: &dyn Fn(&RdSample) -> f64| g.iter().map(|s| f(s)).sum::<f64>() / n;
            let edits: Vec<EditCounts> = g.iter().filter_map(|s| s.editability).collect();
            let emean = |f: &dyn Fn(&EditCounts) -> usize| {
                (!edits.is_empty())
                    .then(|| edits.iter().map(|e| f(e) as f64).sum::<f64>() / edits.len() as f64)
            };
            RdMean {
                set: set.to_string(),
                tool: tool.to_string(),
                setting: setting.to_string(),
                images: g.len(),
                paths: mean(&|s| s.paths as f64),
                // Identical renders (infinite PSNR) count as 100 dB.
                psnr: mean(&|s| s.psnr.min(100.0)),
                ssim: mean(&|s| s.ssim),
                svg_bytes: mean(&|s| s.svg_bytes as f64),
                svg_gz_bytes: mean(&|s| s.svg_gz_bytes as f64),
                seconds: mean(&|s| s.seconds),
                self_intersecting: emean(&|e| e.self_intersecting),
                hidden: emean(&|e| e.hidden),
                slivers: emean(&|e| e.slivers),
                colors: emean(&|e| e.colors),
            }
        })
        .collect()
}

/// The upper Pareto frontier of `(x, y)` points: x ascending, y strictly increasing.
pub fn envelope(pts: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    envelope_indices(&pts).into_iter().map(|i| pts[i]).collect()
}

/// Indices of the points of [`envelope`], in its order.
fn envelope_indices(pts: &[(f64, f64)]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..pts.len())
        .filter(|&i| pts[i].0.is_finite() && pts[i].1.is_finite())
        .collect();
    // By x, and at equal x the best y first.
    idx.sort_by(|&a, &b| {
        pts[a]
            .0
            .total_cmp(&pts[b].0)
            .then(pts[b].1.total_cmp(&pts[a].1))
    });
    let mut out: Vec<usize> = Vec::new();
    for i in idx {
        if out.last().is_none_or(|&l| pts[i].1 > pts[l].1) {
            out.push(i);
        }
    }
    out
}

/// The envelope at `x`: linear between its points, its best value after the last, `None`
/// before the first.
pub fn envelope_at(env: &[(f64, f64)], x: f64) -> Option<f64> {
    let first = env.first()?;
    if x < first.0 {
        return None;
    }
    for w in env.windows(2) {
        let ((x0, y0), (x1, y1)) = (w[0], w[1]);
        if x <= x1 {
            return Some(if x1 > x0 {
                y0 + (y1 - y0) * (x - x0) / (x1 - x0)
            } else {
                y1
            });
        }
    }
    env.last().map(|p| p.1)
}

/// Envelopes of every tool on one set and basis, and `live − peer` at each size.
fn summarise_set(means: &[RdMean], set: &str, basis: &str, kbs: &[f64]) -> RdSummary {
    let mut tools: Vec<&str> = Vec::new();
    for m in means.iter().filter(|m| m.set == set) {
        if !tools.contains(&m.tool.as_str()) {
            tools.push(&m.tool);
        }
    }
    let envelopes: Vec<Envelope> = tools
        .iter()
        .map(|&tool| {
            let rows: Vec<&RdMean> = means
                .iter()
                .filter(|m| m.set == set && m.tool == tool)
                .collect();
            let pts: Vec<(f64, f64)> = rows
                .iter()
                .map(|m| {
                    let bytes = if basis == "gzip" {
                        m.svg_gz_bytes
                    } else {
                        m.svg_bytes
                    };
                    (bytes / 1000.0, m.psnr)
                })
                .collect();
            let idx = envelope_indices(&pts);
            Envelope {
                tool: tool.to_string(),
                points: idx.iter().map(|&i| pts[i]).collect(),
                settings: idx.iter().map(|&i| rows[i].setting.clone()).collect(),
            }
        })
        .collect();
    let live = envelopes.iter().find(|e| e.tool == "live");
    let mut deltas = Vec::new();
    if let Some(live) = live {
        for peer in envelopes.iter().filter(|e| e.tool != "live") {
            for &kb in kbs {
                let l = envelope_at(&live.points, kb);
                let p = envelope_at(&peer.points, kb);
                let past = |e: &Envelope| e.points.last().is_some_and(|p| kb > p.0);
                deltas.push(Delta {
                    peer: peer.tool.clone(),
                    kb,
                    live: l,
                    peer_psnr: p,
                    delta_db: l.zip(p).map(|(l, p)| l - p),
                    beyond: past(live) || past(peer),
                });
            }
        }
    }
    RdSummary {
        set: set.to_string(),
        basis: basis.to_string(),
        envelopes,
        deltas,
    }
}

fn opt(v: Option<f64>, width: usize, prec: usize) -> String {
    match v {
        Some(v) => format!("{v:>width$.prec$}"),
        None => format!("{:>width$}", "—"),
    }
}

fn print_tables(
    sets: &[(String, usize)],
    means: &[RdMean],
    summaries: &[RdSummary],
    skipped: &[(String, String)],
    all_rows: bool,
) {
    for (tool, why) in skipped {
        println!("SKIP {tool}: {why}");
    }
    for (set, n) in sets {
        let on_envelope = |m: &RdMean| {
            summaries.iter().filter(|s| &s.set == set).any(|s| {
                s.envelopes
                    .iter()
                    .any(|e| e.tool == m.tool && e.settings.contains(&m.setting))
            })
        };
        let rows: Vec<&RdMean> = means
            .iter()
            .filter(|m| &m.set == set && (all_rows || m.tool == "live" || on_envelope(m)))
            .collect();
        let hidden = means.iter().filter(|m| &m.set == set).count() - rows.len();
        println!("\n== set {set}: {n} images, means ==");
        if hidden > 0 {
            println!("({hidden} peer settings on no envelope left out; --all-rows shows them)");
        }
        println!(
            "{:12} {:24} {:>6} {:>7} {:>6} {:>8} {:>7} {:>6} {:>6} {:>6} {:>6} {:>7}",
            "tool",
            "setting",
            "paths",
            "PSNR",
            "SSIM",
            "bytes",
            "gz",
            "colors",
            "selfx",
            "hidden",
            "sliver",
            "seconds"
        );
        for m in rows {
            println!(
                "{:12} {:24} {:>6.1} {:>7.2} {:>6.4} {:>8.0} {:>7.0} {} {} {} {} {:>7.3}",
                m.tool,
                m.setting,
                m.paths,
                m.psnr,
                m.ssim,
                m.svg_bytes,
                m.svg_gz_bytes,
                opt(m.colors, 6, 1),
                opt(m.self_intersecting, 6, 1),
                opt(m.hidden, 6, 1),
                opt(m.slivers, 6, 1),
                m.seconds
            );
        }
        for s in summaries.iter().filter(|s| &s.set == set) {
            println!("-- R–D envelopes, {} KB: (KB, PSNR dB) --", s.basis);
            for e in &s.envelopes {
                let pts: Vec<String> = e
                    .points
                    .iter()
                    .map(|(x, y)| format!("({x:.2}, {y:.2})"))
                    .collect();
                println!("{:12} {}", e.tool, pts.join(" "));
            }
            let mut kbs: Vec<f64> = Vec::new();
            let mut peers: Vec<&str> = Vec::new();
            for d in &s.deltas {
                if !kbs.contains(&d.kb) {
                    kbs.push(d.kb);
                }
                if !peers.contains(&d.peer.as_str()) {
                    peers.push(&d.peer);
                }
            }
            if peers.is_empty() {
                continue;
            }
            let head: Vec<String> = kbs
                .iter()
                .map(|k| format!("{:>8}", format!("{k}KB")))
                .collect();
            println!(
                "{:18} {}",
                format!("live − peer, {}", s.basis),
                head.join(" ")
            );
            for p in peers {
                let row: Vec<String> = s
                    .deltas
                    .iter()
                    .filter(|d| d.peer == p)
                    .map(|d| match d.delta_db {
                        Some(v) => format!(
                            "{:>8}",
                            format!("{v:+.2}{}", if d.beyond { "*" } else { " " })
                        ),
                        None => format!("{:>8}", "— "),
                    })
                    .collect();
                println!("{:18} {}", p, row.join(" "));
            }
        }
    }
    println!(
        "\n(dB; —: a curve does not reach that size; *: past the largest point of a curve, read flat)"
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn envelope_keeps_the_pareto_frontier() {
        let env = envelope(vec![
            (4.0, 25.0),
            (2.0, 20.0),
            (3.0, 19.0), // beaten by (2, 20)
            (8.0, 30.0),
            (6.0, 24.0), // beaten by (4, 25)
            (2.0, 21.0),
        ]);
        assert_eq!(env, vec![(2.0, 21.0), (4.0, 25.0), (8.0, 30.0)]);
        assert_eq!(envelope_at(&env, 1.0), None);
        assert_eq!(envelope_at(&env, 2.0), Some(21.0));
        assert_eq!(envelope_at(&env, 3.0), Some(23.0));
        assert_eq!(envelope_at(&env, 6.0), Some(27.5));
        assert_eq!(envelope_at(&env, 20.0), Some(30.0));
        assert_eq!(envelope_at(&[], 2.0), None);
    }

    #[test]
    fn pbm_marks_dark_pixels_over_white() {
        let mut im = Image::filled(10, 2, [0.0, 0.0, 0.0, 1.0]);
        // Pixel 1: transparent (white over white); pixel 9: light grey.
        im.data[4..8].copy_from_slice(&[0.0, 0.0, 0.0, 0.0]);
        im.data[36..40].copy_from_slice(&[0.8, 0.8, 0.8, 1.0]);
        let pbm = to_pbm(&im);
        let head = b"P4\n10 2\n";
        assert_eq!(&pbm[..head.len()], head);
        assert_eq!(&pbm[head.len()..], &[0b1011_1111, 0b1000_0000, 0xff, 0xc0]);
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

    #[test]
    fn spread_picks_evenly() {
        let files: Vec<PathBuf> = (0..10).map(|i| PathBuf::from(format!("{i}"))).collect();
        let got: Vec<String> = spread(files.clone(), Some(3))
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        assert_eq!(got, ["0", "3", "6"]);
        assert_eq!(spread(files.clone(), Some(20)).len(), 10);
        assert_eq!(spread(files, None).len(), 10);
    }
}
