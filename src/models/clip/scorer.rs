//! [`ClipScorer`]: a CLIP model, its tokenizer and its preprocessing, loaded from a directory,
//! scoring images against captions (rejection sampling and evaluation).

use super::model::ClipModel;
use super::preprocess::{PreprocessConfig, preprocess};
use super::tokenizer::ClipTokenizer;
use super::{ClipError, openclip};
use crate::image::Image;
use candle_core::{Device, Tensor};
use std::path::{Path, PathBuf};

/// Images and texts are embedded in chunks of this many.
const BATCH: usize = 16;

/// A loaded CLIP scorer.
#[derive(Debug, Clone)]
pub struct ClipScorer {
    pub model: ClipModel,
    pub tokenizer: ClipTokenizer,
    pub preprocess: PreprocessConfig,
    device: Device,
    name: String,
}

impl ClipScorer {
    /// Loads a scorer on the CPU from a local directory in the `transformers` layout
    /// (`config.json`, safetensors, `vocab.json`+`merges.txt` or `tokenizer.json`, optional
    /// `preprocessor_config.json`) or the OpenCLIP layout (`open_clip_config.json`,
    /// `open_clip_model.safetensors` and the tokenizer files).
    ///
    /// Hub download is not built in: a missing directory is an error that says how to fetch it.
    pub fn load(dir: &Path) -> Result<Self, ClipError> {
        Self::load_on(dir, &Device::Cpu)
    }

    pub fn load_on(dir: &Path, device: &Device) -> Result<Self, ClipError> {
        if !dir.is_dir() {
            let s = dir.display().to_string();
            let hint = if s.matches('/').count() == 1 && !s.starts_with('.') {
                format!(
                    " (it looks like a Hugging Face repo id: download it first, e.g. \
                     `huggingface-cli download {s} --local-dir models/{}`, and pass that directory)",
                    s.replace('/', "--")
                )
            } else {
                String::new()
            };
            return Err(ClipError::Input(format!(
                "scorer directory {s} does not exist{hint}"
            )));
        }
        let name = dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| dir.display().to_string());
        let (model, preprocess, tokenizer) = if dir.join("config.json").is_file() {
            let model = ClipModel::load(dir, device)?;
            let size = model.config.vision_config.image_size as u32;
            let pp = dir.join("preprocessor_config.json");
            let preprocess = if pp.is_file() {
                PreprocessConfig::from_file(&pp, size)?
            } else {
                PreprocessConfig::for_image_size(size)
            };
            (model, preprocess, ClipTokenizer::from_dir(dir)?)
        } else if dir.join(openclip::CONFIG_FILE).is_file() {
            openclip::load(dir, device)?
        } else {
            return Err(missing(dir));
        };
        let (h, w) = preprocess.output_size();
        let s = model.config.vision_config.image_size as u32;
        if (h, w) != (s, s) {
            return Err(ClipError::Config(format!(
                "preprocessing crops to {w}x{h} but the vision tower takes {s}x{s}"
            )));
        }
        let max_pos = model.config.text_config.max_position_embeddings;
        let mut tokenizer = tokenizer;
        tokenizer.max_length = tokenizer.max_length.min(max_pos);
        Ok(Self {
            model,
            tokenizer,
            preprocess,
            device: device.clone(),
            name,
        })
    }

    /// Short name (the directory name), used in evaluation tables.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Side of the square input image.
    pub fn image_size(&self) -> u32 {
        self.preprocess.output_size().0
    }

    /// Unit-norm text embeddings, one per caption.
    pub fn text_embeddings(&self, texts: &[&str]) -> Result<Vec<Vec<f32>>, ClipError> {
        let mut out = Vec::with_capacity(texts.len());
        for chunk in texts.chunks(BATCH) {
            let len = self.tokenizer.max_length;
            let ids: Vec<u32> = chunk
                .iter()
                .flat_map(|t| self.tokenizer.encode_padded(t))
                .collect();
            let ids = Tensor::from_vec(ids, (chunk.len(), len), &self.device)?;
            out.extend(self.model.text_embeddings(&ids)?.to_vec2::<f32>()?);
        }
        Ok(out)
    }

    /// Preprocessed `(n, 3, s, s)` pixel tensor.
    pub fn pixel_values(&self, images: &[Image]) -> Result<Tensor, ClipError> {
        let (h, w) = self.preprocess.output_size();
        let mut data = Vec::with_capacity(images.len() * 3 * (h * w) as usize);
        for img in images {
            data.extend(preprocess(img, &self.preprocess)?);
        }
        Ok(Tensor::from_vec(
            data,
            (images.len(), 3, h as usize, w as usize),
            &self.device,
        )?)
    }

    /// Unit-norm image embeddings, one per image (RGBA composited over white).
    pub fn image_embeddings(&self, images: &[Image]) -> Result<Vec<Vec<f32>>, ClipError> {
        let mut out = Vec::with_capacity(images.len());
        for chunk in images.chunks(BATCH) {
            let px = self.pixel_values(chunk)?;
            out.extend(self.model.image_embeddings(&px)?.to_vec2::<f32>()?);
        }
        Ok(out)
    }

    /// Cosine similarity of every image with the caption (in [-1, 1]; the paper reports ×100).
    pub fn score_images(&self, images: &[Image], caption: &str) -> Result<Vec<f32>, ClipError> {
        if images.is_empty() {
            return Ok(Vec::new());
        }
        let t = self.text_embeddings(&[caption])?;
        let t = t
            .first()
            .ok_or_else(|| ClipError::Input("no text embedding".into()))?;
        Ok(self
            .image_embeddings(images)?
            .iter()
            .map(|i| dot(i, t))
            .collect())
    }

    /// Index and score of the best image for the caption (rejection sampling), plus all scores.
    pub fn best_of(&self, images: &[Image], caption: &str) -> Result<(usize, Vec<f32>), ClipError> {
        let scores = self.score_images(images, caption)?;
        let best = scores
            .iter()
            .enumerate()
            .fold(None, |acc: Option<(usize, f32)>, (i, &s)| match acc {
                Some((_, b)) if b >= s => acc,
                _ => Some((i, s)),
            })
            .map(|(i, _)| i)
            .ok_or_else(|| ClipError::Input("no images to choose from".into()))?;
        Ok((best, scores))
    }
}

/// Dot product (cosine similarity of unit vectors).
pub fn dot(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn missing(dir: &Path) -> ClipError {
    let want = [
        "config.json",
        "model.safetensors",
        "vocab.json + merges.txt (or tokenizer.json)",
        "preprocessor_config.json (optional)",
    ];
    let files = want
        .iter()
        .filter(|f| !dir.join(f.split(' ').next().unwrap_or(f)).is_file())
        .map(|s| s.to_string())
        .collect();
    ClipError::MissingFiles {
        dir: PathBuf::from(dir),
        files,
    }
}
