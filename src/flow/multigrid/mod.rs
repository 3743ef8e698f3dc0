//! Classical (Ruge–Stüben) algebraic multigrid preconditioner for the Reynolds operator.
//!
//! # The finest level: red cells eliminated exactly
//!
//! The five-point stencil joins each cell only to cells of the other colour of a
//! checkerboard, so the red half of the unknowns is eliminated exactly ([`reduce`]): the
//! preconditioner is the block factorisation `L diag(D_R, S) Lᵀ` of the fine operator with
//! the Schur complement `S` on the black half replaced by one cycle of the classical
//! multigrid below. Nothing of the finest level is smoothed or interpolated, and `S` is
//! formed from the stencil directly; against a classical first coarsening (its splitting
//! halved the unknowns too) this took the 4097² gap's multigrid from 42 to 39 CG iterations,
//! its cycle from 0.45 to 0.29 s and its setup from 12.3 to 6.8 s (docs/flow.md).
//!
//! CG with that preconditioner on `A` is CG on `S` with `M_S`, the red half carried along:
//! so the refinement's inner solves run on `S` itself ([`Multigrid::reduce`], CG on
//! [`Multigrid::inner_reduced_product`] and [`Multigrid::cycle`], [`Multigrid::extend`]).
//! CG applies the stored single-precision `S` when every face of it is a normal single
//! (each then within 2^-24 of the exact face, so the energy of any vector within 2^-24 of
//! its exact value, and an inner solve to 1e-6 on it is one to about 1e-6 on the exact
//! `S`); the refinement's residual, computed exactly on the fine operator, is what the
//! answer is held to either way. A face below single precision's normal range (a
//! conductance some 1e-38 of the largest, where the rounding is coarse or drops the face)
//! makes CG apply `S` in double precision from the stencil instead
//! ([`Multigrid::reduced_product`]). [`Multigrid::precondition`] is the block
//! preconditioner on `A` itself.
//!
//! # Why classical coarsening
//!
//! Near the percolation threshold the spanning cluster is a maze of necks, dead ends and
//! one-cell walls whose face conductances `g³` change by large factors from one cell to the
//! next (the gap closes as `r^{3/2}` at a contact edge, so `g³ ∝ r^{4.5}`). Aggregation that
//! only joins cells across faces within a factor of the strongest one (pairwise aggregation)
//! then finds few pairs on such graded chains, coarsens by less than 10 % per pass and needs
//! dozens of levels, or lumps a wide cell with the neck that throttles it when forced to
//! coarsen: docs/flow.md has the measurements. Classical coarsening keeps every unknown
//! either on the coarse grid (C) or interpolated from strong C neighbours (F) with weights
//! built from its own row, so a neck is never averaged with the cells it separates and each
//! level roughly halves the unknowns whatever the contrast.
//!
//! # Construction
//!
//! Below `S`, on the conductance form `(A x)_i = d_i x_i − Σ_j w_ij x_j`,
//! `d_i = dir_i + Σ_j w_ij`:
//!
//! - strength: `j` strongly influences `i` when `w_ij ≥ θ max_k w_ik` (`θ` = [`THETA`];
//!   only `w_ij > 0` counts);
//! - C/F splitting: the first pass of Ruge and Stüben, sequential in unknown order (so
//!   deterministic): repeatedly the undecided unknown on which most undecided ones depend
//!   strongly becomes C and its strong dependents F; then a second pass in unknown order:
//!   a strong F neighbour `k` of an F unknown `i` joined to none of the strong C neighbours
//!   of `i` becomes C. Without the second pass the interpolation lumps such `w_ik` and the
//!   cycle contracts the error by only about 0.5–0.6 per CG step on near-threshold gaps;
//!   with it about 0.15–0.4 (the iterations to the default tolerance drop from 73–78 to
//!   42–43 at 1025² and 2049², docs/flow.md), for some 10 % more operator complexity.
//!   The code can also split fixed blocks of unknowns in parallel, the same for any thread
//!   count, but the seams cost iterations (`SPLIT_BLOCK`, one block by default);
//! - interpolation to an F unknown `i`, classical with lumping: weak faces go to the
//!   diagonal, a strong F neighbour `k` is distributed over the strong C neighbours of `i`
//!   in proportion to `w_km` (lumped to the diagonal when it has none):
//!
//! ```text
//! P_ij = (w_ij + Σ_k w_ik w_kj / Σ_m w_km) / (dir_i + Σ_strong w_ik − Σ_lumped w_ik)
//! ```
//!
//!   whose row sum is `1 − dir_i / den` exactly, so constants are interpolated exactly away
//!   from the reservoirs;
//! - Galerkin coarse operator `Pᵀ A P`, its off-diagonal entries by the triple product and
//!   its diagonal as reservoir + Σ faces, the reservoir `Pᵀ A (P 1)` computed from the known
//!   row-sum deficits `δ_i = dir_i / den` (zero away from the reservoirs), so the diagonal
//!   has no cancellation.
//!
//! # Cycle
//!
//! A cycle on `S`: one sweep of ℓ1 hybrid Gauss–Seidel before the coarse correction and one
//! reversed sweep after it. The coarse correction of `S` and of the level below it is two
//! cycles of the next level (the second from the first's result), one further down: a
//! W-cycle on the top levels, a V-cycle below ([`cycle::W_LEVELS`]). On near-threshold
//! contact gaps the plain V-cycle left CG 36–51 iterations (1025² to 4097²) and this 21–23,
//! for a cycle some 65 % dearer (0.33 s against 0.20 s at 4097², docs/flow.md). Rows lie
//! in fixed blocks of [`CHUNK`]: Gauss–Seidel inside a block, other blocks' values from
//! before the sweep, and each row's divisor enlarged by the faces it has outside its block,
//!
//! ```text
//! x_i ← x_i + (b_i − d_i x_i + Σ_j w_ij x_j) / (d_i + Σ_{j outside the block} |w_ij|),
//! ```
//!
//! so the sweep is convergent however strongly the blocks are coupled (plain hybrid
//! Gauss–Seidel, divisor `d_i`, needed 13 % more iterations than a sequential sweep; the
//! ℓ1 divisor recovers them). A cycle from 0 sweeps with each row's faces to the rows
//! before it in its block only ([`Graph::smooth_from_zero`]: the others meet zeros) and
//! takes the residual from the remaining faces ([`Graph::residual_after_zero_sweep`]), so
//! the two read each face once. Two cycles in a row are two steps of an `A`-symmetric
//! convergent iteration, so the cycle is a symmetric positive definite operator and
//! conjugate gradients apply; the coarsest level (≤ [`COARSEST`] unknowns) is solved by a
//! dense Cholesky factor. Block boundaries and every sum's order are fixed, so the bits do
//! not depend on the thread count.
//!
//! # Storage
//!
//! The finest level is never copied into compressed rows: the reduction and the operator
//! read its rows from the grid stencil through the map from cells to unknowns ([`rows`]).
//! `S` and the coarser levels store their faces and interpolation weights in single
//! precision; each diagonal is summed from the rounded faces, so a level is exactly the
//! conductance form of its rounded faces (each face changed by at most 2^-24 of itself:
//! where the faces are positive the level's energy `Σ w_ij (x_i − x_j)² + Σ dir_i x_i²`
//! changes by at most that fraction, however ill-conditioned the level) and the next level
//! is built from what is stored. Vectors, the cycle's arithmetic and CG stay in double
//! precision: the preconditioner changes a little, the answer is that of the exact fine
//! operator. Each level's reservoir part is freed once the level below it is built.

