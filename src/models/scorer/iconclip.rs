//! IconClip (`docs/EMBEDDED.md`): the embedded model's small contrastive image/caption scorer.
//! Image tower: `stem` conv + SiLU, stride-2 `blocks` (conv, group norm, SiLU ×2), spatial mean,
//! `proj`, L2 norm. Text tower: the frozen MiniLM sentence embedding (mean pooled over the
//! attention mask, L2 norm) → `text_proj` → L2 norm. Field names are the checkpoint keys.

use super::clip::embed_in_batches;
use super::{ImageTextScorer, ScorerError};
use crate::image::Image;
use crate::image::ops::resize;
use crate::models::ConfigIssue;
use crate::models::bert::{BertTextEncoder, l2_normalize};
use candle_core::{DType, Device, Tensor};
use candle_nn::{Conv2d, Conv2dConfig, GroupNorm, Linear, Module, VarBuilder};
use std::path::Path;

/// `model_type` of `scorer/config.json`.
pub const MODEL_TYPE: &str = "vf_iconclip";

/// `scorer/config.json`.
#[derive(Debug, Clone, PartialEq, serde::Deserialize, serde::Serialize)]
pub struct IconClipConfig {
    pub model_type: String,
    pub image_size: usize,
    pub channels: Vec<usize>,
    pub groups: usize,
    pub embed_dim: usize,
    pub text_max_length: usize,
}

impl IconClipConfig {
    pub fn from_file(path: &Path) -> Result<Self, ScorerError> {
        let s = std::fs::read_to_string(path).map_err(|e| ScorerError::io(path, e))?;
        let cfg: Self = serde_json::from_str(&s).map_err(|e| ScorerError::config(path, e))?;
        cfg.validate().map_err(|e| ScorerError::config(path, e))?;
        Ok(cfg)
    }

    pub fn validate(&self) -> Result<(), ConfigIssue> {
        if self.model_type != MODEL_TYPE {
            return Err(ConfigIssue::Inconsistent(format!(
                "model_type {:?} is not {MODEL_TYPE:?}",
                self.model_type
            )));
        }
        if !(8..=1024).contains(&self.image_size) {
            return Err(ConfigIssue::Inconsistent(format!(
                "image_size {} outside 8..=1024",
                self.image_size
            )));
        }
        if self.channels.is_empty() || self.channels.len() > 12 {
            return Err(ConfigIssue::Inconsistent(
                "channels must list 1 to 12 widths".into(),
            ));
        }
        if self.groups == 0
            || self
                .channels
                .iter()
                .any(|&c| c == 0 || c % self.groups != 0)
        {
            return Err(ConfigIssue::Inconsistent(format!(
                "every channel count {:?} must be a positive multiple of groups {}",
                self.channels, self.groups
            )));
        }
        if self.embed_dim == 0 {
            return Err(ConfigIssue::Inconsistent(
                "embed_dim must be positive".into(),
            ));
        }
        if !(2..=512).contains(&self.text_max_length) {
            return Err(ConfigIssue::Inconsistent(format!(
                "text_max_length {} outside 2..=512",
                self.text_max_length
            )));
        }
        Ok(())
    }
}

#[derive(Debug, Clone)]
struct Block {
    conv1: Conv2d,
    norm1: GroupNorm,
    conv2: Conv2d,
    norm2: GroupNorm,
}

impl Block {
    fn new(vb: VarBuilder, cin: usize, cout: usize, groups: usize) -> candle_core::Result<Self> {
        let down = Conv2dConfig {
            padding: 1,
            stride: 2,
            ..Default::default()
        };
        let same = Conv2dConfig {
            padding: 1,
            ..Default::default()
        };
        Ok(Self {
            conv1: candle_nn::conv2d(cin, cout, 3, down, vb.pp("conv1"))?,
            norm1: candle_nn::group_norm(groups, cout, 1e-5, vb.pp("norm1"))?,
            conv2: candle_nn::conv2d(cout, cout, 3, same, vb.pp("conv2"))?,
            norm2: candle_nn::group_norm(groups, cout, 1e-5, vb.pp("norm2"))?,
        })
    }

    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        let x = self.norm1.forward(&self.conv1.forward(x)?)?.silu()?;
        self.norm2.forward(&self.conv2.forward(&x)?)?.silu()
    }
}

/// The IconClip weights (image tower, text projection, logit scale).
#[derive(Debug, Clone)]
pub struct IconClip {
    pub config: IconClipConfig,
    stem: Conv2d,
    blocks: Vec<Block>,
    proj: Linear,
    text_proj: Linear,
    /// `logit_scale` (log of the temperature's inverse).
    pub logit_scale: f32,
}

