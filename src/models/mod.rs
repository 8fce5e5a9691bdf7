//! Neural networks on candle.

pub mod clip;