mod coarsen;
mod coarsest;
mod columns;
mod cycle;
mod galerkin;
mod interpolate;
mod reduce;
mod rows;
mod sweeps;
#[cfg(test)]
mod tests;

use std::sync::Mutex;
use std::time::Instant;

use rayon::prelude::*;

use super::assemble::Stencil;
use super::cg::{profiling, secs, CHUNK};
use crate::alloc::{zeroed_now, ZeroedAhead};
use coarsen::{split, strong, strongest};
#[cfg(test)]
use coarsen::{split_in_blocks, split_with, NEAR_CAP, SPLIT_BLOCK};
use coarsest::DenseCholesky;
use cycle::{level_cycle, Fine, SharedMut};
use galerkin::galerkin;
use interpolate::interpolation;
use reduce::Reduction;
#[cfg(test)]
use reduce::PRODUCT_BLOCK;
use rows::Rows;

/// Strength threshold θ.
const THETA: f64 = 0.25;

/// Coarsening stops at this many unknowns; the coarsest level is factored (dense).
const COARSEST: usize = 500;

/// Most levels built (a guard; each level roughly halves the unknowns).
const MAX_LEVELS: usize = 40;

/// Coarsening that keeps more than this share of the unknowns stops the hierarchy.
const MIN_REDUCTION: f64 = 0.9;

