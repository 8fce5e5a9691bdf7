//! CPU f32 kernels for the diffusion models: convolution as shifted GEMMs or Winograd ([`conv`],
//! [`winograd`]) and a fused group norm (+SiLU) ([`norm`]), each with its input adjoint for the
//! autoencoders' VJP; for the UNet's transformer blocks, linear layers with fused epilogues
//! ([`linear`]), fused tiled attention ([`attention`]), layer norm and GEGLU.
//!
//! The layers in [`super::nn`] use them when their tensors are f32 on the CPU and fall back to
//! candle's ops otherwise (CUDA, f16). [`set_enabled`]`(false)` forces the fallback everywhere,
//! which `vectorfusion bench models --candle-kernels` uses as the in-run baseline.

pub mod attention;
pub mod conv;
pub mod cpu;
pub mod linear;
pub mod math;
pub mod norm;
pub mod pointwise;
pub mod winograd;

use candle_core::{DType, Device, Storage, Tensor};
use std::sync::atomic::{AtomicBool, Ordering};

static ENABLED: AtomicBool = AtomicBool::new(true);

/// Turns the kernels on (the default) or off (candle's own ops) for the whole process.
pub fn set_enabled(on: bool) {
    ENABLED.store(on, Ordering::Relaxed);
}

/// Whether the kernels apply to these tensors: enabled, all f32 and on the CPU.
pub fn applies(ts: &[&Tensor]) -> bool {
    ENABLED.load(Ordering::Relaxed) && cpu_f32(ts)
}

/// Whether the kernels can run on these tensors (all f32 and on the CPU), enabled or not.
pub fn cpu_f32(ts: &[&Tensor]) -> bool {
    ts.iter()
        .all(|t| t.dtype() == DType::F32 && t.device().is_cpu())
}

/// Runs `f` on the contiguous f32 values of a CPU tensor.
pub fn with_f32<T>(
    t: &Tensor,
    f: impl FnOnce(&[f32]) -> candle_core::Result<T>,
) -> candle_core::Result<T> {
    let t = t.contiguous()?;
    let (storage, layout) = t.storage_and_layout();
    let Storage::Cpu(cpu) = &*storage else {
        candle_core::bail!("kernel called on a non-CPU tensor");
    };
    let all = cpu.as_slice::<f32>()?;
    let Some((start, end)) = layout.contiguous_offsets() else {
        candle_core::bail!("kernel called on a non-contiguous tensor");
    };
    f(&all[start..end])
}

/// A CPU tensor from kernel output (moved, not copied).
pub fn tensor(v: Vec<f32>, shape: &[usize]) -> candle_core::Result<Tensor> {
    Tensor::from_vec(v, shape, &Device::Cpu)
}

/// Why a kernel refused its arguments: the buffers do not fit the geometry it was given (the
/// layers in [`super::nn`] check shapes first, so this is a bug, never a user's input).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum KernelError {
    /// A buffer holds `got` values where the geometry needs `want`.
    #[error("{op}: {what} has {got} values, expected {want}")]
    Length {
        op: &'static str,
        what: &'static str,
        got: usize,
        want: usize,
    },
    /// A buffer of `len` values is not a whole number of rows (or planes) of `row` values.
    #[error("{op}: {len} values are not rows of {row}")]
    Rows {
        op: &'static str,
        len: usize,
        row: usize,
    },
    /// A `rows × cols` window (a matrix view, a GEMM output) reaches past its buffer's `len`
    /// values.
    #[error("{op}: a {rows}x{cols} window does not fit {len} values")]
    Window {
        op: &'static str,
        rows: usize,
        cols: usize,
        len: usize,
    },
    /// A geometry the kernel cannot run: zero sizes, channels that do not divide into
    /// groups or heads, a kernel larger than its padded input.
    #[error("{op}: {reason}")]
    Geometry { op: &'static str, reason: String },
}

/// What the kernels return.
pub type KernelResult<T> = Result<T, KernelError>;

/// `Err(Length)` unless `got == want`.
pub(crate) fn check_len(
    op: &'static str,
    what: &'static str,
    got: usize,
    want: usize,
) -> KernelResult<()> {
    if got == want {
        Ok(())
    } else {
        Err(KernelError::Length {
            op,
            what,
            got,
            want,
        })
    }
}

/// A kernel's error as a candle error (kept as its source).
pub fn err(e: KernelError) -> candle_core::Error {
    candle_core::Error::wrap(e)
}

/// A raw pointer that may cross threads. Users write disjoint parts of the buffer from
/// different threads and say so at each `unsafe` use.
#[derive(Clone, Copy)]
pub(crate) struct SyncPtr(pub(crate) *mut f32);
unsafe impl Send for SyncPtr {}
unsafe impl Sync for SyncPtr {}

impl SyncPtr {
    /// The pointer (a method, so closures capture the whole `Sync` wrapper).
    pub(crate) fn get(self) -> *mut f32 {
        self.0
    }
}

/// One GEMM `dst (+)= beta · lhs · rhs`, the way every kernel here calls the `gemm` crate: an
/// `m × n` output with row pitch `dst.1` (column stride 1), `lhs` (`m × k`) and `rhs` (`k × n`)
/// as `(pointer, row stride, column stride)`; `read_dst` adds to what `dst` holds instead of
/// overwriting it. No conjugation.
///
/// # Safety
/// Every element of the three windows lies inside its buffer, and nothing else reads or writes
/// the output window during the call.
pub(crate) unsafe fn gemm_strided(
    (m, n, k): (usize, usize, usize),
    (dst, dst_rs): (*mut f32, usize),
    read_dst: bool,
    (lhs, lhs_rs, lhs_cs): (*const f32, usize, usize),
    (rhs, rhs_rs, rhs_cs): (*const f32, usize, usize),
    beta: f32,
    threads: gemm::Parallelism,
) {
    // SAFETY: the caller's contract covers every access the GEMM makes.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst,
            1,
            dst_rs as isize,
            read_dst,
            lhs,
            lhs_cs as isize,
            lhs_rs as isize,
            rhs,
            rhs_cs as isize,
            rhs_rs as isize,
            1.0,
            beta,
            false,
            false,
            false,
            threads,
        )
    }
}

/// Deterministic values in [-1, 1) for the kernel tests (an LCG; no RNG state to share).
#[cfg(test)]
pub(crate) fn test_values(n: usize, seed: u64) -> Vec<f32> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        })
        .collect()
}

/// The largest absolute difference between two equally long value lists (the kernel tests'
/// error measure).
#[cfg(test)]
pub(crate) fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0f32, f32::max)
}
