//! diffusers `UNet2DConditionModel` built from `unet/config.json`.
//!
//! The config is parsed completely and mapped onto candle-transformers' UNet (whose module
//! names are the checkpoint keys); every field that would change the computation and that the
//! implementation does not cover is rejected with a clear error instead of being ignored.

use super::{ModelError, Result};
use candle_core::Tensor;
use candle_nn::VarBuilder;
use candle_transformers::models::stable_diffusion::unet_2d::{
    BlockConfig, UNet2DConditionModel, UNet2DConditionModelConfig,
};
use serde::Deserialize;
use serde_json::Value;

/// `unet/config.json` (fields that decide the architecture).
#[derive(Debug, Clone, Deserialize)]
pub struct UnetConfig {
    #[serde(default = "four")]
    pub in_channels: usize,
    #[serde(default = "four")]
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
    #[serde(default = "two")]
    pub layers_per_block: usize,
    #[serde(default = "one_f")]
    pub downsample_padding: f64,
    #[serde(default = "one_f")]
    pub mid_block_scale_factor: f64,
    #[serde(default = "silu")]
    pub act_fn: String,
    #[serde(default = "thirty_two")]
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
    #[serde(default)]
    pub upcast_attention: bool,
    #[serde(default)]
    pub class_embed_type: Option<String>,
    #[serde(default)]
    pub addition_embed_type: Option<String>,
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
}

fn four() -> usize {
    4
}
fn two() -> usize {
    2
}
fn thirty_two() -> usize {
    32
}
fn one_f() -> f64 {
    1.0
}
fn yes() -> bool {
    true
}
fn norm_eps() -> f64 {
    1e-5
}
fn silu() -> String {
    "silu".into()
}
fn transformer_layers() -> Value {
    Value::from(1)
}
fn head_dim() -> Value {
    Value::from(8)
}

/// An int or a per-block list of ints.
fn per_block(v: &Value, n: usize, name: &str) -> std::result::Result<Vec<usize>, String> {
    match v {
        Value::Number(x) => x
            .as_u64()
            .map(|x| vec![x as usize; n])
            .ok_or_else(|| format!("{name} must be a positive integer")),
        Value::Array(a) if a.len() == n => a
            .iter()
            .map(|x| {
                x.as_u64()
                    .map(|x| x as usize)
                    .ok_or_else(|| format!("{name} entries must be integers"))
            })
            .collect(),
        Value::Array(a) => Err(format!("{name} has {} entries for {n} blocks", a.len())),
        _ => Err(format!("{name} must be an integer or a list")),
    }
}

impl UnetConfig {
    /// Maps the config onto candle-transformers' UNet config, or says why it cannot.
    pub fn to_candle(&self) -> std::result::Result<UNet2DConditionModelConfig, String> {
        let n = self.block_out_channels.len();
        if n == 0 {
            return Err("block_out_channels is empty".into());
        }
        if self.down_block_types.len() != n || self.up_block_types.len() != n {
            return Err(format!(
                "{} down / {} up block types for {n} block_out_channels",
                self.down_block_types.len(),
                self.up_block_types.len()
            ));
        }
        let bad = |what: &str| Err(format!("{what} is not supported"));
        if self.norm_num_groups != 32 {
            // candle-transformers' down/up resnets always build 32-group norms
            return bad(&format!(
                "norm_num_groups {} (only 32)",
                self.norm_num_groups
            ));
        }
        if self.act_fn != "silu" {
            return bad(&format!("act_fn {:?}", self.act_fn));
        }
        if self.dual_cross_attention {
            return bad("dual_cross_attention");
        }
        if matches!(&self.only_cross_attention, Value::Bool(true))
            || matches!(&self.only_cross_attention, Value::Array(a) if a.iter().any(|x| x == &Value::Bool(true)))
        {
            return bad("only_cross_attention");
        }
        for (name, v) in [
            ("class_embed_type", &self.class_embed_type),
            ("addition_embed_type (SDXL)", &self.addition_embed_type),
            ("time_embedding_act_fn", &self.time_embedding_act_fn),
            ("timestep_post_act", &self.timestep_post_act),
        ] {
            if v.is_some() {
                return bad(name);
            }
        }
        if self.num_class_embeds.is_some() {
            return bad("num_class_embeds");
        }
        if self.encoder_hid_dim.is_some() {
            return bad("encoder_hid_dim");
        }
        if self.time_cond_proj_dim.is_some() {
            return bad("time_cond_proj_dim (LCM)");
        }
        if let Some(d) = self.time_embedding_dim
            && d != 4 * self.block_out_channels[0]
        {
            return bad("time_embedding_dim other than 4 × block_out_channels[0]");
        }
        if self
            .time_embedding_type
            .as_deref()
            .is_some_and(|t| t != "positional")
        {
            return bad("time_embedding_type other than positional");
        }
        if self
            .resnet_time_scale_shift
            .as_deref()
            .is_some_and(|t| t != "default")
        {
            return bad("resnet_time_scale_shift other than default");
        }
        if self.conv_in_kernel.is_some_and(|k| k != 3)
            || self.conv_out_kernel.is_some_and(|k| k != 3)
        {
            return bad("conv kernels other than 3");
        }
        if self
            .attention_type
            .as_deref()
            .is_some_and(|t| t != "default")
        {
            return bad("attention_type other than default");
        }
        if self
            .mid_block_type
            .as_deref()
            .is_some_and(|t| t != "UNetMidBlock2DCrossAttn")
        {
            return bad(&format!("mid_block_type {:?}", self.mid_block_type));
        }
        if !self.num_attention_heads.is_null() {
            return bad(
                "num_attention_heads (SD configs leave it null and use attention_head_dim)",
            );
        }
        let cross = match &self.cross_attention_dim {
            Value::Number(x) => x.as_u64().map(|x| x as usize),
            _ => None,
        }
        .ok_or("cross_attention_dim must be a single integer")?;
        let heads = per_block(&self.attention_head_dim, n, "attention_head_dim")?;
        let layers = per_block(
            &self.transformer_layers_per_block,
            n,
            "transformer_layers_per_block",
        )?;
        let mut blocks = Vec::with_capacity(n);
        for i in 0..n {
            let down = self.down_block_types[i].as_str();
            let up = self.up_block_types[n - 1 - i].as_str();
            let cross_attn = match (down, up) {
                ("CrossAttnDownBlock2D", "CrossAttnUpBlock2D") => true,
                ("DownBlock2D", "UpBlock2D") => false,
                _ => {
                    return Err(format!(
                        "block pair {down:?} / {up:?} (down block {i}, mirrored up block) is not supported"
                    ));
                }
            };
            let c = self.block_out_channels[i];
            if heads[i] == 0 || c % heads[i] != 0 {
                return Err(format!("{c} channels not divisible by {} heads", heads[i]));
            }
            if c % self.norm_num_groups != 0 {
                return Err(format!(
                    "{c} channels not divisible by norm_num_groups {}",
                    self.norm_num_groups
                ));
            }
            blocks.push(BlockConfig {
                out_channels: c,
                use_cross_attn: cross_attn.then_some(layers[i]),
                attention_head_dim: heads[i],
            });
        }
        // candle's mid block uses the last block's head count and one transformer layer
        if layers[n - 1] != 1 {
            return bad("transformer_layers_per_block > 1 in the last block (mid block)");
        }
        Ok(UNet2DConditionModelConfig {
            center_input_sample: self.center_input_sample,
            flip_sin_to_cos: self.flip_sin_to_cos,
            freq_shift: self.freq_shift,
            blocks,
            layers_per_block: self.layers_per_block,
            downsample_padding: self.downsample_padding as usize,
            mid_block_scale_factor: self.mid_block_scale_factor,
            norm_num_groups: self.norm_num_groups,
            norm_eps: self.norm_eps,
            cross_attention_dim: cross,
            sliced_attention_size: None,
            use_linear_projection: self.use_linear_projection,
        })
    }