/// No unknown (cells without one; F unknowns on the coarse map).
const NONE: u32 = u32::MAX;

/// A symmetric operator in compressed rows, conductance form:
/// `(A x)_i = d_i x_i − Σ_j w_ij x_j`, `d_i = dir_i + Σ_j w_ij` (`w` of either sign on
/// coarse levels).
struct Graph {
    n: usize,
    ptr: Vec<usize>,
    /// Absolute columns, while the hierarchy is built (and on a level whose offsets do
    /// not fit `near`).
    col: Vec<u32>,
    /// The columns as offsets from their row ([`columns`]), once the level is complete;
    /// empty before, or when an offset does not fit.
    near: Vec<i16>,
    /// Faces in single precision (`d` is summed from the rounded faces: the level is the
    /// conductance form of its rounded faces exactly).
    w: Vec<f32>,
    dir: Vec<f64>,
    d: Vec<f64>,
    /// `Σ |w_ij|` over the faces of row `i` to rows outside its block of [`CHUNK`]: the
    /// sweeps' ℓ1 divisor is `d_i + out_i`, the same in both directions.
    out: Vec<f64>,
}

/// Interpolation from one level to the next, by rows (`p`) and by columns (`pt`).
struct Interp {
    ptr: Vec<usize>,
    col: Vec<u32>,
    /// Weights in single precision.
    val: Vec<f32>,
    tptr: Vec<usize>,
    trow: Vec<u32>,
    tval: Vec<f32>,
}

/// Work vectors of one level.
struct Buffers {
    x: Vec<f64>,
    b: Vec<f64>,
    /// Residual, and the sweeps' scratch.
    r: Vec<f64>,
}

/// The multigrid hierarchy (one cycle per application).
pub struct Multigrid {
    fine: Stencil,
    /// Grid cell of each fine unknown.
    cells: Vec<u32>,
    /// Fine unknown of each grid cell ([`NONE`] without one).
    index: Vec<u32>,
    /// Entries off the diagonal of the finest level.
    fine_entries: usize,
    /// The finest level's red unknowns eliminated exactly; `levels[0]` is then their Schur
    /// complement `S` ([`reduce`]). `None` when the finest level is the coarsest.
    reduction: Option<Reduction>,
    levels: Vec<Graph>,
    /// `interps[l]`: `levels[l]` → `levels[l + 1]`.
    interps: Vec<Interp>,
    bufs: Mutex<Vec<Buffers>>,
    coarse: DenseCholesky,
}

/// Bytes of the hierarchy for `unknowns` fine unknowns, its setup's transient vectors
/// included. Built, [`Multigrid::bytes`] is about 106 bytes per unknown on random fields with
/// a third of the cells closed (`multigrid_memory_estimate_is_honest` in the tests): the red
/// half of the finest level eliminated, its Schur complement and the levels below in
/// single-precision faces and weights. Measured on a 4097² contact gap (docs/flow.md): the
/// resident set grows by about 90 bytes per unknown from the start to the end of the setup.
pub fn memory_estimate(unknowns: usize) -> u64 {
    unknowns as u64 * 150
}

