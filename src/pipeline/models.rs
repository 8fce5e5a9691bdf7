//! Model discovery and loading: where the models are ([`ModelDirs`], the embedded default,
//! TAESD beside a model), what is known of them before loading ([`ModelDirs::facts`]) and the one
//! loader ([`Models::load`]) that the executor, `generate`, `eval` and `bench` share.

use super::PipelineError;
use super::canvas::SampleShape;
use super::plan::{ModelFacts, few_step};
use crate::models::ComputeDevice;
use crate::models::scheduler::SamplerKind;
use crate::models::scorer::{ImageTextScorer, Scorer};
use crate::models::stable_diffusion::{ModelHints, load_scheduler};
use crate::retrieval::{IconIndex, RetrievalLocations};
use crate::stages::sample::NoStarts;
use crate::teacher::{AnalyticTeacher, AnalyticTeacherConfig, SdTeacher, Teacher};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The sampler `model`'s `scheduler/scheduler_config.json` names (DDIM when it cannot be read:
/// the loader reports a malformed one when the run starts).
fn sampler_kind(model: &Path) -> SamplerKind {
    load_scheduler(&model.join("scheduler")).map_or(SamplerKind::Ddim, |c| SamplerKind::of(&c))
}

/// Which encoder turns renders into latents for SDS with a latent (Stable Diffusion) model.
/// Pixel-space models have no encoder to choose and ignore it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EncoderChoice {
    /// TAESD when a TAESD directory is configured or found beside the model and the preset
    /// prefers it (every preset but `paper`), else the VAE.
    #[default]
    Auto,
    /// The model's VAE encoder (exact, slow on a CPU).
    Vae,
    /// TAESD (`madebyollin/taesd` layout): ~10× cheaper, approximate; needs its directory.
    Taesd,
}

impl std::str::FromStr for EncoderChoice {
    type Err = UnknownEncoder;
    fn from_str(s: &str) -> Result<Self, UnknownEncoder> {
        match s.to_ascii_lowercase().as_str() {
            "auto" => Ok(EncoderChoice::Auto),
            "vae" => Ok(EncoderChoice::Vae),
            "taesd" => Ok(EncoderChoice::Taesd),
            other => Err(UnknownEncoder(other.to_string())),
        }
    }
}

/// A TAESD directory (`config.json` + weights) for `model`: `configured` if given, else a
/// `taesd/` folder inside the model directory, else a `taesd/` folder beside it.
pub fn find_taesd(model: &Path, configured: Option<&Path>) -> Option<PathBuf> {
    if let Some(c) = configured {
        return Some(c.to_path_buf());
    }
    let inside = model.join("taesd");
    let beside = model.parent().map(|p| p.join("taesd"));
    [Some(inside), beside]
        .into_iter()
        .flatten()
        .find(|d| d.join("config.json").is_file())
}

/// The TAESD directory to use as the SDS encoder of `model` (`None` = the VAE), or why the
/// choice cannot be honoured. Pixel-space models never use one.
pub fn resolve_encoder(
    choice: EncoderChoice,
    prefer_taesd: bool,
    model: &Path,
    configured: Option<&Path>,
) -> Result<Option<PathBuf>, PipelineError> {
    if is_pixel_model(model) {
        return Ok(None);
    }
    match choice {
        EncoderChoice::Vae => Ok(None),
        EncoderChoice::Auto if !prefer_taesd => Ok(None),
        EncoderChoice::Auto => Ok(find_taesd(model, configured)),
        EncoderChoice::Taesd => find_taesd(model, configured).map(Some).ok_or_else(|| {
            PipelineError::InvalidInput(format!(
                "encoder taesd needs a TAESD directory: pass --taesd DIR (or set models.taesd_dir), \
                 or put one at {}/taesd",
                model.display()
            ))
        }),
    }
}

/// Environment variable naming the default (embedded) model directory.
pub const DEFAULT_MODEL_ENV: &str = "VF_DEFAULT_MODEL";
/// The embedded model, relative to the working directory or the crate root.
pub const EMBEDDED_MODEL: &str = "models/vf-icon";

/// Whether `dir` looks like a diffusers model directory (has `unet/config.json`).
pub fn is_model_dir(dir: &Path) -> bool {
    dir.join("unet").join("config.json").is_file()
}

/// Whether `dir` is a pixel-space model directory (a model directory without `vae/`; see
/// [`crate::models::codec::is_pixel_space`]).
pub fn is_pixel_model(dir: &Path) -> bool {
    is_model_dir(dir) && crate::models::codec::is_pixel_space(dir).unwrap_or(false)
}

