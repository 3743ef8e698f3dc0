//! Sparse Cholesky solve of the Reynolds system on the cells with unknowns (faer's
//! supernodal symbolic analysis, the numeric factor in [`super::supernodal`]; each factor's
//! arithmetic on one thread, so the bits do not depend on the thread count).
//!
//! The gaps of a contact close continuously at the contact edges, so `g³` spans fifteen
//! orders of magnitude and the flow near the percolation threshold passes through necks whose
//! conductance is that small: conjugate gradients then stall far from the answer in double
//! precision, while the factorisation is exact to round-off.
//!
//! # Ordering
//!
//! The fill-reducing order is [`super::order::ordering`]: a nested dissection of the grid on
//! large or mostly open grids, approximate minimum degree on pieces otherwise.
//!
//! # Two halves
//!
//! When the nested dissection has a top cut and there are at least
//! [`halves::MIN_UNKNOWNS`] unknowns, the two sides of the cut are factored at once, one per
//! thread, and the cut's Schur complement densely after them ([`super::halves`]); otherwise
//! one faer factor of all unknowns.
//!
//! # Solves
//!
//! The flow's two right-hand sides (and their refinement) are solved by plain loops over
//! each supernode's dense block ([`super::substitution`]) instead of faer's general solve,
//! which dispatches dense kernels and a temporary per supernode (the supernodes here have
//! about five columns); 2.2× faster on the 513² contact gap of the benchmarks
//! (docs/flow.md). With one factor the two columns are solved at once on two threads, each
//! with the arithmetic it has alone; in halves each side's thread solves both columns in
//! one pass over its factor (docs/flow.md).
//!
//! # Memory
//!
//! The factor's size is known exactly once the symbolic analysis is done, before any value
//! is computed: [`Factor::new`] refuses with [`Error::TooLarge`] there, so a caller can fall
//! back to an iterative solver without having allocated the factor.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, LltRef, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use faer::{Conj, Mat, Par, Side};
use std::sync::Arc;

use super::assemble::Stencil;
use super::cg;
use super::halves;
use super::llt::{failed, llt_values};
use super::lower::lower_csc;
use super::substitution::supernodal_solve;
use super::symbolic::Layout;
use crate::alloc::ZeroedByIdle;
use crate::error::{Error, Result};

/// Iterative-refinement steps at most per right-hand side.
const REFINE: usize = 4;

/// [`Factor::solve`] stops refining once the relative residual is at or below this.
const REFINED: f64 = 1e-15;

/// The ordering and symbolic analysis of a factor: the grid cells it has unknowns for and
/// the structure of the factor of the operator on them (its couplings along every grid face
/// between two of them). A later operator on the same grid whose active cells are among
/// them is factored on it without a new analysis ([`Factor::new_reusing`]): its other cells
/// get identity rows and no couplings, whose factor entries are exact zeros.
pub struct Analysis {
    ny: usize,
    nx: usize,
    periodic: bool,
    /// Grid cell of each unknown (cell order).
    cells: Vec<usize>,
    structure: Structure,
}

/// The factor's structure: one supernodal factor of all unknowns, or two halves and their
/// separator ([`halves`]). One per factor: the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
enum Structure {
    Whole(SymbolicCholesky<usize>),
    Halves(halves::Analysis),
}

impl Analysis {
    /// Unknowns of the analysis.
    pub fn unknowns(&self) -> usize {
        self.cells.len()
    }

    /// Entries of a factor on this analysis.
    pub fn entries(&self) -> usize {
        match &self.structure {
            Structure::Whole(symbolic) => symbolic.len_val(),
            Structure::Halves(h) => h.entries(),
        }
    }

    /// Multiply-adds on the numeric factor's critical path: the heavier half's and the
    /// separator's for a factor in halves, every column's for a whole one (which runs on
    /// one thread).
    pub fn critical_flops(&self) -> f64 {
        match &self.structure {
            Structure::Whole(symbolic) => whole_flops(symbolic),
            Structure::Halves(h) => h.critical_flops(),
        }
    }

