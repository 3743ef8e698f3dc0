//! The numeric supernodal Cholesky factor `A = L Lᵀ` on a supernodal symbolic structure
//! (faer's, or [`super::symbolic`]'s, the same layout), in plain loops.
//!
//! The flow's factors have thousands of supernodes of about four to sixteen columns
//! (docs/flow.md): faer's numeric factor dispatches a dense product per update and a dense
//! Cholesky and triangular solve per supernode, whose set-up costs more than their
//! arithmetic at these sizes. Here the values keep faer's layout (each supernode a dense
//! column-major block, its diagonal block on top of the rows of its pattern `P`), so the
//! solves ([`super::substitution`]) read either, and the supernodes are taken in order,
//! right-looking:
//!
//! 1. the supernode's columns of `A` are added into its block (the updates of the
//!    supernodes before it are already there);
//! 2. the block is factored column by column: `L_cc = √a_cc`, the column below divided by
//!    it, and its outer product subtracted from the columns to its right;
//! 3. its update `U = L[P, :] L[P, :]ᵀ` (lower triangle) is formed once, in 4 × 4 tiles of
//!    its packed rows, and each column of `U` is subtracted from the block of the later
//!    supernode that holds that column, through the rows' positions in that block.
//!
//! Supernodes of [`DENSE`] columns and more are factored and multiplied by faer's dense
//! kernels. The others' arithmetic is plain code, compiled twice on x86-64: for the baseline
//! instruction set and with AVX2 (256-bit vectors, taken when the CPU has them). Neither
//! fuses a multiply and an add (Rust never contracts them), so both give the same bits on
//! every x86-64 CPU (tested); the AVX2 build takes about a tenth less time (the 513² contact
//! gap of the benchmarks, docs/flow.md). All of it is sequential, so the values do not
//! depend on the thread count.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch, LltError};
use faer::linalg::matmul::triangular::{matmul, BlockStructure};
use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::sparse::SparseColMatRef;
use faer::{Accum, MatMut, MatRef, Par};

use super::symbolic::Layout;

/// The values of the factor of `a` (its lower triangle, by columns, in the factor's order)
/// on `sn`, written into `values` (`sn.len_val()` of them, whatever they hold on entry:
/// each supernode's block is zeroed where it is first touched, by its first update or its
/// own turn, so no separate pass of zeros runs over the whole factor first and the block is
/// in cache when the factor adds into it). The supernodes from column `stop` on (a
/// supernode boundary; `sn.nrows()` for the whole factor) get their columns of `a` and the
/// updates of those before `stop`, and are not factored: their blocks' lower triangles
/// then hold the Schur complement of the columns before `stop`. `Err(j)`: the pivot of
/// column `j` is not positive and finite (`a` is not positive definite to working
/// precision).
pub(super) fn factor_values(
    sn: Layout<'_>,
    a: SparseColMatRef<'_, usize, f64>,
    values: &mut [f64],
    stop: usize,
) -> Result<(), usize> {
    super::wide::run(
        #[inline(always)]
        || factor_values_plain(sn, a, values, stop),
    )
}

