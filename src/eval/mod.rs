//! Evaluation: CLIP R-Precision and CLIP similarity (the paper's Table 1).

pub mod clip;
