//! Peak multiply-accumulate throughput of one core, per instruction family: f32 FMA on 256-bit
//! (AVX2) and 512-bit (AVX-512F) registers, and the bf16 pair dot product `vdpbf16ps`
//! (AVX-512 BF16, two bf16 products summed into each f32 lane). Twelve independent
//! accumulators in registers, so the figure is the issue rate, not a latency.
//!
//! Whether bf16 arithmetic can make a model faster on this CPU is decided here: where the bf16
//! dot product retires fewer multiply-accumulates per second than f32 FMA, a bf16 matrix kernel
//! cannot beat the f32 one however it is blocked.
//!
//! `cargo run --release --example cpu_peak [MILLION_ITERATIONS]`

use std::time::Instant;

/// Multiply-accumulates per second (G) of `f` run `n` times over 12 accumulators of `lanes`
/// products each; the best of three.
fn rate(n: usize, lanes: usize, f: impl Fn(usize) -> f32) -> f64 {
    let mut best = f64::INFINITY;
    let mut sink = 0.0;
    for _ in 0..3 {
        let t = Instant::now();
        sink += f(n);
        best = best.min(t.elapsed().as_secs_f64());
    }
    std::hint::black_box(sink);
    (n * 12 * lanes) as f64 / best / 1e9
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    /// `unsafe fn NAME(n)`: `n` rounds of one `STEP` (on the operand `X = INIT`, opaque to the
    /// optimiser) on each of twelve accumulators, compiled for `FEATURES` (the caller checks the
    /// CPU has them), returning their sum through `SUM`.
    macro_rules! peak {
        ($name:ident, $features:literal, $zero:expr, $x:ident = $init:expr,
         |$acc:ident| $step:expr, $sum:path) => {
            /// # Safety
            /// The CPU has the target features this function is compiled for.
            #[target_feature(enable = $features)]
            pub unsafe fn $name(n: usize) -> f32 {
                let $x = std::hint::black_box($init);
                let mut accs = [$zero; 12];
                for _ in 0..n {
                    for $acc in accs.iter_mut() {
                        *$acc = $step;
                    }
                }
                accs.into_iter().fold(0.0f32, |s, a| s + $sum(a))
            }
        };
    }

    peak!(
        fma256,
        "avx2,fma",
        _mm256_setzero_ps(),
        a = _mm256_set1_ps(1.000_000_1),
        |acc| _mm256_fmadd_ps(a, a, *acc),
        _mm256_cvtss_f32
    );
    peak!(
        fma512,
        "avx512f",
        _mm512_setzero_ps(),
        a = _mm512_set1_ps(1.000_000_1),
        |acc| _mm512_fmadd_ps(a, a, *acc),
        _mm512_reduce_add_ps
    );
    // 1.0 in bf16 in both halves of every 32-bit lane.
    peak!(
        dpbf16,
        "avx512f,avx512bf16",
        _mm512_setzero_ps(),
        a = _mm512_cvtne2ps_pbh(_mm512_set1_ps(1.0), _mm512_set1_ps(1.0)),
        |acc| _mm512_dpbf16_ps(*acc, a, a),
        _mm512_reduce_add_ps
    );
}

fn main() {
    let millions: usize = match std::env::args().nth(1).map(|s| s.parse()) {
        None => 20,
        Some(Ok(m)) if m > 0 => m,
        Some(_) => {
            eprintln!("usage: cpu_peak [MILLION_ITERATIONS > 0]");
            std::process::exit(2);
        }
    };
    let n = millions * 1_000_000;
    let cpu = vectorfusion::models::kernels::cpu::CpuReport::detect();
    println!("{}", serde_json::to_string(&cpu).unwrap_or_default());
    #[cfg(target_arch = "x86_64")]
    {
        let row = |name: &str, ok: bool, lanes: usize, f: unsafe fn(usize) -> f32| {
            if ok {
                // SAFETY: `ok` is the runtime check of the features `f` is compiled for.
                let g = rate(n, lanes, |n| unsafe { f(n) });
                println!("{name:<22} {g:7.1} G multiply-accumulates/s on one core");
            } else {
                println!("{name:<22} not on this CPU");
            }
        };
        let has = |f: &str| match f {
            "avx2" => is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma"),
            "avx512f" => is_x86_feature_detected!("avx512f"),
            _ => is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("avx512bf16"),
        };
        row("f32 FMA, AVX2", has("avx2"), 8, x86::fma256);
        row("f32 FMA, AVX-512F", has("avx512f"), 16, x86::fma512);
        row("bf16 dot, AVX-512 BF16", has("bf16"), 32, x86::dpbf16);
    }
    #[cfg(not(target_arch = "x86_64"))]
    println!("only x86-64 instruction families are measured");
}
