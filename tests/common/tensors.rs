//! Tensor and fixture helpers for the model tests.

use candle_core::{DType, Tensor};
use std::path::{Path, PathBuf};

/// `tests/fixtures/<name>` of this checkout.
pub fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// A context alone as one guidance branch's conditioning (SD 1.x/2.x fixtures).
pub fn tc(t: &Tensor) -> vectorfusion::models::TextCond {
    t.clone().into()
}

/// Largest absolute elementwise difference of two tensors of the same shape (compared in f32).
pub fn max_abs(a: &Tensor, b: &Tensor) -> f32 {
    assert_eq!(a.dims(), b.dims(), "shape mismatch");
    abs_max(&(a.to_dtype(DType::F32).unwrap() - b.to_dtype(DType::F32).unwrap()).unwrap())
}

/// Largest absolute value of an f32 tensor.
pub fn abs_max(a: &Tensor) -> f32 {
    a.abs()
        .unwrap()
        .flatten_all()
        .unwrap()
        .max(0)
        .unwrap()
        .to_scalar::<f32>()
        .unwrap()
}

/// Asserts `got` is within `tol` (max abs) of the reference `want`, and that the reference is
/// not trivially small.
pub fn assert_close(name: &str, got: &Tensor, want: &Tensor, tol: f32) {
    let e = max_abs(got, want);
    assert!(
        e <= tol,
        "{name}: max abs err {e} > {tol} (ref scale {})",
        abs_max(want)
    );
    assert!(abs_max(want) > 1e-3, "{name}: reference is trivially small");
}