    /// Whether an operator `st` with `active` unknowns can be factored on this analysis:
    /// (on the same grid and wrap) at least [`REUSE_FRACTION`] of its unknowns, all its
    /// active cells among them (`index`: grid cell → unknown of the analysis).
    fn fits(&self, st: &Stencil, index: &[usize], active: usize) -> bool {
        active as f64 >= REUSE_FRACTION * self.cells.len() as f64
            && st
                .active
                .iter()
                .zip(index)
                .all(|(&on, &q)| !on || q != usize::MAX)
    }
}

/// `x_c[cells[q]] = value(q, c)` (or `+=` with `add`) for every column `x_c` of `xs` and
/// every unknown `q` that is `live`, in parallel over fixed chunks of unknowns: `cells` is
/// increasing, so each chunk writes its own range of each column. The columns in one pass:
/// an unknown's values sit side by side in the factor's solve vectors, read once.
fn scatter(
    xs: &mut [&mut [f64]],
    cells: &[usize],
    live: impl Fn(usize) -> bool + Sync,
    value: impl Fn(usize, usize) -> f64 + Sync,
    add: bool,
) {
    use rayon::prelude::*;
    const CHUNK: usize = 1 << 13;
    let chunks = cells.len().div_ceil(CHUNK).max(1);
    // pieces[t]: chunk `t`'s range of every column, from cell `offsets[t]` on.
    let mut pieces: Vec<Vec<&mut [f64]>> =
        (0..chunks).map(|_| Vec::with_capacity(xs.len())).collect();
    let offsets: Vec<usize> = (0..chunks)
        .map(|t| if t == 0 { 0 } else { cells[t * CHUNK] })
        .collect();
    for x in xs.iter_mut() {
        let mut rest: &mut [f64] = x;
        for t in 0..chunks {
            let end = offsets.get(t + 1).map_or(rest.len(), |&e| e - offsets[t]);
            let (piece, tail) = rest.split_at_mut(end);
            pieces[t].push(piece);
            rest = tail;
        }
    }
    pieces
        .into_par_iter()
        .enumerate()
        .for_each(|(t, mut cols)| {
            let offset = offsets[t];
            let q0 = t * CHUNK;
            let mine = &cells[q0..cells.len().min(q0 + CHUNK)];
            for (q, &cell) in (q0..).zip(mine) {
                if live(q) {
                    let k = cell - offset;
                    for (c, col) in cols.iter_mut().enumerate() {
                        let v = value(q, c);
                        col[k] = if add { col[k] + v } else { v };
                    }
                }
            }
        });
}

/// A kept [`Analysis`] is used for an operator with at least this fraction of its unknowns
/// (fewer: the factor on it costs more than a new analysis and a smaller factor).
pub const REUSE_FRACTION: f64 = 0.95;

/// The Cholesky factor of the operator on its active cells.
pub struct Factor {
    analysis: Arc<Analysis>,
    /// Whether each unknown of the analysis is an active cell of the factored operator
    /// (`None`: all are).
    live: Option<Vec<bool>>,
    numeric: Numeric,
    /// Two columns, one after the other, in the factor's order ([`supernodal_solve`]); empty
    /// for a factor in halves.
    work: Vec<f64>,
    /// Whether the analysis was a kept one.
    reused: bool,
}

/// The factor's values, of its analysis's [`Structure`].
enum Numeric {
    Whole {
        values: Vec<f64>,
        /// Scratch of one solve.
        solve_buf: MemBuffer,
    },
    Halves(halves::Factor),
}

/// The operator's matrix for a [`Structure`]: the whole lower triangle, or each half's.
enum Matrices {
    Whole(SparseColMat<usize, f64>),
    Halves([SparseColMat<usize, f64>; 2]),
}

/// Cells a thread numbers at a time in [`unknowns_of`].
const UNKNOWNS_BLOCK: usize = 1 << 15;

