//! The same request and seed give the same SVG, whatever the code between the request and the
//! stages looks like: SVGs of the service's submit path (`parse_submit` → executor), of
//! `generate` (the shared pipeline and the analytic test teacher) and of vectorize jobs, on the
//! tiny fixtures, against `tests/fixtures/golden/run_plan.json`.
//!
//! The golden file was written by the code before the run-plan refactor (issue #20); the
//! refactor had to reproduce it. Numbers are compared with a tolerance (`TOL` SVG units), so a
//! CPU with other SIMD kernels (AVX2 vs AVX-512 rounding) still passes while any change of
//! behaviour (another seed, size, step count, path count or init) fails. `VF_GOLDEN_WRITE=1`
//! rewrites the file (only when a change of output is intended, and say so in the commit).

mod common;

use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::Command;
use vectorfusion::pipeline::{DefaultExecutor, Executor, JobContext, Limits, ModelDirs};
use vectorfusion::progress::CancelToken;

/// Largest allowed difference of any number in an SVG (coordinates are on 32–64 px canvases).
const TOL: f64 = 0.35;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn golden_path() -> PathBuf {
    fixture("golden").join("run_plan.json")
}

fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vf-golden-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Every number in `svg`, in order.
fn numbers(svg: &str) -> Vec<f64> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let flush = |cur: &mut String, out: &mut Vec<f64>| {
        if let Ok(v) = cur.parse::<f64>() {
            out.push(v);
        }
        cur.clear();
    };
    for ch in svg.chars() {
        if ch.is_ascii_digit()
            || ch == '.'
            || (ch == '-' && cur.is_empty())
            || ch == 'e' && !cur.is_empty()
        {
            cur.push(ch);
        } else {
            flush(&mut cur, &mut out);
            if ch == '-' {
                cur.push(ch);
            }
        }
    }
    flush(&mut cur, &mut out);
    out
}

fn same(name: &str, want: &str, got: &str) -> Result<(), String> {
    let strip = |s: &str| {
        s.chars()
            .filter(|c| !c.is_ascii_digit() && !matches!(c, '.' | '-' | 'e'))
            .collect::<String>()
    };
    if strip(want) != strip(got) {
        return Err(format!(
            "{name}: the SVG's structure differs\nwant {want}\n got {got}"
        ));
    }
    let (a, b) = (numbers(want), numbers(got));
    if a.len() != b.len() {
        return Err(format!("{name}: {} numbers, want {}", b.len(), a.len()));
    }
    let worst = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f64, f64::max);
    if worst > TOL {
        return Err(format!(
            "{name}: a number differs by {worst} (> {TOL})\nwant {want}\n got {got}"
        ));
    }
    Ok(())
}

fn executor() -> DefaultExecutor {
    DefaultExecutor::new(ModelDirs {
        sd_dir: Some(fixture("sd-tiny")),
        clip_dir: Some(fixture("clip-tiny")),
        ..ModelDirs::default()
    })
}

fn icon_b64() -> String {
    use base64::Engine;
    let bytes = std::fs::read(fixture("iconclip-tiny/icon64.png")).unwrap();
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

/// A job submitted as the service receives it, run by the executor.
fn service_job(exec: &DefaultExecutor, body: Value) -> String {
    let spec = vectorfusion::server::types::parse_submit(
        body.to_string().as_bytes(),
        &Limits::default(),
        11,
        exec,
    )
    .unwrap_or_else(|e| panic!("{body}: {e:?}"));
    exec.run(&spec, &JobContext::detached(CancelToken::new()))
        .unwrap_or_else(|e| panic!("{body}: {e}"))
        .svg
}

fn generate(args: &[&str], dir: &std::path::Path) -> String {
    let out = dir.join("out.svg");
    let st = Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
        .arg("generate")
        .args(args)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&st.stderr)
    );
    std::fs::read_to_string(&out).unwrap()
}

