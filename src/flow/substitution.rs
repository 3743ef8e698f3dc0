//! Forward and backward substitution with a supernodal Cholesky factor `L Lᵀ` (faer's
//! supernodal structure and values), in plain loops over each supernode's dense block:
//! faer's general solve dispatches dense kernels and a temporary per supernode, and the
//! supernodes of the flow's factors have about five columns (docs/flow.md).

use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;

/// Supernode `s` of a supernodal factor with values `values`: its first column `start`, its
/// `ncols` columns, the rows of its pattern below them, and its dense column-major block
/// (`ncols + pattern.len()` rows: the diagonal block on top of the pattern's rows).
pub(super) struct Supernode<'a> {
    pub(super) start: usize,
    pub(super) ncols: usize,
    pub(super) pattern: &'a [usize],
    pub(super) block: &'a [f64],
}

impl<'a> Supernode<'a> {
    #[inline(always)]
    pub(super) fn of(
        sn: &'a SymbolicSupernodalCholesky<usize>,
        values: &'a [f64],
        s: usize,
    ) -> Self {
        let (start, end) = (sn.supernode_begin()[s], sn.supernode_end()[s]);
        let (rptr, vptr) = (sn.col_ptr_for_row_idx(), sn.col_ptr_for_val());
        Supernode {
            start,
            ncols: end - start,
            pattern: &sn.row_idx()[rptr[s]..rptr[s + 1]],
            block: &values[vptr[s]..vptr[s + 1]],
        }
    }

    /// Column `c` of the block (its diagonal entry at `c`, the pattern's rows from `ncols`).
    #[inline(always)]
    pub(super) fn column(&self, c: usize) -> &'a [f64] {
        let nrows = self.ncols + self.pattern.len();
        &self.block[c * nrows..(c + 1) * nrows]
    }
}

/// `L Lᵀ y = w` in place (positions in the factor's order) with the supernodal factor
/// `values` of `sn`: each supernode is a dense column-major block, its diagonal block (lower
/// triangle) on top of the rows of its pattern. Forward by columns (`y_c = w_c / L_cc`,
/// then `w_r −= L_rc y_c` below), backward by rows of `Lᵀ`
/// (`y_c = (w_c − Σ_r L_rc y_r) / L_cc`).
pub(super) fn supernodal_solve(
    sn: &SymbolicSupernodalCholesky<usize>,
    values: &[f64],
    w: &mut [f64],
) {
    let n = w.len();
    supernodal_forward::<1>(sn, values, w, n);
    supernodal_backward::<1>(sn, values, w, n);
}

/// The forward half of [`supernodal_solve`] for `K` columns interleaved (`w[K p + c]`, read
/// from the factor once), on the factor's columns before `stop` (a factor in halves stops
/// at its separator, [`super::halves`]): their `y`, and their updates `w_r −= L_rc y_c` to
/// every row below, the separator's included. Each column's arithmetic is that of
/// `K = 1`.
pub(super) fn supernodal_forward<const K: usize>(
    sn: &SymbolicSupernodalCholesky<usize>,
    values: &[f64],
    w: &mut [f64],
    stop: usize,
) {
    super::wide::run(
        #[inline(always)]
        || supernodal_forward_plain::<K>(sn, values, w, stop),
    )
}

/// [`supernodal_forward`] in the instruction set of the function it is inlined into.
#[inline(always)]
pub(super) fn supernodal_forward_plain<const K: usize>(
    sn: &SymbolicSupernodalCholesky<usize>,
    values: &[f64],
    w: &mut [f64],
    stop: usize,
) {
    for s in 0..sn.n_supernodes() {
        let node = Supernode::of(sn, values, s);
        let (start, ncols, pattern) = (node.start, node.ncols, node.pattern);
        for c in 0..ncols {
            let i = start + c;
            if i >= stop {
                return;
            }
            let col = node.column(c);
            let mut y = [0.0; K];
            for (k, yk) in y.iter_mut().enumerate() {
                *yk = w[K * i + k] / col[c];
                w[K * i + k] = *yk;
            }
            for (wt, &l) in w[K * (i + 1)..K * (start + ncols)]
                .chunks_exact_mut(K)
                .zip(&col[c + 1..ncols])
            {
                for k in 0..K {
                    wt[k] -= l * y[k];
                }
            }
            for (&t, &l) in pattern.iter().zip(&col[ncols..]) {
                for k in 0..K {
                    w[K * t + k] -= l * y[k];
                }
            }
        }
    }
}

/// The backward half of [`supernodal_solve`] for `K` interleaved columns, on the factor's
/// columns before `stop`, the values of `w` from `stop` on taken as solved (a separator's).
pub(super) fn supernodal_backward<const K: usize>(
    sn: &SymbolicSupernodalCholesky<usize>,
    values: &[f64],
    w: &mut [f64],
    stop: usize,
) {
    super::wide::run(
        #[inline(always)]
        || supernodal_backward_plain::<K>(sn, values, w, stop),
    )
}

/// [`supernodal_backward`] in the instruction set of the function it is inlined into.
#[inline(always)]
pub(super) fn supernodal_backward_plain<const K: usize>(
    sn: &SymbolicSupernodalCholesky<usize>,
    values: &[f64],
    w: &mut [f64],
    stop: usize,
) {
    for s in (0..sn.n_supernodes()).rev() {
        let node = Supernode::of(sn, values, s);
        let (start, ncols, pattern) = (node.start, node.ncols, node.pattern);
        if start >= stop {
            continue;
        }
        for c in (0..ncols.min(stop - start)).rev() {
            let col = node.column(c);
            let i = start + c;
            let mut a = [0.0; K];
            a.copy_from_slice(&w[K * i..K * (i + 1)]);
            for (wt, &l) in w[K * (i + 1)..K * (start + ncols)]
                .chunks_exact(K)
                .zip(&col[c + 1..ncols])
            {
                for k in 0..K {
                    a[k] -= l * wt[k];
                }
            }
            // The pattern's sum in four interleaved partial sums: one chain of dependent
            // multiply-adds would wait on each before the next (the forward half's updates
            // are independent).
            let below = &col[ncols..];
            let mut part = [[0.0; K]; 4];
            let (rows4, rows_rest) = pattern.split_at(pattern.len() & !3);
            for (ts, ls) in rows4.chunks_exact(4).zip(below.chunks_exact(4)) {
                for (q, p) in part.iter_mut().enumerate() {
                    for k in 0..K {
                        p[k] += ls[q] * w[K * ts[q] + k];
                    }
                }
            }
            for (&t, &l) in rows_rest.iter().zip(&below[rows4.len()..]) {
                for k in 0..K {
                    part[0][k] += l * w[K * t + k];
                }
            }
            for k in 0..K {
                a[k] -= (part[0][k] + part[1][k]) + (part[2][k] + part[3][k]);
                w[K * i + k] = a[k] / col[c];
            }
        }
    }
}
