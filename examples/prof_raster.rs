//! Profiling helper for `perf stat` / `perf record`: `prof_raster MODE N SIZE` runs one stage of
//! the rasteriser N times on `shared/bench/scene64.json` scaled to SIZE px. MODE: `f` forward,
//! `ft` forward with tape, `fb` forward + backward, `ts` tiny-skia forward.
use vectorfusion::{raster, svg};
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let mode = args.get(1).map(String::as_str).unwrap_or("fb");
    let n: usize = args.get(2).and_then(|v| v.parse().ok()).unwrap_or(100);
    let size: u32 = args.get(3).and_then(|v| v.parse().ok()).unwrap_or(512);
    let s = svg::load_scene(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/bench/scene64.json"
    )))
    .expect("scene64.json (../shared/bench) is readable");
    let s = s.scaled_to_width(size);
    let (im, tape) = raster::render_tape(&s);
    let (_, g) = vectorfusion::cli::bench::ramp_l2(&im);
    drop(tape);
    for _ in 0..n {
        match mode {
            "f" => {
                std::hint::black_box(raster::render(&s));
            }
            "ft" => {
                std::hint::black_box(raster::render_tape(&s));
            }
            "ts" => {
                std::hint::black_box(vectorfusion::cli::bench::tiny_skia_render(&s));
            }
            _ => {
                let (_, tape) = raster::render_tape(&s);
                std::hint::black_box(raster::backward(&s, &tape, &g));
            }
        }
    }
}
