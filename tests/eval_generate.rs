//! `vectorfusion eval --method`: generate one SVG per caption with the shared pipeline on the
//! tiny random Stable Diffusion fixture, then score them with the tiny random CLIP (numbers
//! meaningless, mechanics not).

use std::path::{Path, PathBuf};
use std::process::Command;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
}

#[test]
fn eval_method_generates_then_scores_every_method() {
    let dir = tempfile::tempdir().unwrap();
    let prompts = dir.path().join("prompts.txt");
    std::fs::write(&prompts, "a crown\na red apple\na blue car\n").unwrap();
    let out_dir = dir.path().join("out");
    let report = dir.path().join("report.json");
    let o = bin()
        .args(["eval", "--prompts", s(&prompts), "--json"])
        .args(["--method", "sd_live", "--method", "sd_live_sds"])
        .args(["--preset", "draft", "--steps", "4", "--limit", "2"])
        .args(["--model", s(&fixture("sd-tiny"))])
        .args(["--rerank-scorer", s(&fixture("clip-tiny"))])
        .args(["--scorer", s(&fixture("clip-tiny"))])
        .args(["--out-dir", s(&out_dir), "--out", s(&report)])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let file: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(v, file);
    assert_eq!(v["prompts"], 2);
    assert_eq!(v["preset"], "draft");
    let methods = v["methods"].as_array().unwrap();
    assert_eq!(methods.len(), 2);
    for (m, name) in methods.iter().zip(["sd_live", "sd_live_sds"]) {
        assert_eq!(m["method"], name);
        assert_eq!(m["prompts"], 2);
        // --limit 2: two SVGs, named by prompt line, and no third.
        for line in ["0001.svg", "0002.svg"] {
            let svg = std::fs::read_to_string(out_dir.join(name).join(line)).unwrap();
            assert!(svg.starts_with("<svg"), "{svg}");
        }
        assert!(!out_dir.join(name).join("0003.svg").exists());
        assert!(m["mean_seconds"].as_f64().unwrap() > 0.0, "{m}");
        assert!(m["mean_paths"].as_f64().unwrap() >= 1.0, "{m}");
        let sc = &m["scorers"][0];
        let rp = sc["r_precision"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&rp), "{sc}");
        assert!(sc["mean_similarity"].as_f64().unwrap().is_finite());
        assert_eq!(sc["per_svg"].as_array().unwrap().len(), 2);
    }

    // The table: one row per method with paths and seconds per SVG.
    let o = bin()
        .args(["eval", "--prompts", s(&prompts)])
        .args(["--method", "scratch", "--preset", "draft", "--steps", "2"])
        .args(["--limit", "2", "--model", s(&fixture("sd-tiny"))])
        .args(["--scorer", s(&fixture("clip-tiny"))])
        .args(["--out-dir", s(&out_dir), "--json", s(&report)])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // `--json OUT` writes the report and still prints the table.
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(v["methods"][0]["method"], "scratch");
    let table = String::from_utf8_lossy(&o.stdout);
    let lines: Vec<&str> = table.lines().collect();
    assert!(
        lines[1].contains("paths/SVG") && lines[1].contains("s/SVG"),
        "{table}"
    );
    assert!(lines[2].starts_with("scratch"), "{table}");
    assert!(out_dir.join("scratch/0002.svg").is_file());
}

#[test]
fn eval_method_rejects_empty_lines_and_missing_models() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.txt");
    std::fs::write(&bad, "a cat\n\na dog\n").unwrap();
    let o = bin()
        .args(["eval", "--prompts", s(&bad), "--method", "sd_live"])
        .args(["--model", s(&fixture("sd-tiny"))])
        .args(["--scorer", s(&fixture("clip-tiny"))])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("line 2 is empty"));

    let good = dir.path().join("good.txt");
    std::fs::write(&good, "a cat\n").unwrap();
    let o = bin()
        .args(["eval", "--prompts", s(&good), "--method", "sd_live"])
        .args(["--model", s(&dir.path().join("no-such-model"))])
        .args(["--scorer", s(&fixture("clip-tiny"))])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{o:?}");
    assert!(String::from_utf8_lossy(&o.stderr).contains("no-such-model"));
    let o = bin()
        .args(["eval", "--prompts", s(&good), "--method", "diffuse"])
        .args(["--model", s(&fixture("sd-tiny"))])
        .args(["--scorer", s(&fixture("clip-tiny"))])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{o:?}");
}

/// `--method samples`: the raster row of Table 1. The rerank scorer's pick of K samples per
/// caption is saved as NNNN.png and scored as an image; the same seed draws the same picture.
#[test]
fn eval_samples_row_scores_the_reranked_raster_samples() {
    let dir = tempfile::tempdir().unwrap();
    let prompts = dir.path().join("prompts.txt");
    std::fs::write(&prompts, "a crown\na red apple\n").unwrap();
    let run = |out: &Path| {
        let o = bin()
            .args(["eval", "--prompts", s(&prompts), "--json"])
            .args(["--method", "samples", "--preset", "draft", "--samples", "3"])
            .args(["--model", s(&fixture("sd-tiny"))])
            .args(["--rerank-scorer", s(&fixture("clip-tiny"))])
            .args(["--scorer", s(&fixture("clip-tiny"))])
            .args(["--out-dir", s(out)])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()
    };
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let v = run(&a);
    let m = &v["methods"][0];
    assert_eq!(m["method"], "samples");
    assert_eq!(m["mean_paths"], 0.0);
    assert!(m["mean_seconds"].as_f64().unwrap() > 0.0, "{m}");
    let sc = &m["scorers"][0];
    assert_eq!(sc["per_svg"].as_array().unwrap().len(), 2);
    assert!(sc["mean_similarity"].as_f64().unwrap().is_finite(), "{sc}");
    let png = |d: &Path, f: &str| std::fs::read(d.join("samples").join(f)).unwrap();
    let first = png(&a, "0001.png");
    assert!(first.starts_with(b"\x89PNG"));
    assert_ne!(
        first,
        png(&a, "0002.png"),
        "each caption line has its own seed"
    );
    run(&b);
    assert_eq!(first, png(&b, "0001.png"), "seeded: the same sample again");
}
