//! OpenCLIP checkpoints (`open_clip_config.json` + `open_clip_model.safetensors`, the layout of
//! the `laion/CLIP-ViT-*` repositories) mapped onto [`ClipModel`]: key renaming, the fused
//! `attn.in_proj_weight` split into q/k/v, projection matrices transposed into linear weights.
//! Text pooling is OpenCLIP's argmax over token ids, which is the first end-of-text token for
//! the CLIP vocabulary (its highest id), so the `transformers` pooling rule gives the same row.

use super::config::{Activation, ClipConfig, ClipTextConfig, ClipVisionConfig};
use super::model::ClipModel;
use super::preprocess::{CropRounding, PreprocessConfig};
use super::tokenizer::ClipTokenizer;
use super::{ClipError, weight_files};
use crate::models::serde_defaults::num;
use candle_core::{DType, Device, Tensor};
use candle_nn::VarBuilder;
use serde::Deserialize;
use std::collections::HashMap;
use std::path::Path;

pub const CONFIG_FILE: &str = "open_clip_config.json";

fn d_mlp() -> f64 {
    4.0
}

#[derive(Debug, Clone, Deserialize)]
pub struct TextCfg {
    #[serde(default = "num::<77>")]
    pub context_length: usize,
    #[serde(default = "num::<49408>")]
    pub vocab_size: usize,
    #[serde(default = "num::<512>")]
    pub width: usize,
    #[serde(default = "num::<8>")]
    pub heads: usize,
    #[serde(default = "num::<12>")]
    pub layers: usize,
    #[serde(default = "d_mlp")]
    pub mlp_ratio: f64,
    #[serde(default)]
    pub ls_init_value: Option<f64>,
    #[serde(default)]
    pub hf_model_name: Option<String>,
}

#[derive(Debug, Clone, Deserialize)]
pub struct VisionCfg {
    #[serde(default = "num::<12>")]
    pub layers: usize,
    #[serde(default = "num::<768>")]
    pub width: usize,
    #[serde(default = "num::<64>")]
    pub head_width: usize,
    #[serde(default = "d_mlp")]
    pub mlp_ratio: f64,
    #[serde(default = "num::<16>")]
    pub patch_size: usize,
    #[serde(default = "num::<224>")]
    pub image_size: usize,
    #[serde(default)]
    pub ls_init_value: Option<f64>,
    #[serde(default)]
    pub timm_model_name: Option<String>,
}

#[derive(Debug, Clone, Deserialize)]
pub struct ModelCfg {
    pub embed_dim: usize,
    pub vision_cfg: VisionCfg,
    pub text_cfg: TextCfg,
    #[serde(default)]
    pub quick_gelu: bool,
}

#[derive(Debug, Clone, Deserialize, Default)]
pub struct PreprocessCfg {
    pub mean: Option<Vec<f32>>,
    pub std: Option<Vec<f32>>,
    pub interpolation: Option<String>,
    pub resize_mode: Option<String>,
}

/// `open_clip_config.json`.
#[derive(Debug, Clone, Deserialize)]
pub struct OpenClipConfig {
    pub model_cfg: ModelCfg,
    #[serde(default)]
    pub preprocess_cfg: PreprocessCfg,
}

impl OpenClipConfig {
    pub fn from_file(path: &Path) -> Result<Self, ClipError> {
        let text = std::fs::read_to_string(path).map_err(|e| ClipError::io(path, e))?;
        serde_json::from_str(&text)
            .map_err(|e| ClipError::Config(format!("{}: {e}", path.display())))
    }

