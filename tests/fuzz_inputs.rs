//! A bounded mutation fuzzer for the untrusted-input entry points (issue #21): SVG text
//! (`svg::parse_usvg`, then `svg::from_svg` for what it accepts) and uploaded images
//! (`server::types::check_image`). Seeds are real inputs and known attacks; each round mutates one
//! (byte flips, spliced attack tokens, deleted and repeated ranges) with a seeded RNG. Every
//! input must come back as `Ok` or `Err` — no panic — within `HANG` (a hang check, not a speed
//! target). `VF_FUZZ_SECS` sets each target's budget (default 15 s); `VF_FUZZ_SEED` the seed.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::time::{Duration, Instant};
use vectorfusion::pipeline::Limits;

const HANG: Duration = Duration::from_secs(10);

fn budget() -> Duration {
    let secs = std::env::var("VF_FUZZ_SECS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(15.0);
    Duration::from_secs_f64(secs)
}

fn rng(salt: u64) -> ChaCha8Rng {
    let seed: u64 = std::env::var("VF_FUZZ_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20261202);
    ChaCha8Rng::seed_from_u64(seed ^ salt)
}

const TOKENS: &[&str] = &[
    "<g>",
    "</g>",
    "<use href=\"#a\"/>",
    "<g id=\"a\"><use href=\"#a\"/></g>",
    "<!DOCTYPE svg [<!ENTITY e \"xxxxxxxx\">]>",
    "&e;",
    "1e38",
    "-1e308",
    "NaN",
    "inf",
    " transform=\"scale(1e9)\"",
    " transform=\"rotate(45) skewX(89.999)\"",
    "<pattern id=\"p\" width=\"1e-9\" height=\"1e-9\">",
    " fill=\"url(#p)\"",
    " clip-path=\"url(#a)\"",
    " filter=\"url(#f)\"",
    "<filter id=\"f\"><feGaussianBlur stdDeviation=\"1e6\"/></filter>",
    "<marker id=\"m\"><use href=\"#m\"/></marker>",
    " marker-start=\"url(#m)\"",
    "<path d=\"M0 0C1 1 2 2 3 3",
    "L",
    "Z",
    "A1e30 1e30 0 1 1",
    "<text>",
    "<![CDATA[",
    "<!--",
    "\u{0}",
    "\u{feff}",
    "<image href=\"data:image/png;base64,AAAA\"/>",
    "<style>*{stroke-width:1e30}</style>",
    " style=\"stroke-width:1e30\"",
    " stroke=\"red\" stroke-width=\"99999\"",
    " viewBox=\"0 0 0 0\"",
    " width=\"1e9\" height=\"1e9\"",
];

fn svg_seeds() -> Vec<String> {
    let svg = |body: &str| {
        format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64" viewBox="0 0 64 64">{body}</svg>"#
        )
    };
    let mut seeds = vec![
        svg(
            r##"<rect width="64" height="64" fill="#fff"/><path d="M4 4C20 0 40 0 60 4L60 60Z" fill="#e33" fill-opacity="0.8"/>"##,
        ),
        svg(
            r##"<defs><path id="a" d="M0 0L9 9"/></defs><use href="#a"/><use href="#a" transform="translate(10 10)"/>"##,
        ),
        svg(
            r##"<g stroke="#000" stroke-width="2" fill="none"><path d="M1 1Q30 60 63 1"/><circle cx="32" cy="32" r="12"/></g>"##,
        ),
        svg(
            r##"<linearGradient id="g"><stop offset="0" stop-color="red"/><stop offset="1" stop-color="blue"/></linearGradient><rect width="64" height="64" fill="url(#g)"/>"##,
        ),
        format!(
            r#"<!DOCTYPE svg [<!ENTITY a "{}">]>{}"#,
            "x".repeat(64),
            svg("<text>&a;&a;</text>")
        ),
    ];
    let golden: serde_json::Value =
        serde_json::from_str(include_str!("fixtures/golden/run_plan.json")).expect("golden SVGs");
    if let Some(map) = golden.as_object() {
        seeds.extend(
            map.values()
                .filter_map(|v| v.as_str())
                .take(6)
                .map(str::to_string),
        );
    }
    seeds
}

fn mutate(input: &[u8], r: &mut ChaCha8Rng) -> Vec<u8> {
    let mut b = input.to_vec();
    for _ in 0..r.random_range(1..=4) {
        let n = b.len().max(1);
        match r.random_range(0..5) {
            0 => {
                let i = r.random_range(0..n).min(b.len().saturating_sub(1));
                if let Some(x) = b.get_mut(i) {
                    *x ^= 1 << r.random_range(0..8);
                }
            }
            1 | 2 => {
                let t = TOKENS[r.random_range(0..TOKENS.len())].as_bytes();
                let i = r.random_range(0..=b.len());
                b.splice(i..i, t.iter().copied());
            }
            3 => {
                let i = r.random_range(0..=b.len());
                let j = (i + r.random_range(0..32)).min(b.len());
                b.drain(i..j);
            }
            _ => {
                let i = r.random_range(0..=b.len());
                let j = (i + r.random_range(0..64)).min(b.len());
                let piece = b[i..j].to_vec();
                for _ in 0..r.random_range(1..8) {
                    b.splice(j..j, piece.iter().copied());
                }
            }
        }
    }
    b
}

/// Runs `check` on mutations of `seeds` for [`budget`]; returns how many inputs it tried.
fn fuzz(name: &str, salt: u64, seeds: &[Vec<u8>], check: impl Fn(&[u8])) -> usize {
    let mut r = rng(salt);
    let end = Instant::now() + budget();
    let mut tried = 0;
    while Instant::now() < end {
        let seed = &seeds[r.random_range(0..seeds.len())];
        let input = mutate(seed, &mut r);
        let t = Instant::now();
        let outcome = catch_unwind(AssertUnwindSafe(|| check(&input)));
        let took = t.elapsed();
        assert!(
            outcome.is_ok(),
            "{name}: panicked on input {tried} (seed {:?}): {:?}",
            std::env::var("VF_FUZZ_SEED").ok(),
            String::from_utf8_lossy(&input)
        );
        assert!(
            took < HANG,
            "{name}: input {tried} took {took:?}: {:?}",
            String::from_utf8_lossy(&input[..input.len().min(2000)])
        );
        tried += 1;
    }
    eprintln!("{name}: {tried} inputs, no panic, none over {HANG:?}");
    tried
}

#[test]
fn mutated_svgs_are_parsed_or_refused_without_panics_or_hangs() {
    let seeds: Vec<Vec<u8>> = svg_seeds().into_iter().map(String::into_bytes).collect();
    let n = fuzz("svg", 1, &seeds, |bytes| {
        let text = String::from_utf8_lossy(bytes);
        if vectorfusion::svg::parse_usvg(&text).is_ok() {
            let _ = vectorfusion::svg::from_svg(&text);
        }
    });
    assert!(n > 0);
}

#[test]
fn mutated_images_are_decoded_or_refused_without_panics_or_hangs() {
    let mut seeds = Vec::new();
    for (w, h) in [(8u32, 8u32), (33, 17), (64, 64)] {
        let img = image::RgbaImage::from_fn(w, h, |x, y| {
            image::Rgba([
                (x as u8).wrapping_mul(7),
                (y as u8).wrapping_mul(5),
                90,
                255,
            ])
        });
        let mut png = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        seeds.push(png);
        let rgb = image::DynamicImage::ImageRgba8(img).to_rgb8();
        let mut jpg = Vec::new();
        rgb.write_to(
            &mut std::io::Cursor::new(&mut jpg),
            image::ImageFormat::Jpeg,
        )
        .unwrap();
        seeds.push(jpg);
    }
    let limits = Limits::default();
    let n = fuzz("image", 2, &seeds, |bytes| {
        let _ = vectorfusion::server::types::check_image(bytes, &limits);
    });
    assert!(n > 0);
}
