//! Forward and backward substitution with a supernodal Cholesky factor `L Lᵀ` (faer's
//! layout of the structure and values, [`super::symbolic::Layout`]), in plain loops over
//! each supernode's dense block: faer's general solve dispatches dense kernels and a
//! temporary per supernode, and the supernodes of the flow's factors have about five
//! columns (docs/flow.md).

use super::symbolic::Layout;

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
    pub(super) fn of(sn: Layout<'a>, values: &'a [f64], s: usize) -> Self {
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
pub(super) fn supernodal_solve(sn: Layout<'_>, values: &[f64], w: &mut [f64]) {
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
    sn: Layout<'_>,
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
///
/// Per supernode whose `w` is not all zero: its diagonal block column by column, then the
/// pattern's updates `t_r = Σ_c L_rc y_c` summed over the supernode's columns in a
/// contiguous buffer (column by column, each a loop over contiguous rows that vectorises)
/// and subtracted from `w` in one scattered pass, instead of one scattered
/// read-modify-write of `w` per column.
#[inline(always)]
pub(super) fn supernodal_forward_plain<const K: usize>(
    sn: Layout<'_>,
    values: &[f64],
    w: &mut [f64],
    stop: usize,
) {
    let mut t = vec![0.0; K * widest_pattern(sn)];
    for s in 0..sn.n_supernodes() {
        let node = Supernode::of(sn, values, s);
        let (start, ncols, pattern) = (node.start, node.ncols, node.pattern);
        if start >= stop {
            return;
        }
        let solved = ncols.min(stop - start);
        // Nothing reached these columns yet (every `w` on them is 0): their `y` is 0 and
        // their updates subtract nothing, so the block is not read. The flow's first
        // right-hand sides are nonzero on the inlet or outlet row only, and most of the
        // grid's supernodes lie below none of those cells in the elimination tree.
        if w[K * start..K * (start + solved)].iter().all(|&v| v == 0.0) {
            if solved < ncols {
                return;
            }
            continue;
        }
        for c in 0..solved {
            let i = start + c;
            let col = node.column(c);
            for k in 0..K {
                w[K * i + k] /= col[c];
            }
            let (head, tail) = w[K * i..K * (start + ncols)].split_at_mut(K);
            for (wt, &l) in tail.chunks_exact_mut(K).zip(&col[c + 1..ncols]) {
                for k in 0..K {
                    wt[k] -= l * head[k];
                }
            }
        }
        let t = &mut t[..K * pattern.len()];
        t.iter_mut().for_each(|v| *v = 0.0);
        for c in 0..solved {
            let mut y = [0.0; K];
            y.copy_from_slice(&w[K * (start + c)..K * (start + c + 1)]);
            for (tr, &l) in t.chunks_exact_mut(K).zip(&node.column(c)[ncols..]) {
                for k in 0..K {
                    tr[k] += l * y[k];
                }
            }
        }
        for (tr, &r) in t.chunks_exact(K).zip(pattern) {
            for k in 0..K {
                w[K * r + k] -= tr[k];
            }
        }
        if solved < ncols {
            return;
        }
    }
}

/// The longest pattern of a supernode of `sn`: the rows a supernode's updates reach.
fn widest_pattern(sn: Layout<'_>) -> usize {
    let rptr = sn.col_ptr_for_row_idx();
    (0..sn.n_supernodes())
        .map(|s| rptr[s + 1] - rptr[s])
        .max()
        .unwrap_or(0)
}

/// The backward half of [`supernodal_solve`] for `K` interleaved columns, on the factor's
/// columns before `stop`, the values of `w` from `stop` on taken as solved (a separator's).
pub(super) fn supernodal_backward<const K: usize>(
    sn: Layout<'_>,
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
///
/// Per supernode: `w` on its pattern gathered once into a contiguous buffer, then each
/// column (last first) as its pattern's dot product with it (in four interleaved partial
/// sums: one chain of dependent multiply-adds would wait on each before the next) and the
/// diagonal block's rows below it.
#[inline(always)]
pub(super) fn supernodal_backward_plain<const K: usize>(
    sn: Layout<'_>,
    values: &[f64],
    w: &mut [f64],
    stop: usize,
) {
    let mut g = vec![0.0; K * widest_pattern(sn)];
    for s in (0..sn.n_supernodes()).rev() {
        let node = Supernode::of(sn, values, s);
        let (start, ncols, pattern) = (node.start, node.ncols, node.pattern);
        if start >= stop {
            continue;
        }
        let g = &mut g[..K * pattern.len()];
        for (gr, &r) in g.chunks_exact_mut(K).zip(pattern) {
            gr.copy_from_slice(&w[K * r..K * (r + 1)]);
        }
        let (g4, g_rest) = g.split_at(K * (pattern.len() & !3));
        for c in (0..ncols.min(stop - start)).rev() {
            let col = node.column(c);
            let below = &col[ncols..];
            let mut part = [[0.0; K]; 4];
            for (gs, ls) in g4.chunks_exact(4 * K).zip(below.chunks_exact(4)) {
                for (q, p) in part.iter_mut().enumerate() {
                    for k in 0..K {
                        p[k] += ls[q] * gs[K * q + k];
                    }
                }
            }
            for (gr, &l) in g_rest.chunks_exact(K).zip(&below[g4.len() / K..]) {
                for k in 0..K {
                    part[0][k] += l * gr[k];
                }
            }
            let i = start + c;
            let (head, tail) = w[K * i..K * (start + ncols)].split_at_mut(K);
            let mut a = [0.0; K];
            for k in 0..K {
                a[k] = head[k] - ((part[0][k] + part[1][k]) + (part[2][k] + part[3][k]));
            }
            for (wt, &l) in tail.chunks_exact(K).zip(&col[c + 1..ncols]) {
                for k in 0..K {
                    a[k] -= l * wt[k];
                }
            }
            for k in 0..K {
                head[k] = a[k] / col[c];
            }
        }
    }
}
