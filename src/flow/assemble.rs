//! The finite-volume system of the Reynolds equation on the connected cells.
//!
//! The grid is row-major `ny × nx`, flow along axis 0 (rows): the inlet reservoir sits half a
//! cell before row 0, the outlet half a cell after row `ny − 1`. With `periodic`, column
//! `nx − 1` neighbours column 0. The operator is the 5-point stencil
//!
//! ```text
//! (A x)_k = d_k x_k − Σ_faces c_f x_neighbour,   d_k = Σ_faces c_f + dir_k,
//! ```
//!
//! where `c_f` are face conductances and `dir_k` the conductance of the face to a reservoir
//! (`2c` on rows 0 and `ny − 1`). Cells without unknowns keep `d = 1` and no faces: their
//! equation is `x = 0`, decoupled from the rest, so one structured layout serves every level.

use rayon::prelude::*;

use super::compensated::{self, Compensated};

/// Rows per parallel task: large enough that a task costs far more than handing it out.
pub(crate) const ROWS_PER_TASK: usize = 8;

/// A symmetric 5-point operator on a structured grid (one multigrid level).
#[derive(Clone, Debug)]
pub struct Stencil {
    pub ny: usize,
    pub nx: usize,
    pub periodic: bool,
    /// Face between `(i, j)` and `(i, j + 1)` (`(i, 0)` at `j = nx − 1` when periodic, else 0).
    pub e: Vec<f64>,
    /// Face between `(i, j)` and `(i + 1, j)`; 0 on the last row.
    pub s: Vec<f64>,
    /// Conductance to the reservoirs (Dirichlet part of the diagonal).
    pub dir: Vec<f64>,
    /// Diagonal; 1 on cells without unknowns.
    pub d: Vec<f64>,
    /// Cells carrying an unknown.
    pub active: Vec<bool>,
}

impl Stencil {
    /// Index of the west neighbour of column `j` (`None` at a wall).
    #[inline(always)]
    pub fn west(&self, j: usize) -> Option<usize> {
        if j > 0 {
            Some(j - 1)
        } else if self.periodic && self.nx > 1 {
            Some(self.nx - 1)
        } else {
            None
        }
    }

    /// Fills `d` from the faces and `dir`; cells with nothing attached become inactive.
    pub fn finish_diagonal(&mut self) {
        let (ny, nx) = (self.ny, self.nx);
        let (e, s, dir) = (&self.e, &self.s, &self.dir);
        let periodic = self.periodic;
        self.d
            .par_chunks_mut(nx)
            .zip(self.active.par_chunks_mut(nx))
            .enumerate()
            .for_each(|(i, (drow, arow))| {
                for j in 0..nx {
                    let k = i * nx + j;
                    let mut sum = dir[k] + e[k] + s[k];
                    if j > 0 {
                        sum += e[k - 1];
                    } else if periodic && nx > 1 {
                        sum += e[k + nx - 1];
                    }
                    if i > 0 {
                        sum += s[k - nx];
                    }
                    arow[j] = sum > 0.0;
                    drow[j] = if sum > 0.0 { sum } else { 1.0 };
                }
            });
        debug_assert_eq!(self.d.len(), ny * nx);
    }

    /// Closes the cells `cells` (they carry no unknown): their faces and their reservoir
    /// conductances set to 0, then the diagonal and the active cells recomputed
    /// ([`Stencil::finish_diagonal`]). The result is, bit for bit, the stencil of
    /// conductances that are 0 on those cells ([`fine_stencil`]: a face with a closed cell
    /// on either side is 0), so a stencil can be built before the cells to close are known.
    pub fn close_cells(&mut self, cells: impl IntoIterator<Item = usize>) {
        let nx = self.nx;
        for k in cells {
            let (i, j) = (k / nx, k % nx);
            self.e[k] = 0.0;
            self.s[k] = 0.0;
            self.dir[k] = 0.0;
            if let Some(w) = self.west(j) {
                self.e[i * nx + w] = 0.0;
            }
            if i > 0 {
                self.s[k - nx] = 0.0;
            }
        }
        self.finish_diagonal();
    }

