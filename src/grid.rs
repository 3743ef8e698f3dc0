//! Grid geometry shared by the operators and the solvers: the boundary condition, transform
//! sizes, and the shape check.

use crate::error::{Error, Result};

/// Smallest 2,3,5-smooth integer `≥ n`.
pub fn smooth_size(n: usize) -> usize {
    let mut m = n.max(1);
    loop {
        let mut r = m;
        for p in [2, 3, 5] {
            while r % p == 0 {
                r /= p;
            }
        }
        if r == 1 {
            return m;
        }
        m += 1;
    }
}

/// Boundary condition of the elastic problem.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Boundary {
    Free,
    Periodic,
}

/// Transform sizes for a grid: for the free boundary the smallest 2,3,5-smooth `P ≥ 2n − 2`
/// per axis. The kernel is even, `K(d) = K(−d)`, so a circulant of period `P` reproduces the
/// linear convolution on the `n`-point patch as soon as every distance `|d| ≤ n − 1` has
/// `|d| ≤ P/2`: the two images `d` and `d − P` of the largest one then carry the same value.
/// `2n − 2` rather than `2n − 1` makes the paper's `n = 2^m + 1` grids exact powers of two
/// (129 → 256, where `2n − 1` needs 270).
pub fn padded(ny: usize, nx: usize, boundary: Boundary) -> (usize, usize) {
    let free = |n: usize| smooth_size(n.saturating_mul(2).saturating_sub(2).max(1));
    match boundary {
        Boundary::Free => (free(ny), free(nx)),
        Boundary::Periodic => (ny, nx),
    }
}

/// Validate a grid shape for the operators.
pub fn check_shape(ny: usize, nx: usize) -> Result<()> {
    if ny == 0 || nx == 0 {
        return Err(Error::invalid(
            "heights",
            "the grid must have at least one point",
        ));
    }
    Ok(())
}
