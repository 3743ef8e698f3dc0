//! The flow operator's lower triangle in compressed columns, the input of the sparse
//! Cholesky factors ([`super::direct`], [`super::halves`]).

use super::assemble::Stencil;

/// The lower triangle (row ≥ column) of the operator on the unknowns `cells` (`pos`: grid
/// cell → its position in `cells`, `usize::MAX` for none), by columns, rows ascending:
/// each unknown's diagonal, then its neighbours of larger index along every grid face between two unknowns, with the face's
/// conductance (0 on a closed face). An unknown on a cell that is not active (a kept
/// analysis's) has diagonal 1 and no couplings (its faces are closed).
pub(super) fn lower_csc(
    st: &Stencil,
    cells: &[usize],
    pos: impl Fn(usize) -> usize,
) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
    let m = cells.len();
    let (ny, nx) = (st.ny, st.nx);
    let mut col_ptr = Vec::with_capacity(m + 1);
    let mut row_idx = Vec::with_capacity(3 * m);
    let mut vals = Vec::with_capacity(3 * m);
    col_ptr.push(0);
    for (q, &k) in cells.iter().enumerate() {
        let (i, j) = (k / nx, k % nx);
        let base = i * nx;
        // Every grid face of `k`: (neighbour, conductance).
        let mut faces: [(usize, f64); 4] = [(usize::MAX, 0.0); 4];
        let mut nf = 0;
        let mut face = |l: usize, c: f64| {
            faces[nf] = (l, c);
            nf += 1;
        };
        if j + 1 < nx {
            face(k + 1, st.e[k]);
        } else if st.periodic && nx > 1 {
            face(base, st.e[k]);
        }
        if let Some(wj) = st.west(j) {
            face(base + wj, st.e[base + wj]);
        }
        if i + 1 < ny {
            face(k + nx, st.s[k]);
        }
        if i > 0 {
            face(k - nx, st.s[k - nx]);
        }
        let mut below: [(usize, f64); 4] = [(usize::MAX, 0.0); 4];
        let mut nb = 0;
        for &(l, c) in &faces[..nf] {
            let t = pos(l);
            if t != usize::MAX && t > q {
                // The two faces of a 2-wide periodic row join the same pair: add them.
                if let Some(e) = below[..nb].iter_mut().find(|e| e.0 == t) {
                    e.1 -= c;
                } else {
                    below[nb] = (t, -c);
                    nb += 1;
                }
            }
        }
        below[..nb].sort_unstable_by_key(|e| e.0);
        row_idx.push(q);
        vals.push(if st.active[k] { st.d[k] } else { 1.0 });
        for &(t, v) in &below[..nb] {
            row_idx.push(t);
            // `-0.0 → 0.0`: a closed face stores a plain zero.
            vals.push(v + 0.0);
        }
        col_ptr.push(row_idx.len());
    }
    (col_ptr, row_idx, vals)
}