    /// `y = A x`.
    pub fn apply(&self, x: &[f64], y: &mut [f64]) {
        let nx = self.nx;
        y.par_chunks_mut(nx)
            .enumerate()
            .with_min_len(ROWS_PER_TASK)
            .for_each(|(i, yrow)| self.apply_row(i, x, yrow));
    }

    #[inline(always)]
    #[allow(clippy::needless_range_loop)]
    fn apply_row(&self, i: usize, x: &[f64], yrow: &mut [f64]) {
        let (ny, nx) = (self.ny, self.nx);
        let base = i * nx;
        for j in 0..nx {
            let k = base + j;
            let mut v = self.d[k] * x[k];
            if j + 1 < nx {
                v -= self.e[k] * x[k + 1];
            } else if self.periodic && nx > 1 {
                v -= self.e[k] * x[base];
            }
            if let Some(w) = self.west(j) {
                v -= self.e[base + w] * x[base + w];
            }
            if i + 1 < ny {
                v -= self.s[k] * x[k + nx];
            }
            if i > 0 {
                v -= self.s[k - nx] * x[k - nx];
            }
            yrow[j] = v;
        }
    }

    /// `r = b − A x`.
    pub fn residual(&self, x: &[f64], b: &[f64], r: &mut [f64]) {
        let nx = self.nx;
        r.par_chunks_mut(nx)
            .enumerate()
            .with_min_len(ROWS_PER_TASK)
            .for_each(|(i, rrow)| {
                self.apply_row(i, x, rrow);
                for (j, v) in rrow.iter_mut().enumerate() {
                    *v = b[i * nx + j] - *v;
                }
            });
    }
}

impl Stencil {
    /// Calls `f(l, c)` for every face of cell `k` with conductance `c > 0` to neighbour `l`
    /// (east, west, south, north, with the wrap).
    #[inline(always)]
    pub fn for_each_face(&self, k: usize, f: impl FnMut(usize, f64)) {
        assert!(
            k < self.ny * self.nx && self.faces_complete(),
            "a cell of a complete stencil"
        );
        // SAFETY: checked just above.
        unsafe { self.for_each_face_unchecked(k, f) }
    }

    /// Whether the face arrays cover the grid: what [`Stencil::for_each_face_unchecked`]
    /// relies on, checked once by a caller that walks many cells.
    pub fn faces_complete(&self) -> bool {
        let n = self.ny * self.nx;
        self.e.len() == n && self.s.len() == n
    }

    /// The four faces of cell `k` as `(neighbour, conductance)` in the order of
    /// [`Stencil::for_each_face`] (east, west, south, north), a missing one as `(k, 0)`: the
    /// same faces without a closure, for the kernels compiled with a fused multiply-add
    /// (a closure is compiled apart, without it).
    #[inline(always)]
    fn faces_of(&self, k: usize) -> [(usize, f64); 4] {
        self.faces_at(k / self.nx, k % self.nx)
    }

    /// [`Stencil::faces_of`] cell `(i, j)`, for a loop that walks a row.
    #[inline(always)]
    fn faces_at(&self, i: usize, j: usize) -> [(usize, f64); 4] {
        let (ny, nx) = (self.ny, self.nx);
        let base = i * nx;
        let k = base + j;
        let (e, s) = (&self.e, &self.s);
        let east = if j + 1 < nx {
            (k + 1, e[k])
        } else if self.periodic && nx > 1 {
            (base, e[k])
        } else {
            (k, 0.0)
        };
        let west = match self.west(j) {
            Some(wj) => (base + wj, e[base + wj]),
            None => (k, 0.0),
        };
        let south = if i + 1 < ny { (k + nx, s[k]) } else { (k, 0.0) };
        let north = if i > 0 { (k - nx, s[k - nx]) } else { (k, 0.0) };
        [east, west, south, north]
    }