/// Whether `dir` is a small prior (a pixel-space model, or one whose `model_index.json` says
/// `"_small_prior": true`, as the embedded latent `vf-icon` does): its presets are
/// [`Preset::settings_for`]`(true)`, not Stable Diffusion's.
pub fn is_small_model(dir: &Path) -> bool {
    is_pixel_model(dir)
        || (is_model_dir(dir) && crate::models::ModelHints::read(dir).is_ok_and(|h| h.small_prior))
}

/// The default model directory: `env_value` (from [`DEFAULT_MODEL_ENV`]) when set — an error if
/// it is not a model directory — else [`EMBEDDED_MODEL`] under `cwd`, then under `crate_root`.
/// `Ok(None)` when none is present.
pub fn resolve_default_model(
    env_value: Option<&std::ffi::OsStr>,
    cwd: Option<&Path>,
    crate_root: &Path,
) -> Result<Option<PathBuf>, NotReady> {
    if let Some(v) = env_value.filter(|v| !v.is_empty()) {
        let dir = PathBuf::from(v);
        return if is_model_dir(&dir) {
            Ok(Some(dir))
        } else {
            Err(NotReady::EnvNotAModel(dir))
        };
    }
    Ok([
        cwd.map(|c| c.join(EMBEDDED_MODEL)),
        Some(crate_root.join(EMBEDDED_MODEL)),
    ]
    .into_iter()
    .flatten()
    .find(|d| is_model_dir(d)))
}

/// [`resolve_default_model`] for this process (environment, current directory, this crate's
/// source tree).
pub fn default_model_dir() -> Result<Option<PathBuf>, NotReady> {
    resolve_default_model(
        std::env::var_os(DEFAULT_MODEL_ENV).as_deref(),
        std::env::current_dir().ok().as_deref(),
        Path::new(env!("CARGO_MANIFEST_DIR")),
    )
}

/// Why text runs cannot run here; each message says how to configure what is missing.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NotReady {
    /// No model configured, and the embedded one not found.
    #[error(
        "text-to-SVG needs a diffusion model: the embedded {EMBEDDED_MODEL} was not found (set \
         {DEFAULT_MODEL_ENV} to its directory), or set `sd_dir` in the [models] section of \
         config.toml (or the VECTORFUSION_MODELS_SD_DIR environment variable) to a \
         diffusers-layout model directory, then restart the server"
    )]
    NoModel,
    /// The command line was given no model at all.
    #[error("no model")]
    NoModelGiven,
    #[error("the analytic test teacher directory {} does not exist", .0.display())]
    AnalyticDir(PathBuf),
    #[error(
        "the configured Stable Diffusion directory {} does not exist or is not a diffusers \
         layout (no unet/config.json): fix `sd_dir` in the [models] section of config.toml (or \
         VECTORFUSION_MODELS_SD_DIR)",
        .0.display()
    )]
    NotDiffusers(PathBuf),
    #[error(
        "the model {} has no text encoder weights ({} holds none; for the embedded model run \
         `vectorfusion setup` or set VF_MINILM_DIR: see docs/EMBEDDED.md, \"MiniLM weights\")",
        model.display(),
        encoder.display()
    )]
    NoTextEncoderWeights { model: PathBuf, encoder: PathBuf },
    #[error(
        "the configured CLIP scorer directory {} does not exist: fix `clip_dir` in the [models] \
         section of config.toml",
        .0.display()
    )]
    ClipDir(PathBuf),
    /// The model environment variable names a directory that is not a model.
    #[error("{DEFAULT_MODEL_ENV}={} is not a model directory (no unet/config.json)", .0.display())]
    EnvNotAModel(PathBuf),
    /// A test executor built without text models.
    #[error("test executor configured without text models")]
    Disabled,
}

/// An encoder name that is none of vae, taesd, auto.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown encoder {0:?} (expected vae, taesd or auto)")]
pub struct UnknownEncoder(pub String);

/// Model locations (diffusers-layout directories).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ModelDirs {
    pub sd_dir: Option<PathBuf>,
    /// CLIP scorer for reranking samples (optional: without it the first sample is kept).
    pub clip_dir: Option<PathBuf>,
    /// TAESD encoder (optional; used for SDS per `encoder`).
    #[serde(default)]
    pub taesd_dir: Option<PathBuf>,
    /// SDS encoder of latent models (`auto`: TAESD when available and the preset prefers it).
    #[serde(default)]
    pub encoder: EncoderChoice,
    /// Where the diffusion model runs (`cpu`, or `cuda:N` in builds with the `cuda` feature).
    #[serde(default)]
    pub device: ComputeDevice,
    /// Testing only: a directory of PNG targets for the analytic TEST teacher, used when no
    /// `sd_dir` is set.
    #[serde(default)]
    pub analytic_dir: Option<PathBuf>,
}

