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

/// Cells per side (`SIDE`, else `default_side`) and the cells' conductances of a square
/// grid: read from the file `CONDUCTANCES` (`SIDE²` little-endian `f64` in row-major order,
/// as `benchmarks/flow_conductances.py` writes them), else each drawn from `uniform` over
/// six decades, `10^(−6u)`.
// Not every bench that includes this file reads a grid.
#[allow(dead_code)]
pub fn grid_conductances(default_side: usize, uniform: &mut Uniform) -> (usize, Vec<f64>) {
    let side: usize = std::env::var("SIDE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default_side);
    let n = side * side;
    let c: Vec<f64> = match std::env::var("CONDUCTANCES") {
        Ok(path) => std::fs::read(&path)
            .unwrap_or_else(|e| panic!("CONDUCTANCES={path}: {e}"))
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")))
            .collect(),
        Err(_) => (0..n).map(|_| 10f64.powf(-6.0 * uniform.next())).collect(),
    };
    assert_eq!(c.len(), n, "CONDUCTANCES must hold SIDE² = {n} values");
    (side, c)
}