impl Graph {
    /// The level with faces `w` in compressed rows (`ptr`, `col`) and reservoir parts `dir`,
    /// each diagonal summed from the stored (rounded) faces: the level is the conductance form
    /// of its rounded faces exactly.
    fn from_faces(ptr: Vec<usize>, col: Vec<u32>, w: Vec<f32>, dir: Vec<f64>) -> Self {
        let n = dir.len();
        check_rows(&ptr, &col, n, n);
        assert_eq!(w.len(), col.len(), "a weight per column");
        let d: Vec<f64> = (0..n)
            .into_par_iter()
            .with_min_len(CHUNK)
            .map(|i| {
                let row = &w[ptr[i]..ptr[i + 1]];
                let s = dir[i] + row.iter().map(|&v| f64::from(v)).sum::<f64>();
                // A positive definite operator has a positive diagonal; guard round-off.
                if s > 0.0 {
                    s
                } else {
                    row.iter().map(|&v| f64::from(v).abs()).sum::<f64>() + dir[i]
                }
            })
            .collect();
        let out: Vec<f64> = (0..n)
            .into_par_iter()
            .with_min_len(CHUNK)
            .map(|i| {
                let blk = i / CHUNK;
                let (i0, i1) = (blk * CHUNK, ((blk + 1) * CHUNK).min(n));
                (ptr[i]..ptr[i + 1])
                    .filter(|&p| (col[p] as usize) < i0 || (col[p] as usize) >= i1)
                    .map(|p| f64::from(w[p]).abs())
                    .sum()
            })
            .collect();
        Graph {
            n,
            ptr,
            col,
            near: Vec::new(),
            w,
            dir,
            d,
            out,
        }
    }

    /// Entries off the diagonal.
    fn entries(&self) -> usize {
        self.w.len()
    }

    /// Stores the columns as offsets from their rows where they all fit 16 bits (the level
    /// complete: only the cycle reads it from here on).
    fn compress_columns(&mut self) {
        if !self.near.is_empty() || self.col.is_empty() {
            return;
        }
        if let Some(near) = columns::offsets(&self.ptr, &self.col) {
            self.near = near;
            self.col = Vec::new();
        }
    }

    /// Column of entry `p` of row `i` (either storage).
    #[inline(always)]
    fn column(&self, p: usize, i: usize) -> usize {
        if self.near.is_empty() {
            self.col[p] as usize
        } else {
            columns::from_offset(i, self.near[p])
        }
    }

    /// A level of `n` unknowns without stored rows (the finest, applied from the stencil).
    fn sized(n: usize) -> Self {
        Graph {
            n,
            ptr: Vec::new(),
            col: Vec::new(),
            near: Vec::new(),
            w: Vec::new(),
            dir: Vec::new(),
            d: Vec::new(),
            out: Vec::new(),
        }
    }
}

/// Checks compressed rows once, where they are built, for the loops that then index them
/// without bounds checks: `rows + 1` pointers from 0 to the entry count, never decreasing,
/// and every column below `cols`.
fn check_rows(ptr: &[usize], col: &[u32], rows: usize, cols: usize) {
    assert_eq!(
        ptr.len(),
        rows + 1,
        "a pointer per row and one past the last"
    );
    assert_eq!(ptr[0], 0, "rows start at the first entry");
    assert_eq!(ptr[rows], col.len(), "rows end at the last entry");
    assert!(
        ptr.windows(2).all(|p| p[0] <= p[1]),
        "row pointers never decrease"
    );
    assert!(
        col.par_iter().all(|&c| (c as usize) < cols),
        "columns within the level"
    );
}

/// The cell of each unknown (the active cells in grid order) and the unknown of each cell.
fn unknowns(st: &Stencil) -> (Vec<u32>, Vec<u32>) {
    let n = st.ny * st.nx;
    let mut index = vec![NONE; n];
    let mut cells = Vec::new();
    for (k, slot) in index.iter_mut().enumerate() {
        if st.active[k] {
            *slot = cells.len() as u32;
            cells.push(k as u32);
        }
    }
    (cells, index)
}

