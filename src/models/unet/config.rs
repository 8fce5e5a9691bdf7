//! `unet/config.json`, parsed completely and resolved into [`UnetArch`]: every field that would
//! change the computation and that the implementation does not cover is rejected with a clear
//! error instead of being ignored.

use crate::models::ConfigIssue;
use crate::models::serde_defaults::{num, silu, yes};
use serde::Deserialize;
use serde_json::Value;

/// `unet/config.json` (fields that decide the architecture).
#[derive(Debug, Clone, Deserialize)]
pub struct UnetConfig {
    #[serde(default = "num::<4>")]
    pub in_channels: usize,
    #[serde(default = "num::<4>")]
    pub out_channels: usize,
    #[serde(default)]
    pub center_input_sample: bool,
    #[serde(default = "yes")]
    pub flip_sin_to_cos: bool,
    #[serde(default)]
    pub freq_shift: f64,
    pub down_block_types: Vec<String>,
    pub up_block_types: Vec<String>,
    #[serde(default)]
    pub mid_block_type: Option<String>,
    pub block_out_channels: Vec<usize>,
    #[serde(default = "num::<2>")]
    pub layers_per_block: usize,
    #[serde(default = "one_f")]
    pub downsample_padding: f64,
    #[serde(default = "one_f")]
    pub mid_block_scale_factor: f64,
    #[serde(default = "silu")]
    pub act_fn: String,
    #[serde(default = "num::<32>")]
    pub norm_num_groups: usize,
    #[serde(default = "norm_eps")]
    pub norm_eps: f64,
    pub cross_attention_dim: Value,
    #[serde(default = "transformer_layers")]
    pub transformer_layers_per_block: Value,
    #[serde(default = "head_dim")]
    pub attention_head_dim: Value,
    #[serde(default)]
    pub num_attention_heads: Value,
    #[serde(default)]
    pub use_linear_projection: bool,
    #[serde(default)]
    pub sample_size: Option<usize>,
    // fields that must keep their SD defaults
    #[serde(default)]
    pub dual_cross_attention: bool,
    #[serde(default)]
    pub only_cross_attention: Value,
    /// `null` in SDXL's config (false).
    #[serde(default)]
    pub upcast_attention: Option<bool>,
    #[serde(default)]
    pub class_embed_type: Option<String>,
    /// `"text_time"` (SDXL): pooled text embedding + size/crop time ids added to the time
    /// embedding; other kinds are refused.
    #[serde(default)]
    pub addition_embed_type: Option<String>,
    #[serde(default)]
    pub addition_time_embed_dim: Option<usize>,
    #[serde(default)]
    pub projection_class_embeddings_input_dim: Option<usize>,
    #[serde(default)]
    pub encoder_hid_dim_type: Option<String>,
    #[serde(default)]
    pub num_class_embeds: Option<usize>,
    #[serde(default)]
    pub encoder_hid_dim: Option<usize>,
    #[serde(default)]
    pub time_cond_proj_dim: Option<usize>,
    #[serde(default)]
    pub time_embedding_type: Option<String>,
    #[serde(default)]
    pub time_embedding_dim: Option<usize>,
    #[serde(default)]
    pub time_embedding_act_fn: Option<String>,
    #[serde(default)]
    pub timestep_post_act: Option<String>,
    #[serde(default)]
    pub resnet_time_scale_shift: Option<String>,
    #[serde(default)]
    pub conv_in_kernel: Option<usize>,
    #[serde(default)]
    pub conv_out_kernel: Option<usize>,
    #[serde(default)]
    pub attention_type: Option<String>,
    #[serde(default)]
    pub reverse_transformer_layers_per_block: Value,
    #[serde(default)]
    pub resnet_out_scale_factor: Option<f64>,
    #[serde(default)]
    pub resnet_skip_time_act: bool,
    #[serde(default)]
    pub mid_block_only_cross_attention: Option<bool>,
    #[serde(default)]
    pub cross_attention_norm: Option<String>,
    #[serde(default)]
    pub class_embeddings_concat: bool,
}

fn one_f() -> f64 {
    1.0
}
fn norm_eps() -> f64 {
    1e-5
}
fn transformer_layers() -> Value {
    Value::from(1)
}
fn head_dim() -> Value {
    Value::from(8)
}

/// `Err(Unsupported)`: `setting` (with `value`) is a feature this implementation does not have.
fn unsupported<T>(
    setting: &'static str,
    value: Option<String>,
) -> std::result::Result<T, ConfigIssue> {
    Err(ConfigIssue::Unsupported { setting, value })
}

