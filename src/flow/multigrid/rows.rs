//! Row access to a level's operator during the setup: compressed rows on coarse levels,
//! the grid stencil itself on the finest (never copied into compressed rows).

use super::cycle::Fine;
use super::{Graph, NONE};

/// The rows of a level's operator in conductance form,
/// `(A x)_i = d_i x_i − Σ_j w_ij x_j`, `d_i = dir_i + Σ_j w_ij`.
pub(super) trait Rows: Sync {
    /// Unknowns.
    fn n(&self) -> usize;
    /// The faces `(j, w_ij)` of row `i`, `j` ascending.
    fn row(&self, i: usize) -> impl Iterator<Item = (u32, f64)> + '_;
    /// Diagonal `d_i`.
    fn diag(&self, i: usize) -> f64;
    /// Reservoir part `dir_i` of the diagonal.
    fn reservoir(&self, i: usize) -> f64;
    /// `w_ij` (0 when `j` is not a neighbour of `i`).
    fn weight(&self, i: usize, j: u32) -> f64;
}

impl Rows for Graph {
    fn n(&self) -> usize {
        self.n
    }

    #[inline(always)]
    fn row(&self, i: usize) -> impl Iterator<Item = (u32, f64)> + '_ {
        (self.ptr[i]..self.ptr[i + 1])
            .map(move |p| (self.column(p, i) as u32, f64::from(self.w[p])))
    }

    #[inline(always)]
    fn diag(&self, i: usize) -> f64 {
        self.d[i]
    }

    #[inline(always)]
    fn reservoir(&self, i: usize) -> f64 {
        self.dir[i]
    }

    #[inline(always)]
    fn weight(&self, i: usize, j: u32) -> f64 {
        let row = self.ptr[i]..self.ptr[i + 1];
        if !self.near.is_empty() {
            return row
                .into_iter()
                .find(|&p| self.column(p, i) == j as usize)
                .map_or(0.0, |p| f64::from(self.w[p]));
        }
        match self.col[row.clone()].binary_search(&j) {
            Ok(p) => f64::from(self.w[row.start + p]),
            Err(_) => 0.0,
        }
    }
}

impl Fine<'_> {
    /// The faces of unknown `i` to cells with unknowns, as `(unknown, w)` sorted by unknown,
    /// the two faces of a 2-wide periodic row (the same pair) added; and their number.
    #[inline(always)]
    fn faces(&self, i: usize) -> ([(u32, f64); 4], usize) {
        let mut row: [(u32, f64); 4] = [(NONE, 0.0); 4];
        let mut nb = 0;
        self.st.for_each_face(self.cells[i] as usize, |l, c| {
            let t = self.index[l];
            if t == NONE {
                return;
            }
            if let Some(e) = row[..nb].iter_mut().find(|e| e.0 == t) {
                e.1 += c;
            } else {
                row[nb] = (t, c);
                nb += 1;
            }
        });
        row[..nb].sort_unstable_by_key(|e| e.0);
        (row, nb)
    }
}

impl Rows for Fine<'_> {
    fn n(&self) -> usize {
        self.cells.len()
    }

    #[inline(always)]
    fn row(&self, i: usize) -> impl Iterator<Item = (u32, f64)> + '_ {
        let (row, nb) = self.faces(i);
        row.into_iter().take(nb)
    }

    #[inline(always)]
    fn diag(&self, i: usize) -> f64 {
        self.st.d[self.cells[i] as usize]
    }

    #[inline(always)]
    fn reservoir(&self, i: usize) -> f64 {
        self.st.dir[self.cells[i] as usize]
    }

    #[inline(always)]
    fn weight(&self, i: usize, j: u32) -> f64 {
        let (row, nb) = self.faces(i);
        row[..nb].iter().find(|e| e.0 == j).map_or(0.0, |e| e.1)
    }
}
