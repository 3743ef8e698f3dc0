//! Helpers shared by the Rust tests (compiled for tests only).

/// The multiplier and increment of the 64-bit linear congruential sequence of [`lcg`].
pub(crate) const LCG: (u64, u64) = (6364136223846793005, 1442695040888963407);

/// `n` uniform numbers in `[0, 1)` from the linear congruential sequence started at `seed`
/// (each state advanced once before its top 53 bits are used): test inputs that are the same
/// on every machine, with no dependency for them.
pub(crate) fn lcg(seed: u64, n: usize) -> Vec<f64> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            s = s.wrapping_mul(LCG.0).wrapping_add(LCG.1);
            (s >> 11) as f64 / (1u64 << 53) as f64
        })
        .collect()
}