impl IconClip {
    /// Builds from a var builder; `text_dim` is the text encoder's hidden size.
    pub fn new(
        vb: VarBuilder,
        config: IconClipConfig,
        text_dim: usize,
    ) -> candle_core::Result<Self> {
        let c = &config.channels;
        let same = Conv2dConfig {
            padding: 1,
            ..Default::default()
        };
        let stem = candle_nn::conv2d(3, c[0], 3, same, vb.pp("stem"))?;
        let blocks = c
            .windows(2)
            .enumerate()
            .map(|(i, w)| Block::new(vb.pp(format!("blocks.{i}")), w[0], w[1], config.groups))
            .collect::<candle_core::Result<Vec<_>>>()?;
        let last = c[c.len() - 1];
        let proj = candle_nn::linear(last, config.embed_dim, vb.pp("proj"))?;
        let text_proj = candle_nn::linear(text_dim, config.embed_dim, vb.pp("text_proj"))?;
        let ls = vb.get_unchecked_dtype("logit_scale", DType::F32)?;
        if ls.elem_count() != 1 {
            candle_core::bail!("logit_scale has shape {:?}, expected a scalar", ls.dims());
        }
        let logit_scale = ls.flatten_all()?.to_vec1::<f32>()?[0];
        Ok(Self {
            config,
            stem,
            blocks,
            proj,
            text_proj,
            logit_scale,
        })
    }

    /// Unit image embeddings `[b, embed_dim]` of RGB pixels `[b, 3, s, s]` in `[0, 1]`.
    pub fn encode_image(&self, x01: &Tensor) -> candle_core::Result<Tensor> {
        let mut x = self.stem.forward(&x01.affine(2.0, -1.0)?)?.silu()?;
        for b in &self.blocks {
            x = b.forward(&x)?;
        }
        let pooled = x.mean(3)?.mean(2)?;
        l2_normalize(&self.proj.forward(&pooled)?)
    }

    /// Unit text embeddings `[b, embed_dim]` of MiniLM sentence embeddings `[b, text_dim]`.
    pub fn encode_text(&self, sentence: &Tensor) -> candle_core::Result<Tensor> {
        l2_normalize(&self.text_proj.forward(sentence)?)
    }

    /// `exp(logit_scale) · img · txtᵀ`, `[n_img, n_txt]`.
    pub fn logits(&self, img: &Tensor, txt: &Tensor) -> candle_core::Result<Tensor> {
        img.matmul(&txt.t()?)? * f64::from(self.logit_scale.exp())
    }
}

/// IconClip with its MiniLM text encoder, scoring images against captions.
#[derive(Debug)]
pub struct IconClipScorer {
    pub model: IconClip,
    pub text: BertTextEncoder,
    device: Device,
    name: String,
}

impl IconClipScorer {
    /// Loads `scorer_dir` (`config.json`, `model.safetensors`) with the text encoder of
    /// `text_root` (`tokenizer/`, `text_encoder/`; MiniLM weights resolved as in
    /// [`crate::models::bert::weights`], downloaded only when `allow_download`).
    pub fn load(
        scorer_dir: &Path,
        text_root: &Path,
        device: &Device,
        allow_download: bool,
    ) -> Result<Self, ScorerError> {
        let config = IconClipConfig::from_file(&scorer_dir.join("config.json"))?;
        let text = BertTextEncoder::load(text_root, DType::F32, device, allow_download)?;
        let wp = scorer_dir.join("model.safetensors");
        if !wp.is_file() {
            return Err(ScorerError::Weights {
                path: wp.display().to_string(),
                reason: "missing".into(),
            });
        }
        let tensors =
            candle_core::safetensors::load(&wp, device).map_err(|e| ScorerError::Weights {
                path: wp.display().to_string(),
                reason: e.to_string(),
            })?;
        let vb = VarBuilder::from_tensors(tensors, DType::F32, device);
        let model = IconClip::new(vb, config, text.model.hidden_size()).map_err(|e| {
            ScorerError::Weights {
                path: wp.display().to_string(),
                reason: e.to_string(),
            }
        })?;
        let name = text_root
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "iconclip".into());
        Ok(Self {
            model,
            text,
            device: device.clone(),
            name,
        })
    }

    /// `(n, 3, s, s)` pixels: composited over white, area-resized to `image_size`.
    pub fn pixel_values(&self, images: &[Image]) -> Result<Tensor, ScorerError> {
        let s = self.image_size();
        let n = (s * s) as usize;
        let mut data = vec![0f32; images.len() * 3 * n];
        for (img, out) in images.iter().zip(data.chunks_exact_mut(3 * n)) {
            if img.width == 0 || img.height == 0 {
                return Err(ScorerError::Input("empty image".into()));
            }
            let im = resize(&img.over([1.0; 3]), s, s);
            for (p, px) in im.data.chunks_exact(4).enumerate() {
                for c in 0..3 {
                    out[c * n + p] = px[c].clamp(0.0, 1.0);
                }
            }
        }
        let s = s as usize;
        Ok(Tensor::from_vec(
            data,
            (images.len(), 3, s, s),
            &self.device,
        )?)
    }
}

impl ImageTextScorer for IconClipScorer {
    fn name(&self) -> &str {
        &self.name
    }

    fn image_size(&self) -> u32 {
        self.model.config.image_size as u32
    }

    /// Unit image embeddings, one per image.
    fn image_embeddings(&self, images: &[Image]) -> Result<Vec<Vec<f32>>, ScorerError> {
        embed_in_batches(images, |chunk| {
            Ok(self.model.encode_image(&self.pixel_values(chunk)?)?)
        })
    }

    /// Unit text embeddings, one per caption.
    fn text_embeddings(&self, texts: &[&str]) -> Result<Vec<Vec<f32>>, ScorerError> {
        embed_in_batches(texts, |chunk| {
            let s = self
                .text
                .sentence_embeddings(chunk, self.model.config.text_max_length)?;
            Ok(self.model.encode_text(&s)?)
        })
    }
}
