//! Renders iconify JSON icon sets to a raw image dataset for the embedded model
//! (`scripts/embedded/prepare_data.sh`, docs/EMBEDDED.md).
//!
//! Usage: `cargo run --release --example icon_dataset -- OUT SIZE [--words VOCAB] SET=ICONS.json...`
//!
//! Writes `OUT/images_SIZE.u8` (raw uint8 `[N, SIZE, SIZE, 3]`, RGB over white) and
//! `OUT/captions.jsonl` (`{"set","name","caption"}` per image, same order), and prints per-set
//! counts as JSON on stdout. Each icon's SVG is `<svg xmlns=... viewBox="left top w h">body</svg>`
//! parsed with the crate's safe `parse_usvg`, fitted and centred in the square, rendered with
//! resvg. Icons that fail to parse or render blank are skipped and counted; `aliases` are skipped.
//!
//! Captions come from names: `-`/`_` become spaces; a trailing `-N` variant number is dropped when
//! the name without it is also in the set (`man-farmer-2`); in sets whose names have no separators
//! at all (fxemoji: `sakebottleandcup`) each name is split into the fewest whole words of `VOCAB`
//! (one word per line, e.g. the MiniLM `vocab.txt`), when given.

use resvg::tiny_skia;
use serde_json::{Value, json};
use std::collections::{BTreeMap, HashSet};
use std::io::Write;
use std::path::Path;

type Res<T> = Result<T, Box<dyn std::error::Error>>;

/// Short words accepted as pieces of a split name; other pieces must have 3+ letters, so that
/// `aries` stays whole instead of becoming `ari es`.
const SHORT_WORDS: &[&str] = &[
    "a", "an", "ab", "at", "by", "cd", "do", "in", "no", "of", "ok", "on", "or", "ox", "to", "tv",
    "up", "vs",
];

/// Splits `s` into the fewest words from `vocab` (ties: earlier split points); `None` if impossible.
fn segment(s: &str, vocab: &HashSet<String>) -> Option<Vec<String>> {
    let chars: Vec<char> = s.chars().collect();
    let n = chars.len();
    // best[i] = (word count, previous split) for the prefix of length i.
    let mut best: Vec<Option<(usize, usize)>> = vec![None; n + 1];
    best[0] = Some((0, 0));
    for i in 1..=n {
        for j in i.saturating_sub(20)..i {
            let Some((c, _)) = best[j] else { continue };
            let w: String = chars[j..i].iter().collect();
            let ok = vocab.contains(&w) && (w.len() > 2 || SHORT_WORDS.contains(&w.as_str()));
            if ok && best[i].is_none_or(|(b, _)| c + 1 < b) {
                best[i] = Some((c + 1, j));
            }
        }
    }
    let mut words = Vec::new();
    let mut i = n;
    while i > 0 {
        let (_, j) = best[i]?;
        words.push(chars[j..i].iter().collect());
        i = j;
    }
    words.reverse();
    Some(words)
}

fn caption(name: &str, names: &HashSet<&str>, vocab: Option<&HashSet<String>>) -> String {
    let mut base = name;
    if let Some((stem, last)) = name.rsplit_once('-')
        && !last.is_empty()
        && last.chars().all(|c| c.is_ascii_digit())
        && names.contains(stem)
    {
        base = stem;
    }
    let words: Vec<String> = base
        .split(['-', '_'])
        .filter(|w| !w.is_empty())
        .flat_map(|w| match vocab.and_then(|v| segment(w, v)) {
            Some(ws) => ws,
            None => vec![w.to_string()],
        })
        .collect();
    words.join(" ")
}

fn num(v: &Value, key: &str, default: f64) -> f64 {
    v.get(key).and_then(Value::as_f64).unwrap_or(default)
}

/// Renders one icon to `size x size` RGB over white; `Ok(None)` if the result is blank.
fn render(svg: &str, size: u32) -> Res<Option<Vec<u8>>> {
    let tree = vectorfusion::svg::parse_usvg(svg)?;
    let mut pixmap = tiny_skia::Pixmap::new(size, size).ok_or("bad size")?;
    pixmap.fill(tiny_skia::Color::WHITE);
    let s = tree.size();
    let k = size as f32 / s.width().max(s.height());
    let (dx, dy) = (
        (size as f32 - s.width() * k) / 2.0,
        (size as f32 - s.height() * k) / 2.0,
    );
    let t = tiny_skia::Transform::from_row(k, 0.0, 0.0, k, dx, dy);
    resvg::render(&tree, t, &mut pixmap.as_mut());
    let rgb: Vec<u8> = pixmap
        .data()
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    Ok(if rgb.iter().all(|&b| b == 255) {
        None
    } else {
        Some(rgb)
    })
}

fn main() -> Res<()> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut vocab = None;
    if let Some(i) = args.iter().position(|a| a == "--words") {
        let path = args.get(i + 1).ok_or("--words needs a path")?.clone();
        let text = std::fs::read_to_string(&path)?;
        vocab = Some(
            text.lines()
                .map(str::trim)
                .filter(|w| !w.is_empty() && w.chars().all(|c| c.is_ascii_lowercase()))
                .map(str::to_string)
                .collect::<HashSet<String>>(),
        );
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
        let data: Value = serde_json::from_str(&std::fs::read_to_string(path)?)?;
        let icons = data
            .get("icons")
            .and_then(Value::as_object)
            .ok_or("no icons object")?;
        let (dw, dh) = (num(&data, "width", 16.0), num(&data, "height", 16.0));
        let names: HashSet<&str> = icons.keys().map(String::as_str).collect();
        // Segment only sets whose names carry no separators (e.g. fxemoji).
        let seps = names.iter().filter(|n| n.contains(['-', '_'])).count();
        let seg_vocab = if seps * 20 < names.len() {
            vocab.as_ref()
        } else {
            None
        };
        let (mut ok, mut failed, mut blank) = (0usize, 0usize, 0usize);
        let mut keys: Vec<&String> = icons.keys().collect();
        keys.sort();
        for name in keys {
            let icon = &icons[name];
            let Some(body) = icon.get("body").and_then(Value::as_str) else {
                failed += 1;
                continue;
            };
            let (w, h) = (num(icon, "width", dw), num(icon, "height", dh));
            let (l, t) = (num(icon, "left", 0.0), num(icon, "top", 0.0));
            let svg = format!(
                r#"<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" width="{w}" height="{h}" viewBox="{l} {t} {w} {h}">{body}</svg>"#
            );
            match render(&svg, size) {
                Ok(Some(rgb)) => {
                    images.write_all(&rgb)?;
                    let cap = caption(name, &names, seg_vocab);
                    let line = json!({"set": set, "name": name, "caption": cap});
                    writeln!(captions, "{line}")?;
                    ok += 1;
                }
                Ok(None) => blank += 1,
                Err(e) => {
                    eprintln!("{set}:{name}: {e}");
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
