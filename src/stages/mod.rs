//! Pipeline stages: pure functions of (inputs, config, progress sink, cancel flag) → scene.

pub mod live;
pub mod sample;
pub mod sds;
pub mod steer;
pub mod styles;
