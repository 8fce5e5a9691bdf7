//! SDXL's dual text conditioning, as `StableDiffusionXLPipeline.encode_prompt` computes it:
//! `text_encoder` (`CLIPTextModel`) and `text_encoder_2` (`CLIPTextModelWithProjection`), each
//! with its own tokenizer (`tokenizer`, `tokenizer_2`: the same vocabulary, SDXL's second one
//! pads with `!`); the context is both penultimate hidden states concatenated along the feature
//! axis, the pooled embedding is `text_encoder_2`'s projected pooled output. An empty negative
//! prompt gives zeros when `model_index.json` says `force_zeros_for_empty_prompt` (the default).

use super::clip::{ClipTextConfig, ClipTextModel, ClipTextModelWithProjection, ClipTokenizer};
use super::loader::{self, Precision};
use super::stable_diffusion::check_precision;
use super::{ModelError, Result};
use candle_core::{DType, Device, Tensor};
use candle_nn::VarBuilder;
use std::path::{Path, PathBuf};

/// A prompt's SDXL conditioning: `context [1, 77, cross_attention_dim]` and `pooled [1, proj]`.
#[derive(Debug, Clone)]
pub struct SdxlEmbedding {
    pub context: Tensor,
    pub pooled: Tensor,
}

/// The two CLIP text encoders of an SDXL checkpoint with their tokenizers.
#[derive(Debug)]
pub struct SdxlTextEncoders {
    pub tokenizer: ClipTokenizer,
    pub text_encoder: ClipTextModel,
    pub tokenizer_2: ClipTokenizer,
    pub text_encoder_2: ClipTextModelWithProjection,
    /// `force_zeros_for_empty_prompt` of `model_index.json` (diffusers' default: true).
    pub zeros_for_empty: bool,
}

/// The tokenizer, config and weights of one CLIP text encoder of a diffusers directory.
pub(crate) struct ClipParts {
    pub tokenizer: ClipTokenizer,
    pub config: ClipTextConfig,
    pub vb: VarBuilder<'static>,
    pub weights: PathBuf,
}

impl ClipParts {
    /// `root/tok/` and `root/enc/` (`config.json` + safetensors).
    pub(crate) fn load(
        root: &Path,
        (tok, enc): (&str, &str),
        precision: Precision,
        device: &Device,
    ) -> Result<Self> {
        let dir = root.join(enc);
        let weights = loader::find_weights(&dir, loader::TEXT_WEIGHTS)?;
        Ok(Self {
            tokenizer: ClipTokenizer::from_dir(&root.join(tok))?,
            config: ClipTextConfig::from_file(&dir.join("config.json"))?,
            vb: loader::var_builder(&weights, precision.dtype(), device)?,
            weights,
        })
    }
}

impl SdxlTextEncoders {
    /// Loads both encoders and tokenizers of the SDXL directory `root`.
    pub fn load(root: &Path, precision: Precision, device: &Device) -> Result<Self> {
        check_precision("text_encoder", precision, device)?;
        let one = ClipParts::load(root, ("tokenizer", "text_encoder"), precision, device)?;
        let text_encoder = ClipTextModel::new(one.vb, &one.config)
            .map_err(loader::mismatch("text_encoder", &one.weights))?;
        let two = ClipParts::load(root, ("tokenizer_2", "text_encoder_2"), precision, device)?;
        let text_encoder_2 =
            ClipTextModelWithProjection::new(two.vb, &two.config, two.config.projection_dim)
                .map_err(loader::mismatch("text_encoder_2", &two.weights))?;
        Ok(Self {
            tokenizer: one.tokenizer,
            text_encoder,
            tokenizer_2: two.tokenizer,
            text_encoder_2,
            zeros_for_empty: zeros_for_empty(root)?,
        })
    }

    /// Width of the context (`cross_attention_dim` of the UNet it feeds).
    pub fn context_dim(&self) -> usize {
        self.text_encoder.text_model.config().hidden_size
            + self.text_encoder_2.text_model.config().hidden_size
    }

    /// Width of the pooled embedding.
    pub fn pooled_dim(&self) -> usize {
        self.text_encoder_2.text_projection.weight.dims()[0]
    }

    /// The conditioning of `prompt` (f32).
    pub fn embed(&self, prompt: &str, device: &Device) -> Result<SdxlEmbedding> {
        let ids = |t: &ClipTokenizer| -> Result<Tensor> {
            let ids = t.encode_padded(prompt);
            Ok(Tensor::from_vec(ids.clone(), (1, ids.len()), device)?)
        };
        let h1 = penultimate(
            self.text_encoder
                .text_model
                .forward_with_hidden_states(&ids(&self.tokenizer)?)?
                .hidden_states,
        )?;
        let out = self
            .text_encoder_2
            .text_model
            .forward_with_hidden_states(&ids(&self.tokenizer_2)?)?;
        let pooled = self.text_encoder_2.text_projection.forward(&out.pooled)?;
        let h2 = penultimate(out.hidden_states)?;
        Ok(SdxlEmbedding {
            context: Tensor::cat(&[&h1, &h2], 2)?.to_dtype(DType::F32)?,
            pooled: pooled.to_dtype(DType::F32)?,
        })
    }

    /// The unconditional side for classifier-free guidance: zeros for an empty negative prompt
    /// when `force_zeros_for_empty_prompt`, else the embedding of `negative`.
    pub fn embed_negative(&self, negative: &str, device: &Device) -> Result<SdxlEmbedding> {
        if negative.is_empty() && self.zeros_for_empty {
            let seq = self.tokenizer.max_length;
            return Ok(SdxlEmbedding {
                context: Tensor::zeros((1, seq, self.context_dim()), DType::F32, device)?,
                pooled: Tensor::zeros((1, self.pooled_dim()), DType::F32, device)?,
            });
        }
        self.embed(negative, device)
    }
}

/// `hidden_states[-2]`: the output of the second-to-last layer, before the final layer norm.
fn penultimate(mut states: Vec<Tensor>) -> Result<Tensor> {
    let n = states.len();
    if n < 2 {
        return Err(ModelError::InvalidInput(
            "an SDXL text encoder needs at least one layer".into(),
        ));
    }
    Ok(states.swap_remove(n - 2))
}

/// `force_zeros_for_empty_prompt` of `root/model_index.json` (true when absent).
fn zeros_for_empty(root: &Path) -> Result<bool> {
    let index: serde_json::Value = loader::read_config(&root.join("model_index.json"))?;
    Ok(index
        .get("force_zeros_for_empty_prompt")
        .and_then(|v| v.as_bool())
        .unwrap_or(true))
}
