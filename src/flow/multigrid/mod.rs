//! Classical (Ruge–Stüben) algebraic multigrid preconditioner for the Reynolds operator.
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
//! On the conductance form `(A x)_i = d_i x_i − Σ_j w_ij x_j`, `d_i = dir_i + Σ_j w_ij`:
//!
//! - strength: `j` strongly influences `i` when `w_ij ≥ θ max_k w_ik` (`θ` = [`THETA`];
//!   only `w_ij > 0` counts);
//! - C/F splitting: the first pass of Ruge and Stüben, sequential in unknown order (so
//!   deterministic): repeatedly the undecided unknown on which most undecided ones depend
//!   strongly becomes C and its strong dependents F; then a second pass in unknown order:
//!   a strong F neighbour `k` of an F unknown `i` joined to none of the strong C neighbours
//!   of `i` becomes C. Without it the interpolation lumps such `w_ik` and the cycle
//!   contracts the error by only about 0.5–0.6 per CG step on near-threshold gaps; with it
//!   about 0.15–0.4 (the iterations to the default tolerance drop from 73–78 to 42–43 at
//!   1025² and 2049², docs/flow.md), for some 10 % more operator complexity;
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
//! A V-cycle: one sweep of ℓ1 hybrid Gauss–Seidel before the coarse correction and one
//! reversed sweep after it. Rows lie in fixed blocks of [`CHUNK`]: Gauss–Seidel inside a
//! block, other blocks' values from before the sweep, and each row's divisor enlarged by the
//! faces it has outside its block,
//!
//! ```text
//! x_i ← x_i + (b_i − d_i x_i + Σ_j w_ij x_j) / (d_i + Σ_{j outside the block} |w_ij|),
//! ```
//!
//! so the sweep is convergent however strongly the blocks are coupled (plain hybrid
//! Gauss–Seidel, divisor `d_i`, needed 13 % more iterations than a sequential sweep; the
//! ℓ1 divisor recovers them). The cycle is a symmetric positive definite operator and
//! conjugate gradients apply; the coarsest level (≤ [`COARSEST`] unknowns) is solved by a
//! dense Cholesky factor. Block boundaries and every sum's order are fixed, so the bits do
//! not depend on the thread count.
//!
//! The finest level is built in compressed rows like the others (the setup reads rows by
//! index), then freed: the cycle applies it from the grid stencil through the map from
//! cells to unknowns (4 bytes per cell instead of some 56 per unknown).

mod coarsen;
mod coarsest;
mod cycle;
mod galerkin;
mod interpolate;
#[cfg(test)]
mod tests;

use std::sync::Mutex;

use rayon::prelude::*;

use super::assemble::Stencil;
use super::cg::CHUNK;
use coarsen::{split, strong, strongest};
use coarsest::DenseCholesky;
use cycle::{vcycle, Fine, SharedMut};
use galerkin::galerkin;
use interpolate::interpolation;

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
    col: Vec<u32>,
    w: Vec<f64>,
    dir: Vec<f64>,
    d: Vec<f64>,
}

/// Interpolation from one level to the next, by rows (`p`) and by columns (`pt`).
struct Interp {
    ptr: Vec<usize>,
    col: Vec<u32>,
    val: Vec<f64>,
    tptr: Vec<usize>,
    trow: Vec<u32>,
    tval: Vec<f64>,
}

/// Work vectors of one level.
struct Buffers {
    x: Vec<f64>,
    b: Vec<f64>,
    r: Vec<f64>,
    old: Vec<f64>,
}

/// The multigrid hierarchy (one V-cycle per application).
pub struct Multigrid {
    fine: Stencil,
    /// Grid cell of each fine unknown.
    cells: Vec<u32>,
    /// Fine unknown of each grid cell ([`NONE`] without one).
    index: Vec<u32>,
    /// Entries off the diagonal of the finest level.
    fine_entries: usize,
    levels: Vec<Graph>,
    /// `interps[l]`: `levels[l]` → `levels[l + 1]`.
    interps: Vec<Interp>,
    bufs: Mutex<Vec<Buffers>>,
    coarse: DenseCholesky,
}

/// Bytes of the hierarchy for `unknowns` fine unknowns: while it is built (the finest level
/// still in compressed rows) [`Multigrid::bytes`] measured 321 to 328 bytes per unknown on
/// contact gaps from 1025² to 4097² (operator complexity 2.25 to 2.36), plus the setup's
/// transient vectors; about 70 fewer once built.
pub fn memory_estimate(unknowns: usize) -> u64 {
    unknowns as u64 * 360
}

