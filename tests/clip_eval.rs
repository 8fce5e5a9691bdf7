//! `vectorfusion eval` end to end on the tiny random CLIP (numbers meaningless, mechanics not).

use std::path::{Path, PathBuf};
use std::process::Command;
use vectorfusion::eval::clip::{
    EvalError, evaluate, evaluate_svg_dir, read_prompts, render_svg, render_svg_dir,
};
use vectorfusion::models::scorer::ClipScorer;
use vectorfusion::models::scorer::ImageTextScorer;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn tmpdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vf-clip-eval-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

const CAPTIONS: &[&str] = &[
    "a hot air balloon with a yin-yang symbol, with the moon visible in the daytime sky",
    "自転車",
    "a red circle. minimal flat 2d vector icon. lineal color. on a white background. trending on artstation",
    "a photograph of a fiddle next to a basketball on a ping pong table a photograph of a fiddle next to a basketball on a ping pong table a photograph of a fiddle next to a basketball on a ping pong table a basketball to the left of two soccer balls on a gravel driveway",
];

fn svg(i: usize) -> String {
    let colors = ["#e33", "#3a3", "#33e", "#fb0"];
    let mut paths = String::new();
    for k in 0..=i {
        let x = 10 + 40 * k;
        paths.push_str(&format!(
            r#"<path d="M{x} 20 L{} 180 L{} 100 Z" fill="{}"/>"#,
            x + 30,
            x + 60,
            colors[(i + k) % 4]
        ));
    }
    format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="224" height="224" viewBox="0 0 224 224">{paths}</svg>"#
    )
}

fn setup(tag: &str) -> (PathBuf, PathBuf) {
    let d = tmpdir(tag);
    let prompts = d.join("prompts.txt");
    std::fs::write(&prompts, CAPTIONS.join("\n") + "\n").unwrap();
    let svgs = d.join("svgs");
    std::fs::create_dir_all(&svgs).unwrap();
    for i in 0..CAPTIONS.len() {
        std::fs::write(svgs.join(format!("{:04}.svg", i + 1)), svg(i)).unwrap();
    }
    (prompts, svgs)
}

#[test]
fn benchmark_prompt_file_reads_and_empty_lines_are_rejected() {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/bench/svg_bench_prompts.txt");
    let p = if p.is_file() {
        p
    } else {
        PathBuf::from("/work/shared/bench/svg_bench_prompts.txt")
    };
    if p.is_file() {
        let caps = read_prompts(&p).unwrap();
        assert_eq!(caps.len(), 128);
        assert!(caps.iter().any(|c| c == "自転車"));
    }
    let d = tmpdir("empty");
    let f = d.join("p.txt");
    std::fs::write(&f, "a cat\na dog\n   \na bird\n").unwrap();
    let e = read_prompts(&f).unwrap_err();
    assert!(matches!(e, EvalError::EmptyLine { line: 3, .. }), "{e}");
    assert!(e.to_string().contains("line 3"));
}

#[test]
fn svgs_render_over_white_at_scorer_size_and_count_paths() {
    let r = render_svg(&svg(2), 32).unwrap();
    assert_eq!((r.image.width, r.image.height, r.paths), (32, 32, 3));
    // Top-left corner is empty canvas: white and opaque.
    assert_eq!(r.image.pixel(0, 0), [1.0, 1.0, 1.0, 1.0]);
    assert!(render_svg("<svg", 32).is_err());
    let (_, svgs) = setup("missing");
    std::fs::remove_file(svgs.join("0003.svg")).unwrap();
    let e = render_svg_dir(&svgs, 4, 32).unwrap_err();
    assert!(e.to_string().contains("0003.svg"), "{e}");
}

