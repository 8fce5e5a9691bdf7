//! The same request and seed give the same SVG, whatever the code between the request and the
//! stages looks like: SVGs of the service's submit path (`parse_submit` → executor), of
//! `generate` (the shared pipeline and the analytic test teacher) and of vectorize jobs, on the
//! tiny fixtures, against `tests/fixtures/golden/run_plan.json` (AVX2 kernels) or
//! `run_plan_avx512.json` (AVX-512 kernels).
//!
//! Both files are written by the same code on the same requests (the AVX2 one by a build with
//! `--no-default-features --features mimalloc`). Both SVGs are read back into scenes (`same`), so the spelling of
//! the numbers (absolute or relative, shorthand commands, grouping: the compact writer) does not
//! matter, and points are compared with a tolerance (`TOL` SVG units), so the last digits of
//! another CPU's cache blocking still pass while any change of behaviour (another seed, size,
//! step count, path count or init) fails. The AVX2 and AVX-512 matrix-product kernels each have
//! their golden file (`golden_path`). `VF_GOLDEN_WRITE=1` rewrites this CPU's file (only when a
//! change of output is intended, and say so in the commit).

mod common;

use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::Command;
use vectorfusion::models::kernels::cpu::CpuReport;
use vectorfusion::pipeline::{DefaultExecutor, Executor, JobContext, Limits, ModelDirs};
use vectorfusion::progress::CancelToken;
use vectorfusion::scene::{Rgba, Scene};
use vectorfusion::svg::from_svg;

/// Largest allowed difference of a coordinate or stroke width (canvases are 32–64 px).
const TOL: f64 = 0.35;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// The golden file of this process's matrix-product kernels: `gemm`'s AVX-512 micro-kernels
/// sum in another order than its AVX2 ones, and a few steps of optimisation carry that past
/// `TOL`, so each kernel path has its own file (written by the same code; both checked for the
/// same request, seed, sizes and counts).
fn golden_path() -> PathBuf {
    let name = match CpuReport::detect().gemm.as_str() {
        "avx512f" => "run_plan_avx512.json",
        _ => "run_plan.json",
    };
    fixture("golden").join(name)
}

fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vf-golden-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Largest difference of a colour channel: 8-bit RGB must match; opacities may differ by the
/// rounding of the two formats (2 decimals in the golden file, 3 since the compact writer).
const RGB_TOL: f32 = 0.5 / 255.0;
const ALPHA_TOL: f32 = 0.005 + 0.0005 + 1e-6;

fn close_color(a: Option<Rgba>, b: Option<Rgba>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => {
            let [a, b] = [a.to_array(), b.to_array()];
            (0..3).all(|i| (a[i] - b[i]).abs() <= RGB_TOL) && (a[3] - b[3]).abs() <= ALPHA_TOL
        }
        _ => false,
    }
}

/// The text of the `<metadata>` element, if any.
fn metadata(svg: &str) -> Option<&str> {
    let start = svg.find("<metadata>")? + "<metadata>".len();
    let len = svg[start..].find("</metadata>")?;
    Some(&svg[start..start + len])
}

/// Compares two SVGs by what they draw, not by how the numbers are spelled (absolute or
/// relative, shorthand commands, grouping): both are read with `from_svg`, the scenes must have
/// the same canvas, background, shapes (kind, point count, fill and stroke), every point and
/// stroke width within `TOL` and colours within `RGB_TOL`/`ALPHA_TOL`; metadata text equal.
fn same(name: &str, want: &str, got: &str) -> Result<(), String> {
    let read = |which: &str, svg: &str| {
        from_svg(svg).map_err(|e| format!("{name}: cannot read the {which} SVG: {e}\n{svg}"))
    };
    let (a, b): (Scene, Scene) = (read("golden", want)?, read("produced", got)?);
    let differ = |what: String| Err(format!("{name}: {what}\nwant {want}\n got {got}"));
    if metadata(want) != metadata(got) {
        return differ("the metadata differs".into());
    }
    if (a.width, a.height) != (b.width, b.height) {
        return differ(format!(
            "canvas {}x{}, want {}x{}",
            b.width, b.height, a.width, a.height
        ));
    }
    if !close_color(Some(a.background), Some(b.background)) {
        return differ("the background differs".into());
    }
    if a.shapes.len() != b.shapes.len() {
        return differ(format!(
            "{} shapes, want {}",
            b.shapes.len(),
            a.shapes.len()
        ));
    }
    let mut worst = 0.0f64;
    for (i, (p, q)) in a.shapes.iter().zip(&b.shapes).enumerate() {
        if p.kind != q.kind
            || p.points.len() != q.points.len()
            || p.fill.is_some() != q.fill.is_some()
            || p.stroke.is_some() != q.stroke.is_some()
        {
            return differ(format!("shape {i}'s structure differs"));
        }
        if !close_color(p.fill, q.fill)
            || !close_color(p.stroke.map(|s| s.color), q.stroke.map(|s| s.color))
        {
            return differ(format!("shape {i}'s colour differs"));
        }
        for (u, v) in p.points.iter().zip(&q.points) {
            worst = worst
                .max((u.x - v.x).abs() as f64)
                .max((u.y - v.y).abs() as f64);
        }
        if let (Some(s), Some(t)) = (p.stroke, q.stroke) {
            worst = worst.max((s.width - t.width).abs() as f64);
        }
    }
    if worst > TOL {
        return differ(format!("a number differs by {worst} (> {TOL})"));
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
    .unwrap_or_else(|e| panic!("{body}: {e:?}"))
    .spec;
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

/// The comparison looks through the spelling: every golden SVG (the old absolute format), read
/// and written again by the compact writer with every option, still compares equal, and a moved
/// point does not.
#[test]
fn the_comparison_accepts_the_compact_format() {
    use vectorfusion::svg::{SvgOptions, to_svg};
    let want: BTreeMap<String, String> =
        serde_json::from_str(&std::fs::read_to_string(golden_path()).unwrap()).unwrap();
    for (name, w) in &want {
        let scene = from_svg(w).unwrap();
        for (group_by_color, ids) in [(false, false), (true, true)] {
            let opts = SvgOptions {
                group_by_color,
                ids,
                ..SvgOptions::default()
            };
            let again = to_svg(&scene, &opts);
            same(name, w, &again).unwrap_or_else(|e| panic!("{e}"));
        }
        let mut moved = scene.clone();
        moved.shapes[0].points[0].x += 1.0;
        assert!(same(name, w, &to_svg(&moved, &SvgOptions::default())).is_err());
    }
}