/// The unknowns of the active cells, numbered in grid order: each cell's unknown
/// (`usize::MAX` for none) and each unknown's cell. Both written by every thread, a block
/// of cells each, at the offset that the counts of the blocks before it give (2.1 MB of
/// index at 513²: faulted in and written on one core, it was a millisecond and a half of
/// the call).
fn unknowns_of(active: &[bool]) -> (Vec<usize>, Vec<usize>) {
    use rayon::prelude::*;
    let counts: Vec<usize> = active
        .par_chunks(UNKNOWNS_BLOCK)
        .map(|b| b.iter().filter(|&&on| on).count())
        .collect();
    let mut cells = vec![0usize; counts.iter().sum()];
    let mut parts = Vec::with_capacity(counts.len());
    let (mut rest, mut start) = (&mut cells[..], 0);
    for &c in &counts {
        let (part, tail) = rest.split_at_mut(c);
        parts.push((start, part));
        (rest, start) = (tail, start + c);
    }
    let mut index = Vec::with_capacity(active.len());
    index
        .spare_capacity_mut()
        .par_chunks_mut(UNKNOWNS_BLOCK)
        .zip(active.par_chunks(UNKNOWNS_BLOCK))
        .zip(parts)
        .enumerate()
        .for_each(|(b, ((slots, on), (start, part)))| {
            let mut t = 0;
            for (j, (slot, &on)) in slots.iter_mut().zip(on).enumerate() {
                if on {
                    slot.write(start + t);
                    part[t] = b * UNKNOWNS_BLOCK + j;
                    t += 1;
                } else {
                    slot.write(usize::MAX);
                }
            }
        });
    // SAFETY: the blocks cover the whole capacity (`active.len()` values), each written.
    unsafe { index.set_len(active.len()) };
    (index, cells)
}

/// The numeric factor of `a` on `symbolic`, and the scratch of its solves.
fn whole_numeric(
    symbolic: &SymbolicCholesky<usize>,
    a: &SparseColMat<usize, f64>,
    par: Par,
) -> Result<Numeric> {
    let values = llt_values(symbolic, a, par)?;
    let solve_buf = MemBuffer::try_new(symbolic.solve_in_place_scratch::<f64>(2, par))
        .map_err(|_| failed("out of memory"))?;
    Ok(Numeric::Whole { values, solve_buf })
}

/// `LEAKPATH_FLOW_PROFILE`'s lines for a factor: its supernodes and flops, and the stages'
/// times (`t0`: the numeric factor's start).
#[allow(clippy::too_many_arguments)]
fn profile(
    structure: &Structure,
    m: usize,
    reused: bool,
    active: usize,
    t_matrix: f64,
    t_order: f64,
    t_symbolic: f64,
    t0: std::time::Instant,
) {
    let t_numeric = cg::secs(t0);
    let supernodal = |symbolic: &SymbolicCholesky<usize>| {
        if let SymbolicCholeskyRaw::Supernodal(sn) = symbolic.raw() {
            let flops = whole_flops(symbolic);
            let (b, e) = (sn.supernode_begin(), sn.supernode_end());
            let big = (0..sn.n_supernodes())
                .map(|s| e[s] - b[s])
                .max()
                .unwrap_or(0);
            eprintln!(
                "factor: {} supernodes, largest {big} columns, {flops:.3e} flops",
                sn.n_supernodes()
            );
        }
    };
    let entries = match structure {
        Structure::Whole(symbolic) => {
            supernodal(symbolic);
            symbolic.len_val()
        }
        Structure::Halves(h) => {
            eprintln!(
                "factor: in two halves, separator of {} unknowns (matrices with the symbolic \
                 analysis)",
                h.separator()
            );
            h.entries()
        }
    };
    eprintln!(
        "factor: {m} unknowns{}, {entries} entries; matrix {t_matrix:.3} s, order {t_order:.3} s, \
         symbolic {t_symbolic:.3} s, numeric {t_numeric:.3} s",
        if reused {
            format!(" (kept analysis, {active} active)")
        } else {
            String::new()
        },
    );
}

/// Multiply-adds of a whole factor, `Σ (entries of the column, its diagonal's included)²`
/// over its columns.
fn whole_flops(symbolic: &SymbolicCholesky<usize>) -> f64 {
    match symbolic.raw() {
        SymbolicCholeskyRaw::Supernodal(sn) => Layout::of_faer(sn).flops_before(usize::MAX),
        SymbolicCholeskyRaw::Simplicial(s) => s
            .col_ptr()
            .windows(2)
            .map(|w| ((w[1] - w[0]) as f64).powi(2))
            .sum(),
    }
}

