//! [`ClipScorer`]: a CLIP model, its tokenizer and its preprocessing, loaded from a directory,
//! scoring images against captions (rejection sampling and evaluation).

use crate::image::Image;
use crate::models::clip::model::ClipModel;
use crate::models::clip::preprocess::{PreprocessConfig, preprocess};
use crate::models::clip::tokenizer::ClipTokenizer;
use crate::models::clip::{ClipError, openclip};
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
            let hint = if looks_like_repo_id(&s) {
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

    /// Loads from a local directory or, for a Hugging Face repo id `org/name` that is not a
    /// local path, from the hub cache (`HF_HOME`), downloading missing files when
    /// `allow_download` and `HF_HUB_OFFLINE` is not set. The scorer is named after the repo id.
    pub fn load_source(source: &str, allow_download: bool) -> Result<Self, ClipError> {
        let path = Path::new(source);
        if path.is_dir() || !looks_like_repo_id(source) {
            return Self::load(path);
        }
        let offline = std::env::var("HF_HUB_OFFLINE").is_ok_and(|v| v != "0" && !v.is_empty());
        let dir = resolve_hub(source, allow_download && !offline)?;
        let mut s = Self::load(&dir)?;
        s.name = source.to_string();
        Ok(s)
    }

    /// Short name (the directory name, or the repo id), used in evaluation tables.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Side of the square input image.
    pub fn image_size(&self) -> u32 {
        self.preprocess.output_size().0
    }

    /// Unit-norm text embeddings, one per caption.
    pub fn text_embeddings(&self, texts: &[&str]) -> Result<Vec<Vec<f32>>, ClipError> {
        embed_in_batches(texts, |chunk| {
            let len = self.tokenizer.max_length;
            let ids: Vec<u32> = chunk
                .iter()
                .flat_map(|t| self.tokenizer.encode_padded(t))
                .collect();
            let ids = Tensor::from_vec(ids, (chunk.len(), len), &self.device)?;
            Ok(self.model.text_embeddings(&ids)?)
        })
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
        embed_in_batches(images, |chunk| {
            Ok(self.model.image_embeddings(&self.pixel_values(chunk)?)?)
        })
    }
}

/// `org/name` with the characters the hub allows, and not an existing path.
pub fn looks_like_repo_id(s: &str) -> bool {
    let mut parts = s.split('/');
    let ok = |p: &str| {
        !p.is_empty()
            && !p.starts_with('.')
            && p.chars()
                .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c))
    };
    matches!((parts.next(), parts.next(), parts.next()), (Some(a), Some(b), None) if ok(a) && ok(b))
        && !Path::new(s).exists()
}

/// Files of a transformers-layout CLIP repo: (name, required).
const HUB_FILES: &[(&str, bool)] = &[
    ("config.json", true),
    ("model.safetensors", true),
    ("vocab.json", false),
    ("merges.txt", false),
    ("tokenizer.json", false),
    ("tokenizer_config.json", false),
    ("special_tokens_map.json", false),
    ("preprocessor_config.json", false),
];

/// Files of an OpenCLIP-only repo.
const HUB_FILES_OPENCLIP: &[(&str, bool)] = &[
    ("open_clip_config.json", true),
    ("open_clip_model.safetensors", true),
    ("vocab.json", false),
    ("merges.txt", false),
    ("tokenizer.json", false),
    ("tokenizer_config.json", false),
    ("special_tokens_map.json", false),
];

fn resolve_hub(repo: &str, allow_download: bool) -> Result<PathBuf, ClipError> {
    use hf_hub::Cache;
    let cache = Cache::from_env();
    let cached = cache.model(repo.to_string());
    let api = if allow_download {
        hf_hub::api::sync::ApiBuilder::from_env()
            .build()
            .ok()
            .map(|a| a.model(repo.to_string()))
    } else {
        None
    };
    let fetch = |name: &str| -> Option<PathBuf> {
        cached
            .get(name)
            .or_else(|| api.as_ref().and_then(|a| a.get(name).ok()))
    };
    let mut missing_all = Vec::new();
    for files in [HUB_FILES, HUB_FILES_OPENCLIP] {
        let mut dir = None;
        let mut missing = Vec::new();
        for (name, required) in files {
            match fetch(name) {
                Some(p) if dir.is_none() => dir = p.parent().map(Path::to_path_buf),
                Some(_) => {}
                None if *required => missing.push(name.to_string()),
                None => {}
            }
            if !missing.is_empty() {
                break;
            }
        }
        match dir {
            Some(d) if missing.is_empty() => {
                let has_tok = d.join("tokenizer.json").is_file()
                    || (d.join("vocab.json").is_file() && d.join("merges.txt").is_file());
                if has_tok {
                    return Ok(d);
                }
                missing_all.push("vocab.json + merges.txt (or tokenizer.json)".to_string());
            }
            _ => missing_all.extend(missing),
        }
    }
    let how = if allow_download {
        "the download failed or the repo has no such files"
    } else {
        "not in the local Hugging Face cache and downloads are off (HF_HUB_OFFLINE)"
    };
    Err(ClipError::MissingFiles {
        dir: cache
            .path()
            .join(format!("models--{}", repo.replace('/', "--"))),
        files: missing_all,
        hint: format!(
            " for hub repo {repo}: {how}; fetch it with `huggingface-cli download {repo}` \
             (the transformers files, or open_clip_config.json + open_clip_model.safetensors) \
             or pass a local directory"
        ),
    })
}

/// `embed` over `items` in batches of [`BATCH`]: the rows of its `[batch, d]` outputs, in order
/// (how both scorers embed captions and images).
pub(crate) fn embed_in_batches<T, E: From<candle_core::Error>>(
    items: &[T],
    embed: impl Fn(&[T]) -> Result<Tensor, E>,
) -> Result<Vec<Vec<f32>>, E> {
    let mut out = Vec::with_capacity(items.len());
    for chunk in items.chunks(BATCH) {
        out.extend(embed(chunk)?.to_vec2::<f32>()?);
    }
    Ok(out)
}

/// Index of the largest score (the first one on ties), `None` when empty.
pub fn argmax(scores: &[f32]) -> Option<usize> {
    scores
        .iter()
        .enumerate()
        .fold(None, |acc: Option<(usize, f32)>, (i, &s)| match acc {
            Some((_, b)) if b >= s => acc,
            _ => Some((i, s)),
        })
        .map(|(i, _)| i)
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
    ];
    let files = want
        .iter()
        .filter(|f| !dir.join(f.split(' ').next().unwrap_or(f)).is_file())
        .map(|s| s.to_string())
        .collect();
    ClipError::MissingFiles {
        dir: PathBuf::from(dir),
        files,
        hint: format!(
            " (a transformers CLIP directory, or an OpenCLIP one with {}; {}",
            openclip::CONFIG_FILE,
            crate::models::clip::DOWNLOAD_HINT
                .trim_start()
                .trim_start_matches('(')
        ),
    }
}
