//! CLIP vision tower (ViT), as `transformers`' `CLIPVisionTransformer`: patch convolution
//! (no bias), class embedding, learned positions, `pre_layrnorm`, encoder, `post_layernorm` on
//! the class token. Key names follow the checkpoint (`vision_model.…`).

use super::config::ClipVisionConfig;
use super::text::{ClipEncoder, EncoderShape};
use candle_core::{IndexOp, Module, Result, Tensor};
use candle_nn::{Conv2d, Conv2dConfig, Embedding, LayerNorm, VarBuilder, embedding, layer_norm};

/// Outputs of the vision tower.
#[derive(Debug, Clone)]
pub struct VisionOutput {
    /// `(batch, 1 + patches, hidden)`: encoder output (before `post_layernorm`).
    pub last_hidden_state: Tensor,
    /// `(batch, hidden)`: `post_layernorm` of the class token.
    pub pooled: Tensor,
}

/// `CLIPVisionTransformer` (the weights under `vision_model.`).
#[derive(Debug, Clone)]
pub struct ClipVisionTransformer {
    patch_embedding: Conv2d,
    class_embedding: Tensor,
    position_embedding: Embedding,
    pre_layrnorm: LayerNorm,
    encoder: ClipEncoder,
    post_layernorm: LayerNorm,
    config: ClipVisionConfig,
}

/// The prefix of the vision tower: `vision_model.` or none (standalone checkpoints saved by
/// transformers >= 5).
pub fn vision_tower(vb: VarBuilder) -> VarBuilder {
    if vb.contains_tensor("vision_model.embeddings.class_embedding") {
        vb.pp("vision_model")
    } else {
        vb
    }
}

impl ClipVisionTransformer {
    /// `vb` points at the `vision_model` prefix.
    pub fn new(vb: VarBuilder, config: &ClipVisionConfig) -> Result<Self> {
        let c = config;
        let emb = vb.pp("embeddings");
        let conv_cfg = Conv2dConfig {
            stride: c.patch_size,
            ..Default::default()
        };
        let patch_embedding = candle_nn::conv2d_no_bias(
            c.num_channels,
            c.hidden_size,
            c.patch_size,
            conv_cfg,
            emb.pp("patch_embedding"),
        )?;
        let shape = EncoderShape {
            hidden_size: c.hidden_size,
            intermediate_size: c.intermediate_size,
            num_layers: c.num_hidden_layers,
            num_heads: c.num_attention_heads,
            act: c.hidden_act,
            eps: c.layer_norm_eps,
        };
        Ok(Self {
            patch_embedding,
            class_embedding: emb.get(c.hidden_size, "class_embedding")?,
            position_embedding: embedding(
                c.num_positions(),
                c.hidden_size,
                emb.pp("position_embedding"),
            )?,
            pre_layrnorm: layer_norm(c.hidden_size, c.layer_norm_eps, vb.pp("pre_layrnorm"))?,
            encoder: ClipEncoder::new(vb.pp("encoder"), &shape)?,
            post_layernorm: layer_norm(c.hidden_size, c.layer_norm_eps, vb.pp("post_layernorm"))?,
            config: c.clone(),
        })
    }

    pub fn config(&self) -> &ClipVisionConfig {
        &self.config
    }

    /// `pixel_values`: `(batch, channels, image_size, image_size)`, already normalised.
    pub fn forward(&self, pixel_values: &Tensor) -> Result<VisionOutput> {
        let (b, c, h, w) = pixel_values.dims4()?;
        let s = self.config.image_size;
        if c != self.config.num_channels || h != s || w != s {
            candle_core::bail!(
                "pixel_values must be (batch, {}, {s}, {s}), got ({b}, {c}, {h}, {w})",
                self.config.num_channels
            );
        }
        let hidden = self.config.hidden_size;
        let patches = self
            .patch_embedding
            .forward(pixel_values)?
            .flatten_from(2)?
            .transpose(1, 2)?; // (b, n, hidden)
        let cls = self
            .class_embedding
            .reshape((1, 1, hidden))?
            .broadcast_as((b, 1, hidden))?
            .to_dtype(patches.dtype())?;
        let x = Tensor::cat(&[&cls, &patches], 1)?;
        let n = x.dim(1)?;
        let pos = Tensor::arange(0u32, n as u32, x.device())?;
        let x = x.broadcast_add(&self.position_embedding.forward(&pos)?)?;
        let x = self.pre_layrnorm.forward(&x)?;
        let last = self.encoder.forward(&x, false)?;
        let pooled = self.post_layernorm.forward(&last.i((.., 0, ..))?)?;
        Ok(VisionOutput {
            last_hidden_state: last,
            pooled,
        })
    }
}