/// An int or a per-block list of ints.
fn per_block(v: &Value, n: usize, name: &str) -> std::result::Result<Vec<usize>, ConfigIssue> {
    match v {
        Value::Number(x) => x
            .as_u64()
            .map(|x| vec![x as usize; n])
            .ok_or_else(|| ConfigIssue::Inconsistent(format!("{name} must be a positive integer"))),
        Value::Array(a) if a.len() == n => a
            .iter()
            .map(|x| {
                x.as_u64().map(|x| x as usize).ok_or_else(|| {
                    ConfigIssue::Inconsistent(format!("{name} entries must be integers"))
                })
            })
            .collect(),
        Value::Array(a) => Err(ConfigIssue::Inconsistent(format!(
            "{name} has {} entries for {n} blocks",
            a.len()
        ))),
        _ => Err(ConfigIssue::Inconsistent(format!(
            "{name} must be an integer or a list"
        ))),
    }
}

/// A block's transformer: `heads` attention heads (head size = channels / heads) and `layers`
/// `BasicTransformerBlock`s.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AttnArch {
    pub heads: usize,
    pub layers: usize,
}

/// One resolution level: its output channels and the transformers of its down and up block
/// (`None` for `DownBlock2D` / `UpBlock2D`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LevelArch {
    pub channels: usize,
    pub down_attn: Option<AttnArch>,
    /// The up block that mirrors this level (up block `n − 1 − i` for level `i`).
    pub up_attn: Option<AttnArch>,
}

/// SDXL's added conditioning (`addition_embed_type = "text_time"`): `add_time_proj` embeds each
/// of the 6 time ids (original size, crop top-left, target size) in `time_dim` sinusoidal
/// channels; with the pooled text embedding (`pooled_dim` = `input_dim − 6 × time_dim`) they
/// go through `add_embedding` into the time embedding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TextTimeArch {
    pub time_dim: usize,
    /// `projection_class_embeddings_input_dim`.
    pub input_dim: usize,
}

impl TextTimeArch {
    /// The number of time ids (`[orig_h, orig_w, crop_top, crop_left, target_h, target_w]`).
    pub const TIME_IDS: usize = 6;

    /// Width of the pooled text embedding the UNet takes.
    pub fn pooled_dim(&self) -> usize {
        self.input_dim - Self::TIME_IDS * self.time_dim
    }
}

/// The resolved architecture: everything the forward pass needs, checked for consistency.
#[derive(Debug, Clone, PartialEq)]
pub struct UnetArch {
    pub in_channels: usize,
    pub out_channels: usize,
    pub levels: Vec<LevelArch>,
    pub layers_per_block: usize,
    pub mid: AttnArch,
    pub groups: usize,
    pub eps: f64,
    pub cross_attention_dim: usize,
    pub downsample_padding: usize,
    pub mid_block_scale_factor: f64,
    pub flip_sin_to_cos: bool,
    pub freq_shift: f64,
    pub center_input_sample: bool,
    pub upcast_attention: bool,
    /// SDXL's size/crop and pooled-text conditioning, when the config has it.
    pub text_time: Option<TextTimeArch>,
}

impl UnetArch {
    /// Channels of the time embedding (`4 × block_out_channels[0]`).
    pub fn time_embed_dim(&self) -> usize {
        4 * self.levels[0].channels
    }
}

impl UnetConfig {
    /// Resolves the config into the architecture, or says why it cannot.
    pub fn arch(&self) -> std::result::Result<UnetArch, ConfigIssue> {
        let n = self.block_out_channels.len();
        if n == 0 {
            return Err(ConfigIssue::Inconsistent(
                "block_out_channels is empty".into(),
            ));
        }
        if self.down_block_types.len() != n || self.up_block_types.len() != n {
            return Err(ConfigIssue::Inconsistent(format!(
                "{} down / {} up block types for {n} block_out_channels",
                self.down_block_types.len(),
                self.up_block_types.len()
            )));
        }
        self.check_blocks_supported()?;
        self.check_embeddings_supported()?;
        let cross = match &self.cross_attention_dim {
            Value::Number(x) => x.as_u64().map(|x| x as usize),
            _ => None,
        }
        .ok_or_else(|| {
            ConfigIssue::Inconsistent("cross_attention_dim must be a single integer".into())
        })?;
        let (levels, mid) = self.levels(n)?;
        if self.layers_per_block == 0 {
            return Err(ConfigIssue::Inconsistent("layers_per_block is 0".into()));
        }
        Ok(UnetArch {
            in_channels: self.in_channels,
            out_channels: self.out_channels,
            levels,
            layers_per_block: self.layers_per_block,
            mid,
            groups: self.norm_num_groups,
            eps: self.norm_eps,
            cross_attention_dim: cross,
            downsample_padding: self.downsample_padding as usize,
            mid_block_scale_factor: self.mid_block_scale_factor,
            flip_sin_to_cos: self.flip_sin_to_cos,
            freq_shift: self.freq_shift,
            center_input_sample: self.center_input_sample,
            upcast_attention: self.upcast_attention.unwrap_or(false),
            text_time: self.text_time()?,
        })
    }

