//! Resolving a diffusers-layout model (local directory or Hugging Face hub repo), reading its
//! configs and memory-mapping its safetensors weights.

use super::{ModelError, Result};
use candle_core::{DType, Device};
use candle_nn::VarBuilder;
use serde::de::DeserializeOwned;
use std::path::{Path, PathBuf};

/// Numeric precision of one component's weights and activations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    #[default]
    F32,
    F16,
    Bf16,
}

impl Precision {
    pub fn dtype(self) -> DType {
        match self {
            Precision::F32 => DType::F32,
            Precision::F16 => DType::F16,
            Precision::Bf16 => DType::BF16,
        }
    }
}

/// A precision name that is none of f32, f16, bf16.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown precision {0:?} (f32, f16, bf16)")]
pub struct UnknownPrecision(pub String);

impl std::str::FromStr for Precision {
    type Err = UnknownPrecision;
    fn from_str(s: &str) -> std::result::Result<Self, UnknownPrecision> {
        match s.to_ascii_lowercase().as_str() {
            "f32" | "fp32" => Ok(Self::F32),
            "f16" | "fp16" => Ok(Self::F16),
            "bf16" => Ok(Self::Bf16),
            other => Err(UnknownPrecision(other.to_string())),
        }
    }
}

/// Why a device setting cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DeviceError {
    /// Not a device name.
    #[error("unknown device {0:?} (expected cpu, cuda or cuda:N)")]
    Unknown(String),
    /// A CUDA device in a build without the `cuda` feature.
    #[error(
        "device {0} needs a build with CUDA support: cargo build --release --features cuda \
         (see docs/MODELS.md)"
    )]
    NotBuilt(ComputeDevice),
}

/// Where the models run: `cpu` (the default) or `cuda` / `cuda:N`, a CUDA GPU, in builds with
/// the `cuda` cargo feature. On the CPU, f32 layers run on our kernels ([`super::kernels`]);
/// elsewhere the same graphs run on candle's ops.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum ComputeDevice {
    #[default]
    Cpu,
    /// CUDA device ordinal.
    Cuda(usize),
}

impl ComputeDevice {
    /// Whether this build can open the device: always for the CPU; for CUDA only with the
    /// `cuda` feature (whether a GPU is present is known only when [`Self::open`] tries).
    pub fn check_built(self) -> std::result::Result<(), DeviceError> {
        match self {
            ComputeDevice::Cpu => Ok(()),
            ComputeDevice::Cuda(_) if cfg!(feature = "cuda") => Ok(()),
            ComputeDevice::Cuda(_) => Err(DeviceError::NotBuilt(self)),
        }
    }

    /// Parses `s` and refuses a device this build cannot open ([`Self::check_built`]): what a
    /// setting or a flag naming the device should accept.
    pub fn parse_built(s: &str) -> std::result::Result<Self, DeviceError> {
        let d: Self = s.parse()?;
        d.check_built()?;
        Ok(d)
    }

    /// Opens the candle device.
    pub fn open(self) -> Result<Device> {
        self.check_built().map_err(|e| ModelError::Unsupported {
            component: "device",
            path: self.to_string(),
            reason: e.to_string(),
        })?;
        match self {
            ComputeDevice::Cpu => Ok(Device::Cpu),
            ComputeDevice::Cuda(n) => Device::new_cuda(n).map_err(|e| ModelError::Unsupported {
                component: "device",
                path: self.to_string(),
                reason: format!("cannot open CUDA device {n}: {e}"),
            }),
        }
    }
}

impl std::fmt::Display for ComputeDevice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ComputeDevice::Cpu => f.write_str("cpu"),
            ComputeDevice::Cuda(n) => write!(f, "cuda:{n}"),
        }
    }
}