/// Bytes of the values of a factor with `entries` entries, its numeric scratch `scratch`
/// and the symbolic structure (an index per entry at most).
fn factor_bytes(entries: usize, scratch: usize) -> u64 {
    16 * entries as u64 + scratch as u64
}

impl Factor {
    /// Orders, analyses and factors `st` on its active cells. With `memory_limit`, refuses
    /// with [`Error::TooLarge`] after the symbolic analysis when the factor would need more.
    pub fn new(st: &Stencil, memory_limit: Option<u64>) -> Result<Self> {
        let made = Self::new_reusing(st, memory_limit, None, None, None)?;
        made.ok_or_else(|| failed("a factor declined without a test"))
    }

    /// [`Factor::new`] on `kept` when it fits `st` ([`REUSE_FRACTION`], the active cells
    /// among its unknowns): no ordering nor symbolic analysis, the factor's values only.
    /// [`Factor::analysis`] gives the analysis used, to keep for the next operator.
    /// With `idle`, a thread whose share of the factor in halves is done before the other's
    /// zeroes its vectors meanwhile ([`ZeroedByIdle::work_while`]). With `declines`, `None`
    /// when it holds for the analysis: the numeric factor, the costly part, is not computed
    /// (`Auto` predicting the multigrid faster, [`super::cost`]).
    pub fn new_reusing(
        st: &Stencil,
        memory_limit: Option<u64>,
        kept: Option<&Arc<Analysis>>,
        idle: Option<&ZeroedByIdle>,
        declines: Option<&dyn Fn(&Analysis) -> bool>,
    ) -> Result<Option<Self>> {
        let n = st.ny * st.nx;
        let t0 = std::time::Instant::now();
        let active = st.active.iter().filter(|&&on| on).count();
        let same_grid =
            |a: &&Arc<Analysis>| (a.ny, a.nx, a.periodic) == (st.ny, st.nx, st.periodic);
        let reuse = kept.filter(same_grid).and_then(|a| {
            let mut index = vec![usize::MAX; n];
            for (q, &k) in a.cells.iter().enumerate() {
                index[k] = q;
            }
            a.fits(st, &index, active).then(|| (a.clone(), index))
        });
        let (index, cells, reuse) = match reuse {
            Some((a, index)) => (index, Vec::new(), Some(a)),
            None => {
                let (index, cells) = unknowns_of(&st.active);
                (index, cells, None)
            }
        };
        let on = match &reuse {
            Some(a) => &a.cells,
            None => &cells,
        };
        let m = on.len();
        let reused = reuse.is_some();
        let (mut t_order, mut t_symbolic, mut t_matrix) = (0.0, 0.0, 0.0);
        // The whole matrix, unless the analysis is in halves (each builds its own).
        let whole_matrix = |on: &[usize]| {
            let (col_ptr, row_idx, vals) = lower_csc(st, on);
            let pattern = SymbolicSparseColMat::new_checked(m, m, col_ptr, None, row_idx);
            SparseColMat::new(pattern, vals)
        };
        let (analysis, matrices) = match reuse {
            Some(an) => {
                let matrices = match &an.structure {
                    Structure::Whole(_) => Matrices::Whole(whole_matrix(&an.cells)),
                    Structure::Halves(h) => Matrices::Halves(h.matrices(st, &an.cells)),
                };
                t_matrix = cg::secs(t0);
                (an, matrices)
            }
            None => {
                let t0 = std::time::Instant::now();
                let (fwd, cut) = super::order::ordering(st, &index, m);
                t_order = cg::secs(t0);
                let halved = cut.filter(|&(na, nb)| {
                    m >= halves::MIN_UNKNOWNS
                        && na > 0
                        && nb > 0
                        && m - na - nb <= halves::MAX_SEPARATOR
                });
                let t0 = std::time::Instant::now();
                let (structure, matrices) = match halved {
                    Some(cut) => {
                        let (h, mats) = halves::Analysis::new(st, &index, &fwd, cut)?;
                        // The sides' matrices are built with their analyses.
                        t_symbolic = cg::secs(t0);
                        (Structure::Halves(h), Matrices::Halves(mats))
                    }
                    None => {
                        let a = whole_matrix(&cells);
                        t_matrix = cg::secs(t0);
                        let t0 = std::time::Instant::now();
                        let mut inv = vec![0usize; m];
                        for (new, &old) in fwd.iter().enumerate() {
                            inv[old] = new;
                        }
                        let perm = faer::perm::PermRef::new_checked(&fwd, &inv, m);
                        let symbolic = factorize_symbolic_cholesky(
                            a.symbolic(),
                            Side::Lower,
                            SymmetricOrdering::Custom(perm),
                            Default::default(),
                        )
                        .map_err(failed)?;
                        t_symbolic = cg::secs(t0);
                        (Structure::Whole(symbolic), Matrices::Whole(a))
                    }
                };
                let an = Arc::new(Analysis {
                    ny: st.ny,
                    nx: st.nx,
                    periodic: st.periodic,
                    cells,
                    structure,
                });
                (an, matrices)
            }
        };
        drop(index);
        cg::mark("matrices, order, symbolic analysis");
        let live = reused.then(|| analysis.cells.iter().map(|&k| st.active[k]).collect());
        let t0 = std::time::Instant::now();
        let par = Par::Seq;
        let (entries, scratch_bytes) = match &analysis.structure {
            Structure::Whole(symbolic) => {
                (symbolic.len_val(), super::llt::scratch_bytes(symbolic, par))
            }
            Structure::Halves(h) => (h.entries(), h.scratch_bytes()),
        };
        let need = factor_bytes(entries, scratch_bytes as usize);
        if let Some(limit) = memory_limit {
            if need > limit {
                return Err(Error::TooLarge {
                    bytes: need,
                    limit,
                    what: format!("the sparse Cholesky factor of {m} flow unknowns"),
                });
            }
        }
        if declines.is_some_and(|d| d(&analysis)) {
            return Ok(None);
        }
        if m > 16 {
            // The supernodes' dense products: a refusal, not an abort, when their CPU-sized
            // scratch does not fit.
            crate::dense_scratch::ensure(par)?;
        }
        let numeric = match (&analysis.structure, matrices) {
            (Structure::Whole(symbolic), Matrices::Whole(a)) => whole_numeric(symbolic, &a, par)?,
            (Structure::Halves(h), Matrices::Halves(mats)) => {
                Numeric::Halves(halves::Factor::new(h, mats, idle)?)
            }
            _ => unreachable!("matrices built for their structure"),
        };
        if cg::profiling() {
            profile(
                &analysis.structure,
                m,
                reused,
                active,
                t_matrix,
                t_order,
                t_symbolic,
                t0,
            );
        }
        Ok(Some(Factor {
            // A factor in halves keeps its own (by side).
            work: match numeric {
                Numeric::Whole { .. } => vec![0.0; 2 * m],
                Numeric::Halves(_) => Vec::new(),
            },
            analysis,
            live,
            numeric,
            reused,
        }))
    }