    /// `addition_embed_type`: none, or `"text_time"` with both of its widths.
    fn text_time(&self) -> std::result::Result<Option<TextTimeArch>, ConfigIssue> {
        match self.addition_embed_type.as_deref() {
            None => Ok(None),
            Some("text_time") => {
                let (Some(time_dim), Some(input_dim)) = (
                    self.addition_time_embed_dim,
                    self.projection_class_embeddings_input_dim,
                ) else {
                    return Err(ConfigIssue::Inconsistent(
                        "addition_embed_type \"text_time\" needs addition_time_embed_dim and \
                         projection_class_embeddings_input_dim"
                            .into(),
                    ));
                };
                if time_dim == 0 || input_dim <= TextTimeArch::TIME_IDS * time_dim {
                    return Err(ConfigIssue::Inconsistent(format!(
                        "projection_class_embeddings_input_dim {input_dim} leaves no room for the \
                         pooled text embedding beside 6 × addition_time_embed_dim {time_dim}"
                    )));
                }
                Ok(Some(TextTimeArch {
                    time_dim,
                    input_dim,
                }))
            }
            Some(t) => unsupported("addition_embed_type", Some(format!("{t:?}"))),
        }
    }

    /// Refuses the block features this implementation does not have (other activations,
    /// attention variants, class and extra embeddings, resnet options).
    fn check_blocks_supported(&self) -> std::result::Result<(), ConfigIssue> {
        if self.act_fn != "silu" {
            return unsupported("act_fn", Some(format!("{:?}", self.act_fn)));
        }
        if self.dual_cross_attention {
            return unsupported("dual_cross_attention", None);
        }
        if matches!(&self.only_cross_attention, Value::Bool(true))
            || matches!(&self.only_cross_attention, Value::Array(a) if a.iter().any(|x| x == &Value::Bool(true)))
            || self.mid_block_only_cross_attention == Some(true)
        {
            return unsupported("only_cross_attention", None);
        }
        for (name, v) in [
            ("class_embed_type", &self.class_embed_type),
            ("encoder_hid_dim_type", &self.encoder_hid_dim_type),
            ("time_embedding_act_fn", &self.time_embedding_act_fn),
            ("timestep_post_act", &self.timestep_post_act),
            ("cross_attention_norm", &self.cross_attention_norm),
        ] {
            if v.is_some() {
                return unsupported(name, None);
            }
        }
        if self.num_class_embeds.is_some() || self.class_embeddings_concat {
            return unsupported("class embeddings", None);
        }
        if self.encoder_hid_dim.is_some() {
            return unsupported("encoder_hid_dim", None);
        }
        if self.time_cond_proj_dim.is_some() {
            return unsupported("time_cond_proj_dim (LCM)", None);
        }
        if self.resnet_skip_time_act {
            return unsupported("resnet_skip_time_act", None);
        }
        if self.resnet_out_scale_factor.is_some_and(|f| f != 1.0) {
            return unsupported("resnet_out_scale_factor other than 1", None);
        }
        if !self.reverse_transformer_layers_per_block.is_null() {
            return unsupported("reverse_transformer_layers_per_block", None);
        }
        Ok(())
    }

    /// Refuses the time-embedding and layout variants this implementation does not have.
    fn check_embeddings_supported(&self) -> std::result::Result<(), ConfigIssue> {
        if let Some(d) = self.time_embedding_dim
            && d != 4 * self.block_out_channels[0]
        {
            return unsupported(
                "time_embedding_dim other than 4 × block_out_channels[0]",
                None,
            );
        }
        for (name, v, only) in [
            (
                "time_embedding_type",
                &self.time_embedding_type,
                "positional",
            ),
            (
                "resnet_time_scale_shift",
                &self.resnet_time_scale_shift,
                "default",
            ),
            ("attention_type", &self.attention_type, "default"),
        ] {
            if v.as_deref().is_some_and(|t| t != only) {
                return unsupported(name, Some(format!("other than {only}")));
            }
        }
        if self.conv_in_kernel.is_some_and(|k| k != 3)
            || self.conv_out_kernel.is_some_and(|k| k != 3)
        {
            return unsupported("conv kernels other than 3", None);
        }
        if self
            .mid_block_type
            .as_deref()
            .is_some_and(|t| t != "UNetMidBlock2DCrossAttn")
        {
            return unsupported("mid_block_type", Some(format!("{:?}", self.mid_block_type)));
        }
        if self.downsample_padding.fract() != 0.0 || !(0.0..=1.0).contains(&self.downsample_padding)
        {
            return unsupported(
                "downsample_padding",
                Some(self.downsample_padding.to_string()),
            );
        }
        Ok(())
    }

