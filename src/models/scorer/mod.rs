//! Image/caption scorers for rejection sampling and evaluation: CLIP ([`ClipScorer`]) and the
//! embedded model's IconClip ([`IconClipScorer`]) behind one [`ImageTextScorer`] trait and one
//! [`Scorer`] enum that loads either from a directory.
//!
//! [`Scorer::load`] accepts
//! - a model root with a `scorer/` folder (e.g. `models/vf-icon`): IconClip with the root's
//!   `tokenizer/` and `text_encoder/`;
//! - a `scorer/` folder itself (`config.json` with `model_type: "vf_iconclip"`), with the text
//!   encoder of its parent directory;
//! - anything else: a CLIP directory (transformers or OpenCLIP layout), or for
//!   [`Scorer::load_source`] a hub repo id.

pub mod clip;
pub mod iconclip;

pub use clip::ClipScorer;
pub use iconclip::{IconClip, IconClipConfig, IconClipScorer};

use crate::image::Image;
use crate::models::bert::BertError;
use crate::models::clip::ClipError;
use candle_core::Device;
use std::path::{Path, PathBuf};

/// Errors of the scorer layer.
#[derive(Debug, thiserror::Error)]
pub enum ScorerError {
    #[error(transparent)]
    Clip(#[from] ClipError),
    #[error(transparent)]
    Bert(#[from] BertError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("bad scorer config {path}: {reason}")]
    Config { path: String, reason: String },
    #[error("scorer weights {path}: {reason}")]
    Weights { path: String, reason: String },
    #[error("bad input: {0}")]
    Input(String),
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
}

impl ScorerError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        ScorerError::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    pub(crate) fn config(path: &Path, reason: impl std::fmt::Display) -> Self {
        ScorerError::Config {
            path: path.display().to_string(),
            reason: reason.to_string(),
        }
    }
}

/// What rerank and evaluation need from a scorer.
pub trait ImageTextScorer {
    /// Short name for tables and logs.
    fn name(&self) -> &str;
    /// Side of the square image the scorer looks at (SVGs are rendered at this size).
    fn image_size(&self) -> u32;
    /// Unit-norm text embeddings, one per caption.
    fn text_embeddings(&self, texts: &[&str]) -> Result<Vec<Vec<f32>>, ScorerError>;
    /// Unit-norm image embeddings, one per image (RGBA composited over white).
    fn image_embeddings(&self, images: &[Image]) -> Result<Vec<Vec<f32>>, ScorerError>;

    /// Cosine similarity of every image with the caption (in [-1, 1]; reported ×100).
    fn score_images(&self, images: &[Image], caption: &str) -> Result<Vec<f32>, ScorerError> {
        if images.is_empty() {
            return Ok(Vec::new());
        }
        let t = self.text_embeddings(&[caption])?;
        let t = t
            .first()
            .ok_or_else(|| ScorerError::Input("no text embedding".into()))?;
        Ok(self
            .image_embeddings(images)?
            .iter()
            .map(|i| clip::dot(i, t))
            .collect())
    }

    /// Index of the best image for the caption (rejection sampling), plus all scores.
    fn best_of(&self, images: &[Image], caption: &str) -> Result<(usize, Vec<f32>), ScorerError> {
        let scores = self.score_images(images, caption)?;
        let best = clip::argmax(&scores)
            .ok_or_else(|| ScorerError::Input("no images to choose from".into()))?;
        Ok((best, scores))
    }
}

impl ImageTextScorer for ClipScorer {
    fn name(&self) -> &str {
        ClipScorer::name(self)
    }
    fn image_size(&self) -> u32 {
        ClipScorer::image_size(self)
    }
    fn text_embeddings(&self, texts: &[&str]) -> Result<Vec<Vec<f32>>, ScorerError> {
        Ok(ClipScorer::text_embeddings(self, texts)?)
    }
    fn image_embeddings(&self, images: &[Image]) -> Result<Vec<Vec<f32>>, ScorerError> {
        Ok(ClipScorer::image_embeddings(self, images)?)
    }
}

/// A loaded scorer of either kind.
#[derive(Debug)]
pub enum Scorer {
    Clip(Box<ClipScorer>),
    IconClip(Box<IconClipScorer>),
}

/// Where an IconClip lives: `(scorer dir, text root)`, or `None` for a CLIP directory.
pub fn iconclip_dirs(dir: &Path) -> Result<Option<(PathBuf, PathBuf)>, ScorerError> {
    if dir.join("scorer").join("config.json").is_file() {
        return Ok(Some((dir.join("scorer"), dir.to_path_buf())));
    }
    let cfg = dir.join("config.json");
    if cfg.is_file() {
        let s = std::fs::read_to_string(&cfg).map_err(|e| ScorerError::io(&cfg, e))?;
        let v: serde_json::Value =
            serde_json::from_str(&s).map_err(|e| ScorerError::config(&cfg, e))?;
        if v.get("model_type").and_then(|t| t.as_str()) == Some(iconclip::MODEL_TYPE) {
            let abs = std::path::absolute(dir).map_err(|e| ScorerError::io(dir, e))?;
            let root = abs
                .parent()
                .ok_or_else(|| ScorerError::config(&cfg, "an IconClip scorer/ folder needs a parent model directory with tokenizer/ and text_encoder/"))?
                .to_path_buf();
            return Ok(Some((dir.to_path_buf(), root)));
        }
    }
    Ok(None)
}

impl Scorer {
    /// Loads from a local directory on the CPU (see the module docs); the MiniLM weights of an
    /// IconClip may be downloaded (unless `VF_OFFLINE`).
    pub fn load(dir: &Path) -> Result<Self, ScorerError> {
        Self::load_on(dir, &Device::Cpu, true)
    }

    pub fn load_on(dir: &Path, device: &Device, allow_download: bool) -> Result<Self, ScorerError> {
        match iconclip_dirs(dir)? {
            Some((scorer, root)) => Ok(Self::IconClip(Box::new(IconClipScorer::load(
                &scorer,
                &root,
                device,
                allow_download,
            )?))),
            None => Ok(Self::Clip(Box::new(ClipScorer::load_on(dir, device)?))),
        }
    }

    /// A local directory, or a Hugging Face CLIP repo id (see [`ClipScorer::load_source`]).
    pub fn load_source(source: &str, allow_download: bool) -> Result<Self, ScorerError> {
        let p = Path::new(source);
        if p.is_dir() {
            return Self::load_on(p, &Device::Cpu, allow_download);
        }
        Ok(Self::Clip(Box::new(ClipScorer::load_source(
            source,
            allow_download,
        )?)))
    }

    fn inner(&self) -> &dyn ImageTextScorer {
        match self {
            Scorer::Clip(s) => s.as_ref(),
            Scorer::IconClip(s) => s.as_ref(),
        }
    }
}

impl ImageTextScorer for Scorer {
    fn name(&self) -> &str {
        self.inner().name()
    }
    fn image_size(&self) -> u32 {
        self.inner().image_size()
    }
    fn text_embeddings(&self, texts: &[&str]) -> Result<Vec<Vec<f32>>, ScorerError> {
        self.inner().text_embeddings(texts)
    }
    fn image_embeddings(&self, images: &[Image]) -> Result<Vec<Vec<f32>>, ScorerError> {
        self.inner().image_embeddings(images)
    }
}
