//! The sparse Cholesky factor computed as two halves at once, one per thread.
//!
//! The nested-dissection order ([`super::order::ordering`]) eliminates the two
//! sides `A` and `B` of the grid's top cut first, each on its own, and the cut (the
//! separator `S`, `k` unknowns) last. With the unknowns ordered `[A, B, S]` the factor is
//!
//! ```text
//! L = | L_AA   0     0    |
//!     | 0      L_BB  0    |
//!     | L_SA   L_SB  L_SS |
//! ```
//!
//! and the columns of a side depend only on the rows of that side and of `S`. The factors
//! of the principal submatrix `M_A = A[A ∪ S, A ∪ S]` (positive definite, as a principal
//! submatrix of a positive definite matrix), whose columns on `A` are `[L_AA; L_SA]`
//! exactly, and of `M_B` are computed on the two threads ([`super::llt`]), each stopped
//! at its separator columns (a supernode boundary the analysis keeps there): the
//! separator's blocks of `M_A` are left holding `A_SS − L_SA L_SAᵀ`, so the separator's
//! Schur complement is `A_SS − L_SA L_SAᵀ − L_SB L_SBᵀ` = (that of `M_A`) + (that of
//! `M_B`) − `A_SS`, factored densely: `L_SS` (`k³/3` flops, `k` ≈ the grid's side, on one
//! core: small against the half of the factor that runs on the second; docs/flow.md,
//! "The factor in two halves").
//!
//! A solve runs forward on each side's factor up to its separator columns (the sides at
//! once), the separator's right-hand side gathered from both, the dense `L_SS` both ways,
//! then backward on each side from the separator's values. Each half's arithmetic is the
//! same whatever the threads, so the answer does not depend on them.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch};
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use faer::{Mat, Par};
use std::sync::atomic::{AtomicUsize, Ordering};

use super::assemble::Stencil;
use super::llt::{failed, supernodal_values};
use super::lower::{lower_csc, lower_csc_by};
use super::substitution::{supernodal_backward, supernodal_forward, Supernode};
use super::symbolic::Supernodes;
use crate::alloc::ZeroedByIdle;
use crate::error::Result;

/// Grids with at least this many unknowns are factored in halves when their order has a
/// top cut (fewer: the two threads' start and the separator's dense work cost more than
/// the half of the factor they take off one core).
pub const MIN_UNKNOWNS: usize = 1 << 15;

/// Largest separator factored in halves: its dense blocks (four of `k²` values) stay a
/// small part of the factor's memory.
pub const MAX_SEPARATOR: usize = 1 << 13;

/// One side's principal submatrix `M = A[side ∪ S, side ∪ S]` and its symbolic factor,
/// the matrix in elimination order (the side's unknowns, then the separator's).
struct SideAnalysis {
    /// Unknowns (indices into the analysis's cells) of the side, then of the separator.
    unknowns: Vec<usize>,
    /// Unknowns of the side itself (the separator's are the last `k`).
    own: usize,
    /// The side's own unknowns as (unknown, position), unknowns increasing: a solve gathers
    /// its right-hand side in this order, reading the cells' values in grid order (in the
    /// elimination order nearly every read was a cache miss).
    by_unknown: Vec<(u32, u32)>,
    symbolic: Supernodes,
}

/// The symbolic analysis of a factor in halves.
pub struct Analysis {
    sides: [SideAnalysis; 2],
    /// Unknowns of the separator.
    k: usize,
    /// Each unknown's position in the elimination order `[A, B, S]` (the order's inverse):
    /// where a solve's answer for it is ([`Solved::value`]).
    place: Vec<u32>,
}

/// The numeric factor in halves: each side's supernodal values and the separator's dense
/// factor `L_SS` (lower triangle), with each side's two interleaved columns of a solve
/// (made at the first, reused by the next: a refinement step's solve faults no new pages).
pub struct Factor {
    values: [Vec<f64>; 2],
    ls: Mat<f64>,
    work: [Vec<f64>; 2],
    /// The separator's values of the last solve (`k × 2`).
    u: Mat<f64>,
}

/// The answer of [`Factor::solve`], read by unknown.
pub struct Solved<'a> {
    an: &'a Analysis,
    work: &'a [Vec<f64>; 2],
    u: &'a Mat<f64>,
}

