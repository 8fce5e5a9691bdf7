//! `vectorfusion bench <what>`: benchmarks. Each benchmark is one variant of [`BenchCommand`].
//!
//! `bench raster --scene FILE --size N [--json]` renders the scene scaled to `N` px wide and
//! reports median times of our forward pass, our forward + backward pass (L2 loss against the
//! colour ramp R = x/W, G = y/H, B = 0.5) and, in the same run, tiny-skia's forward pass on the
//! same scene as the baseline.

use super::CliError;
use crate::raster;
use crate::scene::{Scene, ShapeKind};
use resvg::tiny_skia;
use std::path::PathBuf;
use std::time::Instant;

#[derive(clap::Subcommand, Debug)]
pub enum BenchCommand {
    /// Rasteriser forward and forward+backward against tiny-skia.
    Raster(RasterBenchArgs),
    /// Stable Diffusion / TAESD components (random weights, full size): median ms each.
    Models(super::bench_models::BenchModelsArgs),
    /// LIVE vs vtracer fidelity (PSNR, seconds, SVG bytes) on a folder of PNGs.
    Vectorize(Box<super::bench_vectorize::BenchVectorizeArgs>),
    /// Failure rate, quality spread and time of every method x style over seeds.
    Stability(super::bench_stability::BenchStabilityArgs),
}

#[derive(clap::Args, Debug)]
pub struct RasterBenchArgs {
    /// Scene file: bench JSON (`shared/bench/scene64.json`) or SVG.
    #[arg(long)]
    pub scene: PathBuf,
    /// Canvas width in pixels (the scene is scaled uniformly).
    #[arg(long, default_value_t = 512)]
    pub size: u32,
    /// Timed iterations per measurement (after 3 warm-up runs).
    #[arg(long, default_value_t = 50)]
    pub iters: usize,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Paint every fill flat (the scene's colours) or with a linear or radial gradient (the
    /// cost of gradient paint; tiny-skia draws the same gradients).
    #[arg(long, value_enum, default_value_t = super::bench_paint::BenchPaint::Flat)]
    pub paint: super::bench_paint::BenchPaint,
}

pub fn run(cmd: BenchCommand) -> Result<(), CliError> {
    match cmd {
        BenchCommand::Raster(a) => raster_bench(a),
        BenchCommand::Models(a) => super::bench_models::run(a),
        BenchCommand::Vectorize(a) => super::bench_vectorize::run(*a),
        BenchCommand::Stability(a) => super::bench_stability::run(a),
    }
}

/// Result of `bench raster`.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RasterBench {
    pub size: u32,
    pub paint: super::bench_paint::BenchPaint,
    pub forward_ms: f64,
    /// `raster::render_with(.., Antialias::Supersampled)`: 16 samples a pixel, as tiny-skia.
    pub supersampled_forward_ms: f64,
    pub forward_backward_ms: f64,
    pub tiny_skia_forward_ms: f64,
    pub loss: f64,
    pub iters: usize,
    pub threads: usize,
}

/// Median of `v` (mean of the middle two for even lengths); NaN when empty.
pub(super) fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn time_ms<R>(iters: usize, mut f: impl FnMut() -> R) -> f64 {
    for _ in 0..3 {
        std::hint::black_box(f());
    }
    let mut t = Vec::with_capacity(iters);
    for _ in 0..iters {
        let s = Instant::now();
        std::hint::black_box(f());
        t.push(s.elapsed().as_secs_f64() * 1e3);
    }
    median(t)
}

/// L2 loss (mean over pixels and RGB) against the ramp target and its gradient w.r.t. the
/// premultiplied RGBA image.
pub fn ramp_l2(img: &crate::image::Image) -> (f64, Vec<f32>) {
    use rayon::prelude::*;
    let (w, h) = (img.width as usize, img.height as usize);
    let norm = 1.0 / (3 * w * h) as f32;
    let mut grad = vec![0.0f32; img.data.len()];
    let loss: f64 = grad
        .par_chunks_mut(4 * w.max(1))
        .zip(img.data.par_chunks(4 * w.max(1)))
        .enumerate()
        .map(|(y, (grow, irow))| {
            let mut l = 0.0f64;
            for (x, (g, p)) in grow
                .chunks_exact_mut(4)
                .zip(irow.chunks_exact(4))
                .enumerate()
            {
                let t = [x as f32 / w as f32, y as f32 / h as f32, 0.5];
                for c in 0..3 {
                    let d = p[c] - t[c];
                    l += (d * d) as f64;
                    g[c] = 2.0 * d * norm;
                }
            }
            l
        })
        .sum();
    (loss * norm as f64, grad)
}

