//! Evaluation: CLIP R-Precision and CLIP similarity (the paper's Table 1), and colour binding.

pub mod clip;
pub mod colour;
