//! `vectorfusion generate` with the analytic TEST teacher and with the tiny Stable Diffusion
//! fixture (`--model`): writes a valid, NaN-free SVG and snapshots; bad input is a clear error.

mod common;

use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_vectorfusion"))
}

fn tmpdir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("vf-sds-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn generate_with_analytic_teacher_writes_svg_and_snapshots() {
    let dir = tmpdir("ok");
    let targets = common::red_square_targets(&dir);
    let out = dir.join("out.svg");
    let snaps = dir.join("snaps");
    for style in ["iconography", "pixel-art", "sketch", "low-poly", "painting"] {
        let st = bin()
            .args([
                "generate",
                "a red square",
                "--method",
                "scratch",
                "--style",
                style,
            ])
            .arg("--teacher")
            .arg(format!("analytic:{}", targets.display()))
            .args([
                "--size", "32", "--steps", "20", "--paths", "8", "--seed", "3",
            ])
            .arg("-o")
            .arg(&out)
            .arg("--snapshots")
            .arg(&snaps)
            .args(["--snapshot-every", "10"])
            .output()
            .unwrap();
        assert!(
            st.status.success(),
            "{style}: {}",
            String::from_utf8_lossy(&st.stderr)
        );
        let svg = std::fs::read_to_string(&out).unwrap();
        assert!(svg.contains("<svg") && !svg.contains("NaN"), "{style}");
        vectorfusion::svg::check_safe_output(&svg).unwrap();
        let snap = std::fs::read_to_string(snaps.join("sds_00010.svg")).unwrap();
        vectorfusion::svg::check_safe_output(&snap).unwrap();
        let scene = vectorfusion::svg::from_svg(&svg).unwrap();
        assert_eq!(scene.width, 32);
        assert!(String::from_utf8_lossy(&st.stderr).contains("TEST teacher"));
        assert!(snaps.join("sds_00010.svg").exists());
        assert!(snaps.join("sds_00020.svg").exists());
    }
    let st = bin()
        .args([
            "generate", "x", "--t-min", "900", "--t-max", "100", "--size", "32",
        ])
        .arg("--teacher")
        .arg(format!("analytic:{}", targets.display()))
        .arg("-o")
        .arg(dir.join("never.svg"))
        .output()
        .unwrap();
    assert_eq!(
        st.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    assert!(String::from_utf8_lossy(&st.stderr).contains("timestep range"));
    assert!(!dir.join("never.svg").exists());
}

#[test]
fn generate_bad_input_is_a_clear_error() {
    let dir = tmpdir("err");
    let out = dir.join("o.svg");
    let st = bin()
        .args(["generate", "a cat", "--model", "/nonexistent", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    // A model directory that does not exist is bad input (exit 2) naming the path.
    assert_eq!(st.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&st.stderr).contains("/nonexistent"));
    let st = bin()
        .args(["generate", "a cat", "--teacher", "magic:x", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(st.status.code(), Some(2));
    let st = bin()
        .args(["generate", "a cat", "--teacher"])
        .arg(format!("analytic:{}", dir.join("missing").display()))
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(st.status.code(), Some(2));
    let st = bin()
        .args([
            "generate",
            "a cat",
            "--style",
            "oil",
            "--teacher",
            "analytic:x",
            "-o",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(st.status.code(), Some(2));
    let st = bin()
        .args([
            "generate",
            "a cat",
            "--t-min",
            "900",
            "--t-max",
            "100",
            "--teacher",
        ])
        .arg(format!("analytic:{}", dir.display()))
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(
        st.status.code(),
        Some(2),
        "no targets in dir is a usage error"
    );
    // An unknown device, or CUDA in a build without the `cuda` feature, is a usage error.
    let model = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sd-tiny");
    let mut devices = vec!["tpu"];
    if !cfg!(feature = "cuda") {
        devices.push("cuda");
    }
    for device in devices {
        let st = bin()
            .args(["generate", "a cat", "--device", device, "--model"])
            .arg(&model)
            .arg("-o")
            .arg(&out)
            .output()
            .unwrap();
        assert_eq!(st.status.code(), Some(2), "--device {device}");
        assert!(
            String::from_utf8_lossy(&st.stderr).contains("cuda"),
            "--device {device}: {}",
            String::from_utf8_lossy(&st.stderr)
        );
    }
    assert!(!out.exists());
}

#[test]
fn generate_with_the_tiny_model_directory() {
    let dir = tmpdir("model");
    let out = dir.join("m.svg");
    let model = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sd-tiny");
    let st = bin()
        .args([
            "generate",
            "a red cat",
            "--method",
            "scratch",
            "--style",
            "sketch",
        ])
        .arg("--model")
        .arg(&model)
        .args(["--size", "32", "--steps", "3", "--guidance", "7.5", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let svg = std::fs::read_to_string(&out).unwrap();
    let scene = vectorfusion::svg::from_svg(&svg).unwrap();
    assert_eq!(scene.shapes.len(), 16);
    assert!(!svg.contains("NaN"));
}