#[test]
fn eval_library_matches_direct_scoring() {
    let (prompts, svgs) = setup("lib");
    let caps = read_prompts(&prompts).unwrap();
    let scorers = vec![
        ClipScorer::load(&fixture("clip-tiny")).unwrap(),
        ClipScorer::load(&fixture("openclip-tiny")).unwrap(),
    ];
    let rep = evaluate_svg_dir(&caps, &svgs, &scorers).unwrap();
    assert_eq!(rep.prompts, 4);
    assert!((rep.mean_paths - 2.5).abs() < 1e-9);
    assert_eq!(rep.scorers.len(), 2);
    for res in &rep.scorers {
        assert_eq!(res.per_svg.len(), 4);
        assert!((0.0..=1.0).contains(&res.r_precision));
        let hits = res.per_svg.iter().filter(|s| s.hit).count() as f64 / 4.0;
        assert_eq!(res.r_precision, hits);
    }
    // Mechanics: similarity of SVG 3 with its style-stripped caption, computed directly.
    let s = &scorers[0];
    let img = render_svg(&svg(2), s.image_size()).unwrap().image;
    let direct = s
        .score_images(std::slice::from_ref(&img), "a red circle")
        .unwrap()[0]
        * 100.0;
    let got = rep.scorers[0].per_svg[2].similarity;
    assert!((direct - got).abs() < 1e-4, "{direct} vs {got}");
    let with_style = s.score_images(&[img], CAPTIONS[2]).unwrap()[0] * 100.0;
    assert!(
        (with_style - got).abs() > 1e-4,
        "style suffix must be stripped"
    );
    // Mismatched counts are an error.
    assert!(evaluate(s, &caps, &[]).is_err());
}

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn eval_cli_prints_table_and_writes_json() {
    let (prompts, svgs) = setup("cli");
    let out = prompts.with_file_name("report.json");
    let o = bin()
        .args(["eval", "--prompts", s(&prompts), "--svgs", s(&svgs)])
        .args([
            "--scorer",
            s(&fixture("clip-tiny")),
            "--scorer",
            s(&fixture("openclip-tiny")),
        ])
        .args(["--out", s(&out)])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        stdout.contains("R-Precision") && stdout.contains("clip-tiny"),
        "{stdout}"
    );
    assert!(
        stdout.contains("openclip-tiny") && stdout.contains("2.5 paths/SVG"),
        "{stdout}"
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(v["prompts"], 4);
    assert_eq!(v["scorers"].as_array().unwrap().len(), 2);
    assert_eq!(v["scorers"][0]["per_svg"].as_array().unwrap().len(), 4);

    let o = bin()
        .args([
            "eval",
            "--prompts",
            s(&prompts),
            "--svgs",
            s(&svgs),
            "--json",
        ])
        .args(["--scorer", s(&fixture("clip-tiny"))])
        .output()
        .unwrap();
    assert!(o.status.success());
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(v["scorers"][0]["mean_similarity"].is_number());
}

#[test]
fn eval_cli_errors_are_clear() {
    let (prompts, svgs) = setup("clierr");
    let o = bin()
        .args(["eval", "--prompts", s(&prompts), "--method", "sd_live"])
        .args(["--scorer", s(&fixture("clip-tiny"))])
        .env("VF_DEFAULT_MODEL", prompts.with_file_name("no-model-here"))
        .output()
        .unwrap();
    // Generating needs a model: without --model the default model is used, and a default
    // that is not a model directory is a usage error naming the variable
    // (`tests/eval_generate.rs` runs generation end to end).
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("VF_DEFAULT_MODEL"));

    let bad = prompts.with_file_name("bad.txt");
    std::fs::write(&bad, "a cat\n\na dog\n").unwrap();
    let o = bin()
        .args(["eval", "--prompts", s(&bad), "--svgs", s(&svgs)])
        .args(["--scorer", s(&fixture("clip-tiny"))])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("line 2 is empty"));

    let o = bin()
        .args(["eval", "--prompts", s(&prompts), "--svgs", s(&svgs)])
        .env("HF_HUB_OFFLINE", "1")
        .args(["--scorer", "./no/such-model"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("does not exist"));
}

#[test]
fn eval_cli_loads_scorer_from_hub_cache_offline() {
    let (prompts, svgs) = setup("hub");
    let home = prompts.with_file_name("hf_home");
    let repo = home.join("hub/models--tiny--clip-tiny");
    let snap = repo.join("snapshots/0123abcd");
    std::fs::create_dir_all(&snap).unwrap();
    std::fs::create_dir_all(repo.join("refs")).unwrap();
    std::fs::write(repo.join("refs/main"), "0123abcd").unwrap();
    for f in [
        "config.json",
        "model.safetensors",
        "vocab.json",
        "merges.txt",
        "tokenizer_config.json",
        "preprocessor_config.json",
    ] {
        std::fs::copy(fixture("clip-tiny").join(f), snap.join(f)).unwrap();
    }
    let o = bin()
        .env("HF_HOME", &home)
        .env("HF_HUB_OFFLINE", "1")
        .args([
            "eval",
            "--prompts",
            s(&prompts),
            "--svgs",
            s(&svgs),
            "--json",
        ])
        .args(["--scorer", "tiny/clip-tiny"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["scorers"][0]["scorer"], "tiny/clip-tiny");

    // A repo that is not cached, with downloads off: the error lists what is missing.
    let o = bin()
        .env("HF_HOME", &home)
        .env("HF_HUB_OFFLINE", "1")
        .args(["eval", "--prompts", s(&prompts), "--svgs", s(&svgs)])
        .args(["--scorer", "nobody/not-cached"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("config.json") && err.contains("HF_HUB_OFFLINE"),
        "{err}"
    );
}
