//! Every memory estimate of the elastic contact solvers, in bytes, in one place, so the
//! refusals before a large allocation (`Error::TooLarge`) and their documentation agree.
//! Each estimate saturates at `u64::MAX` for sizes no machine holds. (The Reynolds flow's
//! estimate lives with its solvers in `flow/`.)

use crate::grid::{padded, smooth_size, Boundary};

/// Bytes held by an operator for an `ny × nx` grid, and the transient peak of building it.
/// Saturates at `u64::MAX` for sizes no machine holds.
pub fn operator(ny: usize, nx: usize, boundary: Boundary) -> u64 {
    let (py, px) = padded(ny, nx, boundary);
    let (py, px, ny) = (py as u64, px as u64, ny as u64);
    let pxh = px / 2 + 1;
    let spec = (py / 2 + 1).saturating_mul(pxh).saturating_mul(8);
    // One apply: the ny × pxh half spectrum, allocated with the plans and kept.
    let apply = ny.saturating_mul(pxh).saturating_mul(16);
    // Building the free kernel spectrum: the padded kernel and its half spectrum, then
    // that half spectrum and the spectrum.
    let build = match boundary {
        Boundary::Free => py
            .saturating_mul(pxh)
            .saturating_mul(16)
            .saturating_add(py.saturating_mul(px).saturating_mul(8).max(spec)),
        Boundary::Periodic => spec,
    };
    apply.saturating_add(build.max(spec))
}

/// Peak bytes of a Polonsky–Keer solve ([`crate::contact::polonsky_keer::solve`]) on an `ny × nx` grid: the larger of building the operator (free:
/// kernel table, padded kernel and its half spectrum) and iterating (kernel spectrum, the
/// operator's half-spectrum buffer, the preconditioner's, and their `f32` twins, seven `N`-vectors
/// `p, u, g, t, r`, the field of non-linear changes and the influence table of the sparse
/// corrections), plus one copy of the heights (the bindings copy non-contiguous
/// input) and a margin for the coarse-to-fine start.
pub fn polonsky_keer(ny: usize, nx: usize, boundary: Boundary) -> u64 {
    let n = (ny as u64).saturating_mul(nx as u64);
    let (py, px) = padded(ny, nx, boundary);
    let (py, px) = (py as u64, px as u64);
    let pxh = px / 2 + 1;
    let spec = (py / 2 + 1).saturating_mul(pxh).saturating_mul(8);
    let apply = (ny as u64).saturating_mul(pxh).saturating_mul(16);
    let build = match boundary {
        // Kernel table and the operator's apply buffer, then the padded real kernel and its
        // half spectrum together, then the half spectrum with the spectrum.
        Boundary::Free => {
            let padded_kernel = py.saturating_mul(px).saturating_mul(8);
            let half = py.saturating_mul(pxh).saturating_mul(16);
            n.saturating_mul(8)
                .saturating_add(apply)
                .saturating_add(half.saturating_add(padded_kernel.max(spec)))
        }
        Boundary::Periodic => spec.saturating_add(apply),
    };
    // The preconditioner: its spectrum and apply buffer on the smooth-padded grid (its
    // result, z, is written into r).
    let (qy, qx) = (smooth_size(ny) as u64, smooth_size(nx) as u64);
    let qxh = qx / 2 + 1;
    let pre = (qy / 2 + 1)
        .saturating_mul(qxh)
        .saturating_mul(8)
        .saturating_add((ny as u64).saturating_mul(qxh).saturating_mul(16));
    // The f32 twins of the operator and of the preconditioner's transform: half the bytes of
    // their spectra and apply buffers.
    let pre_transform = (qy / 2 + 1)
        .saturating_mul(qxh)
        .saturating_mul(8)
        .saturating_add((ny as u64).saturating_mul(qxh).saturating_mul(16));
    let single = spec.saturating_add(apply).saturating_add(pre_transform) / 2;
    let iterate = spec
        .saturating_add(apply)
        .saturating_add(single)
        .saturating_add(n.saturating_mul(7 * 8))
        .saturating_add(pre);
    // The coarse-start pressure becomes the iterate `p`. The coarse levels run on a quarter of
    // the points before the fine operator is built; with a caller's operator they run beside
    // it, and their peak (a quarter of the iterating arrays and spectra, the coarse solution's
    // three fields and the prolonged pressure, about 30N bytes) stays below the fine
    // iteration's (48N bytes and the preconditioner). The extra N values are a margin for the
    // coarse heights and the allocator.
    n.saturating_mul(8)
        .saturating_add(build.max(iterate))
        .saturating_add(n.saturating_mul(8))
}

/// Bytes the dense contact problem holds besides its operator: the kernel table, the
/// heights and the solvers' `N`-fields (`p, u, g, b`, …), eight `f64` per point.
pub fn contact_problem(ny: usize, nx: usize, boundary: Boundary) -> u64 {
    operator(ny, nx, boundary)
        .saturating_add((ny as u64).saturating_mul(nx as u64).saturating_mul(64))
}

/// Bytes of a dense Cholesky factor with room for `k` passive points (`k²` doubles).
pub fn dense_factor(k: usize) -> u64 {
    (k as u64) * (k as u64) * 8
}

/// Peak bytes of growing the dense factor from `old` to `new` rows: both are held while the
/// old one is copied into the new one.
pub fn dense_factor_growth(new: usize, old: usize) -> u64 {
    dense_factor(new) + dense_factor(old)
}

/// Peak bytes of appending `nb` points to a factor of `k` points with room for `cap`: the
/// factor, `R` (`k × nb`), `S` and its kept copy (`nb × nb` each) and the Cholesky scratch
/// (about one more `nb × nb`).
pub fn dense_factor_update(cap: usize, k: usize, nb: usize) -> u64 {
    let work = 8 * (k as u64 * nb as u64 + 3 * nb as u64 * nb as u64);
    dense_factor(cap).saturating_add(work)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn memory_estimate_4097_free_fits_8_gib() {
        let b = polonsky_keer(4097, 4097, Boundary::Free);
        assert!(b < 8 << 30, "{b}");
        assert!(b > 1 << 30);
        assert!(polonsky_keer(4096, 4096, Boundary::Periodic) < b);
    }

    #[test]
    fn memory_estimate_8193_free_fits_a_24_gib_machine() {
        // 8193² (2^13 + 1, padded FFT grid 16384²): the problem (kernel, operator, fields)
        // and the Polonsky–Keer solve each stay well below the default limit of a 24 GiB
        // machine (80 % of what is available), 9.0 and 8.3 GiB (1.0 GiB of it the operator's
        // f32 twin).
        let problem = contact_problem(8193, 8193, Boundary::Free);
        let solve = polonsky_keer(8193, 8193, Boundary::Free);
        assert!(problem < 10 << 30, "{problem}");
        assert!(solve < 9 << 30, "{solve}");
        assert!(solve > 4 * polonsky_keer(4097, 4097, Boundary::Free) - (1 << 30));
    }

    #[test]
    fn operator_fits_inside_the_solver_estimates() {
        for b in [Boundary::Free, Boundary::Periodic] {
            let op = operator(257, 129, b);
            assert!(op < polonsky_keer(257, 129, b));
            assert!(op < contact_problem(257, 129, b));
        }
        assert_eq!(dense_factor(1000), 8_000_000);
        assert_eq!(dense_factor_growth(3, 2), 8 * (9 + 4));
    }
}