impl Graph {
    /// `r = b − A x`.
    fn residual(&self, x: &[f64], b: &[f64], r: &mut [f64]) {
        r.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, rc)| {
            let i0 = blk * CHUNK;
            for (t, rv) in rc.iter_mut().enumerate() {
                let i = i0 + t;
                let mut v = b[i] - self.d[i] * x[i];
                for p in self.ptr[i]..self.ptr[i + 1] {
                    v += self.w[p] * x[self.col[p] as usize];
                }
                *rv = v;
            }
        });
    }

    /// ℓ1 hybrid Gauss–Seidel sweep (module docs); `old` is scratch of size `n`.
    fn smooth(&self, b: &[f64], x: &mut [f64], old: &mut [f64], reverse: bool) {
        old.copy_from_slice(x);
        let old = &*old;
        x.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, xc)| {
            let i0 = blk * CHUNK;
            let i1 = i0 + xc.len();
            let mut update = |t: usize| {
                let i = i0 + t;
                let mut v = b[i] - self.d[i] * xc[t];
                let mut out = 0.0;
                for p in self.ptr[i]..self.ptr[i + 1] {
                    let j = self.col[p] as usize;
                    let xj = if j >= i0 && j < i1 {
                        xc[j - i0]
                    } else {
                        out += self.w[p].abs();
                        old[j]
                    };
                    v += self.w[p] * xj;
                }
                xc[t] += v / (self.d[i] + out);
            };
            if reverse {
                for t in (0..i1 - i0).rev() {
                    update(t);
                }
            } else {
                for t in 0..i1 - i0 {
                    update(t);
                }
            }
        });
    }

    /// Entries off the diagonal.
    fn entries(&self) -> usize {
        self.col.len()
    }

    /// `w_ij` (0 when `j` is not a neighbour of `i`).
    #[inline]
    fn weight(&self, i: usize, j: u32) -> f64 {
        let row = self.ptr[i]..self.ptr[i + 1];
        match self.col[row.clone()].binary_search(&j) {
            Ok(p) => self.w[row.start + p],
            Err(_) => 0.0,
        }
    }
}

/// The fine operator on its active cells: the graph, the cell of each unknown and the
/// unknown of each cell.
fn fine_graph(st: &Stencil) -> (Graph, Vec<u32>, Vec<u32>) {
    let n = st.ny * st.nx;
    let mut index = vec![NONE; n];
    let mut cells = Vec::new();
    for (k, slot) in index.iter_mut().enumerate() {
        if st.active[k] {
            *slot = cells.len() as u32;
            cells.push(k as u32);
        }
    }
    let m = cells.len();
    type Block = (Vec<usize>, Vec<u32>, Vec<f64>);
    let blocks: Vec<Block> = cells
        .par_chunks(CHUNK)
        .map(|cs| {
            let mut len = Vec::with_capacity(cs.len());
            let mut col = Vec::with_capacity(4 * cs.len());
            let mut w = Vec::with_capacity(4 * cs.len());
            for &k in cs {
                let mut row: [(u32, f64); 4] = [(NONE, 0.0); 4];
                let mut nb = 0;
                st.for_each_face(k as usize, |l, c| {
                    let t = index[l];
                    if t == NONE {
                        return;
                    }
                    // The two faces of a 2-wide periodic row join the same pair: add them.
                    if let Some(e) = row[..nb].iter_mut().find(|e| e.0 == t) {
                        e.1 += c;
                    } else {
                        row[nb] = (t, c);
                        nb += 1;
                    }
                });
                row[..nb].sort_unstable_by_key(|e| e.0);
                len.push(nb);
                for &(t, c) in &row[..nb] {
                    col.push(t);
                    w.push(c);
                }
            }
            (len, col, w)
        })
        .collect();
    let (ptr, col, w) = concat(blocks);
    let dir: Vec<f64> = cells.par_iter().map(|&k| st.dir[k as usize]).collect();
    let d: Vec<f64> = cells.par_iter().map(|&k| st.d[k as usize]).collect();
    (
        Graph {
            n: m,
            ptr,
            col,
            w,
            dir,
            d,
        },
        cells,
        index,
    )
}

/// Row blocks (row lengths, columns, values) concatenated in order into compressed rows.
fn concat<T: Copy>(blocks: Vec<(Vec<usize>, Vec<u32>, Vec<T>)>) -> (Vec<usize>, Vec<u32>, Vec<T>) {
    let rows: usize = blocks.iter().map(|b| b.0.len()).sum();
    let nnz: usize = blocks.iter().map(|b| b.1.len()).sum();
    let mut ptr = Vec::with_capacity(rows + 1);
    let mut col = Vec::with_capacity(nnz);
    let mut val = Vec::with_capacity(nnz);
    ptr.push(0);
    for (l, c, v) in blocks {
        for len in l {
            ptr.push(ptr.last().copied().unwrap_or(0) + len);
        }
        col.extend_from_slice(&c);
        val.extend_from_slice(&v);
    }
    (ptr, col, val)
}