    /// [`Stencil::for_each_face`] without bounds checks, for a loop over many cells that
    /// checks [`Stencil::faces_complete`] once (the multigrid's product with its Schur
    /// complement).
    ///
    /// # Safety
    ///
    /// `self.faces_complete()` and `k < ny · nx`; then every face index read is below
    /// `ny · nx`, and so is every neighbour `l` passed to `f`.
    #[inline(always)]
    pub unsafe fn for_each_face_unchecked(&self, k: usize, mut f: impl FnMut(usize, f64)) {
        let (ny, nx) = (self.ny, self.nx);
        let (i, j) = (k / nx, k % nx);
        let base = i * nx;
        let mut face = |l: usize, w: f64| {
            if w > 0.0 {
                f(l, w)
            }
        };
        let (e, s) = (&self.e, &self.s);
        if j + 1 < nx {
            face(k + 1, *e.get_unchecked(k));
        } else if self.periodic && nx > 1 {
            face(base, *e.get_unchecked(k));
        }
        if let Some(wj) = self.west(j) {
            face(base + wj, *e.get_unchecked(base + wj));
        }
        if i + 1 < ny {
            face(k + nx, *s.get_unchecked(k));
        }
        if i > 0 {
            face(k - nx, *s.get_unchecked(k - nx));
        }
    }

    /// `r = b − A x` with every row summed in double-double arithmetic (error-free sums and
    /// products, rounded once) as `b_k − dir_k x_k + Σ_f c_f (x_l − x_k)`, each difference
    /// `x_l − x_k` split exactly first: the residual of the
    /// exact network (not of its rounded diagonal) to about `ε |r|`, not `ε Σ |a x|`,
    /// which is what lets iterative refinement correct the digits a factor loses when the
    /// conductances span many decades.
    pub fn residual_compensated(&self, x: &[f64], b: &[f64], r: &mut [f64]) {
        self.residual_of_parts(&[x], b, r);
    }

    /// `r = b − A (hi + lo)` for a solution carried as two doubles, summed like
    /// [`Stencil::residual_compensated`]: what refines `lo` beyond the digits one double holds.
    pub fn residual_split(&self, hi: &[f64], lo: &[f64], b: &[f64], r: &mut [f64]) {
        self.residual_of_parts(&[hi, lo], b, r);
    }

    /// [`Stencil::residual_compensated`] on the unknowns only, of `x = Σ parts` (one part, or
    /// a solution carried as two doubles `hi + lo`): unknown `i` is cell `cells[i]`, `index`
    /// maps a cell to its unknown (`u32::MAX` without one, whose value is 0), and each part,
    /// `b` and `r` have one entry per unknown. Rows in fixed chunks of `chunk` unknowns.
    pub fn residual_compensated_on(
        &self,
        cells: &[u32],
        index: &[u32],
        parts: &[&[f64]],
        b: &[f64],
        r: &mut [f64],
        chunk: usize,
    ) {
        debug_assert!(matches!(parts.len(), 1 | 2));
        let fused = compensated::fused();
        r.par_chunks_mut(chunk).enumerate().for_each(|(blk, rc)| {
            let on = Unknowns {
                cells,
                index,
                i0: blk * chunk,
            };
            if fused {
                // SAFETY: `fused` checked that the CPU has a fused multiply-add.
                unsafe { self.residual_unknowns_fused(on, parts, b, rc) }
            } else {
                self.residual_unknowns::<false>(on, parts, b, rc)
            }
        });
    }

    /// The rows of [`Stencil::residual_compensated_on`] from unknown `on.i0` on, products
    /// split by fused multiply-add (`FUSED`) or Dekker's splitting ([`compensated`]).
    #[inline(always)]
    fn residual_unknowns<const FUSED: bool>(
        &self,
        on: Unknowns,
        parts: &[&[f64]],
        b: &[f64],
        rc: &mut [f64],
    ) {
        let (hi, lo) = (parts[0], parts.get(1).copied());
        let Unknowns { cells, index, i0 } = on;
        for (t, rv) in rc.iter_mut().enumerate() {
            let i = i0 + t;
            let k = cells[i] as usize;
            let mut acc = Compensated::<FUSED>::new(b[i]);
            acc.add_product(-self.dir[k], hi[i]);
            if let Some(lo) = lo {
                acc.err -= self.dir[k] * lo[i];
            }
            for (l, c) in self.faces_of(k) {
                if c > 0.0 {
                    match index[l] {
                        u32::MAX => acc.add_face(c, 0.0, hi[i], lo.map(|lo| -lo[i])),
                        j => {
                            let j = j as usize;
                            acc.add_face(c, hi[j], hi[i], lo.map(|lo| lo[j] - lo[i]))
                        }
                    }
                }
            }
            *rv = acc.value();
        }
    }