    /// The ordering and symbolic analysis this factor was computed on.
    pub fn analysis(&self) -> &Arc<Analysis> {
        &self.analysis
    }

    /// Whether the factor was computed on a kept analysis ([`Factor::new_reusing`]).
    pub fn reused(&self) -> bool {
        self.reused
    }

    /// Entries of the factor.
    pub fn entries(&self) -> usize {
        self.analysis.entries()
    }

    /// `x = A⁻¹ b` (or `x += A⁻¹ b` with `add`) on the active cells for each pair `(b, x)`
    /// of `cols`, all columns in one pass over the factor (`b` read and `x` written on the
    /// active cells only: the other unknowns of a kept analysis are 0).
    fn solve_cells(&mut self, cols: &mut [(&[f64], &mut [f64])], add: bool) {
        let an = &*self.analysis;
        let cells = &an.cells;
        let live = |q: usize| self.live.as_ref().is_none_or(|l| l[q]);
        let m = cells.len();
        if m == 0 {
            return;
        }
        let set = |x: &mut f64, v: f64| {
            if add {
                *x += v;
            } else {
                *x = v;
            }
        };
        let symbolic = match (&an.structure, &mut self.numeric) {
            (Structure::Halves(h), Numeric::Halves(f)) => {
                // Two columns at once (a second of zeros with one), each side gathering its
                // right-hand side from the cells; the answer written back in parallel.
                let sol = f.solve(h, |q, c| match cols.get(c) {
                    Some(col) if live(q) => col.0[cells[q]],
                    _ => 0.0,
                });
                let mut xs: Vec<&mut [f64]> = cols.iter_mut().map(|col| &mut *col.1).collect();
                scatter(&mut xs, cells, live, |q, c| sol.value(q, c), add);
                return;
            }
            (Structure::Whole(symbolic), _) => symbolic,
            _ => unreachable!("a factor of its analysis's structure"),
        };
        let Numeric::Whole { values, solve_buf } = &mut self.numeric else {
            unreachable!("a factor of its analysis's structure")
        };
        if let (SymbolicCholeskyRaw::Supernodal(sn), 2, Some(perm)) =
            (symbolic.raw(), cols.len(), symbolic.perm())
        {
            // Each column in the factor's order (`w_c[p]` at position `p`, whose cell is
            // `cells[fwd[p]]`), the two solved at once on two threads: each column's
            // arithmetic is the same as alone, so the answer does not depend on the threads.
            let fwd = perm.arrays().0;
            let (w0, w1) = self.work.split_at_mut(m);
            for (p, &q) in fwd.iter().enumerate() {
                let k = cells[q];
                let on = live(q);
                w0[p] = if on { cols[0].0[k] } else { 0.0 };
                w1[p] = if on { cols[1].0[k] } else { 0.0 };
            }
            let (values, sn) = (&*values, Layout::of_faer(sn));
            rayon::join(
                || supernodal_solve(sn, values, w0),
                || supernodal_solve(sn, values, w1),
            );
            for (p, &q) in fwd.iter().enumerate() {
                if live(q) {
                    set(&mut cols[0].1[cells[q]], w0[p]);
                    set(&mut cols[1].1[cells[q]], w1[p]);
                }
            }
            return;
        }
        let mut sol = Mat::<f64>::from_fn(m, cols.len(), |r, c| {
            if live(r) {
                cols[c].0[cells[r]]
            } else {
                0.0
            }
        });
        let llt = LltRef::<'_, usize, f64>::new(symbolic, values);
        llt.solve_in_place_with_conj(Conj::No, sol.as_mut(), Par::Seq, MemStack::new(solve_buf));
        for c in 0..cols.len() {
            for r in 0..m {
                if live(r) {
                    set(&mut cols[c].1[cells[r]], sol[(r, c)]);
                }
            }
        }
    }