fn produce() -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    let exec = executor();
    for method in ["scratch", "sd_live", "sd_live_sds"] {
        for style in ["iconography", "pixel_art", "sketch"] {
            let body = json!({"kind": "text", "caption": "a crown", "method": method,
                "style": style, "preset": "draft", "steps": 4, "samples": 2, "seed": 7});
            out.insert(
                format!("service/{method}/{style}"),
                service_job(&exec, body),
            );
        }
    }
    // Preset-resolved paths/steps/samples (nothing explicit but the preset).
    out.insert(
        "service/draft-defaults".into(),
        service_job(
            &exec,
            json!({"kind": "text", "caption": "a red heart", "preset": "draft"}),
        ),
    );
    let svg = out["service/sd_live/iconography"].clone();
    out.insert(
        "service/from-svg".into(),
        service_job(
            &exec,
            json!({"kind": "text", "caption": "a crown", "svg": svg, "preset": "draft",
                "steps": 3, "seed": 5}),
        ),
    );
    out.insert(
        "service/vectorize".into(),
        service_job(
            &exec,
            json!({"kind": "vectorize", "image": icon_b64(), "preset": "draft", "paths": 6, "seed": 2}),
        ),
    );
    out.insert(
        "service/vectorize-caption".into(),
        service_job(
            &exec,
            json!({"kind": "vectorize", "image": icon_b64(), "caption": "an icon",
                "preset": "draft", "paths": 6, "steps": 3, "seed": 2}),
        ),
    );
    let pixel = DefaultExecutor::new(ModelDirs {
        sd_dir: Some(fixture("sd-tiny-pixel")),
        clip_dir: Some(fixture("clip-tiny")),
        ..ModelDirs::default()
    });
    out.insert(
        "service/small-prior".into(),
        service_job(
            &pixel,
            json!({"kind": "text", "caption": "a crown", "preset": "draft", "seed": 4}),
        ),
    );

    // The command line: the analytic test teacher (plain scratch) and the tiny SD model.
    let dir = tmpdir("cli");
    let targets = common::red_square_targets(&dir);
    let analytic = format!("analytic:{}", targets.display());
    for style in ["iconography", "pixel-art", "sketch"] {
        out.insert(
            format!("cli/analytic/{style}"),
            generate(
                &[
                    "a red square",
                    "--teacher",
                    &analytic,
                    "--style",
                    style,
                    "--size",
                    "32",
                    "--steps",
                    "12",
                    "--paths",
                    "6",
                    "--seed",
                    "3",
                ],
                &dir,
            ),
        );
    }
    let sd = fixture("sd-tiny");
    let clip = fixture("clip-tiny");
    out.insert(
        "cli/sd-tiny/draft".into(),
        generate(
            &[
                "a crown",
                "--model",
                sd.to_str().unwrap(),
                "--scorer",
                clip.to_str().unwrap(),
                "--preset",
                "draft",
                "--steps",
                "4",
                "--seed",
                "9",
            ],
            &dir,
        ),
    );
    out
}

#[test]
fn the_same_request_gives_the_same_svg() {
    let got = produce();
    if std::env::var_os("VF_GOLDEN_WRITE").is_some() {
        std::fs::create_dir_all(golden_path().parent().unwrap()).unwrap();
        std::fs::write(
            golden_path(),
            serde_json::to_string_pretty(&got).unwrap() + "\n",
        )
        .unwrap();
        eprintln!("wrote {}", golden_path().display());
        return;
    }
    let want: BTreeMap<String, String> =
        serde_json::from_str(&std::fs::read_to_string(golden_path()).unwrap()).unwrap();
    let mut errors = Vec::new();
    for (name, w) in &want {
        match got.get(name) {
            Some(g) => {
                if let Err(e) = same(name, w, g) {
                    errors.push(e);
                }
            }
            None => errors.push(format!("{name}: not produced")),
        }
    }
    assert!(errors.is_empty(), "{}", errors.join("\n\n"));
}
