//! Prepares fidelity-benchmark images: renders every `.svg` in SRC with resvg and centre-crops
//! and resizes every `.png`/`.jpg` photo, writing `SIZE x SIZE` PNGs into OUT.
//!
//! Usage: `cargo run --example fidelity_render -- SRC OUT [SIZE]` (used by
//! `scripts/prepare_fidelity_set.sh`).

use resvg::{tiny_skia, usvg};
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: fidelity_render SRC OUT [SIZE]".into());
    }
    let (src, out) = (Path::new(&args[1]), Path::new(&args[2]));
    let size: u32 = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(256);
    std::fs::create_dir_all(out)?;
    let mut entries: Vec<_> = std::fs::read_dir(src)?.collect::<Result<_, _>>()?;
    entries.sort_by_key(|e| e.path());
    let mut n = 0;
    for e in entries {
        let path = e.path();
        let ext = path.extension().and_then(|s| s.to_str()).unwrap_or("");
        let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("img");
        let dst = out.join(format!("{stem}.png"));
        match ext {
            "svg" => {
                let data = std::fs::read(&path)?;
                let tree = usvg::Tree::from_data(&data, &usvg::Options::default())?;
                let mut pixmap = tiny_skia::Pixmap::new(size, size).ok_or("bad size")?;
                let s = tree.size();
                let k = size as f32 / s.width().max(s.height());
                resvg::render(
                    &tree,
                    tiny_skia::Transform::from_scale(k, k),
                    &mut pixmap.as_mut(),
                );
                pixmap.save_png(&dst)?;
            }
            "png" | "jpg" | "jpeg" => {
                let img = image::open(&path)?.to_rgba8();
                let (w, h) = img.dimensions();
                let side = w.min(h);
                let crop =
                    image::imageops::crop_imm(&img, (w - side) / 2, (h - side) / 2, side, side)
                        .to_image();
                let small = image::imageops::resize(
                    &crop,
                    size,
                    size,
                    image::imageops::FilterType::Triangle,
                );
                small.save(&dst)?;
            }
            _ => continue,
        }
        n += 1;
    }
    println!("wrote {n} images to {}", out.display());
    Ok(())
}