/// Renders `scene` with tiny-skia (nonzero fill, round caps/joins, anti-aliased).
pub fn tiny_skia_render(scene: &Scene) -> Option<tiny_skia::Pixmap> {
    let mut pm = tiny_skia::Pixmap::new(scene.width, scene.height)?;
    let bg = scene.background;
    pm.fill(tiny_skia::Color::from_rgba(bg.r, bg.g, bg.b, bg.a)?);
    for sh in &scene.shapes {
        let mut pb = tiny_skia::PathBuilder::new();
        match sh.kind {
            ShapeKind::Polygon => {
                for (i, p) in sh.points.iter().enumerate() {
                    if i == 0 {
                        pb.move_to(p.x, p.y);
                    } else {
                        pb.line_to(p.x, p.y);
                    }
                }
            }
            _ => {
                pb.move_to(sh.points[0].x, sh.points[0].y);
                for i in 0..sh.num_segments() {
                    let s = sh.segment(i);
                    pb.cubic_to(s[1].x, s[1].y, s[2].x, s[2].y, s[3].x, s[3].y);
                }
            }
        }
        if sh.is_closed() {
            pb.close();
        }
        let Some(path) = pb.finish() else {
            continue;
        };
        let paint = |c: crate::scene::Rgba| {
            let mut p = tiny_skia::Paint::default();
            p.set_color(
                tiny_skia::Color::from_rgba(c.r, c.g, c.b, c.a).unwrap_or(tiny_skia::Color::BLACK),
            );
            p.anti_alias = true;
            p
        };
        let fill_gradient = sh.gradients.as_ref().and_then(|g| g.fill.as_ref());
        if let Some(f) = sh.fill.filter(|_| sh.is_closed()) {
            let mut p = paint(f);
            if let Some(s) = fill_gradient.and_then(super::bench_paint::shader) {
                p.shader = s;
            }
            pm.fill_path(
                &path,
                &p,
                tiny_skia::FillRule::Winding,
                tiny_skia::Transform::identity(),
                None,
            );
        }
        if let Some(st) = sh.stroke.filter(|s| s.width > 0.0) {
            let stroke = tiny_skia::Stroke {
                width: st.width,
                line_cap: tiny_skia::LineCap::Round,
                line_join: tiny_skia::LineJoin::Round,
                ..Default::default()
            };
            pm.stroke_path(
                &path,
                &paint(st.color),
                &stroke,
                tiny_skia::Transform::identity(),
                None,
            );
        }
    }
    Some(pm)
}

fn raster_bench(a: RasterBenchArgs) -> Result<(), CliError> {
    if a.size == 0 || a.size > crate::scene::MAX_SIDE {
        return Err(CliError::Usage(format!(
            "--size must be in 1..={}",
            crate::scene::MAX_SIDE
        )));
    }
    if a.iters == 0 {
        return Err(CliError::Usage("--iters must be at least 1".into()));
    }
    let scene = crate::svg::load_scene(&a.scene).map_err(|e| CliError::Other(e.into()))?;
    let scene = super::bench_paint::with_gradients(&scene.scaled_to_width(a.size), a.paint);
    scene
        .validate()
        .map_err(|e| CliError::Usage(format!("scaled scene is invalid: {e}")))?;
    let forward_ms = time_ms(a.iters, || raster::render(&scene));
    let supersampled_forward_ms = time_ms(a.iters, || {
        raster::render_with(&scene, raster::Antialias::Supersampled)
    });
    let mut loss = 0.0;
    let forward_backward_ms = time_ms(a.iters, || {
        let (img, tape) = raster::render_tape(&scene);
        let (l, g) = ramp_l2(&img);
        loss = l;
        raster::backward(&scene, &tape, &g)
    });
    let tiny_skia_forward_ms = time_ms(a.iters, || tiny_skia_render(&scene));
    let r = RasterBench {
        size: a.size,
        paint: a.paint,
        forward_ms,
        supersampled_forward_ms,
        forward_backward_ms,
        tiny_skia_forward_ms,
        loss,
        iters: a.iters,
        threads: rayon::current_num_threads(),
    };
    if a.json {
        let s = serde_json::to_string(&r).map_err(|e| CliError::Other(e.into()))?;
        println!("{s}");
    } else {
        println!(
            "raster bench: {} shapes at {}x{}, {} iterations, {} threads (medians)",
            scene.shapes.len(),
            scene.width,
            scene.height,
            r.iters,
            r.threads
        );
        println!("  forward            {:8.3} ms", r.forward_ms);
        println!("  forward, 4x4 AA    {:8.3} ms", r.supersampled_forward_ms);
        println!("  forward+backward   {:8.3} ms", r.forward_backward_ms);
        println!("  tiny-skia forward  {:8.3} ms", r.tiny_skia_forward_ms);
        println!("  loss (L2 vs ramp)  {:.6}", r.loss);
    }
    Ok(())
}
