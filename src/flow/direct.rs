//! Sparse Cholesky solve of the Reynolds system on the cells with unknowns (faer, AMD
//! ordering, supernodal, one thread so the bits do not depend on the thread count).
//!
//! The gaps of a contact close continuously at the contact edges, so `g³` spans fifteen
//! orders of magnitude and the flow near the percolation threshold passes through necks whose
//! conductance is that small: conjugate gradients then stall far from the answer in double
//! precision, while the factorisation is exact to round-off.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, SymmetricOrdering};
use faer::sparse::{SparseColMat, Triplet};
use faer::{Conj, Mat, Par, Side};

use super::assemble::Stencil;
use crate::error::{Error, Result};

fn failed(what: impl std::fmt::Display) -> Error {
    Error::NotConverged {
        iterations: 0,
        residual: f64::NAN,
        what: format!("reynolds-flow sparse Cholesky ({what})"),
    }
}

/// Solves `A x_c = b_c` for every right-hand side `b_c` of `rhs` on the active cells of `st`
/// (others get 0) with one factor, `refine` steps of iterative refinement each.
pub fn solve(st: &Stencil, rhs: &[&[f64]], xs: &mut [Vec<f64>], refine: usize) -> Result<()> {
    let (ny, nx) = (st.ny, st.nx);
    let n = ny * nx;
    let mut index = vec![usize::MAX; n];
    let mut cells = Vec::new();
    for (k, slot) in index.iter_mut().enumerate() {
        if st.active[k] {
            *slot = cells.len();
            cells.push(k);
        }
    }
    let m = cells.len();
    for x in xs.iter_mut() {
        x.iter_mut().for_each(|v| *v = 0.0);
    }
    if m == 0 {
        return Ok(());
    }
    // Lower triangle (row ≥ column) of the symmetric matrix.
    let mut trip = Vec::with_capacity(3 * m);
    for (r, &k) in cells.iter().enumerate() {
        trip.push(Triplet::new(r, r, st.d[k]));
        let (i, j) = (k / nx, k % nx);
        let mut push = |l: usize, c: f64| {
            let q = index[l];
            if c > 0.0 && q != usize::MAX && q < r {
                trip.push(Triplet::new(r, q, -c));
            }
        };
        if j > 0 {
            push(k - 1, st.e[k - 1]);
        } else if st.periodic && nx > 1 {
            push(k + nx - 1, st.e[k + nx - 1]);
        }
        if j + 1 < nx {
            push(k + 1, st.e[k]);
        } else if st.periodic && nx > 1 {
            push(i * nx, st.e[k]);
        }
        if i > 0 {
            push(k - nx, st.s[k - nx]);
        }
        if i + 1 < ny {
            push(k + nx, st.s[k]);
        }
    }
    // Duplicates (the two faces of a 2-wide periodic row) are summed by the constructor.
    let a = SparseColMat::<usize, f64>::try_new_from_triplets(m, m, &trip).map_err(failed)?;
    drop(trip);
    let sym = factorize_symbolic_cholesky(
        a.symbolic(),
        Side::Lower,
        SymmetricOrdering::Amd,
        Default::default(),
    )
    .map_err(failed)?;
    let par = Par::Seq;
    let mut values = Vec::new();
    values
        .try_reserve_exact(sym.len_val())
        .map_err(|_| failed("out of memory"))?;
    values.resize(sym.len_val(), 0.0);
    let mut buf =
        MemBuffer::try_new(sym.factorize_numeric_llt_scratch::<f64>(par, Default::default()))
            .map_err(|_| failed("out of memory"))?;
    let llt = sym
        .factorize_numeric_llt::<f64>(
            &mut values,
            a.as_ref(),
            Side::Lower,
            Default::default(),
            par,
            MemStack::new(&mut buf),
            Default::default(),
        )
        .map_err(|e| failed(format!("{e:?}")))?;
    let mut sbuf = MemBuffer::try_new(sym.solve_in_place_scratch::<f64>(1, par))
        .map_err(|_| failed("out of memory"))?;
    let mut res = vec![0.0; n];
    for (b, x) in rhs.iter().zip(xs.iter_mut()) {
        let mut sol = Mat::<f64>::from_fn(m, 1, |r, _| b[cells[r]]);
        llt.solve_in_place_with_conj(Conj::No, sol.as_mut(), par, MemStack::new(&mut sbuf));
        for (r, &k) in cells.iter().enumerate() {
            x[k] = sol[(r, 0)];
        }
        for _ in 0..refine {
            st.residual(x, b, &mut res);
            let mut corr = Mat::<f64>::from_fn(m, 1, |r, _| res[cells[r]]);
            llt.solve_in_place_with_conj(Conj::No, corr.as_mut(), par, MemStack::new(&mut sbuf));
            for (r, &k) in cells.iter().enumerate() {
                x[k] += corr[(r, 0)];
            }
        }
    }
    Ok(())
}
