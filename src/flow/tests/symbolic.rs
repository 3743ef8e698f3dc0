//! leakpath's supernodal symbolic analysis against faer's on the same matrices: every array
//! of the structure equal (columns of each supernode, patterns, offsets of the values).
use super::supernodal::{analysis, grid_operator};
use super::*;
use crate::flow::llt::permuted_lower;
use crate::flow::symbolic::{Layout, Supernodes};
use faer::sparse::linalg::cholesky::SymbolicCholeskyRaw;
use faer::sparse::{SparseColMat, SymbolicSparseColMat};

/// The structure faer computes for `a` (lower triangle) in its own order, against ours.
fn assert_same_structure(a: &SparseColMat<usize, f64>, what: &str) {
    let symbolic = analysis(a, false);
    let SymbolicCholeskyRaw::Supernodal(sn) = symbolic.raw() else {
        panic!("{what}: a supernodal analysis")
    };
    let theirs = Layout::of_faer(sn);
    let (ptr, rows) = (a.symbolic().col_ptr(), a.symbolic().row_idx());
    let ours = Supernodes::analyse(a.nrows(), ptr, rows, a.nrows()).unwrap();
    let ours = ours.layout();
    assert_eq!(ours.nrows(), theirs.nrows(), "{what}: columns");
    assert_eq!(
        ours.supernode_begin(),
        theirs.supernode_begin(),
        "{what}: supernodes' first columns"
    );
    assert_eq!(
        ours.supernode_end(),
        theirs.supernode_end(),
        "{what}: supernodes' ends"
    );
    assert_eq!(
        ours.col_ptr_for_row_idx(),
        theirs.col_ptr_for_row_idx(),
        "{what}: patterns' offsets"
    );
    assert_eq!(ours.row_idx(), theirs.row_idx(), "{what}: patterns");
    assert_eq!(
        ours.col_ptr_for_val(),
        theirs.col_ptr_for_val(),
        "{what}: blocks' offsets"
    );
    assert_eq!(ours.len_val(), symbolic.len_val(), "{what}: values");
}

/// A lower triangle by columns from `(row, column)` couplings (`row > column`, any order,
/// repeats allowed) and a diagonal, each column's rows in a scrambled order.
fn lower_from(n: usize, couplings: &[(usize, usize)], seed: u64) -> SparseColMat<usize, f64> {
    let mut cols: Vec<Vec<usize>> = (0..n).map(|j| vec![j]).collect();
    for &(i, j) in couplings {
        assert!(i > j);
        if !cols[j].contains(&i) {
            cols[j].push(i);
        }
    }
    let u = lcg(seed, n);
    let (mut ptr, mut rows) = (vec![0], Vec::new());
    for (j, col) in cols.iter_mut().enumerate() {
        col.sort_unstable();
        // Rotate by a random amount: rows need not be sorted.
        let by = (u[j] * col.len() as f64) as usize % col.len();
        col.rotate_left(by);
        rows.extend_from_slice(col);
        ptr.push(rows.len());
    }
    let vals = vec![1.0; rows.len()];
    SparseColMat::new(
        SymbolicSparseColMat::new_unsorted_checked(n, n, ptr, None, rows),
        vals,
    )
}

/// Grids in their own order, wrapped and not, and the same grids in a fill-reducing
/// (minimum-degree) order: thousands of supernodes, merged and not, of every width.
#[test]
fn the_analysis_matches_faers_on_grids() {
    for (ny, nx) in [
        (3, 3),
        (3, 17),
        (24, 31),
        (40, 40),
        (9, 70),
        (64, 64),
        (97, 50),
    ] {
        let a = grid_operator(ny, nx, 11 + nx as u64, None);
        assert_same_structure(&a, &format!("{ny}×{nx} in grid order"));
        let amd = analysis(&a, true);
        let inv = amd.perm().unwrap().arrays().1;
        let p = permuted_lower(&a, inv);
        assert_same_structure(&p, &format!("{ny}×{nx} in minimum-degree order"));
    }
}

/// Random sparse patterns: forests of several trees, empty columns, long chains, and
/// columns coupled to far rows (supernodes of one column, and wide ones).
#[test]
fn the_analysis_matches_faers_on_random_patterns() {
    for (seed, n, per_column, reach) in [
        (1u64, 1usize, 0usize, 1usize),
        (2, 50, 1, 3),
        (3, 300, 2, 300),
        (4, 500, 3, 20),
        (5, 800, 1, 800),
        (6, 1000, 4, 60),
        (7, 2000, 2, 2000),
    ] {
        let u = lcg(seed, 2 * n * per_column.max(1));
        let mut couplings = Vec::new();
        for j in 0..n {
            for t in 0..per_column {
                let d = 1 + (u[2 * (j * per_column + t)] * reach as f64) as usize;
                // Some columns stay uncoupled (roots of their own trees).
                if j + d < n && u[2 * (j * per_column + t) + 1] > 0.15 {
                    couplings.push((j + d, j));
                }
            }
        }
        let a = lower_from(n, &couplings, seed + 100);
        assert_same_structure(&a, &format!("random pattern {seed} ({n} columns)"));
    }
    // A dense lower triangle: one supernode.
    let n = 60;
    let dense: Vec<(usize, usize)> = (0..n)
        .flat_map(|j| (j + 1..n).map(move |i| (i, j)))
        .collect();
    assert_same_structure(&lower_from(n, &dense, 9), "dense 60 × 60");
    // No couplings: a forest of single columns.
    assert_same_structure(&lower_from(40, &[], 9), "diagonal 40 × 40");
}

/// A pattern that is not a lower triangle is refused, not analysed.
#[test]
fn the_analysis_refuses_a_pattern_that_is_not_a_lower_triangle() {
    let err = Supernodes::analyse(3, &[0, 2, 3, 4], &[0, 1, 0, 2], 3).err();
    assert!(err.unwrap().contains("lower triangle"));
    let err = Supernodes::analyse(3, &[0, 2, 3], &[0, 1, 1], 3).err();
    assert!(err.unwrap().contains("column pointers"));
    let empty = Supernodes::analyse(0, &[0], &[], 0).unwrap();
    assert_eq!(empty.layout().n_supernodes(), 0);
    assert_eq!(empty.layout().len_val(), 0);
}
