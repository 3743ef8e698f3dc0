//! One faer supernodal numeric factor `L Lᵀ` of a matrix on its symbolic analysis, and the
//! error a sparse Cholesky factor reports ([`super::direct`], [`super::halves`]).

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::SymbolicCholesky;
use faer::sparse::SparseColMat;
use faer::{Par, Side};

use crate::error::{Error, Result};

/// The sparse Cholesky factor's failure: `what` went wrong.
pub(super) fn failed(what: impl std::fmt::Display) -> Error {
    Error::NotConverged {
        iterations: 0,
        residual: f64::NAN,
        what: format!("reynolds-flow sparse Cholesky ({what})"),
    }
}

/// The values of the factor of `a` (lower triangle) on `symbolic`, with `par`.
pub(super) fn llt_values(
    symbolic: &SymbolicCholesky<usize>,
    a: &SparseColMat<usize, f64>,
    par: Par,
) -> Result<Vec<f64>> {
    let scratch = symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default());
    // Zeroed pages from the kernel: the factorisation writes every value, so filling them
    // here too would be a pass over the whole factor for nothing.
    let mut values: Vec<f64> = crate::alloc::try_zeroed(symbolic.len_val(), "the factor")
        .map_err(|_| failed("out of memory"))?;
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