    /// The `n` levels (their channels and transformers) and the mid block's transformer.
    fn levels(&self, n: usize) -> std::result::Result<(Vec<LevelArch>, AttnArch), ConfigIssue> {
        // diffusers: `num_attention_heads or attention_head_dim` is the head count (the legacy
        // naming of SD 1.x/2.x configs)
        let heads = if self.num_attention_heads.is_null() {
            per_block(&self.attention_head_dim, n, "attention_head_dim")?
        } else {
            per_block(&self.num_attention_heads, n, "num_attention_heads")?
        };
        let layers = per_block(
            &self.transformer_layers_per_block,
            n,
            "transformer_layers_per_block",
        )?;
        if self.norm_num_groups == 0 {
            return Err(ConfigIssue::Inconsistent("norm_num_groups is 0".into()));
        }
        // the transformer of level i (its down and up blocks; the mid block uses the last)
        let attn = |i: usize| -> std::result::Result<AttnArch, ConfigIssue> {
            let c = self.block_out_channels[i];
            if heads[i] == 0 || !c.is_multiple_of(heads[i]) || layers[i] == 0 {
                return Err(ConfigIssue::Inconsistent(format!(
                    "{c} channels, {} heads, {} transformer layers in block {i}",
                    heads[i], layers[i]
                )));
            }
            Ok(AttnArch {
                heads: heads[i],
                layers: layers[i],
            })
        };
        let mut levels = Vec::with_capacity(n);
        for i in 0..n {
            let c = self.block_out_channels[i];
            if !c.is_multiple_of(self.norm_num_groups) {
                return Err(ConfigIssue::Inconsistent(format!(
                    "{c} channels not divisible by norm_num_groups {}",
                    self.norm_num_groups
                )));
            }
            let down_attn = match self.down_block_types[i].as_str() {
                "CrossAttnDownBlock2D" => Some(attn(i)?),
                "DownBlock2D" => None,
                t => return unsupported("down_block_types", Some(format!("{t:?}"))),
            };
            let up_attn = match self.up_block_types[n - 1 - i].as_str() {
                "CrossAttnUpBlock2D" => Some(attn(i)?),
                "UpBlock2D" => None,
                t => return unsupported("up_block_types", Some(format!("{t:?}"))),
            };
            levels.push(LevelArch {
                channels: c,
                down_attn,
                up_attn,
            });
        }
        let mid = attn(n - 1).map_err(|e| ConfigIssue::Inconsistent(format!("mid block: {e}")))?;
        Ok((levels, mid))
    }

    /// The full-size SD 1.5 UNet config (benchmarks with random weights).
    pub fn sd15() -> Self {
        Self::sd(768, Value::from(8), false)
    }

    /// The full-size SD 2.1 UNet config (benchmarks with random weights).
    pub fn sd21() -> Self {
        Self::sd(1024, serde_json::json!([5, 10, 20, 20]), true)
    }

    /// The full-size SDXL base UNet config (benchmarks with random weights).
    pub fn sdxl() -> Self {
        let cfg = serde_json::json!({
            "block_out_channels": [320, 640, 1280],
            "down_block_types": ["DownBlock2D", "CrossAttnDownBlock2D", "CrossAttnDownBlock2D"],
            "up_block_types": ["CrossAttnUpBlock2D", "CrossAttnUpBlock2D", "UpBlock2D"],
            "cross_attention_dim": 2048,
            "attention_head_dim": [5, 10, 20],
            "transformer_layers_per_block": [1, 2, 10],
            "use_linear_projection": true,
            "layers_per_block": 2,
            "addition_embed_type": "text_time",
            "addition_time_embed_dim": 256,
            "projection_class_embeddings_input_dim": 2816,
            "upcast_attention": null,
        });
        // a literal config: deserialising it cannot fail
        serde_json::from_value(cfg).unwrap_or_else(|_| unreachable!())
    }

    fn sd(cross: usize, heads: Value, linear: bool) -> Self {
        let cfg = serde_json::json!({
            "block_out_channels": [320, 640, 1280, 1280],
            "down_block_types": ["CrossAttnDownBlock2D", "CrossAttnDownBlock2D", "CrossAttnDownBlock2D", "DownBlock2D"],
            "up_block_types": ["UpBlock2D", "CrossAttnUpBlock2D", "CrossAttnUpBlock2D", "CrossAttnUpBlock2D"],
            "cross_attention_dim": cross,
            "attention_head_dim": heads,
            "use_linear_projection": linear,
            "layers_per_block": 2,
        });
        // a literal config: deserialising it cannot fail
        serde_json::from_value(cfg).unwrap_or_else(|_| unreachable!())
    }
}