impl Solved<'_> {
    /// Column `c`'s value at unknown `q` (an index into the analysis's cells).
    #[inline]
    pub fn value(&self, q: usize, c: usize) -> f64 {
        let p = self.an.place[q] as usize;
        let (oa, ob) = (self.an.sides[0].own, self.an.sides[1].own);
        if p < oa {
            self.work[0][2 * p + c]
        } else if p < oa + ob {
            self.work[1][2 * (p - oa) + c]
        } else {
            self.u[(p - oa - ob, c)]
        }
    }
}

/// Adds the lower triangle of a side's separator blocks (the supernodes from its column
/// `own` on, not factored) into `s` (`k × k`, the separator's unknowns in order).
fn add_separator_block(sa: &SideAnalysis, values: &[f64], s: &mut Mat<f64>) {
    let sn = sa.symbolic.layout();
    let own = sa.own;
    for t in 0..sn.n_supernodes() {
        let node = Supernode::of(sn, values, t);
        let (start, ncols, pattern) = (node.start, node.ncols, node.pattern);
        if start < own {
            continue;
        }
        for c in 0..ncols {
            let j = start + c - own;
            let col = node.column(c);
            for (r, &v) in col[c..ncols].iter().enumerate() {
                s[(j + r, j)] += v;
            }
            for (&i, &v) in pattern.iter().zip(&col[ncols..]) {
                s[(i - own, j)] += v;
            }
        }
    }
}

/// Called by each side of the numeric factor when it is done (`done` counts them): the
/// first has the other's remaining time to spare (the sides' flops differ by up to half),
/// and zeroes `idle`'s vectors meanwhile.
fn spare_time(done: &AtomicUsize, idle: Option<&ZeroedByIdle>) {
    if done.fetch_add(1, Ordering::AcqRel) == 0 {
        if let Some(z) = idle {
            z.work_while(&|| done.load(Ordering::Acquire) < 2);
        }
    }
}

/// A side's matrix: lower triangle by columns in elimination order.
type Lower = SparseColMat<usize, f64>;

impl Analysis {
    /// The analysis for the unknowns of `index` (grid cell → unknown, `usize::MAX` for
    /// none) ordered `order` whose first `cut.0` and next `cut.1` unknowns are the two
    /// sides of the separator that follows: the two sides' matrices (for [`Factor::new`])
    /// with it.
    pub fn new(
        st: &Stencil,
        index: &[usize],
        order: &[usize],
        cut: (usize, usize),
    ) -> Result<(Self, [Lower; 2])> {
        let (na, nb) = cut;
        let sep = &order[na + nb..];
        let mut place = vec![0u32; order.len()];
        for (p, &q) in order.iter().enumerate() {
            place[q] = p as u32;
        }
        let side = |own: &[usize], first: usize| -> Result<(SideAnalysis, Lower)> {
            let unknowns: Vec<usize> = own.iter().chain(sep).copied().collect();
            let span = first as u32..(first + own.len()) as u32;
            let by_unknown: Vec<(u32, u32)> = (0..place.len() as u32)
                .filter_map(|q| {
                    let p = place[q as usize];
                    span.contains(&p).then(|| (q, p - span.start))
                })
                .collect();
            // Grid cell → the side's column: its own unknowns, then the separator's.
            let (own_end, sep_start) = (first + own.len(), na + nb);
            let column = |k: usize| -> u32 {
                let Some(&p) = index.get(k).and_then(|&q| place.get(q)) else {
                    return u32::MAX;
                };
                let p = p as usize;
                if (first..own_end).contains(&p) {
                    (p - first) as u32
                } else if p >= sep_start {
                    (own.len() + p - sep_start) as u32
                } else {
                    u32::MAX
                }
            };
            let (col_ptr, row_idx, vals) = lower_csc_by(st, unknowns.len(), column);
            let m = unknowns.len();
            let pattern = SymbolicSparseColMat::new_checked(m, m, col_ptr, None, row_idx);
            let a = SparseColMat::new(pattern, vals);
            // In the side's own order (its matrix is built in elimination order), with a
            // supernode boundary where the separator begins: the numeric factor stops there
            // (`Factor::new`).
            let symbolic = Supernodes::analyse(
                unknowns.len(),
                a.symbolic().col_ptr(),
                a.symbolic().row_idx(),
                own.len(),
            )
            .map_err(failed)?;
            Ok((
                SideAnalysis {
                    unknowns,
                    own: own.len(),
                    by_unknown,
                    symbolic,
                },
                a,
            ))
        };
        let (a, b) = rayon::join(|| side(&order[..na], 0), || side(&order[na..na + nb], na));
        let ((sa, ma), (sb, mb)) = (a?, b?);
        Ok((
            Analysis {
                sides: [sa, sb],
                k: sep.len(),
                place,
            },
            [ma, mb],
        ))
    }

