//! The flow operator's lower triangle in compressed columns, the input of the sparse
//! Cholesky factors ([`super::direct`], [`super::halves`]).

use super::assemble::Stencil;

/// The lower triangle (row ≥ column) of the operator on the unknowns `cells` (unknown `t`
/// on grid cell `cells[t]`, each cell at most once), by columns, rows ascending: each
/// unknown's diagonal, then its neighbours of larger index along every grid face between
/// two unknowns, with minus the face's conductance (0 on a closed face). An unknown on a
/// cell that is not active (a kept analysis's) has diagonal 1 and no couplings (its faces
/// are closed).
///
/// Built in grid order, not in the order of `cells`: the unknowns of a factor in halves
/// come in elimination order, scattered over the grid, and a pass that gathers each one's
/// four faces in that order waits on a cache miss at nearly every read (3.2–4.5 ms for a
/// side of 53,000 unknowns at 513², against 1.8–2.2 ms here). Here the grid is read twice
/// in its own order: each face between two unknowns is counted, then written, into the
/// column of its smaller index, and each column's few entries are then sorted by row.
pub(super) fn lower_csc(st: &Stencil, cells: &[usize]) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
    let m = cells.len();
    let n = st.ny * st.nx;
    assert!(m < u32::MAX as usize && cells.iter().all(|&k| k < n));
    // Grid cell → its unknown (`u32::MAX`: none).
    let mut at = vec![u32::MAX; n];
    for (t, &k) in cells.iter().enumerate() {
        at[k] = t as u32;
    }
    lower_csc_by(st, m, |k| at[k])
}

