//! Whether the CPU has 256-bit vector instructions (AVX2), for the loops compiled twice:
//! for the baseline instruction set and with AVX2. Both builds do the same operations in the
//! same order and never fuse a multiply and an add, so they give the same bits; the wide one
//! only runs faster.

/// Whether this CPU has AVX2 (the standard library caches the check).
#[cfg(target_arch = "x86_64")]
#[inline]
pub(super) fn avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}