    /// The full-size SD 1.5 UNet config (benchmarks with random weights).
    pub fn sd15() -> Self {
        Self::sd(768, Value::from(8), false)
    }

    /// The full-size SD 2.1 UNet config (benchmarks with random weights).
    pub fn sd21() -> Self {
        Self::sd(1024, serde_json::json!([5, 10, 20, 20]), true)
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

/// The UNet plus its parsed config.
pub struct Unet {
    pub config: UnetConfig,
    model: UNet2DConditionModel,
    dtype: candle_core::DType,
}

impl std::fmt::Debug for Unet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Unet")
            .field("config", &self.config)
            .finish()
    }
}

impl Unet {
    /// Builds the UNet (`path` is only used in error messages).
    pub fn new(vb: VarBuilder, config: UnetConfig, path: &std::path::Path) -> Result<Self> {
        let cc = config
            .to_candle()
            .map_err(|reason| ModelError::Unsupported {
                component: "unet",
                path: path.display().to_string(),
                reason,
            })?;
        let dtype = vb.dtype();
        let model =
            UNet2DConditionModel::new(vb, config.in_channels, config.out_channels, false, cc)
                .map_err(super::loader::mismatch("unet", path))?;
        Ok(Self {
            config,
            model,
            dtype,
        })
    }

    /// Raw model output (ε or v, as the scheduler's `prediction_type` says) for latents
    /// `[b, c, h, w]` at timestep `t`, conditioned on `context [b, seq, cross_attention_dim]`.
    pub fn forward(&self, latents: &Tensor, t: f64, context: &Tensor) -> Result<Tensor> {
        let (b, c, _, _) = latents.dims4().map_err(|_| {
            ModelError::InvalidInput(format!(
                "latents must be [b, c, h, w], got {:?}",
                latents.dims()
            ))
        })?;
        if c != self.config.in_channels {
            return Err(ModelError::InvalidInput(format!(
                "latents have {c} channels, the UNet expects {}",
                self.config.in_channels
            )));
        }
        let (cb, _, cd) = context.dims3().map_err(|_| {
            ModelError::InvalidInput(format!(
                "context must be [b, seq, dim], got {:?}",
                context.dims()
            ))
        })?;
        let want = self.config.cross_attention_dim.as_u64().unwrap_or(0) as usize;
        if cb != b || cd != want {
            return Err(ModelError::InvalidInput(format!(
                "context shape {:?} does not match batch {b} and cross_attention_dim {want}",
                context.dims()
            )));
        }
        let dtype = self.dtype;
        let out = self
            .model
            .forward(&latents.to_dtype(dtype)?, t, &context.to_dtype(dtype)?)?;
        Ok(out.to_dtype(latents.dtype())?)
    }
}