impl Multigrid {
    /// Builds the hierarchy below the fine operator `fine` (moved in).
    pub fn new(fine: Stencil) -> Self {
        let (g0, cells, index) = fine_graph(&fine);
        let mut levels = vec![g0];
        let mut interps = Vec::new();
        loop {
            let g = levels.last().expect("non-empty");
            if g.n <= COARSEST || levels.len() >= MAX_LEVELS {
                break;
            }
            let wmax = strongest(g);
            let (cidx, nc) = split(g, &wmax);
            if nc == 0 || nc as f64 > MIN_REDUCTION * g.n as f64 {
                break;
            }
            let (ip, delta) = interpolation(g, &wmax, &cidx, nc);
            drop((cidx, wmax));
            let c = galerkin(g, &ip, &delta, nc);
            interps.push(ip);
            levels.push(c);
        }
        let bufs = levels
            .iter()
            .map(|g| {
                let n = g.n;
                Buffers {
                    x: vec![0.0; n],
                    b: vec![0.0; n],
                    r: vec![0.0; n],
                    old: vec![0.0; n],
                }
            })
            .collect();
        let coarse = DenseCholesky::new(levels.last().expect("non-empty"));
        // The cycle applies the finest level from the grid stencil (the same faces), and no
        // level needs its reservoir part any more: free them.
        let fine_entries = levels[0].entries();
        if levels.len() > 1 {
            let g0 = &mut levels[0];
            g0.ptr = Vec::new();
            g0.col = Vec::new();
            g0.w = Vec::new();
            g0.d = Vec::new();
        }
        for g in levels.iter_mut() {
            g.dir = Vec::new();
        }
        Multigrid {
            fine,
            cells,
            index,
            fine_entries,
            levels,
            interps,
            bufs: Mutex::new(bufs),
            coarse,
        }
    }

    /// The finest operator.
    pub fn fine(&self) -> &Stencil {
        &self.fine
    }

    /// Unknowns per level, the finest first.
    pub fn sizes(&self) -> Vec<usize> {
        self.levels.iter().map(|g| g.n).collect()
    }

    /// Bytes held by the hierarchy (the fine stencil not counted).
    pub fn bytes(&self) -> u64 {
        let g =
            |g: &Graph| 8 * (g.ptr.len() + g.dir.len() + g.d.len()) + 12 * g.col.len() + 32 * g.n;
        let p = |p: &Interp| 8 * (p.ptr.len() + p.tptr.len()) + 24 * p.col.len();
        (4 * (self.cells.len() + self.index.len())
            + self.levels.iter().map(g).sum::<usize>()
            + self.interps.iter().map(p).sum::<usize>()) as u64
    }

    /// Operator complexity: entries (diagonal included) of all levels over the finest's.
    pub fn complexity(&self) -> f64 {
        let e = |g: &Graph| (g.entries() + g.n) as f64;
        let fine = (self.fine_entries + self.levels[0].n) as f64;
        (fine + self.levels[1..].iter().map(e).sum::<f64>()) / fine
    }

    /// The finest operator, the hierarchy dropped.
    pub fn into_fine(self) -> Stencil {
        self.fine
    }

    /// Number of levels, the finest included.
    pub fn n_levels(&self) -> usize {
        self.levels.len()
    }

    /// `z = M⁻¹ r` on the grid's cells (0 on cells without unknowns): one V-cycle from 0.
    pub fn apply(&self, r: &[f64], z: &mut [f64]) {
        let mut bufs = self.bufs.lock().unwrap_or_else(|e| e.into_inner());
        let cells = &self.cells;
        {
            let b = &mut bufs[0].b;
            b.par_chunks_mut(CHUNK)
                .zip(cells.par_chunks(CHUNK))
                .for_each(|(bc, cc)| bc.iter_mut().zip(cc).for_each(|(v, &k)| *v = r[k as usize]));
        }
        let top = Fine {
            st: &self.fine,
            cells,
            index: &self.index,
        };
        vcycle(
            &self.levels,
            &self.interps,
            &mut bufs,
            &self.coarse,
            Some(&top),
        );
        z.par_iter_mut().for_each(|v| *v = 0.0);
        let x = &bufs[0].x;
        // Scatter: each unknown's cell is distinct.
        let zp = SharedMut(z.as_mut_ptr());
        cells
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
    }
}
