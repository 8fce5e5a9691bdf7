//! CLIP configuration as written by `transformers`: the full `CLIPConfig` (`config.json` with
//! `text_config` and `vision_config`) and the standalone `CLIPTextConfig` that Stable Diffusion
//! ships as `text_encoder/config.json`.
//!
//! `save_pretrained` writes only the fields that differ from the defaults, so every field has
//! the same default as `transformers`.

use super::ClipError;
use crate::models::serde_defaults::{id, num};
use serde::Deserialize;
use std::path::Path;

/// Activation in the MLP blocks (`hidden_act`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
pub enum Activation {
    /// `x * sigmoid(1.702 x)`: the OpenAI CLIP models (and Stable Diffusion 1.x).
    #[default]
    #[serde(rename = "quick_gelu")]
    QuickGelu,
    /// Exact (erf) GELU: the OpenCLIP models (Stable Diffusion 2.x).
    #[serde(rename = "gelu")]
    Gelu,
    /// Tanh approximation of GELU.
    #[serde(alias = "gelu_new", alias = "gelu_pytorch_tanh", rename = "gelu_fast")]
    GeluTanh,
}

fn d_eps() -> f64 {
    1e-5
}
fn d_logit_scale() -> f64 {
    2.6592
}

/// `CLIPTextConfig`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
pub struct ClipTextConfig {
    #[serde(default = "num::<49408>")]
    pub vocab_size: usize,
    #[serde(default = "num::<512>")]
    pub hidden_size: usize,
    #[serde(default = "num::<2048>")]
    pub intermediate_size: usize,
    #[serde(default = "num::<512>")]
    pub projection_dim: usize,
    #[serde(default = "num::<12>")]
    pub num_hidden_layers: usize,
    #[serde(default = "num::<8>")]
    pub num_attention_heads: usize,
    #[serde(default = "num::<77>")]
    pub max_position_embeddings: usize,
    #[serde(default)]
    pub hidden_act: Activation,
    #[serde(default = "d_eps")]
    pub layer_norm_eps: f64,
    #[serde(default = "id::<49406>")]
    pub bos_token_id: u32,
    #[serde(default = "id::<49407>")]
    pub eos_token_id: u32,
    #[serde(default = "id::<1>")]
    pub pad_token_id: u32,
}

impl Default for ClipTextConfig {
    fn default() -> Self {
        // An empty JSON object always deserialises: every field has a default.
        serde_json::from_str("{}").unwrap_or_else(|_| unreachable!())
    }
}

/// `CLIPVisionConfig`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
pub struct ClipVisionConfig {
    #[serde(default = "num::<768>")]
    pub hidden_size: usize,
    #[serde(default = "num::<3072>")]
    pub intermediate_size: usize,
    #[serde(default = "num::<512>")]
    pub projection_dim: usize,
    #[serde(default = "num::<12>")]
    pub num_hidden_layers: usize,
    #[serde(default = "num::<12>")]
    pub num_attention_heads: usize,
    #[serde(default = "num::<3>")]
    pub num_channels: usize,
    #[serde(default = "num::<224>")]
    pub image_size: usize,
    #[serde(default = "num::<32>")]
    pub patch_size: usize,
    #[serde(default)]
    pub hidden_act: Activation,
    #[serde(default = "d_eps")]
    pub layer_norm_eps: f64,
}

impl Default for ClipVisionConfig {
    fn default() -> Self {
        serde_json::from_str("{}").unwrap_or_else(|_| unreachable!())
    }
}

/// `CLIPConfig`: text tower, vision tower and the shared projection size.
#[derive(Debug, Clone, Deserialize, PartialEq)]
pub struct ClipConfig {
    #[serde(default)]
    pub text_config: ClipTextConfig,
    #[serde(default)]
    pub vision_config: ClipVisionConfig,
    #[serde(default = "num::<512>")]
    pub projection_dim: usize,
    #[serde(default = "d_logit_scale")]
    pub logit_scale_init_value: f64,
}

fn read_json(path: &Path) -> Result<serde_json::Value, ClipError> {
    let text = std::fs::read_to_string(path).map_err(|e| ClipError::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| ClipError::Config(format!("{}: {e}", path.display())))
}

impl ClipTextConfig {
    /// Reads a text config from a standalone `CLIPTextConfig` file or from the `text_config`
    /// of a full `CLIPConfig`.
    pub fn from_file(path: &Path) -> Result<Self, ClipError> {
        let v = read_json(path)?;
        let v = match v.get("text_config") {
            Some(t) => t.clone(),
            None => v,
        };
        let cfg: Self = serde_json::from_value(v)
            .map_err(|e| ClipError::Config(format!("{}: {e}", path.display())))?;
        cfg.validate()?;
        Ok(cfg)
    }

    pub fn validate(&self) -> Result<(), ClipError> {
        if self.num_attention_heads == 0
            || !self.hidden_size.is_multiple_of(self.num_attention_heads)
        {
            return Err(ClipError::Config(format!(
                "text hidden_size {} is not divisible by num_attention_heads {}",
                self.hidden_size, self.num_attention_heads
            )));
        }
        if self.max_position_embeddings < 2 {
            return Err(ClipError::Config(
                "text max_position_embeddings must be at least 2".into(),
            ));
        }
        Ok(())
    }
}

impl ClipVisionConfig {
    pub fn validate(&self) -> Result<(), ClipError> {
        if self.num_attention_heads == 0
            || !self.hidden_size.is_multiple_of(self.num_attention_heads)
        {
            return Err(ClipError::Config(format!(
                "vision hidden_size {} is not divisible by num_attention_heads {}",
                self.hidden_size, self.num_attention_heads
            )));
        }
        if self.patch_size == 0 || !self.image_size.is_multiple_of(self.patch_size) {
            return Err(ClipError::Config(format!(
                "vision image_size {} is not a multiple of patch_size {}",
                self.image_size, self.patch_size
            )));
        }
        Ok(())
    }

    /// Number of patches plus the class token.
    pub fn num_positions(&self) -> usize {
        let n = self.image_size / self.patch_size;
        n * n + 1
    }
}

impl ClipConfig {
    pub fn from_file(path: &Path) -> Result<Self, ClipError> {
        let v = read_json(path)?;
        let cfg: Self = serde_json::from_value(v)
            .map_err(|e| ClipError::Config(format!("{}: {e}", path.display())))?;
        cfg.text_config.validate()?;
        cfg.vision_config.validate()?;
        Ok(cfg)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_match_transformers() {
        let c: ClipConfig = serde_json::from_str("{}").unwrap();
        assert_eq!(c.text_config.vocab_size, 49408);
        assert_eq!(c.text_config.hidden_act, Activation::QuickGelu);
        assert_eq!(c.vision_config.patch_size, 32);
        assert_eq!(c.vision_config.num_positions(), 50);
    }

    #[test]
    fn sd2_text_config_parses_gelu() {
        let c: ClipTextConfig = serde_json::from_str(
            r#"{"hidden_act":"gelu","hidden_size":1024,"num_attention_heads":16,"num_hidden_layers":23,"pad_token_id":1}"#,
        )
        .unwrap();
        assert_eq!(c.hidden_act, Activation::Gelu);
        assert_eq!(c.num_hidden_layers, 23);
        c.validate().unwrap();
        let bad: ClipTextConfig =
            serde_json::from_str(r#"{"hidden_size":30,"num_attention_heads":4}"#).unwrap();
        assert!(bad.validate().is_err());
    }
}
