//! The peer vectorisers run as processes: imagetracerjs (through node and the driver script)
//! and potrace (on PBM bytes), each probed first so that one missing here is skipped.

use super::RdArgs;
use crate::image::Image;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

/// Why a peer cannot run here, or why one of its runs failed.
#[derive(Debug, thiserror::Error)]
pub enum PeerError {
    #[error("{} has no {package} (scripts/prepare_rd_set.sh installs it; or --tools DIR)", .node_path.display())]
    MissingPackage {
        node_path: PathBuf,
        package: &'static str,
    },
    #[error("no driver script at {} (--imagetracer-script)", .0.display())]
    NoScript(PathBuf),
    /// `BIN --version` did not succeed; `hint` says how to install it.
    #[error("cannot run `{bin} --version`{hint}")]
    NotInstalled { bin: String, hint: &'static str },
    #[error("cannot create {}: {source}", .path.display())]
    Scratch {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot run {bin}: {source}")]
    Spawn { bin: String, source: std::io::Error },
    #[error("cannot write to {bin}: {source}")]
    Stdin { bin: String, source: std::io::Error },
    /// The process could not be waited for, or it exited with an error (its stderr).
    #[error("{tool} failed: {message}")]
    Failed { tool: String, message: String },
    #[error("imagetracer printed no JSON report: {0}")]
    Report(#[source] serde_json::Error),
    #[error("cannot read {}: {source}", .path.display())]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{bin}: not UTF-8: {source}")]
    NotUtf8 {
        bin: String,
        source: std::string::FromUtf8Error,
    },
}

/// Whether `bin --version` runs and succeeds.
fn answers_version(bin: &str) -> bool {
    Command::new(bin)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Where the imagetracer peer runs from.
pub struct ImageTracer {
    node: String,
    script: PathBuf,
    node_path: PathBuf,
    /// Scratch directory of its SVGs, removed by [`ImageTracer::remove_scratch`].
    scratch: PathBuf,
}

impl ImageTracer {
    /// The imagetracer peer of `a` (its packages under `--tools`, default `images/_tools`), or
    /// why it cannot run.
    pub fn probe(a: &RdArgs, images: &Path) -> Result<Self, PeerError> {
        let tools = a.tools.clone().unwrap_or_else(|| images.join("_tools"));
        let node_path = tools.join("node_modules");
        for package in ["imagetracerjs", "pngjs"] {
            if !node_path.join(package).is_dir() {
                return Err(PeerError::MissingPackage { node_path, package });
            }
        }
        if !a.imagetracer_script.is_file() {
            return Err(PeerError::NoScript(a.imagetracer_script.clone()));
        }
        if !answers_version(&a.node) {
            return Err(PeerError::NotInstalled {
                bin: a.node.clone(),
                hint: "",
            });
        }
        let scratch = std::env::temp_dir().join(format!("vf-rd-{}", std::process::id()));
        std::fs::create_dir_all(&scratch).map_err(|source| PeerError::Scratch {
            path: scratch.clone(),
            source,
        })?;
        Ok(ImageTracer {
            node: a.node.clone(),
            script: a.imagetracer_script.clone(),
            node_path,
            scratch,
        })
    }

    /// Runs the driver on `png` with `options`: `(svg, seconds)`.
    pub fn run(&self, png: &Path, options: &str) -> Result<(String, f64), PeerError> {
        let out_svg = self.scratch.join("imagetracer.svg");
        let out = Command::new(&self.node)
            .env("NODE_PATH", &self.node_path)
            .arg(&self.script)
            .arg(png)
            .arg(&out_svg)
            .arg(options)
            .output()
            .map_err(|source| PeerError::Spawn {
                bin: self.node.clone(),
                source,
            })?;
        if !out.status.success() {
            return Err(PeerError::Failed {
                tool: "imagetracer".into(),
                message: String::from_utf8_lossy(&out.stderr).trim().to_string(),
            });
        }
        let report: serde_json::Value =
            serde_json::from_slice(&out.stdout).map_err(PeerError::Report)?;
        let seconds = report["seconds"].as_f64().unwrap_or(f64::NAN);
        let svg = std::fs::read_to_string(&out_svg).map_err(|source| PeerError::Read {
            path: out_svg,
            source,
        })?;
        Ok((svg, seconds))
    }

    /// Removes the scratch directory (best effort).
    pub fn remove_scratch(&self) {
        let _ = std::fs::remove_dir_all(&self.scratch);
    }
}

/// The imagetracer grid: `(label, options JSON)`.
pub fn imagetracer_grid(colors: &[usize]) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for &n in colors {
        out.push((
            format!("n{n}"),
            format!(r#"{{"numberofcolors":{n},"over_white":true}}"#),
        ));
        out.push((
            format!("n{n} coarse"),
            format!(
                r#"{{"numberofcolors":{n},"ltres":2,"qtres":2,"pathomit":16,"roundcoords":0,"over_white":true}}"#
            ),
        ));
    }
    out
}

/// Whether the potrace binary `bin` runs here.
pub fn probe_potrace(bin: &str) -> Result<(), PeerError> {
    if answers_version(bin) {
        Ok(())
    } else {
        Err(PeerError::NotInstalled {
            bin: bin.to_string(),
            hint: " (Debian: apt-get install potrace)",
        })
    }
}

/// The potrace grid: `(label, arguments)`.
pub fn potrace_grid() -> Vec<(String, Vec<String>)> {
    let mut out = Vec::new();
    for t in [2, 8] {
        let mut push = |label: String, extra: &[&str]| {
            let mut args = vec!["-t".to_string(), t.to_string()];
            args.extend(extra.iter().map(|s| s.to_string()));
            out.push((label, args));
        };
        push(format!("t{t} a0"), &["-a", "0"]);
        push(format!("t{t} a1 O0.2"), &["-a", "1", "-O", "0.2"]);
        push(format!("t{t} a1 O1"), &["-a", "1", "-O", "1"]);
    }
    out
}

/// The image over white thresholded at luma (Rec. 601) 0.5, as binary PBM (1 = black).
pub fn to_pbm(im: &Image) -> Vec<u8> {
    let (w, h) = (im.width as usize, im.height as usize);
    let mut out = format!("P4\n{w} {h}\n").into_bytes();
    let row_bytes = w.div_ceil(8);
    for y in 0..h {
        let mut row = vec![0u8; row_bytes];
        for x in 0..w {
            let i = 4 * (y * w + x);
            let p = &im.data[i..i + 4];
            let white = 1.0 - p[3];
            let luma = 0.299 * (p[0] + white) + 0.587 * (p[1] + white) + 0.114 * (p[2] + white);
            if luma < 0.5 {
                row[x / 8] |= 0x80 >> (x % 8);
            }
        }
        out.extend_from_slice(&row);
    }
    out
}

/// Runs potrace on PBM bytes: `(svg, seconds)`.
pub fn run_potrace(bin: &str, pbm: &[u8], args: &[String]) -> Result<(String, f64), PeerError> {
    let t0 = Instant::now();
    let mut child = Command::new(bin)
        .args(["-s", "-o", "-"])
        .args(args)
        .arg("-")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|source| PeerError::Spawn {
            bin: bin.to_string(),
            source,
        })?;
    if let Some(mut stdin) = child.stdin.take() {
        stdin.write_all(pbm).map_err(|source| PeerError::Stdin {
            bin: bin.to_string(),
            source,
        })?;
    }
    let failed = |message: String| PeerError::Failed {
        tool: bin.to_string(),
        message,
    };
    let out = child
        .wait_with_output()
        .map_err(|e| failed(e.to_string()))?;
    let seconds = t0.elapsed().as_secs_f64();
    if !out.status.success() {
        return Err(failed(
            String::from_utf8_lossy(&out.stderr).trim().to_string(),
        ));
    }
    let svg = String::from_utf8(out.stdout).map_err(|source| PeerError::NotUtf8 {
        bin: bin.to_string(),
        source,
    })?;
    Ok((svg, seconds))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pbm_marks_dark_pixels_over_white() {
        let mut im = Image::filled(10, 2, [0.0, 0.0, 0.0, 1.0]);
        // Pixel 1: transparent (white over white); pixel 9: light grey.
        im.data[4..8].copy_from_slice(&[0.0, 0.0, 0.0, 0.0]);
        im.data[36..40].copy_from_slice(&[0.8, 0.8, 0.8, 1.0]);
        let pbm = to_pbm(&im);
        let head = b"P4\n10 2\n";
        assert_eq!(&pbm[..head.len()], head);
        assert_eq!(&pbm[head.len()..], &[0b1011_1111, 0b1000_0000, 0xff, 0xc0]);
    }

    #[test]
    fn a_missing_peer_says_how_to_get_it() {
        let e = probe_potrace("/nonexistent/potrace").unwrap_err();
        assert_eq!(
            e.to_string(),
            "cannot run `/nonexistent/potrace --version` (Debian: apt-get install potrace)"
        );
    }
}