/// One coarsening step below `g`: the interpolation and the coarse operator; `None` when
/// the splitting keeps no unknown or more than [`MIN_REDUCTION`] of them.
fn coarsen(g: &impl Rows) -> Option<(Interp, Graph)> {
    let n = g.n();
    let t0 = Instant::now();
    let wmax = strongest(g);
    let t1 = Instant::now();
    let (cidx, nc) = split(g, &wmax);
    let t2 = Instant::now();
    if nc == 0 || nc as f64 > MIN_REDUCTION * n as f64 {
        return None;
    }
    let (ip, delta) = interpolation(g, &wmax, &cidx, nc);
    drop((cidx, wmax));
    let t3 = Instant::now();
    let c = galerkin(g, &ip, &delta, nc);
    if profiling() {
        eprintln!(
            "[flow profile] level of {n} unknowns -> {nc}: strength {:.3} s, splitting {:.3} s, \
             interpolation {:.3} s, Galerkin {:.3} s ({} entries)",
            (t1 - t0).as_secs_f64(),
            (t2 - t1).as_secs_f64(),
            (t3 - t2).as_secs_f64(),
            secs(t3),
            c.col.len()
        );
    }
    Some((ip, c))
}

/// A block of consecutive rows built on its own: row lengths, columns, values, and one
/// `f64` per row (a level's reservoir parts, an interpolation's row-sum deficits).
type RowBlock = (Vec<usize>, Vec<u32>, Vec<f32>, Vec<f64>);

/// Row blocks concatenated in order into compressed rows `(ptr, col, val)` and the per-row
/// vector, each block copied into its place in parallel.
fn concat(blocks: Vec<RowBlock>) -> (Vec<usize>, Vec<u32>, Vec<f32>, Vec<f64>) {
    let rows: usize = blocks.iter().map(|b| b.0.len()).sum();
    let nnz: usize = blocks.iter().map(|b| b.1.len()).sum();
    let mut ptr = vec![0usize; rows + 1];
    let mut col = vec![0u32; nnz];
    let mut val = vec![0.0f32; nnz];
    let mut side = vec![0.0f64; rows];
    let mut parts = Vec::with_capacity(blocks.len());
    let (mut p_rest, mut c_rest, mut v_rest, mut s_rest) =
        (&mut ptr[1..], &mut col[..], &mut val[..], &mut side[..]);
    let mut start = 0;
    for b in &blocks {
        let (p, pr) = std::mem::take(&mut p_rest).split_at_mut(b.0.len());
        let (c, cr) = std::mem::take(&mut c_rest).split_at_mut(b.1.len());
        let (v, vr) = std::mem::take(&mut v_rest).split_at_mut(b.2.len());
        let (r, rr) = std::mem::take(&mut s_rest).split_at_mut(b.3.len());
        (p_rest, c_rest, v_rest, s_rest) = (pr, cr, vr, rr);
        parts.push((p, c, v, r, start));
        start += b.1.len();
    }
    parts
        .into_par_iter()
        .zip(blocks.par_iter())
        .for_each(|((p, c, v, r, start), b)| {
            c.copy_from_slice(&b.1);
            v.copy_from_slice(&b.2);
            r.copy_from_slice(&b.3);
            let mut end = start;
            for (e, &len) in p.iter_mut().zip(&b.0) {
                end += len;
                *e = end;
            }
        });
    (ptr, col, val, side)
}

impl Multigrid {
    /// Builds the hierarchy below the fine operator `fine` (moved in). The first coarse
    /// level is built from the stencil's rows directly; each level's reservoir part is
    /// freed once the level below it is built.
    pub fn new(fine: Stencil) -> Self {
        Self::new_ahead(fine, |_, _| Vec::new()).0
    }