    /// The equivalent `transformers` configuration.
    pub fn to_clip_config(
        &self,
        eos_token_id: u32,
        bos_token_id: u32,
    ) -> Result<ClipConfig, ClipError> {
        let m = &self.model_cfg;
        let unsupported = |what: &str| {
            Err(ClipError::Config(format!(
                "unsupported OpenCLIP variant: {what}"
            )))
        };
        if m.text_cfg.hf_model_name.is_some() {
            return unsupported("Hugging Face text tower (hf_model_name)");
        }
        if m.vision_cfg.timm_model_name.is_some() {
            return unsupported("timm vision tower (timm_model_name)");
        }
        if m.text_cfg.ls_init_value.is_some() || m.vision_cfg.ls_init_value.is_some() {
            return unsupported("layer scale (ls_init_value)");
        }
        if m.vision_cfg.head_width == 0 || m.text_cfg.heads == 0 {
            return Err(ClipError::Config("zero attention heads".into()));
        }
        let act = if m.quick_gelu {
            Activation::QuickGelu
        } else {
            Activation::Gelu
        };
        let text_config = ClipTextConfig {
            vocab_size: m.text_cfg.vocab_size,
            hidden_size: m.text_cfg.width,
            intermediate_size: (m.text_cfg.width as f64 * m.text_cfg.mlp_ratio) as usize,
            projection_dim: m.embed_dim,
            num_hidden_layers: m.text_cfg.layers,
            num_attention_heads: m.text_cfg.heads,
            max_position_embeddings: m.text_cfg.context_length,
            hidden_act: act,
            layer_norm_eps: 1e-5,
            bos_token_id,
            eos_token_id,
            pad_token_id: 0,
        };
        let vision_config = ClipVisionConfig {
            hidden_size: m.vision_cfg.width,
            intermediate_size: (m.vision_cfg.width as f64 * m.vision_cfg.mlp_ratio) as usize,
            projection_dim: m.embed_dim,
            num_hidden_layers: m.vision_cfg.layers,
            num_attention_heads: m.vision_cfg.width / m.vision_cfg.head_width,
            num_channels: 3,
            image_size: m.vision_cfg.image_size,
            patch_size: m.vision_cfg.patch_size,
            hidden_act: act,
            layer_norm_eps: 1e-5,
        };
        text_config.validate()?;
        vision_config.validate()?;
        Ok(ClipConfig {
            text_config,
            vision_config,
            projection_dim: m.embed_dim,
            logit_scale_init_value: 2.6592,
        })
    }

    /// The OpenCLIP eval transform: shortest side bicubic, centre crop (torchvision rounding),
    /// mean/std from `preprocess_cfg` (OpenAI values by default).
    pub fn preprocess(&self) -> Result<PreprocessConfig, ClipError> {
        let p = &self.preprocess_cfg;
        if let Some(i) = &p.interpolation
            && i != "bicubic"
        {
            return Err(ClipError::Config(format!(
                "interpolation {i:?} is not supported"
            )));
        }
        if let Some(r) = &p.resize_mode
            && r != "shortest"
        {
            return Err(ClipError::Config(format!(
                "resize_mode {r:?} is not supported"
            )));
        }
        let mut c = PreprocessConfig::for_image_size(self.model_cfg.vision_cfg.image_size as u32);
        c.crop_rounding = CropRounding::RoundHalfEven;
        let three = |v: &Option<Vec<f32>>, d: [f32; 3]| -> Result<[f32; 3], ClipError> {
            match v.as_deref() {
                None => Ok(d),
                Some([a, b, c]) => Ok([*a, *b, *c]),
                Some(_) => Err(ClipError::Config("mean/std must have 3 values".into())),
            }
        };
        c.mean = three(&p.mean, c.mean)?;
        c.std = three(&p.std, c.std)?;
        Ok(c)
    }
}

fn rename_block(rest: &str) -> Option<String> {
    // rest: "N.<param>"
    let (n, p) = rest.split_once('.')?;
    let p = match p {
        "ln_1.weight" => "layer_norm1.weight",
        "ln_1.bias" => "layer_norm1.bias",
        "ln_2.weight" => "layer_norm2.weight",
        "ln_2.bias" => "layer_norm2.bias",
        "mlp.c_fc.weight" => "mlp.fc1.weight",
        "mlp.c_fc.bias" => "mlp.fc1.bias",
        "mlp.c_proj.weight" => "mlp.fc2.weight",
        "mlp.c_proj.bias" => "mlp.fc2.bias",
        "attn.out_proj.weight" => "self_attn.out_proj.weight",
        "attn.out_proj.bias" => "self_attn.out_proj.bias",
        _ => return None,
    };
    Some(format!("encoder.layers.{n}.{p}"))
}

/// Renames OpenCLIP tensors to the `transformers` CLIPModel key layout.
pub fn convert_state_dict(
    src: HashMap<String, Tensor>,
) -> Result<HashMap<String, Tensor>, ClipError> {
    let mut out = HashMap::with_capacity(src.len() + 64);
    for (k, t) in src {
        let (tower, key) = match k.strip_prefix("visual.") {
            Some(r) => ("vision_model", r),
            None => ("text_model", k.as_str()),
        };
        if let Some(name) = renamed(tower, key) {
            out.insert(name.to_string(), t);
            continue;
        }
        match (tower, key) {
            ("text_model", "text_projection") => {
                out.insert("text_projection.weight".into(), t.t()?.contiguous()?);
                continue;
            }
            ("text_model", "text_projection.weight") => {
                out.insert("text_projection.weight".into(), t);
                continue;
            }
            ("vision_model", "proj") => {
                out.insert("visual_projection.weight".into(), t.t()?.contiguous()?);
                continue;
            }
            (_, "attn_mask") => continue,
            _ => {}
        }
        let unsupported = || {
            ClipError::Config(format!(
                "unsupported OpenCLIP tensor `{k}` (this variant is not supported)"
            ))
        };
        let rest = key
            .strip_prefix("transformer.resblocks.")
            .ok_or_else(unsupported)?;
        if !convert_block(&mut out, tower, rest, &t)? {
            return Err(unsupported());
        }
    }
    Ok(out)
}

