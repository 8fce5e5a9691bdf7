pub mod sds;
pub mod styles;