impl std::str::FromStr for ComputeDevice {
    type Err = DeviceError;
    fn from_str(s: &str) -> std::result::Result<Self, DeviceError> {
        let t = s.trim().to_ascii_lowercase();
        match t.as_str() {
            "cpu" => Ok(Self::Cpu),
            "cuda" | "gpu" => Ok(Self::Cuda(0)),
            _ => t
                .strip_prefix("cuda:")
                .and_then(|n| n.parse().ok())
                .map(Self::Cuda)
                .ok_or_else(|| DeviceError::Unknown(s.to_string())),
        }
    }
}

impl TryFrom<String> for ComputeDevice {
    type Error = DeviceError;
    fn try_from(s: String) -> std::result::Result<Self, DeviceError> {
        s.parse()
    }
}

impl From<ComputeDevice> for String {
    fn from(d: ComputeDevice) -> String {
        d.to_string()
    }
}

/// Where the model comes from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ModelSource {
    /// A local diffusers directory (`model_index.json`, `unet/`, `vae/`, ...).
    Dir(PathBuf),
    /// A hub repo id such as `stabilityai/sd-turbo`, fetched into the usual HF cache.
    Hub { repo: String, revision: String },
}

impl ModelSource {
    /// An existing path is a directory source; otherwise `org/name[@revision]` is a hub repo.
    pub fn parse(s: &str) -> Self {
        let p = Path::new(s);
        if p.exists() || s.starts_with('.') || s.starts_with('/') || s.matches('/').count() != 1 {
            return Self::Dir(p.to_path_buf());
        }
        let (repo, revision) = match s.split_once('@') {
            Some((r, v)) => (r.to_string(), v.to_string()),
            None => (s.to_string(), "main".to_string()),
        };
        Self::Hub { repo, revision }
    }
}

/// Options for [`super::StableDiffusion::load`].
#[derive(Debug, Clone)]
pub struct LoadOptions {
    pub device: Device,
    pub unet: Precision,
    pub vae: Precision,
    pub text: Precision,
    /// Use this TAESD directory (`AutoencoderTiny` layout) as the codec instead of the model's
    /// VAE (precision `vae`); ignored by pixel-space models.
    pub taesd: Option<PathBuf>,
    /// Allow downloading missing files from the hub (otherwise only the local cache is used).
    pub allow_download: bool,
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            device: Device::Cpu,
            unet: Precision::F32,
            vae: Precision::F32,
            text: Precision::F32,
            taesd: None,
            allow_download: true,
        }
    }
}

/// Weight file names accepted for a component, in order of preference.
pub const UNET_WEIGHTS: &[&str] = &[
    "diffusion_pytorch_model.safetensors",
    "diffusion_pytorch_model.fp16.safetensors",
];
pub const TEXT_WEIGHTS: &[&str] = &["model.safetensors", "model.fp16.safetensors"];

/// Reads and parses a JSON config.
pub fn read_config<T: DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        if e.kind() == std::io::ErrorKind::NotFound {
            ModelError::MissingFiles {
                what: "config".into(),
                missing: vec![path.display().to_string()],
                hint: "a diffusers model directory needs a config.json per component".into(),
            }
        } else {
            ModelError::Config {
                path: path.display().to_string(),
                reason: e.to_string(),
            }
        }
    })?;
    serde_json::from_str(&text).map_err(|e| ModelError::Config {
        path: path.display().to_string(),
        reason: e.to_string(),
    })
}

/// The first of `names` present in `dir`, or a [`ModelError::MissingFiles`].
pub fn find_weights(dir: &Path, names: &[&str]) -> Result<PathBuf> {
    for n in names {
        let p = dir.join(n);
        if p.is_file() {
            return Ok(p);
        }
    }
    let has_bin = std::fs::read_dir(dir)
        .map(|rd| {
            rd.flatten()
                .any(|e| e.path().extension().is_some_and(|x| x == "bin"))
        })
        .unwrap_or(false);
    let hint = if has_bin {
        "only PyTorch .bin weights were found; convert them to safetensors \
         (e.g. diffusers `save_pretrained(..., safe_serialization=True)`)"
            .to_string()
    } else {
        format!("put one of {names:?} in {}", dir.display())
    };
    Err(ModelError::MissingFiles {
        what: dir.display().to_string(),
        missing: names
            .iter()
            .map(|n| dir.join(n).display().to_string())
            .collect(),
        hint,
    })
}