/// The transformers name of a tensor OpenCLIP keeps whole outside its blocks.
fn renamed(tower: &str, key: &str) -> Option<&'static str> {
    Some(match (tower, key) {
        ("text_model", "token_embedding.weight") => "text_model.embeddings.token_embedding.weight",
        ("text_model", "positional_embedding") => "text_model.embeddings.position_embedding.weight",
        ("text_model", "ln_final.weight") => "text_model.final_layer_norm.weight",
        ("text_model", "ln_final.bias") => "text_model.final_layer_norm.bias",
        ("text_model", "logit_scale") => "logit_scale",
        ("vision_model", "conv1.weight") => "vision_model.embeddings.patch_embedding.weight",
        ("vision_model", "class_embedding") => "vision_model.embeddings.class_embedding",
        ("vision_model", "positional_embedding") => {
            "vision_model.embeddings.position_embedding.weight"
        }
        ("vision_model", "ln_pre.weight") => "vision_model.pre_layrnorm.weight",
        ("vision_model", "ln_pre.bias") => "vision_model.pre_layrnorm.bias",
        ("vision_model", "ln_post.weight") => "vision_model.post_layernorm.weight",
        ("vision_model", "ln_post.bias") => "vision_model.post_layernorm.bias",
        _ => return None,
    })
}

/// Converts tensor `rest` (after `transformer.resblocks.`) of a block of `tower` into `out`:
/// the fused q/k/v projection split in three, other tensors renamed. `false`: not a tensor of
/// a block this implementation knows.
fn convert_block(
    out: &mut HashMap<String, Tensor>,
    tower: &str,
    rest: &str,
    t: &Tensor,
) -> Result<bool, ClipError> {
    let fused = [
        (".attn.in_proj_weight", "weight"),
        (".attn.in_proj_bias", "bias"),
    ];
    for (suffix, kind) in fused {
        if let Some(n) = rest.strip_suffix(suffix) {
            let w = t.dim(0)? / 3;
            for (i, q) in ["q", "k", "v"].iter().enumerate() {
                out.insert(
                    format!("{tower}.encoder.layers.{n}.self_attn.{q}_proj.{kind}"),
                    t.narrow(0, i * w, w)?.contiguous()?,
                );
            }
            return Ok(true);
        }
    }
    match rename_block(rest) {
        Some(name) => {
            out.insert(format!("{tower}.{name}"), t.clone());
            Ok(true)
        }
        None => Ok(false),
    }
}

/// Loads model, preprocessing and tokenizer from an OpenCLIP directory. The tokenizer files
/// (`vocab.json` + `merges.txt` or `tokenizer.json`) must be present, as in the hub repos.
pub fn load(
    dir: &Path,
    device: &Device,
) -> Result<(ClipModel, PreprocessConfig, ClipTokenizer), ClipError> {
    let cfg = OpenClipConfig::from_file(&dir.join(CONFIG_FILE))?;
    let mut tok = ClipTokenizer::from_dir(dir)?;
    tok.pad_id = 0; // open_clip.tokenize pads with zeros
    tok.max_length = cfg.model_cfg.text_cfg.context_length;
    let clip_cfg = cfg.to_clip_config(tok.eos_id, tok.bos_id)?;
    let mut tensors = HashMap::new();
    let preferred = dir.join("open_clip_model.safetensors");
    let files = if preferred.is_file() {
        vec![preferred]
    } else {
        weight_files(dir)?
    };
    for f in files {
        let t = candle_core::safetensors::load(&f, device)
            .map_err(|e| ClipError::Config(format!("{}: {e}", f.display())))?;
        tensors.extend(t);
    }
    let tensors = convert_state_dict(tensors)?;
    let vb = VarBuilder::from_tensors(tensors, DType::F32, device);
    let model = ClipModel::new(vb, &clip_cfg)?;
    Ok((model, cfg.preprocess()?, tok))
}
