//! The full CLIP model (`CLIPModel`): both towers, their projections and `logit_scale`.

use super::config::ClipConfig;
use super::text::{ClipTextTransformer, l2_normalize, text_tower};
use super::vision::{ClipVisionTransformer, vision_tower};
use super::{ClipError, load_weights};
use candle_core::{DType, Device, Module, Result, Tensor};
use candle_nn::{Linear, VarBuilder, linear_no_bias};
use std::path::Path;

/// `CLIPModel`.
#[derive(Debug, Clone)]
pub struct ClipModel {
    pub text_model: ClipTextTransformer,
    pub vision_model: ClipVisionTransformer,
    pub text_projection: Linear,
    pub visual_projection: Linear,
    /// `logit_scale` as stored (log of the temperature).
    pub logit_scale: f32,
    pub config: ClipConfig,
}

impl ClipModel {
    /// `vb` points at the checkpoint root (`text_model.`, `vision_model.`, `text_projection`,
    /// `visual_projection`, `logit_scale`).
    pub fn new(vb: VarBuilder, config: &ClipConfig) -> Result<Self> {
        let p = config.projection_dim;
        let logit_scale = if vb.contains_tensor("logit_scale") {
            vb.get((), "logit_scale")?
                .to_dtype(DType::F32)?
                .to_scalar::<f32>()?
        } else {
            config.logit_scale_init_value as f32
        };
        Ok(Self {
            text_model: ClipTextTransformer::new(text_tower(vb.clone()), &config.text_config)?,
            vision_model: ClipVisionTransformer::new(
                vision_tower(vb.clone()),
                &config.vision_config,
            )?,
            text_projection: linear_no_bias(
                config.text_config.hidden_size,
                p,
                vb.pp("text_projection"),
            )?,
            visual_projection: linear_no_bias(
                config.vision_config.hidden_size,
                p,
                vb.pp("visual_projection"),
            )?,
            logit_scale,
            config: config.clone(),
        })
    }

    /// Loads `config.json` and the safetensors weights of a `transformers` CLIP directory (f32).
    pub fn load(dir: &Path, device: &Device) -> std::result::Result<Self, ClipError> {
        let config = ClipConfig::from_file(&dir.join("config.json"))?;
        let vb = load_weights(dir, DType::F32, device)?;
        Ok(Self::new(vb, &config)?)
    }

    /// `get_text_features`: projected pooled text output, not normalised.
    pub fn text_features(&self, input_ids: &Tensor) -> Result<Tensor> {
        let out = self.text_model.forward(input_ids)?;
        self.text_projection.forward(&out.pooled)
    }

    /// `get_image_features`: projected pooled image output, not normalised.
    pub fn image_features(&self, pixel_values: &Tensor) -> Result<Tensor> {
        let out = self.vision_model.forward(pixel_values)?;
        self.visual_projection.forward(&out.pooled)
    }

    /// Unit-norm text embeddings `(batch, projection_dim)`.
    pub fn text_embeddings(&self, input_ids: &Tensor) -> Result<Tensor> {
        l2_normalize(&self.text_features(input_ids)?)
    }

    /// Unit-norm image embeddings `(batch, projection_dim)`.
    pub fn image_embeddings(&self, pixel_values: &Tensor) -> Result<Tensor> {
        l2_normalize(&self.image_features(pixel_values)?)
    }

    /// `logits_per_image`: `exp(logit_scale) * cos(image, text)`, `(images, texts)`.
    pub fn logits_per_image(&self, pixel_values: &Tensor, input_ids: &Tensor) -> Result<Tensor> {
        let i = self.image_embeddings(pixel_values)?;
        let t = self.text_embeddings(input_ids)?;
        i.matmul(&t.t()?)? * f64::from(self.logit_scale.exp())
    }
}
