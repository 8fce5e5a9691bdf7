//! CPU timings of the CLIP scorer's pieces (numbers go to docs/BENCHMARKS.md):
//! `cargo run --release --example clip_bench [runs]`.
//!
//! Uses random weights of the real ViT-B/16 shape (the paper's rerank scorer); the tokenizer is
//! the tiny fixture's (a real vocabulary has more merges but the same per-word work).

use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use std::path::Path;
use std::time::Instant;
use vectorfusion::image::Image;
use vectorfusion::models::clip::preprocess::{PreprocessConfig, preprocess};
use vectorfusion::models::clip::text::ClipTextTransformer;
use vectorfusion::models::clip::vision::ClipVisionTransformer;
use vectorfusion::models::clip::{ClipTextConfig, ClipTokenizer, ClipVisionConfig};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn time<F: FnMut()>(runs: usize, mut f: F) -> f64 {
    f(); // warm-up
    median(
        (0..runs)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect(),
    )
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let runs: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(5);
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let prompts = std::fs::read_to_string(root.join("../shared/bench/svg_bench_prompts.txt"))
        .or_else(|_| std::fs::read_to_string("/work/shared/bench/svg_bench_prompts.txt"))?;
    let caps: Vec<&str> = prompts.lines().collect();
    let tok = ClipTokenizer::from_dir(&root.join("tests/fixtures/clip-tiny"))?;
    let ms = time(runs, || {
        for c in &caps {
            std::hint::black_box(tok.encode_padded(c));
        }
    });
    println!("tokenize {} captions: {ms:.2} ms", caps.len());

    let mut img = Image::new(512, 512);
    for (i, v) in img.data.iter_mut().enumerate() {
        *v = ((i * 2654435761usize) % 1000) as f32 / 1000.0;
    }
    for px in img.data.chunks_exact_mut(4) {
        px[3] = 1.0;
    }
    let cfg = PreprocessConfig::for_image_size(224);
    let ms = time(runs, || {
        std::hint::black_box(preprocess(&img, &cfg).ok());
    });
    println!("preprocess 512x512 -> 224 (PIL bicubic, exact): {ms:.2} ms");

    let dev = Device::Cpu;
    let vm = VarMap::new();
    let vb = VarBuilder::from_varmap(&vm, DType::F32, &dev);
    let vcfg = ClipVisionConfig {
        patch_size: 16,
        ..Default::default()
    };
    let vision = ClipVisionTransformer::new(vb.pp("vision_model"), &vcfg)?;
    for k in [1usize, 4] {
        let px = Tensor::randn(0f32, 1.0, (k, 3, 224, 224), &dev)?;
        let ms = time(runs.min(3), || {
            std::hint::black_box(vision.forward(&px).ok());
        });
        println!(
            "ViT-B/16 image tower, batch {k}: {ms:.0} ms ({:.0} ms/image)",
            ms / k as f64
        );
    }
    let tcfg = ClipTextConfig::default();
    let text = ClipTextTransformer::new(vb.pp("text_model"), &tcfg)?;
    let ids = Tensor::zeros((16, 77), DType::U32, &dev)?;
    let ms = time(runs.min(3), || {
        std::hint::black_box(text.forward(&ids).ok());
    });
    println!("ViT-B/16 text tower, batch 16 x 77 tokens: {ms:.0} ms");
    Ok(())
}