impl ModelDirs {
    /// With no model configured (neither `sd_dir` nor `analytic_dir`), `default` (the embedded
    /// model, see [`default_model_dir`]) becomes `sd_dir` and its `scorer/` folder, when present
    /// and no `clip_dir` is set, the scorer.
    pub fn or_default_model(mut self, default: Option<PathBuf>) -> Self {
        if self.sd_dir.is_some() || self.analytic_dir.is_some() {
            return self;
        }
        if let Some(dir) = default {
            let scorer = dir.join("scorer");
            if self.clip_dir.is_none() && scorer.join("config.json").is_file() {
                self.clip_dir = Some(scorer);
            }
            self.sd_dir = Some(dir);
        }
        self
    }

    /// Whether the configured model is a small prior (presets differ: [`is_small_model`]).
    pub fn is_small_prior(&self) -> bool {
        self.sd_dir.as_deref().is_some_and(is_small_model)
    }

    /// What is known of the configured text model without loading it (`None`: no model; see
    /// [`ModelDirs::text_ready`] for why).
    pub fn facts(&self) -> Option<ModelFacts> {
        let Some(sd) = &self.sd_dir else {
            return self
                .analytic_dir
                .as_ref()
                .map(|_| ModelFacts::paper("analytic test teacher"));
        };
        // A malformed model_index.json is reported by the loader when the run starts.
        let mut hints = ModelHints::read(sd).unwrap_or_default();
        let pixel = is_pixel_model(sd);
        hints.small_prior |= pixel;
        let name = sd
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "model".into());
        Some(ModelFacts {
            name,
            hints,
            encoder_choice: if pixel {
                EncoderChoice::Vae
            } else {
                self.encoder
            },
            taesd_found: find_taesd(sd, self.taesd_dir.as_deref()).is_some(),
            sample_shape: if hints.small_prior {
                SampleShape::Square
            } else {
                SampleShape::Multiple(sample_multiple(sd))
            },
            // Sampling and SDS guide with `embed(prompt)` against `embed(negative prompt)` (the
            // embedded model too, trained with dropped captions): any such model takes one.
            negative_prompt: true,
            size_conditioning: takes_size_conditioning(sd),
            few_step: few_step(sampler_kind(sd), &hints),
        })
    }

    /// `Ok` when text runs can run (a model configured and loadable); otherwise why not, with
    /// how to configure one.
    pub fn text_ready(&self) -> Result<(), NotReady> {
        if self.sd_dir.is_none()
            && let Some(dir) = &self.analytic_dir
        {
            return if dir.is_dir() {
                Ok(())
            } else {
                Err(NotReady::AnalyticDir(dir.clone()))
            };
        }
        let Some(dir) = &self.sd_dir else {
            return Err(NotReady::NoModel);
        };
        if !dir.join("unet").join("config.json").is_file() {
            return Err(NotReady::NotDiffusers(dir.clone()));
        }
        let te = dir.join("text_encoder");
        // The embedded model's MiniLM weights are not committed: they resolve from
        // VF_MINILM_DIR or the cache (`vectorfusion setup`), or download on first use.
        let locations = crate::models::bert::weights::MiniLmLocations::from_env();
        if te.is_dir()
            && !crate::models::bert::weights::text_encoder_weights_available(&te, &locations)
        {
            return Err(NotReady::NoTextEncoderWeights {
                model: dir.clone(),
                encoder: te,
            });
        }
        if let Some(c) = &self.clip_dir
            && !c.is_dir()
        {
            return Err(NotReady::ClipDir(c.clone()));
        }
        Ok(())
    }
}

/// Whether the UNet of the diffusers directory `dir` takes SDXL's added size/crop conditioning
/// (`unet/config.json`'s `addition_embed_type` is `text_time`); an unreadable config says no
/// (the loader reports it when the run starts).
pub fn takes_size_conditioning(dir: &Path) -> bool {
    component_config(dir, "unet")
        .is_some_and(|v| v.get("addition_embed_type").and_then(|a| a.as_str()) == Some("text_time"))
}

/// The `config.json` of component `part` (`unet`, `vae`) of the diffusers directory `dir`.
fn component_config(dir: &Path, part: &str) -> Option<serde_json::Value> {
    let text = std::fs::read_to_string(dir.join(part).join("config.json")).ok()?;
    serde_json::from_str(&text).ok()
}