    /// [`Stencil::residual_unknowns`] with the fused multiply-add.
    ///
    /// # Safety
    ///
    /// The CPU has a fused multiply-add ([`compensated::fused`]).
    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "fma"))]
    unsafe fn residual_unknowns_fused(
        &self,
        on: Unknowns,
        parts: &[&[f64]],
        b: &[f64],
        rc: &mut [f64],
    ) {
        self.residual_unknowns::<true>(on, parts, b, rc)
    }

    /// `r = b − A Σ parts`, each row summed in double-double arithmetic from the faces and
    /// the reservoir conductance, not the rounded diagonal: a face below ε d_k is part of the
    /// residual too.
    fn residual_of_parts(&self, parts: &[&[f64]], b: &[f64], r: &mut [f64]) {
        self.residual_of_parts_with(compensated::fused(), parts, b, r)
    }

    /// [`Stencil::residual_of_parts`] with (`fused`, on a CPU that has it) or without the
    /// fused multiply-add: the same bits either way.
    fn residual_of_parts_with(&self, fused: bool, parts: &[&[f64]], b: &[f64], r: &mut [f64]) {
        debug_assert!(matches!(parts.len(), 1 | 2));
        r.par_chunks_mut(self.nx)
            .enumerate()
            .with_min_len(ROWS_PER_TASK)
            .for_each(|(i, rrow)| {
                if fused {
                    // SAFETY: `fused` checked that the CPU has a fused multiply-add.
                    unsafe { self.residual_row_fused(i, parts, b, rrow) }
                } else {
                    self.residual_row::<false>(i, parts, b, rrow)
                }
            });
    }

    /// Row `i` of [`Stencil::residual_of_parts`], products split by fused multiply-add
    /// (`FUSED`) or Dekker's splitting ([`compensated`]). The cells with four faces (not on
    /// the first or last row or column) are summed several at a time, in vector lanes
    /// ([`Stencil::residual_interior`]); each lane does the same operations in the same order
    /// as [`Stencil::residual_cell`] does for its cell, so the bits are the same.
    #[inline(always)]
    fn residual_row<const FUSED: bool>(
        &self,
        i: usize,
        parts: &[&[f64]],
        b: &[f64],
        rrow: &mut [f64],
    ) {
        let nx = self.nx;
        let interior = i > 0 && i + 1 < self.ny && nx > 2;
        let lanes = interior
            && match *parts {
                [hi] => self.residual_interior::<FUSED, false>(i, hi, hi, b, rrow),
                [hi, lo] => self.residual_interior::<FUSED, true>(i, hi, lo, b, rrow),
                _ => false,
            };
        if lanes {
            for j in [0, nx - 1] {
                rrow[j] = self.residual_cell::<FUSED>(i, j, parts, b);
            }
        } else {
            // An edge row, or a product that left the fused multiply-add's exact range.
            for (j, r) in rrow.iter_mut().enumerate() {
                *r = self.residual_cell::<FUSED>(i, j, parts, b);
            }
        }
    }

    /// Cell `(i, j)` of [`Stencil::residual_of_parts`].
    #[inline(always)]
    fn residual_cell<const FUSED: bool>(
        &self,
        i: usize,
        j: usize,
        parts: &[&[f64]],
        b: &[f64],
    ) -> f64 {
        let (hi, lo) = (parts[0], parts.get(1).copied());
        let k = i * self.nx + j;
        let x = hi[k] + lo.map_or(0.0, |lo| lo[k]);
        if !self.active[k] {
            return b[k] - self.d[k] * x;
        }
        let mut acc = Compensated::<FUSED>::new(b[k]);
        acc.add_product(-self.dir[k], hi[k]);
        if let Some(lo) = lo {
            acc.err -= self.dir[k] * lo[k];
        }
        for (l, c) in self.faces_at(i, j) {
            if c > 0.0 {
                acc.add_face(c, hi[l], hi[k], lo.map(|lo| lo[l] - lo[k]));
            }
        }
        acc.value()
    }

    /// Cells `1 ..= nx − 2` of interior row `i` of [`Stencil::residual_of_parts`] with
    /// `x = hi (+ lo when LO)`, in a loop without branches: a face of conductance 0 is summed
    /// and its result dropped (a select, not a jump) and the fused multiply-add's range is
    /// checked for the row as a whole. `false`: some product left that range; nothing
    /// written then is kept ([`Stencil::residual_row`] sums the row by cells).
    #[inline(always)]
    fn residual_interior<const FUSED: bool, const LO: bool>(
        &self,
        i: usize,
        hi: &[f64],
        lo: &[f64],
        b: &[f64],
        rrow: &mut [f64],
    ) -> bool {
        let nx = self.nx;
        let m = nx - 2;
        let k0 = i * nx + 1;
        let at = window(m);
        let (bb, dir, d) = (at(b, k0), at(&self.dir, k0), at(&self.d, k0));
        let active = &self.active[k0..k0 + m];
        let faces = [
            (at(&self.e, k0), k0 + 1),
            (at(&self.e, k0 - 1), k0 - 1),
            (at(&self.s, k0), k0 + nx),
            (at(&self.s, k0 - nx), k0 - nx),
        ];
        let (c, l) = (faces.map(|f| f.0), faces.map(|f| f.1));
        let (hk, lk) = (at(hi, k0), at(lo, k0));
        let (hl, ll) = (l.map(|l| at(hi, l)), l.map(|l| at(lo, l)));
        let out = &mut rrow[1..1 + m];
        let mut exact = true;
        for t in 0..m {
            let x = if LO { hk[t] + lk[t] } else { hk[t] };
            let mut acc = Compensated::<FUSED>::new(bb[t]);
            exact &= acc.add_product_in_range(-dir[t], hk[t]);
            if LO {
                acc.err -= dir[t] * lk[t];
            }
            for f in 0..4 {
                let cf = c[f][t];
                let dlo = LO.then(|| ll[f][t] - lk[t]);
                let mut with = acc;
                let in_range = with.add_face_in_range(cf, hl[f][t], hk[t], dlo);
                let open = cf > 0.0;
                exact &= in_range | !open;
                acc = if open { with } else { acc };
            }
            out[t] = if active[t] {
                acc.value()
            } else {
                bb[t] - d[t] * x
            };
        }
        exact
    }

    /// [`Stencil::residual_row`] with the fused multiply-add.
    ///
    /// # Safety
    ///
    /// The CPU has a fused multiply-add ([`compensated::fused`]).
    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "fma"))]
    unsafe fn residual_row_fused(&self, i: usize, parts: &[&[f64]], b: &[f64], rrow: &mut [f64]) {
        self.residual_row::<true>(i, parts, b, rrow)
    }
}