    /// [`Multigrid::new`], with the solve's vectors of lengths `lens(unknowns, unknowns of
    /// S)` made ahead ([`ZeroedAhead`]) while the level below `S` is split: that splitting's
    /// first pass is sequential and leaves a core idle. Not earlier: the setup's peak, the
    /// Galerkin product from `S`, would then carry them. Nothing is made ahead without `S`
    /// or a level below it to split.
    pub fn new_ahead(
        fine: Stencil,
        lens: impl FnOnce(usize, usize) -> Vec<usize>,
    ) -> (Self, ZeroedAhead) {
        let t_setup = Instant::now();
        let (cells, index) = unknowns(&fine);
        let top = Fine {
            st: &fine,
            cells: &cells,
            index: &index,
        };
        let n0 = cells.len();
        let fine_entries: usize = (0..n0)
            .into_par_iter()
            .with_min_len(CHUNK)
            .map(|i| top.row(i).count())
            .sum();
        let mut levels = Vec::new();
        let mut interps = Vec::new();
        let mut reduction = None;
        if n0 > COARSEST {
            let t = Instant::now();
            let mut red = Reduction::new(&top);
            if red.len() > 0 {
                let s = red.schur(&top);
                if profiling() {
                    eprintln!(
                        "[flow profile] red unknowns of {n0} eliminated -> {}: Schur complement \
                         {:.3} s ({} entries)",
                        s.n,
                        secs(t),
                        s.col.len()
                    );
                }
                levels.push(s);
                reduction = Some(red);
            }
        }
        if levels.is_empty() {
            // The finest level is the coarsest: factored from the stencil's rows (exact).
            levels.push(Graph::sized(n0));
        }
        let mut lens = Some(lens);
        let mut ahead = ZeroedAhead::none();
        loop {
            let g = levels.last().expect("non-empty");
            if g.n <= COARSEST || levels.len() >= MAX_LEVELS {
                break;
            }
            if levels.len() == 2 && reduction.is_some() {
                if let Some(lens) = lens.take() {
                    ahead = ZeroedAhead::start(lens(n0, levels[0].n));
                }
            }
            let Some((ip, c)) = coarsen(g) else { break };
            let done = levels.last_mut().expect("non-empty");
            done.dir = Vec::new();
            done.compress_columns();
            interps.push(ip);
            levels.push(c);
        }
        // Without the reduction the finest level is the coarsest, solved by the dense
        // factor on the caller's vectors: no buffers. With it, `S`'s right-hand side and
        // solution are the caller's vectors too ([`Multigrid::cycle`]): only its scratch.
        let bufs = levels
            .iter()
            .enumerate()
            .map(|(l, g)| {
                let n = if reduction.is_some() { g.n } else { 0 };
                let own = if l == 0 { 0 } else { n };
                Buffers {
                    x: zeroed_now(own),
                    b: zeroed_now(own),
                    r: zeroed_now(n),
                }
            })
            .collect();
        let coarse = if reduction.is_none() {
            DenseCholesky::new(&top)
        } else {
            DenseCholesky::new(levels.last().expect("non-empty"))
        };
        for g in levels.iter_mut() {
            g.dir = Vec::new();
            g.compress_columns();
        }
        if profiling() {
            eprintln!(
                "[flow profile] multigrid setup {:.3} s, {} levels",
                secs(t_setup),
                levels.len()
            );
        }
        let mg = Multigrid {
            fine,
            cells,
            index,
            fine_entries,
            reduction,
            levels,
            interps,
            bufs: Mutex::new(bufs),
            coarse,
        };
        (mg, ahead)
    }

    /// The finest operator.
    pub fn fine(&self) -> &Stencil {
        &self.fine
    }

    /// Unknowns per level, the finest first.
    pub fn sizes(&self) -> Vec<usize> {
        let below = self.reduction.is_some().then_some(&self.levels[..]);
        std::iter::once(self.cells.len())
            .chain(below.into_iter().flatten().map(|g| g.n))
            .collect()
    }