/// [`factor_values`] for the instruction set it is inlined into.
#[inline(always)]
pub(super) fn factor_values_plain(
    sn: Layout<'_>,
    a: SparseColMatRef<'_, usize, f64>,
    values: &mut [f64],
    stop: usize,
) -> Result<(), usize> {
    let n = sn.nrows();
    let ns = sn.n_supernodes();
    let (begin, end) = (sn.supernode_begin(), sn.supernode_end());
    let (rptr, vptr, rows) = (sn.col_ptr_for_row_idx(), sn.col_ptr_for_val(), sn.row_idx());
    assert!(values.len() == vptr[ns] && a.nrows() == n && a.ncols() == n);
    let mut supernode_of = vec![0u32; n];
    for s in 0..ns {
        supernode_of[begin[s]..end[s]].fill(s as u32);
    }
    // Row of the current supernode's block of each pattern row.
    let mut local = vec![0usize; n];
    // Whether each supernode's block still holds what `values` held on entry.
    let mut untouched = vec![true; ns];
    let (mut update, mut packed, mut relative) = (Vec::new(), Vec::new(), Vec::new());
    let (a_ptr, a_rows, a_vals) = (a.col_ptr(), a.row_idx(), a.val());
    for s in 0..ns {
        let (fs, ls) = (begin[s], end[s]);
        let nc = ls - fs;
        let pattern = &rows[rptr[s]..rptr[s + 1]];
        let nr = nc + pattern.len();
        for (q, &r) in pattern.iter().enumerate() {
            local[r] = nc + q;
        }
        let (here, later) = values.split_at_mut(vptr[s + 1]);
        let block = &mut here[vptr[s]..];
        if untouched[s] {
            block.fill(0.0);
            untouched[s] = false;
        }
        for j in fs..ls {
            let col = &mut block[(j - fs) * nr..(j - fs + 1) * nr];
            for p in a_ptr[j]..a_ptr[j + 1] {
                let i = a_rows[p];
                if i >= j {
                    col[if i < ls { i - fs } else { local[i] }] += a_vals[p];
                }
            }
        }
        assert!(
            fs >= stop || ls <= stop,
            "column {stop} is not a supernode boundary"
        );
        if fs >= stop {
            continue;
        }
        factor_block(block, nr, nc).map_err(|c| fs + c)?;
        if pattern.is_empty() {
            continue;
        }
        // `U = L_s[pattern] L_s[pattern]ᵀ`, subtracted from the later supernodes' blocks.
        let m = pattern.len();
        // `U`'s leading dimension.
        let m4 = if nc >= DENSE {
            products_dense(&mut update, block, nr, nc, m);
            m
        } else {
            let m4 = m.next_multiple_of(TILE);
            pack(&mut packed, block, nr, nc, m4);
            products(&mut update, &packed, nc, m4);
            m4
        };
        let mut q = 0;
        while q < m {
            let t = supernode_of[pattern[q]] as usize;
            let (ft, lt) = (begin[t], end[t]);
            let tpat = &rows[rptr[t]..rptr[t + 1]];
            let ntr = lt - ft + tpat.len();
            let q_end = q + pattern[q..].partition_point(|&r| r < lt);
            // Rows of `t`'s block of the pattern's rows from `q` on (all among its rows).
            relative.clear();
            let mut w = 0;
            for &r in &pattern[q..] {
                if r < lt {
                    relative.push(r - ft);
                } else {
                    while tpat[w] < r {
                        w += 1;
                    }
                    relative.push(lt - ft + w);
                }
            }
            let tblock = &mut later[vptr[t] - vptr[s + 1]..vptr[t + 1] - vptr[s + 1]];
            if untouched[t] {
                tblock.fill(0.0);
                untouched[t] = false;
            }
            for qq in q..q_end {
                let col = &mut tblock[(pattern[qq] - ft) * ntr..];
                for (&r, &v) in relative[qq - q..]
                    .iter()
                    .zip(&update[qq * m4 + qq..qq * m4 + m])
                {
                    col[r] -= v;
                }
            }
            q = q_end;
        }
    }
    Ok(())
}

/// Bytes of [`factor_values`]'s scratch on `sn`: each column's supernode and block row, and
/// the largest update with its packed rows (or faer's dense scratch for a wide supernode).
pub(super) fn scratch_bytes(sn: Layout<'_>) -> u64 {
    let (begin, end, rptr) = (
        sn.supernode_begin(),
        sn.supernode_end(),
        sn.col_ptr_for_row_idx(),
    );
    let largest = (0..sn.n_supernodes())
        .map(|s| {
            let (nc, m) = (end[s] - begin[s], rptr[s + 1] - rptr[s]);
            let m4 = m.next_multiple_of(TILE);
            let dense = if nc >= DENSE {
                cholesky_in_place_scratch::<f64>(nc, Par::Seq, Default::default()).size_bytes()
            } else {
                0
            };
            (8 * (m4 * m4 + m4 * nc + m) + dense) as u64
        })
        .max()
        .unwrap_or(0);
    12 * sn.nrows() as u64 + largest
}

/// Rows of the tiles of an update.
const TILE: usize = 4;

/// The pattern's `m` rows of a factored block (`nr` rows, `nc` columns, column-major, the
/// pattern's rows from `nc`) into `packed` by tiles of [`TILE`] rows: tile `t`'s column `c`
/// at `(t · nc + c) · TILE`, rows past `m` zero.
#[inline(always)]
fn pack(packed: &mut Vec<f64>, block: &[f64], nr: usize, nc: usize, m4: usize) {
    packed.clear();
    packed.resize(m4 * nc, 0.0);
    for c in 0..nc {
        let col = &block[c * nr + nc..(c + 1) * nr];
        for (i, &v) in col.iter().enumerate() {
            packed[((i / TILE) * nc + c) * TILE + i % TILE] = v;
        }
    }
}