/// Memory-maps a safetensors file as a [`VarBuilder`] producing `dtype` tensors on `device`.
/// A file that is not valid safetensors gives [`ModelError::CorruptWeights`].
pub fn var_builder(path: &Path, dtype: DType, device: &Device) -> Result<VarBuilder<'static>> {
    // Validate the header first so a truncated/garbage file gets a clear error.
    check_safetensors(path)?;
    // SAFETY: the file is memory-mapped read-only; like every mmap-based loader we rely on it
    // not being modified while the model is alive.
    let st = unsafe { candle_core::safetensors::MmapedSafetensors::new(path) }.map_err(|e| {
        ModelError::CorruptWeights {
            path: path.display().to_string(),
            reason: e.to_string(),
        }
    })?;
    Ok(VarBuilder::from_backend(
        Box::new(st),
        dtype,
        device.clone(),
    ))
}

fn check_safetensors(path: &Path) -> Result<()> {
    use std::io::Read;
    let corrupt = |reason: String| ModelError::CorruptWeights {
        path: path.display().to_string(),
        reason,
    };
    let mut f = std::fs::File::open(path).map_err(|e| corrupt(e.to_string()))?;
    let file_len = f.metadata().map_err(|e| corrupt(e.to_string()))?.len();
    let mut len = [0u8; 8];
    f.read_exact(&mut len)
        .map_err(|_| corrupt("file shorter than a safetensors header".into()))?;
    let n = u64::from_le_bytes(len);
    if n == 0 || n > 100_000_000 || 8 + n > file_len {
        return Err(corrupt(format!(
            "header length {n} does not fit a {file_len}-byte file"
        )));
    }
    let mut header = vec![0u8; n as usize];
    f.read_exact(&mut header)
        .map_err(|e| corrupt(e.to_string()))?;
    let v: serde_json::Value =
        serde_json::from_slice(&header).map_err(|e| corrupt(format!("header is not JSON: {e}")))?;
    // every tensor's data must lie inside the file
    let data_len = file_len - 8 - n;
    if let Some(obj) = v.as_object() {
        for (name, t) in obj {
            if name == "__metadata__" {
                continue;
            }
            let end = t
                .get("data_offsets")
                .and_then(|o| o.get(1))
                .and_then(|e| e.as_u64())
                .ok_or_else(|| corrupt(format!("tensor {name} has no data_offsets")))?;
            if end > data_len {
                return Err(corrupt(format!(
                    "tensor {name} ends at byte {end} but the data section has {data_len} bytes (truncated file?)"
                )));
            }
        }
    }
    Ok(())
}

