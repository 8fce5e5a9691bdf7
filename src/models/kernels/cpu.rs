//! What this CPU is and which SIMD paths the model kernels take on it: named in `bench models`'
//! report so that every timing says where it was measured and with which code.
//!
//! Two paths are chosen at run time, per process: the `gemm` crate's micro-kernels (every
//! matrix product, the im2col and Winograd convolutions' products, and candle's own `matmul`),
//! with its AVX2 + FMA kernels and, in a build with the `avx512` feature (the default), its
//! AVX-512 ones, picked where the CPU has `avx512f`; and our element-wise kernels
//! ([`super::math::vectorised`]), which use AVX2 + FMA where present. Neither needs a
//! `target-cpu` flag: one binary runs everywhere.

use serde::Serialize;

/// The CPU and the kernels' SIMD paths on it.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct CpuReport {
    /// `model name` from `/proc/cpuinfo` (Linux), else the architecture.
    pub model: String,
    /// The SIMD features the kernels could use that this CPU has, among AVX2, FMA, AVX-512F,
    /// AVX-512 BF16, AVX-512 VNNI and AMX (x86-64 only; empty elsewhere).
    pub features: Vec<String>,
    /// The `gemm` crate's micro-kernel: `avx512f` (a build with the `avx512` feature, the
    /// default, on a CPU with AVX-512F), `avx2+fma`, or `generic`.
    pub gemm: String,
    /// Our element-wise kernels: `avx2+fma` (attention's softmax pass with `avx512f` where the
    /// CPU has it: `avx2+fma, softmax avx512f`) or `generic`.
    pub elementwise: String,
}

impl CpuReport {
    /// Detects this CPU.
    pub fn detect() -> Self {
        let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
        let mut features = features();
        // AMX has no stable run-time probe: the kernel's flags say whether it is there.
        features.extend(
            ["amx_tile", "amx_bf16"]
                .into_iter()
                .filter(|f| flags(&cpuinfo).any(|x| x == *f))
                .map(String::from),
        );
        let has = |f: &str| features.iter().any(|x| x == f);
        let avx2 = has("avx2") && has("fma");
        let gemm = if cfg!(feature = "avx512") && has("avx512f") {
            "avx512f"
        } else if avx2 {
            "avx2+fma"
        } else {
            "generic"
        };
        CpuReport {
            model: model_name(&cpuinfo).unwrap_or_else(|| std::env::consts::ARCH.to_string()),
            gemm: gemm.into(),
            elementwise: match (avx2, has("avx512f")) {
                (true, true) => "avx2+fma, softmax avx512f",
                (true, false) => "avx2+fma",
                _ => "generic",
            }
            .into(),
            features,
        }
    }
}

/// The value of the first `key` line of a `/proc/cpuinfo` text.
fn field<'a>(cpuinfo: &'a str, key: &str) -> Option<&'a str> {
    cpuinfo.lines().find_map(|l| {
        let (k, v) = l.split_once(':')?;
        (k.trim() == key).then_some(v.trim())
    })
}

/// The CPU's `model name`.
fn model_name(cpuinfo: &str) -> Option<String> {
    field(cpuinfo, "model name").map(String::from)
}

/// The CPU's `flags`, one word each.
fn flags(cpuinfo: &str) -> impl Iterator<Item = &str> {
    field(cpuinfo, "flags").unwrap_or("").split_whitespace()
}

#[cfg(target_arch = "x86_64")]
fn features() -> Vec<String> {
    let mut out = Vec::new();
    macro_rules! probe {
        ($($f:tt),*) => {$(
            if std::is_x86_feature_detected!($f) {
                out.push($f.to_string());
            }
        )*};
    }
    probe!("avx2", "fma", "avx512f", "avx512bf16", "avx512vnni");
    out
}

#[cfg(not(target_arch = "x86_64"))]
fn features() -> Vec<String> {
    Vec::new()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_model_name_line() {
        let text = "processor\t: 0\nvendor_id\t: AuthenticAMD\nmodel name\t: AMD EPYC 9654\nflags\t: fpu\n";
        assert_eq!(model_name(text).as_deref(), Some("AMD EPYC 9654"));
        assert_eq!(model_name("processor: 0\n"), None);
        assert_eq!(flags(text).collect::<Vec<_>>(), ["fpu"]);
    }

    #[test]
    fn the_gemm_path_follows_the_features() {
        let r = CpuReport::detect();
        let has = |f: &str| r.features.iter().any(|x| x == f);
        let want = if cfg!(feature = "avx512") && has("avx512f") {
            "avx512f"
        } else if has("avx2") && has("fma") {
            "avx2+fma"
        } else {
            "generic"
        };
        assert_eq!(r.gemm, want);
        assert!(!r.model.is_empty());
    }
}
