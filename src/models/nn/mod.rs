//! Layers with a forward pass that can record a tape and a hand-written backward pass that
//! returns only the gradient with respect to the layer input (never the weights' gradients).
//!
//! Score distillation needs `J_encoder^T · g`; candle's autograd would also compute every
//! kernel gradient (one extra convolution per layer, plus memory), which is pure waste here.
//! Field names follow the checkpoint keys.
//!
//! One file per layer: [`Conv2d`] and [`Downsample`] (`conv`), [`GroupNorm`] and [`LayerNorm`]
//! (`norm`), [`Linear`] (`linear`), [`ResnetBlock`] (`resnet`), [`SpatialSelfAttention`]
//! (`spatial_attention`), and the weightless ops (`ops`: attention, fused adds, activation
//! gradients).

mod conv;
mod linear;
mod norm;
mod ops;
mod resnet;
mod spatial_attention;

pub use conv::{Conv2d, Downsample};
pub use linear::Linear;
pub use norm::{GroupNorm, GroupNormTape, LayerNorm};
pub use ops::{add_relu, add_scaled, attention, relu_backward, silu_backward};
pub use resnet::{ResnetBlock, ResnetTape};
pub use spatial_attention::{AttentionTape, SpatialSelfAttention};

type R<T> = candle_core::Result<T>;