/// [`lower_csc`] on `m` unknowns given by `at`: grid cell → its unknown (`u32::MAX` for
/// none; each unknown on one cell), read in grid order, so that a caller that has the map
/// in another form (a factor in halves: the grid's unknowns and their places in the
/// order) builds no grid-sized array for it.
pub(super) fn lower_csc_by(
    st: &Stencil,
    m: usize,
    at: impl Fn(usize) -> u32,
) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
    let (ny, nx) = (st.ny, st.nx);
    assert!(m < u32::MAX as usize);
    // A wrapped row of two cells joins its pair by two faces (east and west of each): the
    // first cell's east face carries both, the second's wrap is not a face of its own.
    let pair_row = st.periodic && nx == 2;
    // Each face once, from the cell west or north of it: (neighbour, conductance).
    let faces = |i: usize, j: usize| -> [(usize, f64); 2] {
        let k = i * nx + j;
        let east = if pair_row {
            if j == 0 {
                (k + 1, st.e[k] + st.e[k + 1])
            } else {
                (usize::MAX, 0.0)
            }
        } else if j + 1 < nx {
            (k + 1, st.e[k])
        } else if st.periodic && nx > 1 {
            (k + 1 - nx, st.e[k])
        } else {
            (usize::MAX, 0.0)
        };
        let south = if i + 1 < ny {
            (k + nx, st.s[k])
        } else {
            (usize::MAX, 0.0)
        };
        [east, south]
    };
    // The two unknowns of a face, smaller first; `None` unless both ends are unknowns.
    let ends = |p: u32, l: usize| -> Option<(usize, usize)> {
        if l == usize::MAX {
            return None;
        }
        let q = at(l);
        (q != u32::MAX && q != p).then(|| (p.min(q) as usize, p.max(q) as usize))
    };
    // Entries per column: the diagonal and the faces to unknowns of larger index (at most
    // five; then, from the column pointers on, the entries placed so far).
    let mut next = vec![1u32; m];
    for i in 0..ny {
        for j in 0..nx {
            let p = at(i * nx + j);
            if p == u32::MAX {
                continue;
            }
            for (l, _) in faces(i, j) {
                if let Some((lo, _)) = ends(p, l) {
                    next[lo] += 1;
                }
            }
        }
    }
    let mut col_ptr = Vec::with_capacity(m + 1);
    col_ptr.push(0);
    let mut total = 0usize;
    for c in next.iter_mut() {
        let len = *c as usize;
        col_ptr.push(total + len);
        // The diagonal goes first.
        *c = 1;
        total += len;
    }
    let mut row_idx = vec![0usize; total];
    let mut vals = vec![0.0f64; total];
    for i in 0..ny {
        for j in 0..nx {
            let k = i * nx + j;
            let p = at(k);
            if p == u32::MAX {
                continue;
            }
            let d = col_ptr[p as usize];
            row_idx[d] = p as usize;
            vals[d] = if st.active[k] { st.d[k] } else { 1.0 };
            for (l, c) in faces(i, j) {
                if let Some((lo, hi)) = ends(p, l) {
                    let e = col_ptr[lo] + next[lo] as usize;
                    next[lo] += 1;
                    row_idx[e] = hi;
                    // `-0.0 → 0.0`: a closed face stores a plain zero.
                    vals[e] = -c + 0.0;
                }
            }
        }
    }
    // Rows ascending below each diagonal (at most four entries: insertion sort).
    for c in 0..m {
        let (rows, vs) = (
            &mut row_idx[col_ptr[c] + 1..col_ptr[c + 1]],
            &mut vals[col_ptr[c] + 1..col_ptr[c + 1]],
        );
        for a in 1..rows.len() {
            let mut b = a;
            while b > 0 && rows[b - 1] > rows[b] {
                rows.swap(b - 1, b);
                vs.swap(b - 1, b);
                b -= 1;
            }
        }
    }
    (col_ptr, row_idx, vals)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flow::assemble::fine_stencil;

    /// Every entry against the operator written out densely, cell by cell, from each
    /// cell's four faces as the stencil defines them (east, west, south, north; a wrapped
    /// row's ends joined, a two-cell wrapped row's pair by both faces): the same pattern (rows
    /// ascending, the diagonal first, closed faces between unknowns kept as zeros) and the
    /// same values, on grids wrapped and not, rows of one, two and three cells, unknowns in
    /// a scattered order, some of them on inactive cells.
    #[test]
    fn lower_triangle_as_the_dense_operator() {
        for (ny, nx, periodic) in [
            (7, 9, true),
            (7, 9, false),
            (6, 2, true),
            (6, 2, false),
            (5, 1, true),
            (4, 3, true),
            (1, 6, true),
        ] {
            let n = ny * nx;
            let u = crate::flow::tests::lcg(11 + n as u64, n);
            // Conductances over six decades, a fifth of the cells closed.
            let c: Vec<f64> = u
                .iter()
                .map(|&v| if v < 0.2 { 0.0 } else { 10f64.powf(-6.0 * v) })
                .collect();
            let (st, _) = fine_stencil(&c, ny, nx, periodic);
            // Unknowns: the active cells and two inactive ones, in a scattered order.
            let mut cells: Vec<usize> = (0..n).filter(|&k| st.active[k]).collect();
            cells.extend((0..n).filter(|&k| !st.active[k]).take(2));
            let perm = crate::flow::tests::lcg(5, cells.len());
            let mut keyed: Vec<(f64, usize)> = perm.into_iter().zip(cells).collect();
            keyed.sort_by(|a, b| a.0.total_cmp(&b.0));
            let cells: Vec<usize> = keyed.into_iter().map(|(_, k)| k).collect();
            let m = cells.len();
            let mut pos = vec![usize::MAX; n];
            for (t, &k) in cells.iter().enumerate() {
                pos[k] = t;
            }
            // Dense reference: A[r][t] for r ≥ t, and which entries the pattern holds.
            let mut dense = vec![vec![0.0f64; m]; m];
            let mut held = vec![vec![false; m]; m];
            for (t, &k) in cells.iter().enumerate() {
                dense[t][t] = if st.active[k] { st.d[k] } else { 1.0 };
                held[t][t] = true;
                let (i, j) = (k / nx, k % nx);
                let mut faces = vec![];
                if j + 1 < nx {
                    faces.push((k + 1, st.e[k]));
                } else if periodic && nx > 1 {
                    faces.push((i * nx, st.e[k]));
                }
                if let Some(wj) = st.west(j) {
                    faces.push((i * nx + wj, st.e[i * nx + wj]));
                }
                if i + 1 < ny {
                    faces.push((k + nx, st.s[k]));
                }
                if i > 0 {
                    faces.push((k - nx, st.s[k - nx]));
                }
                for (l, cf) in faces {
                    let r = pos[l];
                    if r != usize::MAX && r > t {
                        dense[r][t] -= cf;
                        held[r][t] = true;
                    }
                }
            }
            let (col_ptr, row_idx, vals) = lower_csc(&st, &cells);
            assert_eq!(col_ptr.len(), m + 1);
            for t in 0..m {
                let rows = &row_idx[col_ptr[t]..col_ptr[t + 1]];
                let want: Vec<usize> = (t..m).filter(|&r| held[r][t]).collect();
                assert_eq!(
                    rows,
                    &want[..],
                    "column {t} of {ny}×{nx}, periodic {periodic}"
                );
                for (e, &r) in rows.iter().enumerate() {
                    let v = vals[col_ptr[t] + e];
                    assert_eq!(v.to_bits(), (dense[r][t] + 0.0).to_bits(), "({r}, {t})");
                }
            }
        }
    }
}