    /// Bytes held by the hierarchy (the fine stencil not counted).
    pub fn bytes(&self) -> u64 {
        // Per entry: column 4 + single-precision value 4 (interpolation: both by rows and by
        // columns); per row: pointer, diagonal, reservoir part, ℓ1 term; and the work
        // vectors (one on the finest level, three below).
        let g = |g: &Graph| {
            8 * (g.ptr.len() + g.dir.len() + g.d.len() + g.out.len())
                + 4 * (g.w.len() + g.col.len())
                + 2 * g.near.len()
        };
        let p = |p: &Interp| 8 * (p.ptr.len() + p.tptr.len()) + 16 * p.col.len();
        let work: usize = {
            let bufs = self.bufs.lock().unwrap_or_else(|e| e.into_inner());
            bufs.iter()
                .map(|b| 8 * (b.x.len() + b.b.len() + b.r.len()))
                .sum()
        };
        (4 * (self.cells.len() + self.index.len())
            + self.reduction.as_ref().map_or(0, Reduction::bytes)
            + work
            + self.levels.iter().map(g).sum::<usize>()
            + self.interps.iter().map(p).sum::<usize>()) as u64
    }

    /// Operator complexity: entries (diagonal included) of all levels over the finest's.
    pub fn complexity(&self) -> f64 {
        let e = |g: &Graph| (g.entries() + g.n) as f64;
        let fine = (self.fine_entries + self.cells.len()) as f64;
        let below: f64 = match self.reduction {
            Some(_) => self.levels.iter().map(e).sum(),
            None => 0.0,
        };
        (fine + below) / fine
    }

    /// The finest operator and each cell's unknown (`u32::MAX` for none), the hierarchy
    /// dropped.
    pub fn into_fine_and_index(self) -> (Stencil, Vec<u32>) {
        (self.fine, self.index)
    }

    /// Number of levels, the finest included.
    pub fn n_levels(&self) -> usize {
        self.sizes().len()
    }

    /// `z = M⁻¹ r` on the grid's cells (0 on cells without unknowns): one cycle from 0.
    #[cfg(test)]
    pub fn apply(&self, r: &[f64], z: &mut [f64]) {
        let mut zu = vec![0.0; self.n_unknowns()];
        self.precondition(&self.gather(r), &mut zu);
        z.copy_from_slice(&self.scatter(&zu));
    }

    /// Fine unknowns.
    pub fn n_unknowns(&self) -> usize {
        self.cells.len()
    }

    /// The entries of the cell vector `v` at the unknowns' cells (one per unknown).
    pub fn gather(&self, v: &[f64]) -> Vec<f64> {
        self.cells
            .par_iter()
            .with_min_len(CHUNK)
            .map(|&k| v[k as usize])
            .collect()
    }

    /// [`Multigrid::gather`] of a cell vector that is 0 outside the cells
    /// `first..first + row.len()` (a reservoir's row), given by those cells' values `row`.
    pub fn gather_row(&self, row: &[f64], first: usize) -> Vec<f64> {
        let mut out = zeroed_now(self.cells.len());
        for (i, v) in self.row_entries(row, first) {
            out[i as usize] = v;
        }
        out
    }

    /// The non-zero entries `(unknown, value)` of [`Multigrid::gather_row`], in the
    /// unknowns' order.
    pub fn row_entries(&self, row: &[f64], first: usize) -> Vec<(u32, f64)> {
        row.iter()
            .enumerate()
            .map(|(t, &v)| (self.index[first + t], v))
            .filter(|&(i, v)| i != NONE && v != 0.0)
            .collect()
    }

    /// The cell vector with `x` (one entry per unknown) on the unknowns' cells, 0 elsewhere.
    pub fn scatter(&self, x: &[f64]) -> Vec<f64> {
        let mut z = vec![0.0; self.index.len()];
        let zp = SharedMut(z.as_mut_ptr());
        self.cells
            .par_chunks(CHUNK)
            .zip(x.par_chunks(CHUNK))
            .for_each(move |(cc, xc)| {
                let zp = zp;
                for (&k, &v) in cc.iter().zip(xc) {
                    // SAFETY: cells are distinct indices below the grid size, so no two
                    // tasks write the same element.
                    unsafe { *zp.0.add(k as usize) = v };
                }
            });
        z
    }

