//! Pipeline stages: pure functions of (inputs, config, progress sink, cancel flag) → scene.

pub mod live;