/// The side multiple (px) a latent model samples at: its autoencoder's downsampling times
/// its UNet's (`2^(levels - 1)`), read from `vae/config.json` and `unet/config.json`; 64 (Stable
/// Diffusion 1.x/2.x: 8 × 8) when they cannot be read (the loader then says why).
pub fn sample_multiple(dir: &Path) -> u32 {
    let levels = |part: &str| -> Option<u32> {
        let v = component_config(dir, part)?;
        let n = v.get("block_out_channels")?.as_array()?.len() as u32;
        (1..=8).contains(&n).then_some(n)
    };
    match (levels("vae"), levels("unet")) {
        (Some(v), Some(u)) => 1 << ((v - 1) + (u - 1)),
        _ => 64,
    }
}

/// Everything a text run needs, loaded once per teacher size and encoder.
pub struct Models {
    pub teacher: Box<dyn Teacher>,
    pub scorer: Option<Scorer>,
    /// The caption index of the model's training icons, when the model pins icon sets and
    /// `vectorfusion setup` installed it; why not otherwise (reported in the run's detail).
    pub retrieval: Result<Arc<IconIndex>, NoStarts>,
}

impl std::fmt::Debug for Models {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Models")
            .field("teacher", &self.teacher.name())
            .field(
                "scorer",
                &self.scorer.as_ref().map(|s| s.name().to_string()),
            )
            .finish()
    }
}

impl Models {
    /// The one loader: the configured diffusion model (Stable Diffusion layout, pixel-space or
    /// the embedded prior; else the analytic test teacher) for `(width, height)` px teacher
    /// inputs (a square for the test teacher and pixel-space models) with
    /// `encoder` as the SDS encoder of a latent model, its retrieval index, and the scorer.
    /// Loading may download the embedded model's MiniLM weights; the service checks
    /// [`ModelDirs::text_ready`] first, which refuses instead.
    pub fn load(
        dirs: &ModelDirs,
        dims: (u32, u32),
        encoder: EncoderChoice,
    ) -> Result<Self, PipelineError> {
        let size = dims.0;
        let scorer = load_scorer(dirs.clip_dir.as_deref())?;
        let Some(sd_dir) = &dirs.sd_dir else {
            let dir = dirs
                .analytic_dir
                .as_deref()
                .ok_or(PipelineError::NotReady(NotReady::NoModelGiven))?;
            let pool = if size >= 64 && size.is_multiple_of(64) {
                size / 64
            } else {
                1
            };
            let teacher = AnalyticTeacher::from_dir(
                dir,
                AnalyticTeacherConfig {
                    image_size: size,
                    pool,
                    num_train_timesteps: 1000,
                },
            )
            .map_err(|e| {
                let what = format!(
                    "cannot load the analytic test teacher from {}",
                    dir.display()
                );
                PipelineError::ModelLoad {
                    what,
                    source: Box::new(e),
                }
            })?;
            return Ok(Models {
                teacher: Box::new(teacher),
                scorer,
                retrieval: Err(NoStarts::TestTeacher),
            });
        };
        let taesd = match encoder {
            EncoderChoice::Taesd => resolve_encoder(
                EncoderChoice::Taesd,
                true,
                sd_dir,
                dirs.taesd_dir.as_deref(),
            )?,
            EncoderChoice::Vae | EncoderChoice::Auto => None,
        };
        let teacher =
            SdTeacher::load_on(sd_dir, dims, taesd.as_deref(), dirs.device).map_err(|e| {
                let what = format!("cannot load Stable Diffusion from {}", sd_dir.display());
                PipelineError::ModelLoad {
                    what,
                    source: Box::new(e),
                }
            })?;
        let retrieval = match RetrievalLocations::from_env().load(sd_dir) {
            Ok(Some(idx)) => Ok(Arc::new(idx)),
            Ok(None) => Err(NoStarts::NoIconSets),
            Err(e) => {
                tracing::warn!(model = %sd_dir.display(), "sampling from noise only: {e}");
                Err(NoStarts::Retrieval(e))
            }
        };
        Ok(Models {
            teacher: Box::new(teacher),
            scorer,
            retrieval,
        })
    }

    pub fn teacher(&self) -> &dyn Teacher {
        self.teacher.as_ref()
    }
}

fn load_scorer(dir: Option<&Path>) -> Result<Option<Scorer>, PipelineError> {
    dir.map(|d| {
        Scorer::load(d).map_err(|e| {
            let what = format!("cannot load the scorer from {}", d.display());
            PipelineError::ModelLoad {
                what,
                source: Box::new(e),
            }
        })
    })
    .transpose()
}
