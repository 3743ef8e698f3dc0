//! Inputs shared by the Rust benches (`#[path]`-included by each): numbers that are the
//! same on every machine, with no dependency for them.

/// Uniform numbers in `[0, 1)` from a xorshift sequence.
pub struct Uniform(u64);

impl Uniform {
    /// The sequence started at `seed` (non-zero).
    pub fn new(seed: u64) -> Self {
        Uniform(seed)
    }

    /// The next number: the state advanced once, its top 53 bits.
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}
