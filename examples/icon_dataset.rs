//! Renders iconify JSON icon sets to a raw image dataset for the embedded model
//! (`scripts/embedded/prepare_data.sh`, docs/EMBEDDED.md).
//!
//! Usage: `cargo run --release --example icon_dataset -- OUT SIZE [--words VOCAB] SET=ICONS.json...`
//!
//! Writes `OUT/images_SIZE.u8` (raw uint8 `[N, SIZE, SIZE, 3]`, RGB over white) and
//! `OUT/captions.jsonl` (`{"set","name","caption"}` per image, same order), and prints per-set
//! counts as JSON on stdout. Each icon's SVG is `<svg xmlns=... viewBox="left top w h">body</svg>`
//! parsed with the crate's safe `parse_usvg`, fitted and centred in the square, rendered with
//! resvg (`vectorfusion::retrieval::iconify`, which the retrieval sampler renders with too).
//! Icons that fail to parse or render blank are skipped and counted; `aliases` are skipped.
//!
//! Captions come from names: `-`/`_` become spaces; trailing variant markers (`-N`, `-flat`,
//! `-duo`) are dropped while the name without them is also in the set (`man-farmer-2`,
//! `add-layer-2-flat`); in sets whose names have no separators at all (fxemoji:
//! `sakebottleandcup`) each name is split into the fewest whole words of `VOCAB` (one word per
//! line, e.g. the MiniLM `vocab.txt`), when given.

use serde_json::json;
use std::collections::{BTreeMap, HashSet};
use std::io::Write;
use std::path::Path;
use vectorfusion::retrieval::{iconify, names};

type Res<T> = Result<T, Box<dyn std::error::Error>>;

fn main() -> Res<()> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut vocab = None;
    if let Some(i) = args.iter().position(|a| a == "--words") {
        let path = args.get(i + 1).ok_or("--words needs a path")?.clone();
        vocab = Some(names::vocab_words(&std::fs::read_to_string(&path)?));
        args.drain(i..i + 2);
    }
    if args.len() < 3 {
        return Err("usage: icon_dataset OUT SIZE [--words VOCAB] SET=ICONS.json...".into());
    }
    let out = Path::new(&args[0]);
    let size: u32 = args[1].parse()?;
    std::fs::create_dir_all(out)?;
    let mut images = std::io::BufWriter::new(std::fs::File::create(
        out.join(format!("images_{size}.u8")),
    )?);
    let mut captions = std::io::BufWriter::new(std::fs::File::create(out.join("captions.jsonl"))?);
    let mut stats = BTreeMap::new();
    let mut total = 0usize;
    for spec in &args[2..] {
        let (set, path) = spec.split_once('=').ok_or("expected SET=ICONS.json")?;
        let icons = iconify::icons(&std::fs::read_to_string(path)?)?;
        let all: HashSet<&str> = icons.iter().map(|i| i.name.as_str()).collect();
        // Segment only sets whose names carry no separators (e.g. fxemoji).
        let seg_vocab = vocab
            .as_ref()
            .filter(|_| names::needs_segmentation(all.iter().copied()));
        let (mut ok, mut failed, mut blank) = (0usize, 0usize, 0usize);
        for icon in &icons {
            match iconify::render_rgb8(&icon.svg, size) {
                Ok(Some(rgb)) => {
                    images.write_all(&rgb)?;
                    let cap = names::caption(&icon.name, &all, seg_vocab);
                    let line = json!({"set": set, "name": icon.name, "caption": cap});
                    writeln!(captions, "{line}")?;
                    ok += 1;
                }
                Ok(None) => blank += 1,
                Err(e) => {
                    eprintln!("{set}:{}: {e}", icon.name);
                    failed += 1;
                }
            }
        }
        total += ok;
        stats.insert(
            set.to_string(),
            json!({"icons": icons.len(), "rendered": ok, "failed": failed, "blank": blank}),
        );
    }
    images.flush()?;
    captions.flush()?;
    println!(
        "{}",
        json!({"total": total, "image_size": size, "sets": stats})
    );
    Ok(())
}
