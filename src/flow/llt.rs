//! The numeric factor `L Lᵀ` of a matrix on its symbolic analysis, and the
//! error a sparse Cholesky factor reports ([`super::direct`], [`super::halves`]).

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{SymbolicCholesky, SymbolicCholeskyRaw};
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use faer::{Par, Side};

use super::supernodal::{self, factor_values};
use super::symbolic::Layout;
use crate::error::{Error, Result};

/// The sparse Cholesky factor's failure: `what` went wrong.
pub(super) fn failed(what: impl std::fmt::Display) -> Error {
    Error::NotConverged {
        iterations: 0,
        residual: f64::NAN,
        what: format!("reynolds-flow sparse Cholesky ({what})"),
    }
}

/// The values of the factor of `a` (lower triangle) on `symbolic`: a supernodal structure's
/// by [`super::supernodal`] (on `a` permuted to the factor's order when the analysis has a
/// permutation), a simplicial one's by faer with `par`.
pub(super) fn llt_values(
    symbolic: &SymbolicCholesky<usize>,
    a: &SparseColMat<usize, f64>,
    par: Par,
) -> Result<Vec<f64>> {
    let len = symbolic.len_val();
    if let SymbolicCholeskyRaw::Supernodal(sn) = symbolic.raw() {
        let permuted = permutation(symbolic).map(|inv| permuted_lower(a, inv));
        let sn = Layout::of_faer(sn);
        return supernodal_values(sn, permuted.as_ref().unwrap_or(a), sn.nrows());
    }
    // Zeroed pages from the kernel: faer writes every value before it reads one.
    let mut values: Vec<f64> =
        crate::alloc::try_zeroed(len, "the factor").map_err(|_| failed("out of memory"))?;
    let scratch = symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default());
    let mut buf = MemBuffer::try_new(scratch).map_err(|_| failed("out of memory"))?;
    symbolic
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
    Ok(values)
}

/// The values of the factor of `a` (lower triangle, in the factor's order) on the
/// supernodal structure `sn` ([`super::supernodal`]).
/// The supernodes from column `stop` on are not factored ([`factor_values`]).
pub(super) fn supernodal_values(
    sn: Layout<'_>,
    a: &SparseColMat<usize, f64>,
    stop: usize,
) -> Result<Vec<f64>> {
    // The kernel's zeroed pages where the allocator maps fresh memory (no pass of zeros
    // here): the factor writes each block's zeros at its first touch, so a page is first
    // written, not read through the shared zero page and then faulted again.
    let mut values: Vec<f64> = crate::alloc::try_zeroed_huge(sn.len_val(), "the factor")
        .map_err(|_| failed("out of memory"))?;
    factor_values(sn, a.as_ref(), &mut values, stop)
        .map_err(|j| failed(format!("the pivot of column {j} is not positive")))?;
    Ok(values)
}

/// Bytes of [`llt_values`]'s scratch beside the values: the supernodal factor's (with the
/// permuted operator: at most three entries per column of the five-point stencil's lower
/// triangle, row and value each, the column pointers and their fill counters), or faer's
/// for a simplicial one.
pub(super) fn scratch_bytes(symbolic: &SymbolicCholesky<usize>, par: Par) -> u64 {
    match symbolic.raw() {
        SymbolicCholeskyRaw::Supernodal(sn) => {
            let permuted = if permutation(symbolic).is_some() {
                8 * (8 * sn.nrows() as u64 + 1)
            } else {
                0
            };
            supernodal::scratch_bytes(Layout::of_faer(sn)) + permuted
        }
        SymbolicCholeskyRaw::Simplicial(_) => symbolic
            .factorize_numeric_llt_scratch::<f64>(par, Default::default())
            .size_bytes() as u64,
    }
}

/// The analysis's order (`inv[i]`: the position of unknown `i`) when it is not the
/// identity: a custom order that is (a factor in halves, whose sides' matrices are built in
/// elimination order) needs no permuted copy of the operator.
fn permutation(symbolic: &SymbolicCholesky<usize>) -> Option<&[usize]> {
    symbolic
        .perm()
        .filter(|p| !p.arrays().0.iter().enumerate().all(|(i, &q)| i == q))
        .map(|p| p.arrays().1)
}

/// The lower triangle of `P A Pᵀ` from `a`'s (`inv[i]`: the position of unknown `i` in the
/// factor's order), by columns (rows unsorted).
pub(super) fn permuted_lower(
    a: &SparseColMat<usize, f64>,
    inv: &[usize],
) -> SparseColMat<usize, f64> {
    let m = a.nrows();
    let (ptr, rows, vals) = (a.symbolic().col_ptr(), a.symbolic().row_idx(), a.val());
    // Each stored entry's position `(row, column)` in the lower triangle of `P A Pᵀ`.
    let entries = || {
        (0..m).flat_map(move |j| {
            (ptr[j]..ptr[j + 1]).map(move |p| {
                let (r, c) = (inv[rows[p]], inv[j]);
                (r.max(c), r.min(c), vals[p])
            })
        })
    };
    let mut col_ptr = vec![0usize; m + 1];
    for (_, c, _) in entries() {
        col_ptr[c + 1] += 1;
    }
    for c in 0..m {
        col_ptr[c + 1] += col_ptr[c];
    }
    let mut fill = col_ptr[..m].to_vec();
    let (mut row_idx, mut values) = (vec![0usize; ptr[m]], vec![0.0; ptr[m]]);
    for (r, c, v) in entries() {
        row_idx[fill[c]] = r;
        values[fill[c]] = v;
        fill[c] += 1;
    }
    let pattern = SymbolicSparseColMat::new_unsorted_checked(m, m, col_ptr, None, row_idx);
    SparseColMat::new(pattern, values)
}