    /// The two sides' matrices of the operator `st` on this analysis's unknowns.
    pub fn matrices(&self, st: &Stencil, cells: &[usize]) -> [Lower; 2] {
        let [sa, sb] = &self.sides;
        let (a, b) = rayon::join(
            || side_matrix(st, cells, &sa.unknowns),
            || side_matrix(st, cells, &sb.unknowns),
        );
        [a, b]
    }

    /// Entries of the factor: both sides' supernodal values and the dense `L_SS`.
    pub fn entries(&self) -> usize {
        self.sides
            .iter()
            .map(|s| s.symbolic.layout().len_val())
            .sum::<usize>()
            + self.k * self.k
    }

    /// Bytes of the numeric factorisation beyond the entries: both sides' scratch and
    /// the separator's dense blocks while `L_SS` is formed (two products and `A_SS`).
    pub fn scratch_bytes(&self) -> u64 {
        let sides: u64 = self
            .sides
            .iter()
            .map(|s| super::supernodal::scratch_bytes(s.symbolic.layout()))
            .sum();
        sides + 3 * 8 * (self.k * self.k) as u64
    }

    /// Unknowns of the separator.
    pub fn separator(&self) -> usize {
        self.k
    }

    /// Multiply-adds on the factor's critical path: the heavier side's (the two run at
    /// once, one per thread) and the separator's dense factor, `k³/3`.
    pub fn critical_flops(&self) -> f64 {
        let sides = side_flops(&self.sides[0]).max(side_flops(&self.sides[1]));
        sides + (self.k as f64).powi(3) / 3.0
    }
}

/// The lower triangle of `A[unknowns, unknowns]` in the order of `unknowns` (unknown `q` on
/// grid cell `cells[q]`).
fn side_matrix(st: &Stencil, cells: &[usize], unknowns: &[usize]) -> Lower {
    let side_cells: Vec<usize> = unknowns.iter().map(|&q| cells[q]).collect();
    let (col_ptr, row_idx, vals) = lower_csc(st, &side_cells);
    let m = unknowns.len();
    let pattern = SymbolicSparseColMat::new_checked(m, m, col_ptr, None, row_idx);
    SparseColMat::new(pattern, vals)
}

/// Multiply-adds of a side's numeric factor: `Σ (rows below the diagonal + 1)²` over its own
/// columns (the separator's columns are factored densely after both sides).
fn side_flops(sa: &SideAnalysis) -> f64 {
    sa.symbolic.layout().flops_before(sa.own)
}

/// `LEAKPATH_FLOW_PROFILE`'s lines for a side: its supernodes by width (powers of two), the
/// factor's flops (its own columns') and the time of its numeric factor.
fn profile_side(sa: &SideAnalysis, t_factor: f64) {
    let sn = sa.symbolic.layout();
    let (b, e) = (sn.supernode_begin(), sn.supernode_end());
    let mut widths = [0usize; 6];
    for s in 0..sn.n_supernodes() {
        let nc = e[s] - b[s];
        widths[(usize::BITS - nc.leading_zeros()).min(5) as usize] += 1;
    }
    let flops = side_flops(sa);
    eprintln!(
        "halves: side of {} unknowns, {} entries, {} supernodes (by width 1, 2-3, 4-7, 8-15, \
         16+: {:?}), {flops:.3e} flops; numeric {t_factor:.4} s",
        sa.unknowns.len(),
        sn.len_val(),
        sn.n_supernodes(),
        &widths[1..],
    );
}