/// The tile of `X Yᵀ` at rows `i0..i0 + 4` and columns `q0..q0 + 4`, `X` the packed rows
/// ([`pack`]) and `Y` their first rows: `t[b][a] = Σ_c X[i0 + a, c] X[q0 + b, c]`.
#[inline(always)]
fn tile(packed: &[f64], ncd: usize, i0: usize, q0: usize) -> [[f64; TILE]; TILE] {
    let x = &packed[(i0 / TILE) * ncd * TILE..(i0 / TILE + 1) * ncd * TILE];
    let y = &packed[(q0 / TILE) * ncd * TILE..(q0 / TILE + 1) * ncd * TILE];
    let mut t = [[0.0; TILE]; TILE];
    for (xc, yc) in x.chunks_exact(TILE).zip(y.chunks_exact(TILE)) {
        for b in 0..TILE {
            for a in 0..TILE {
                t[b][a] += xc[a] * yc[b];
            }
        }
    }
    t
}

/// `U = X Xᵀ` in tiles ([`tile`]) of the packed rows `X` (`m4` rows, `nc` columns): its
/// lower tiles into `update` (`m4 × m4`, column-major).
#[inline(always)]
fn products(update: &mut Vec<f64>, packed: &[f64], nc: usize, m4: usize) {
    update.clear();
    update.resize(m4 * m4, 0.0);
    for q0 in (0..m4).step_by(TILE) {
        for i0 in (q0..m4).step_by(TILE) {
            let t = tile(packed, nc, i0, q0);
            for (b, tb) in t.iter().enumerate() {
                update[(q0 + b) * m4 + i0..(q0 + b) * m4 + i0 + TILE].copy_from_slice(tb);
            }
        }
    }
}

/// The supernode's block (`nr × nc`, column-major, updated) factored in place column by
/// column; `Err(c)`: the pivot of column `c` is not positive and finite.
#[inline(always)]
fn factor_block(block: &mut [f64], nr: usize, nc: usize) -> Result<(), usize> {
    if nc >= DENSE {
        return factor_block_dense(block, nr, nc);
    }
    for c in 0..nc {
        let (left, right) = block.split_at_mut((c + 1) * nr);
        let col = &mut left[c * nr..];
        let pivot = col[c];
        if !(pivot > 0.0 && pivot.is_finite()) {
            return Err(c);
        }
        let l = pivot.sqrt();
        col[c] = l;
        let inv = 1.0 / l;
        col[c + 1..].iter_mut().for_each(|v| *v *= inv);
        let col = &*col;
        for c2 in c + 1..nc {
            let f = col[c2];
            let target = &mut right[(c2 - c - 1) * nr..(c2 - c) * nr];
            for (t, &v) in target[c2..].iter_mut().zip(&col[c2..]) {
                *t -= v * f;
            }
        }
    }
    Ok(())
}

/// Supernodes of at least this many columns are factored by faer's blocked dense Cholesky
/// and triangular solve, and their updates by its product: the plain loops' passes over
/// a block that no longer fits the first-level cache cost more than the calls.
const DENSE: usize = 32;

/// [`factor_block`] by faer: `L_11 L_11ᵀ = B_11`, then `L_21 = B_21 L_11⁻ᵀ`.
fn factor_block_dense(block: &mut [f64], nr: usize, nc: usize) -> Result<(), usize> {
    let panel = MatMut::from_column_major_slice_mut(block, nr, nc);
    let (top, _) = panel.split_at_row_mut(nc);
    let scratch = cholesky_in_place_scratch::<f64>(nc, Par::Seq, Default::default());
    let mut buf = MemBuffer::new(scratch);
    cholesky_in_place(
        top,
        Default::default(),
        Par::Seq,
        MemStack::new(&mut buf),
        Default::default(),
    )
    .map_err(|e| match e {
        LltError::NonPositivePivot { index } => index,
    })?;
    let panel = MatMut::from_column_major_slice_mut(block, nr, nc);
    let (top, bottom) = panel.split_at_row_mut(nc);
    solve_lower_triangular_in_place(top.as_ref(), bottom.transpose_mut(), Par::Seq);
    Ok(())
}

/// `U = X Xᵀ` (lower triangle; `m × m`, column-major, into `update`) by faer's product, `X`
/// the pattern's `m` rows of a factored block of `nr` rows and `nc` columns.
fn products_dense(update: &mut Vec<f64>, block: &[f64], nr: usize, nc: usize, m: usize) {
    update.clear();
    update.resize(m * m, 0.0);
    let x = MatRef::from_column_major_slice_with_stride(&block[nc..], m, nc, nr);
    matmul(
        MatMut::from_column_major_slice_mut(update, m, m),
        BlockStructure::TriangularLower,
        Accum::Replace,
        x,
        BlockStructure::Rectangular,
        x.transpose(),
        BlockStructure::Rectangular,
        1.0,
        Par::Seq,
    );
}
