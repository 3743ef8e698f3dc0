//! Loops compiled twice: for the baseline instruction set and with AVX2 (256-bit vectors),
//! the latter taken when the CPU has it. Both builds do the same operations in the same order
//! and never fuse a multiply and an add (Rust does not contract them), so they give the same
//! bits; the wide one only runs faster.

/// `f()`, compiled with AVX2 when the CPU has it (the standard library caches the check).
/// `f` (a closure marked `#[inline(always)]`) and what it calls must be inlined into it to
/// be compiled so: a function that is not stays in the baseline build.
#[inline(always)]
pub(super) fn run<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2.
        return unsafe { with_avx2(f) };
    }
    f()
}

/// `f()` compiled with AVX2.
///
/// # Safety
///
/// The CPU has AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn with_avx2<R>(f: impl FnOnce() -> R) -> R {
    f()
}