impl Factor {
    /// Factors the two sides' matrices `m` (of [`Analysis::new`] or
    /// [`Analysis::matrices`]) at once and the separator's Schur complement after them.
    /// With `idle`, the side done first zeroes its vectors until the other is done.
    pub fn new(an: &Analysis, m: [Lower; 2], idle: Option<&ZeroedByIdle>) -> Result<Self> {
        let k = an.k;
        let [ma, mb] = m;
        // `A_SS`'s lower triangle, from the first side's matrix (the same block in both).
        let mut s = Mat::<f64>::zeros(k, k);
        {
            let own = an.sides[0].own;
            let (cp, ri, v) = (ma.symbolic().col_ptr(), ma.symbolic().row_idx(), ma.val());
            for c in own..own + k {
                for p in cp[c]..cp[c + 1] {
                    s[(ri[p] - own, c - own)] = -v[p];
                }
            }
        }
        let done = AtomicUsize::new(0);
        let side = |sa: &SideAnalysis, a: Lower| -> Result<Vec<f64>> {
            let t0 = std::time::Instant::now();
            // The side's own columns factored; its separator's blocks left holding
            // `A_SS − L_SX L_SXᵀ`, the side's part of the Schur complement.
            let values = supernodal_values(sa.symbolic.layout(), &a, sa.own)?;
            drop(a);
            if super::cg::profiling() {
                profile_side(sa, t0.elapsed().as_secs_f64());
            }
            spare_time(&done, idle);
            Ok(values)
        };
        let (a, b) = rayon::join(|| side(&an.sides[0], ma), || side(&an.sides[1], mb));
        let (va, vb) = (a?, b?);
        // `S = (A_SS − L_SA L_SAᵀ) + (A_SS − L_SB L_SBᵀ) − A_SS` (lower triangle; `s` holds
        // `−A_SS`).
        for (sa, values) in an.sides.iter().zip([&va, &vb]) {
            add_separator_block(sa, values, &mut s);
        }
        let scratch = cholesky_in_place_scratch::<f64>(k, Par::Seq, Default::default());
        let mut buf = MemBuffer::try_new(scratch).map_err(|_| failed("out of memory"))?;
        cholesky_in_place(
            s.as_mut(),
            Default::default(),
            Par::Seq,
            MemStack::new(&mut buf),
            Default::default(),
        )
        .map_err(|e| {
            failed(format!(
                "in halves, the separator's Schur complement: {e:?}"
            ))
        })?;
        Ok(Factor {
            values: [va, vb],
            ls: s,
            work: [Vec::new(), Vec::new()],
            u: Mat::zeros(k, 2),
        })
    }