/// Loads the autoencoder in `dir` (`config.json` + `diffusion_pytorch_model.safetensors`): its
/// config, checked by `validate`, then `build` on the weights. Errors name `component`.
pub fn load_autoencoder<C: DeserializeOwned, M>(
    dir: &Path,
    component: &'static str,
    validate: impl FnOnce(&C) -> std::result::Result<(), super::ConfigIssue>,
    (precision, device): (Precision, &Device),
    build: impl FnOnce(VarBuilder<'static>, C) -> candle_core::Result<M>,
) -> Result<M> {
    let cfg_path = dir.join("config.json");
    let cfg: C = read_config(&cfg_path)?;
    validate(&cfg).map_err(|e| ModelError::Unsupported {
        component,
        path: cfg_path.display().to_string(),
        reason: e.to_string(),
    })?;
    let w = find_weights(dir, UNET_WEIGHTS)?;
    let vb = var_builder(&w, precision.dtype(), device)?;
    build(vb, cfg).map_err(mismatch(component, &w))
}

/// Maps a candle error raised while building a component into a weight-mismatch error.
pub fn mismatch(component: &'static str, path: &Path) -> impl Fn(candle_core::Error) -> ModelError {
    let path = path.display().to_string();
    move |e| ModelError::WeightMismatch {
        component,
        path: path.clone(),
        reason: e.to_string(),
    }
}

/// Files a full Stable Diffusion pipeline needs (relative to the model root); the weights of
/// each component may be any of the accepted names.
pub fn required_files() -> Vec<(&'static str, &'static [&'static str])> {
    vec![
        ("model_index.json", &["model_index.json"][..]),
        ("unet/config.json", &["unet/config.json"][..]),
        (
            "unet weights",
            &[
                "unet/diffusion_pytorch_model.safetensors",
                "unet/diffusion_pytorch_model.fp16.safetensors",
            ][..],
        ),
        ("vae/config.json", &["vae/config.json"][..]),
        (
            "vae weights",
            &[
                "vae/diffusion_pytorch_model.safetensors",
                "vae/diffusion_pytorch_model.fp16.safetensors",
            ][..],
        ),
        (
            "scheduler/scheduler_config.json",
            &["scheduler/scheduler_config.json"][..],
        ),
        (
            "text_encoder/config.json",
            &["text_encoder/config.json"][..],
        ),
        (
            "text_encoder weights",
            &[
                "text_encoder/model.safetensors",
                "text_encoder/model.fp16.safetensors",
            ][..],
        ),
        ("tokenizer/vocab.json", &["tokenizer/vocab.json"][..]),
        ("tokenizer/merges.txt", &["tokenizer/merges.txt"][..]),
    ]
}

/// Resolves a source to a local model root directory. For hub sources each required file is
/// taken from the HF cache or (if `allow_download`) downloaded; what cannot be had is listed.
pub fn resolve(source: &ModelSource, allow_download: bool) -> Result<PathBuf> {
    match source {
        ModelSource::Dir(p) => {
            if !p.is_dir() {
                return Err(ModelError::MissingFiles {
                    what: p.display().to_string(),
                    missing: vec![p.display().to_string()],
                    hint: "no such directory: pass a diffusers model directory (model_index.json, \
                           unet/, vae/, scheduler/, text_encoder/, tokenizer/) or a hub repo id \
                           like `stabilityai/sd-turbo`"
                        .into(),
                });
            }
            Ok(p.clone())
        }
        ModelSource::Hub { repo, revision } => resolve_hub(repo, revision, allow_download),
    }
}

fn resolve_hub(repo: &str, revision: &str, allow_download: bool) -> Result<PathBuf> {
    use hf_hub::{Cache, Repo, RepoType};
    let hf_repo = Repo::with_revision(repo.to_string(), RepoType::Model, revision.to_string());
    let cache = Cache::from_env();
    let cached = cache.repo(hf_repo.clone());
    let api = if allow_download {
        hf_hub::api::sync::ApiBuilder::from_env()
            .with_progress(false)
            .build()
            .ok()
    } else {
        None
    };
    let mut root: Option<PathBuf> = None;
    let mut missing = Vec::new();
    let mut last_err = String::new();
    for (label, names) in required_files() {
        let mut found = None;
        for n in names {
            if let Some(p) = cached.get(n) {
                found = Some(p);
                break;
            }
        }
        if found.is_none()
            && let Some(api) = &api
        {
            let r = api.repo(hf_repo.clone());
            for n in names {
                match r.get(n) {
                    Ok(p) => {
                        found = Some(p);
                        break;
                    }
                    Err(e) => last_err = e.to_string(),
                }
            }
        }
        match found {
            Some(p) => {
                if root.is_none() && label == "model_index.json" {
                    root = p.parent().map(Path::to_path_buf);
                }
            }
            None => missing.push(names.join(" or ")),
        }
    }
    let snapshot_hint = cache
        .path()
        .join(hf_repo.folder_name())
        .join("snapshots")
        .join("<commit>");
    if !missing.is_empty() || root.is_none() {
        let how = if allow_download {
            format!("download failed ({last_err}); the machine may be offline.")
        } else {
            "downloads are disabled.".to_string()
        };
        return Err(ModelError::MissingFiles {
            what: format!("hub repo {repo}@{revision}"),
            missing,
            hint: format!(
                "{how} Either download the repo on a connected machine (`huggingface-cli download {repo}`) \
                 and copy the cache to {} (set HF_HOME to move it), or put a diffusers directory with \
                 these files anywhere and pass its path instead of the repo id.",
                snapshot_hint.display()
            ),
        });
    }
    root.ok_or_else(|| ModelError::MissingFiles {
        what: repo.to_string(),
        missing: vec!["model_index.json".into()],
        hint: "unreachable".into(),
    })
}

/// A [`candle_nn::var_builder::SimpleBackend`] that hands out seeded random tensors of
/// whatever shape is asked for: full-size architectures for benchmarks (compute does not
/// depend on the weight values).
pub struct RandomWeights {
    pub std: f64,
}

impl candle_nn::var_builder::SimpleBackend for RandomWeights {
    fn get(
        &self,
        s: candle_core::Shape,
        _name: &str,
        _h: candle_nn::Init,
        dtype: DType,
        dev: &Device,
    ) -> candle_core::Result<candle_core::Tensor> {
        candle_core::Tensor::randn(0f32, self.std as f32, s, dev)?.to_dtype(dtype)
    }

    fn get_unchecked(
        &self,
        name: &str,
        _dtype: DType,
        _dev: &Device,
    ) -> candle_core::Result<candle_core::Tensor> {
        candle_core::bail!("random weights: shape of {name} unknown")
    }

    fn contains_tensor(&self, _name: &str) -> bool {
        true
    }
}

/// A var builder of random weights (see [`RandomWeights`]).
pub fn random_var_builder(dtype: DType, device: &Device) -> VarBuilder<'static> {
    VarBuilder::from_backend(Box::new(RandomWeights { std: 0.02 }), dtype, device.clone())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compute_device_parses_prints_and_round_trips() {
        for (s, d) in [
            ("cpu", ComputeDevice::Cpu),
            (" CPU ", ComputeDevice::Cpu),
            ("cuda", ComputeDevice::Cuda(0)),
            ("gpu", ComputeDevice::Cuda(0)),
            ("cuda:3", ComputeDevice::Cuda(3)),
        ] {
            assert_eq!(s.parse::<ComputeDevice>(), Ok(d), "{s}");
            assert_eq!(d.to_string().parse::<ComputeDevice>(), Ok(d));
        }
        for bad in ["", "tpu", "cuda:", "cuda:x", "cuda:-1"] {
            let e = bad.parse::<ComputeDevice>().unwrap_err();
            assert!(e.to_string().contains("cpu, cuda or cuda:N"), "{bad}: {e}");
        }
        let json = serde_json::to_string(&ComputeDevice::Cuda(2)).unwrap();
        assert_eq!(json, "\"cuda:2\"");
        assert_eq!(
            serde_json::from_str::<ComputeDevice>(&json).unwrap(),
            ComputeDevice::Cuda(2)
        );
        assert!(serde_json::from_str::<ComputeDevice>("\"tpu\"").is_err());
    }

    #[test]
    fn the_cpu_always_opens_and_cuda_needs_the_feature() {
        assert!(ComputeDevice::Cpu.check_built().is_ok());
        assert!(ComputeDevice::Cpu.open().unwrap().is_cpu());
        if !cfg!(feature = "cuda") {
            let e = ComputeDevice::Cuda(0).check_built().unwrap_err();
            assert!(e.to_string().contains("--features cuda"), "{e}");
            assert!(matches!(
                ComputeDevice::Cuda(0).open(),
                Err(ModelError::Unsupported { .. })
            ));
        }
    }
}