/// `v[from .. from + m]`, for the equally long windows of a row's neighbours.
#[inline(always)]
fn window(m: usize) -> impl Fn(&[f64], usize) -> &[f64] {
    move |v, from| &v[from..from + m]
}

/// Where a chunk of [`Stencil::residual_compensated_on`] starts: unknown `i0`, with the
/// unknowns' cells and the cells' unknowns.
#[derive(Clone, Copy)]
struct Unknowns<'a> {
    cells: &'a [u32],
    index: &'a [u32],
    i0: usize,
}

/// Harmonic mean of two cell conductances, `2 c1 c2 / (c1 + c2)`; 0 when either is 0.
#[inline(always)]
pub fn harmonic(c1: f64, c2: f64) -> f64 {
    if c1 > 0.0 && c2 > 0.0 {
        2.0 * c1 * c2 / (c1 + c2)
    } else {
        0.0
    }
}

/// The fine-level operator for cell conductances `c` (0 on cells without unknowns) with
/// reservoirs on rows 0 and `ny − 1`; `rhs` gets the inlet reservoir at unit pressure.
pub fn fine_stencil(c: &[f64], ny: usize, nx: usize, periodic: bool) -> (Stencil, Vec<f64>) {
    let n = ny * nx;
    let mut e = vec![0.0; n];
    let mut s = vec![0.0; n];
    // Nonzero on the first and last rows only, read everywhere: zeros written now (a
    // `calloc`ed buffer would be read through the kernel's shared zero page, and its memory,
    // reused after it is freed, faulted again where first written, each such fault a TLB
    // flush on every core running the solve).
    let mut dir = crate::alloc::zeroed_now(n);
    let mut rhs = crate::alloc::zeroed_now(n);
    e.par_chunks_mut(nx)
        .zip(s.par_chunks_mut(nx))
        .zip(dir.par_chunks_mut(nx).zip(rhs.par_chunks_mut(nx)))
        .enumerate()
        .for_each(|(i, ((erow, srow), (drow, brow)))| {
            let base = i * nx;
            for j in 0..nx {
                let k = base + j;
                if j + 1 < nx {
                    erow[j] = harmonic(c[k], c[k + 1]);
                } else if periodic && nx > 1 {
                    erow[j] = harmonic(c[k], c[base]);
                }
                if i + 1 < ny {
                    srow[j] = harmonic(c[k], c[k + nx]);
                }
                if i == 0 {
                    drow[j] += 2.0 * c[k];
                    brow[j] = 2.0 * c[k];
                }
                if i + 1 == ny {
                    drow[j] += 2.0 * c[k];
                }
            }
        });
    let mut st = Stencil {
        ny,
        nx,
        periodic,
        e,
        s,
        dir,
        d: vec![0.0; n],
        active: vec![false; n],
    };
    st.finish_diagonal();
    (st, rhs)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Closing cells in a built stencil gives the stencil built with those cells closed, bit
    /// for bit (faces, reservoir conductances, diagonal, active cells), on wrapped and walled
    /// grids from one row or column up, closed cells on the reservoir rows and the wrap
    /// included.
    #[test]
    fn closing_cells_as_building_them_closed() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for (ny, nx) in [(1, 1), (1, 5), (5, 1), (2, 2), (3, 7), (8, 6)] {
            for periodic in [false, true] {
                let u: Vec<f64> = (0..2 * ny * nx).map(|_| next()).collect();
                let c = conductances(&u, 0.2, 6.0);
                let shut: Vec<usize> = (0..ny * nx).filter(|_| next() < 0.3).collect();
                let mut closed = c.clone();
                for &k in &shut {
                    closed[k] = 0.0;
                }
                let (want, want_rhs) = fine_stencil(&closed, ny, nx, periodic);
                let (mut got, mut got_rhs) = fine_stencil(&c, ny, nx, periodic);
                got.close_cells(shut.iter().copied());
                for &k in &shut {
                    got_rhs[k] = 0.0;
                }
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                let at = format!("{ny} × {nx}, periodic {periodic}, closed {shut:?}");
                assert_eq!(bits(&got.e), bits(&want.e), "e, {at}");
                assert_eq!(bits(&got.s), bits(&want.s), "s, {at}");
                assert_eq!(bits(&got.dir), bits(&want.dir), "dir, {at}");
                assert_eq!(bits(&got.d), bits(&want.d), "d, {at}");
                assert_eq!(got.active, want.active, "active, {at}");
                assert_eq!(bits(&got_rhs), bits(&want_rhs), "rhs, {at}");
            }
        }
    }

    /// Cell conductances from pairs of `u`: closed below `closed`, else over `decades`.
    fn conductances(u: &[f64], closed: f64, decades: f64) -> Vec<f64> {
        u.chunks_exact(2)
            .map(|w| {
                if w[0] < closed {
                    0.0
                } else {
                    10f64.powf(-decades * w[1])
                }
            })
            .collect()
    }

    /// A solution `hi` over `decades` from pairs of `u[..2n]` and its low part `lo` from
    /// `u[2n..]`, some 1e-17 of it.
    fn solution(u: &[f64], n: usize, decades: f64) -> (Vec<f64>, Vec<f64>) {
        let hi: Vec<f64> = u[..2 * n]
            .chunks_exact(2)
            .map(|w| w[0] * 10f64.powf(-decades * w[1]))
            .collect();
        let lo = hi
            .iter()
            .zip(&u[2 * n..])
            .map(|(v, w)| v * 1e-17 * w)
            .collect();
        (hi, lo)
    }

    fn bits(r: &[f64]) -> Vec<u64> {
        r.iter().map(|v| v.to_bits()).collect()
    }

    /// The residual rows with the fused multiply-add give the bits of those with Dekker's
    /// splitting, on conductances over 300 decades (products and their errors down to the
    /// subnormal range, where the fused path hands over to the splitting) and a solution
    /// carried in one and in two doubles.
    #[test]
    fn fused_residual_rows_give_the_split_bits() {
        if !compensated::fused() {
            return;
        }
        let (ny, nx) = (23, 17);
        let n = ny * nx;
        let u = crate::test_support::lcg(0x2545_f491_4f6c_dd1d, 6 * n);
        let c = conductances(&u[..2 * n], 0.1, 300.0);
        for periodic in [false, true] {
            let (st, rhs) = fine_stencil(&c, ny, nx, periodic);
            let (hi, lo) = solution(&u[2 * n..], n, 320.0);
            for parts in [vec![&hi[..]], vec![&hi[..], &lo[..]]] {
                let (mut r1, mut r2) = (vec![0.0; n], vec![0.0; n]);
                st.residual_of_parts_with(true, &parts, &rhs, &mut r1);
                st.residual_of_parts_with(false, &parts, &rhs, &mut r2);
                assert_eq!(bits(&r1), bits(&r2));
            }
        }
    }

    /// The rows summed in vector lanes give the bits of the same rows summed cell by cell,
    /// with and without the fused multiply-add, in one and two doubles: on conductances of
    /// one decade (every interior row in lanes) and over 300 decades (rows whose products
    /// leave the fused range fall back to cells), closed faces and cells included.
    #[test]
    fn rows_in_lanes_give_the_bits_of_rows_by_cells() {
        let (ny, nx) = (19, 23);
        let n = ny * nx;
        let u = crate::test_support::lcg(0x9e37_79b9_7f4a_7c15, 6 * n);
        for decades in [1.0, 300.0] {
            let c = conductances(&u[..2 * n], 0.15, decades);
            for periodic in [false, true] {
                let (st, rhs) = fine_stencil(&c, ny, nx, periodic);
                let (hi, lo) = solution(&u[2 * n..], n, decades);
                for fused in [false, true] {
                    if fused && !compensated::fused() {
                        continue;
                    }
                    for parts in [vec![&hi[..]], vec![&hi[..], &lo[..]]] {
                        let mut lanes = vec![0.0; n];
                        st.residual_of_parts_with(fused, &parts, &rhs, &mut lanes);
                        let by_cells: Vec<f64> = (0..n)
                            .map(|k| match fused {
                                true => st.residual_cell::<true>(k / nx, k % nx, &parts, &rhs),
                                false => st.residual_cell::<false>(k / nx, k % nx, &parts, &rhs),
                            })
                            .collect();
                        assert_eq!(
                            bits(&lanes),
                            bits(&by_cells),
                            "{decades} {periodic} {fused}"
                        );
                        let mut row = vec![0.0; nx];
                        let in_lanes = (1..ny - 1)
                            .filter(|&i| match fused {
                                true => {
                                    st.residual_interior::<true, false>(i, &hi, &hi, &rhs, &mut row)
                                }
                                false => st
                                    .residual_interior::<false, false>(i, &hi, &hi, &rhs, &mut row),
                            })
                            .count();
                        // One decade: every interior row in lanes; 300 decades with
                        // the fused multiply-add: some rows by cells.
                        match (decades < 2.0, fused) {
                            (true, _) | (false, false) => assert_eq!(in_lanes, ny - 2),
                            (false, true) => assert!(in_lanes < ny - 2),
                        }
                    }
                }
            }
        }
    }
}