    /// `A x = b` for two columns whose right-hand side at unknown `q` (an index into the
    /// analysis's cells) is `b(q, c)`: on each side both columns at once, interleaved (one
    /// pass over the side's factor each way), each side gathering its own right-hand side.
    pub fn solve<'a>(
        &'a mut self,
        an: &'a Analysis,
        b: impl Fn(usize, usize) -> f64 + Sync,
    ) -> Solved<'a> {
        let k = an.k;
        let forward = |sa: &SideAnalysis, values: &[f64], w: &mut Vec<f64>| {
            let len = 2 * sa.unknowns.len();
            if w.len() != len {
                *w = vec![0.0; len];
            }
            for &(q, p) in &sa.by_unknown {
                let (q, p) = (q as usize, p as usize);
                w[2 * p] = b(q, 0);
                w[2 * p + 1] = b(q, 1);
            }
            // The separator's rows gather the sides' updates.
            w[2 * sa.own..].iter_mut().for_each(|v| *v = 0.0);
            supernodal_forward::<2>(sa.symbolic.layout(), values, w, sa.own);
        };
        let [wa, wb] = &mut self.work;
        rayon::join(
            || forward(&an.sides[0], &self.values[0], wa),
            || forward(&an.sides[1], &self.values[1], wb),
        );
        // The separator's right-hand side: `b_S − L_SA y_A − L_SB y_B`.
        let sep = &an.sides[0].unknowns[an.sides[0].own..];
        let (oa, ob) = (an.sides[0].own, an.sides[1].own);
        let u = &mut self.u;
        for c in 0..2 {
            for (i, &q) in sep.iter().enumerate() {
                u[(i, c)] = b(q, c) + wa[2 * (oa + i) + c] + wb[2 * (ob + i) + c];
            }
        }
        solve_lower_triangular_in_place(self.ls.as_ref(), u.as_mut(), Par::Seq);
        solve_upper_triangular_in_place(self.ls.transpose(), u.as_mut(), Par::Seq);
        for c in 0..2 {
            for i in 0..k {
                wa[2 * (oa + i) + c] = u[(i, c)];
                wb[2 * (ob + i) + c] = u[(i, c)];
            }
        }
        let backward = |sa: &SideAnalysis, values: &[f64], w: &mut [f64]| {
            supernodal_backward::<2>(sa.symbolic.layout(), values, w, sa.own);
        };
        rayon::join(
            || backward(&an.sides[0], &self.values[0], wa),
            || backward(&an.sides[1], &self.values[1], wb),
        );
        Solved {
            an,
            work: &self.work,
            u: &self.u,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flow::assemble::fine_stencil;
    use crate::flow::cg;
    use crate::flow::direct;

    /// The factor in halves against the whole factor on the same grids (wrapped and not,
    /// conductances over six decades and a third of the cells at 1e-12, a condition number
    /// beyond 1e12): the relative residuals `‖b − A x‖/‖b‖` (summed exactly) within 10× the
    /// whole factor's.
    #[test]
    fn halves_solve_as_the_whole_factor() {
        for periodic in [true, false] {
            let (ny, nx) = (260, 230);
            let n = ny * nx;
            let u = crate::flow::tests::lcg(5, n);
            let c: Vec<f64> = u
                .iter()
                .map(|&v| if v < 0.3 { 1e-12 } else { 10f64.powf(-6.0 * v) })
                .collect();
            let (st, b1) = fine_stencil(&c, ny, nx, periodic);
            let mut index = vec![usize::MAX; n];
            let mut cells = Vec::new();
            for (k, slot) in index.iter_mut().enumerate() {
                if st.active[k] {
                    *slot = cells.len();
                    cells.push(k);
                }
            }
            let m = cells.len();
            let (order, cut) = crate::flow::order::nd_order(&st, &index, m);
            let cut = cut.expect("a top cut");
            let (an, mats) = Analysis::new(&st, &index, &order, cut).unwrap();
            // The sides' matrices built from the order's places: those built from the
            // sides' cells, entry for entry.
            for (a, b) in mats.iter().zip(an.matrices(&st, &cells)) {
                let (sa, sb) = (a.symbolic(), b.symbolic());
                assert!(sa.col_ptr() == sb.col_ptr() && sa.row_idx() == sb.row_idx());
                assert!(a
                    .val()
                    .iter()
                    .zip(b.val())
                    .all(|(x, y)| x.to_bits() == y.to_bits()));
            }
            let mut f = Factor::new(&an, mats, None).unwrap();
            // With vectors zeroed by the side done first: the same values, bit for bit,
            // and the vectors zeros however far that side got.
            let mut idle = ZeroedByIdle::new(3, n);
            let g = Factor::new(&an, an.matrices(&st, &cells), Some(&idle)).unwrap();
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            for (a, b) in f.values.iter().zip(&g.values) {
                assert!(bits(a) == bits(b));
            }
            assert!(bits(f.ls.col_as_slice(0)) == bits(g.ls.col_as_slice(0)));
            for _ in 0..3 {
                assert!(idle.take().iter().all(|&v| v == 0.0));
            }
            let b2: Vec<f64> = crate::flow::tests::lcg(6, n)
                .iter()
                .zip(&st.active)
                .map(|(&v, &on)| if on { v - 0.5 } else { 0.0 })
                .collect();
            let by_unknown = |b: &[f64]| -> Vec<f64> { cells.iter().map(|&k| b[k]).collect() };
            // A first solve of other columns: the second's answer must not depend on what
            // the reused buffers held.
            let other = [by_unknown(&b2), vec![1.0; m]];
            f.solve(&an, |q, c| other[c][q]);
            let cols = [by_unknown(&b1), by_unknown(&b2)];
            let sol = f.solve(&an, |q, c| cols[c][q]);
            let xs = [0, 1].map(|c| {
                let mut x = vec![0.0; n];
                for (q, &k) in cells.iter().enumerate() {
                    x[k] = sol.value(q, c);
                }
                x
            });
            let mut whole = direct::Factor::new(&st, None).unwrap();
            let (mut w1, mut w2) = (vec![0.0; n], vec![0.0; n]);
            whole.solve_pair(&b1, &b2, &mut w1, &mut w2);
            let mut r = vec![0.0; n];
            let mut rel = |x: &[f64], b: &[f64]| {
                st.residual_compensated(x, b, &mut r);
                cg::dot(&r, &r).sqrt() / cg::dot(b, b).sqrt()
            };
            for (x, (b, w)) in xs.iter().zip([(&b1, &w1), (&b2, &w2)]) {
                let (halves, whole) = (rel(x, b), rel(w, b));
                assert!(
                    halves < 1e-6 && halves <= 10.0 * whole + 1e-15,
                    "periodic={periodic}: residual {halves:e} (whole factor {whole:e})"
                );
            }
        }
    }
}