    /// Diagonal `d_i` of fine unknown `i`.
    pub fn diagonal(&self, i: usize) -> f64 {
        self.fine.d[self.cells[i] as usize]
    }

    fn top(&self) -> Fine<'_> {
        Fine {
            st: &self.fine,
            cells: &self.cells,
            index: &self.index,
        }
    }

    /// `y = A x` on the unknowns.
    pub fn operator(&self, x: &[f64], y: &mut [f64]) {
        let top = self.top();
        top.product(x, y);
    }

    /// `r = b − A Σ parts` on the unknowns (`x`, or `hi + lo`), each row summed in
    /// double-double arithmetic ([`Stencil::residual_compensated`]).
    pub fn residual_exact(&self, parts: &[&[f64]], b: &[f64], r: &mut [f64]) {
        self.fine
            .residual_compensated_on(&self.cells, &self.index, parts, b, r, CHUNK);
    }

    /// `z = M⁻¹ r` on the unknowns: the red unknowns eliminated, one cycle from 0 on
    /// their Schur complement ([`reduce`]); the dense factor when the finest level is the
    /// coarsest.
    pub fn precondition(&self, r: &[f64], z: &mut [f64]) {
        let Some(red) = &self.reduction else {
            self.coarse.solve(r, z);
            return;
        };
        let top = self.top();
        let mut b = vec![0.0; red.len()];
        let mut x = vec![0.0; red.len()];
        red.restrict(&top, r, &mut b);
        self.cycle(&b, &mut x);
        red.extend(&top, r, &x, z);
    }

    /// Unknowns of the Schur complement `S` on which the refinement's corrections are solved
    /// ([`reduce`]); `None` when the finest level is the coarsest (no reduction).
    pub fn reduced_len(&self) -> Option<usize> {
        self.reduction.as_ref().map(Reduction::len)
    }

    /// `s = r_B + W_BR D_R⁻¹ r_R`: the right-hand side on `S` of the fine system with
    /// right-hand side `r` (`A d = r` ⇔ `S d_B = s`, `d_R = D_R⁻¹ (r_R + W_RB d_B)`).
    pub fn reduce(&self, r: &[f64], s: &mut [f64]) {
        if let Some(red) = &self.reduction {
            red.restrict(&self.top(), r, s);
        }
    }

    /// `d_B = d_s`, `d_R = D_R⁻¹ (r_R + W_RB d_s)`: the fine solution of `A d = r` from the
    /// solution `d_s` on `S`.
    pub fn extend(&self, r: &[f64], ds: &[f64], d: &mut [f64]) {
        if let Some(red) = &self.reduction {
            red.extend(&self.top(), r, ds, d);
        }
    }

    /// `y = S v` in double precision from the stencil ([`Reduction::schur_product`]).
    pub fn reduced_product(&self, v: &[f64], y: &mut [f64]) {
        if let Some(red) = &self.reduction {
            red.schur_product(&self.top(), v, y);
        }
    }

    /// `y ≈ S v` for the refinement's inner solves: from the stored `S` when every one of
    /// its faces is a normal single-precision number (each then within 2^-24 of the exact
    /// face; vectors and arithmetic in double), 2.7 times faster than
    /// [`Multigrid::reduced_product`] on the 4097² contact gap (docs/flow.md); otherwise
    /// that exact product.
    pub fn inner_reduced_product(&self, v: &[f64], y: &mut [f64]) {
        match &self.reduction {
            Some(red) if red.faithful() => self.levels[0].product(v, y),
            _ => self.reduced_product(v, y),
        }
    }

    /// `z = M_S⁻¹ s`: one cycle from 0 on `S` (the multigrid below the reduction).
    pub fn cycle(&self, s: &[f64], z: &mut [f64]) {
        let mut bufs = self.bufs.lock().unwrap_or_else(|e| e.into_inner());
        level_cycle(
            &self.levels,
            &self.interps,
            s,
            z,
            &mut bufs,
            &self.coarse,
            0,
            false,
        );
    }
}
