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

/// Transform sizes for a grid.
pub fn padded(ny: usize, nx: usize, boundary: Boundary) -> (usize, usize) {
    match boundary {
        Boundary::Free => (
            smooth_size(ny.saturating_mul(2) - 1),
            smooth_size(nx.saturating_mul(2) - 1),
        ),
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