    /// `A x = b` for the two right-hand sides of a flow (inlet and outlet), from the factor
    /// alone: `x1 = A⁻¹ b1`, `x2 = A⁻¹ b2` on the active cells, 0 elsewhere.
    pub fn solve_pair(&mut self, b1: &[f64], b2: &[f64], x1: &mut [f64], x2: &mut [f64]) {
        x1.iter_mut().for_each(|v| *v = 0.0);
        x2.iter_mut().for_each(|v| *v = 0.0);
        self.solve_cells(&mut [(b1, x1), (b2, x2)], false);
    }

    /// `x1 += A⁻¹ r1`, `x2 += A⁻¹ r2` on the active cells: one refinement step of both.
    pub fn correct_pair(&mut self, r1: &[f64], r2: &[f64], x1: &mut [f64], x2: &mut [f64]) {
        self.solve_cells(&mut [(r1, x1), (r2, x2)], true);
    }

    /// `A x = b` on the active cells (0 elsewhere), refined with double-double residuals
    /// ([`Stencil::residual_compensated`]) until the relative residual is at most
    /// [`REFINED`], a step no longer halves it (the factor's error is then as large as the
    /// correction: a condition number near 1/ε) or [`REFINE`] steps were taken; a step that
    /// made it worse is undone.
    /// Returns the relative residual `‖b − A x‖₂ / ‖b‖₂`.
    pub fn solve(&mut self, st: &Stencil, b: &[f64], x: &mut [f64]) -> f64 {
        x.iter_mut().for_each(|v| *v = 0.0);
        let bnorm = cg::dot(b, b).sqrt();
        if bnorm == 0.0 {
            return 0.0;
        }
        self.solve_cells(&mut [(b, &mut *x)], false);
        let mut res = vec![0.0; b.len()];
        let mut best = f64::INFINITY;
        let mut best_x = x.to_vec();
        for step in 0..=REFINE {
            st.residual_compensated(x, b, &mut res);
            let rel = cg::dot(&res, &res).sqrt() / bnorm;
            if rel >= best {
                x.copy_from_slice(&best_x);
                break;
            }
            let slow = rel > 0.5 * best;
            best = rel;
            if rel <= REFINED || step == REFINE || slow {
                break;
            }
            best_x.copy_from_slice(x);
            self.solve_cells(&mut [(&res, &mut *x)], true);
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flow::assemble::fine_stencil;

    /// The unknowns numbered by blocks on every thread: those of a plain pass in grid
    /// order, on patterns of no, one, some and every active cell, across block boundaries.
    #[test]
    fn unknowns_are_numbered_in_grid_order() {
        for (n, density) in [
            (0, 0.5),
            (1, 1.0),
            (UNKNOWNS_BLOCK, 0.3),
            (3 * UNKNOWNS_BLOCK + 17, 0.6),
        ] {
            for d in [0.0, density, 1.0] {
                let active: Vec<bool> = crate::flow::tests::lcg(31, n)
                    .iter()
                    .map(|&u| u < d)
                    .collect();
                let (mut index, mut cells) = (vec![usize::MAX; n], Vec::new());
                for (k, &on) in active.iter().enumerate() {
                    if on {
                        index[k] = cells.len();
                        cells.push(k);
                    }
                }
                assert_eq!(unknowns_of(&active), (index, cells), "{n} cells, {d}");
            }
        }
    }

    /// The two-column supernodal solve against faer's general solve with the same factor:
    /// on a wrapped grid whose conductances span six decades, the residuals `b − A x`
    /// (summed exactly) of both columns are within 4× of the general solve's and at round-off
    /// (`‖r‖ ≤ 1e-10 ‖b‖`), in the plain and in the accumulating form.
    #[test]
    fn pair_solve_matches_the_general_solve() {
        let (ny, nx) = (90, 70);
        let n = ny * nx;
        let u = crate::flow::tests::lcg(11, n);
        let c: Vec<f64> = u.iter().map(|&v| 10f64.powf(-6.0 * v)).collect();
        let (st, b1) = fine_stencil(&c, ny, nx, true);
        let b2: Vec<f64> = crate::flow::tests::lcg(12, n)
            .iter()
            .zip(&st.active)
            .map(|(&v, &on)| if on { v - 0.5 } else { 0.0 })
            .collect();
        let mut f = Factor::new(&st, None).unwrap();
        assert!(matches!(
            &f.analysis.structure,
            Structure::Whole(symbolic) if matches!(symbolic.raw(), SymbolicCholeskyRaw::Supernodal(_))
        ));
        let mut r = vec![0.0; n];
        let mut rel = |x: &[f64], b: &[f64]| {
            st.residual_compensated(x, b, &mut r);
            cg::dot(&r, &r).sqrt() / cg::dot(b, b).sqrt()
        };
        // faer's solve of each column on its own.
        let general = |f: &mut Factor, b: &[f64]| {
            let m = f.analysis.cells.len();
            let mut sol = Mat::<f64>::from_fn(m, 1, |q, _| b[f.analysis.cells[q]]);
            let (Structure::Whole(symbolic), Numeric::Whole { values, solve_buf }) =
                (&f.analysis.structure, &mut f.numeric)
            else {
                panic!("a whole factor")
            };
            let llt = LltRef::<'_, usize, f64>::new(symbolic, values);
            llt.solve_in_place_with_conj(
                Conj::No,
                sol.as_mut(),
                Par::Seq,
                MemStack::new(solve_buf),
            );
            let mut x = vec![0.0; n];
            for (q, &k) in f.analysis.cells.iter().enumerate() {
                x[k] = sol[(q, 0)];
            }
            x
        };
        let (g1, g2) = (general(&mut f, &b1), general(&mut f, &b2));
        let (e1, e2) = (rel(&g1, &b1), rel(&g2, &b2));
        let (mut x1, mut x2) = (vec![0.0; n], vec![0.0; n]);
        f.solve_pair(&b1, &b2, &mut x1, &mut x2);
        // The two columns on two threads or on one: the same bits.
        let (mut y1, mut y2) = (vec![0.0; n], vec![0.0; n]);
        rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| f.solve_pair(&b1, &b2, &mut y1, &mut y2));
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert!(bits(&x1) == bits(&y1) && bits(&x2) == bits(&y2));
        let (p1, p2) = (rel(&x1, &b1), rel(&x2, &b2));
        assert!(p1 <= 4.0 * e1.max(1e-16) && p1 < 1e-10, "{p1:e} {e1:e}");
        assert!(p2 <= 4.0 * e2.max(1e-16) && p2 < 1e-10, "{p2:e} {e2:e}");
        // x += A⁻¹ (b − A x) from half the solution: back to it.
        x1.iter_mut().for_each(|v| *v *= 0.5);
        x2.iter_mut().for_each(|v| *v *= 0.5);
        let (mut r1, mut r2) = (vec![0.0; n], vec![0.0; n]);
        st.residual_compensated(&x1, &b1, &mut r1);
        st.residual_compensated(&x2, &b2, &mut r2);
        f.correct_pair(&r1, &r2, &mut x1, &mut x2);
        let (q1, q2) = (rel(&x1, &b1), rel(&x2, &b2));
        assert!(q1 <= 4.0 * e1.max(1e-16) && q1 < 1e-10, "{q1:e} {e1:e}");
        assert!(q2 <= 4.0 * e2.max(1e-16) && q2 < 1e-10, "{q2:e} {e2:e}");
    }

    /// A factor in halves on a grid above [`halves::MIN_UNKNOWNS`], and a later operator
    /// with 2 % of its cells closed factored on its kept analysis (identity rows for the
    /// closed ones): both in halves, the later one reused, its residuals (summed exactly)
    /// within 10× a fresh factor's and at round-off, with one column and with two.
    #[test]
    fn a_kept_analysis_in_halves_factors_a_later_operator() {
        let (ny, nx) = (300, 260);
        let n = ny * nx;
        let u = crate::flow::tests::lcg(21, n);
        let c1: Vec<f64> = u.iter().map(|&v| 10f64.powf(-4.0 * v)).collect();
        let (st1, _) = fine_stencil(&c1, ny, nx, true);
        let f1 = Factor::new(&st1, None).unwrap();
        let halved = |f: &Factor| matches!(f.analysis.structure, Structure::Halves(_));
        assert!(halved(&f1));
        let closed = crate::flow::tests::lcg(22, n);
        let c2: Vec<f64> = c1
            .iter()
            .zip(&closed)
            .map(|(&c, &z)| if z < 0.02 { 0.0 } else { c })
            .collect();
        let (st2, b1) = fine_stencil(&c2, ny, nx, true);
        let b2: Vec<f64> = crate::flow::tests::lcg(23, n)
            .iter()
            .zip(&st2.active)
            .map(|(&v, &on)| if on { v - 0.5 } else { 0.0 })
            .collect();
        let mut kept = Factor::new_reusing(&st2, None, Some(f1.analysis()), None, None)
            .unwrap()
            .unwrap();
        assert!(kept.reused() && halved(&kept));
        let mut fresh = Factor::new(&st2, None).unwrap();
        let mut r = vec![0.0; n];
        let mut rel = |x: &[f64], b: &[f64]| {
            st2.residual_compensated(x, b, &mut r);
            cg::dot(&r, &r).sqrt() / cg::dot(b, b).sqrt()
        };
        let (mut x1, mut x2, mut y1, mut y2) =
            (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        kept.solve_pair(&b1, &b2, &mut x1, &mut x2);
        fresh.solve_pair(&b1, &b2, &mut y1, &mut y2);
        for (x, y, b) in [(&x1, &y1, &b1), (&x2, &y2, &b2)] {
            let (p, q) = (rel(x, b), rel(y, b));
            assert!(
                p < 1e-10 && p <= 10.0 * q.max(1e-16),
                "kept {p:e}, fresh {q:e}"
            );
        }
        // One column (the second solved as zeros).
        let mut z = vec![0.0; n];
        let res = kept.solve(&st2, &b1, &mut z);
        assert!(res < 1e-12 && rel(&z, &b1) < 1e-12, "{res:e}");
    }
}
