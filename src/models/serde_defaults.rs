//! Default values for the `#[serde(default = "…")]` fields of the diffusers, transformers and
//! OpenCLIP config structs: `num::<N>` for sizes and counts, `id::<N>` for token ids, and the
//! defaults several configs share.

/// `N`, for a size or count.
pub(crate) fn num<const N: usize>() -> usize {
    N
}

/// `N`, for a token id.
pub(crate) fn id<const N: u32>() -> u32 {
    N
}

pub(crate) fn yes() -> bool {
    true
}

pub(crate) fn silu() -> String {
    "silu".into()
}
