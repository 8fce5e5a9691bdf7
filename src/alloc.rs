//! Allocator tuning (the `mimalloc` feature; without it every function here does nothing).
//!
//! The models allocate and free buffers of tens to hundreds of MB per layer. mimalloc returns
//! freed memory to the OS after `purge_delay` ms, so the next layer's buffer comes back as fresh
//! pages that the kernel faults in and zeroes: 383 k page faults in one `bench models --arch
//! sd15 --size 256 --only encoder,vjp` run. [`tune`] keeps freed memory for 10 s (24 k faults;
//! docs/BENCHMARKS.md has the times); an idle process still gives its memory back after that.

/// `mi_option_purge_delay`: its index in `mi_option_e` (`mimalloc.h`, v2 and v3). The Rust
/// bindings do not name it; `tests/allocator.rs` checks the index against the option that the
/// `MIMALLOC_PURGE_DELAY` environment variable sets.
#[cfg(feature = "mimalloc")]
const MI_OPTION_PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;

/// Purge delay set by [`tune`], in ms.
pub const PURGE_DELAY_MS: i64 = 10_000;

/// Sets mimalloc's purge delay to [`PURGE_DELAY_MS`], unless the user chose one through
/// `MIMALLOC_PURGE_DELAY`. Call once at start-up.
pub fn tune() {
    #[cfg(feature = "mimalloc")]
    if std::env::var_os("MIMALLOC_PURGE_DELAY").is_none() {
        // SAFETY: sets an integer option; mimalloc reads options atomically.
        unsafe { libmimalloc_sys::mi_option_set(MI_OPTION_PURGE_DELAY, PURGE_DELAY_MS as _) }
    }
}

/// mimalloc's current purge delay in ms (`None` without the `mimalloc` feature).
pub fn purge_delay() -> Option<i64> {
    #[cfg(feature = "mimalloc")]
    {
        // SAFETY: reads an integer option.
        Some(unsafe { libmimalloc_sys::mi_option_get(MI_OPTION_PURGE_DELAY) } as i64)
    }
    #[cfg(not(feature = "mimalloc"))]
    None
}
