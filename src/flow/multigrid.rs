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

use std::sync::Mutex;

use rayon::prelude::*;

use super::assemble::Stencil;
use super::cg::CHUNK;

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

/// Largest positive face of every row.
fn strongest(g: &Graph) -> Vec<f64> {
    (0..g.n)
        .into_par_iter()
        .with_min_len(CHUNK)
        .map(|i| {
            g.w[g.ptr[i]..g.ptr[i + 1]]
                .iter()
                .fold(0.0, |m: f64, &w| m.max(w))
        })
        .collect()
}

/// Whether `w` (a face of a row whose largest face is `wmax`) is strong.
#[inline(always)]
fn strong(w: f64, wmax: f64) -> bool {
    w > 0.0 && w >= THETA * wmax
}

/// Ruge–Stüben first pass: the coarse index of every C unknown (`NONE` for F) and their
/// number.
fn split(g: &Graph, wmax: &[f64]) -> (Vec<u32>, usize) {
    let n = g.n;
    const UNDECIDED: u8 = 0;
    const C: u8 = 1;
    const F: u8 = 2;
    // λ_i: unknowns that depend strongly on i (i strongly influences j: w_ji ≥ θ max_k w_jk).
    let mut lambda: Vec<u32> = (0..n)
        .into_par_iter()
        .with_min_len(CHUNK)
        .map(|i| {
            let mut c = 0;
            for p in g.ptr[i]..g.ptr[i + 1] {
                let j = g.col[p] as usize;
                // w_ji = w_ij (symmetric).
                if strong(g.w[p], wmax[j]) {
                    c += 1;
                }
            }
            c
        })
        .collect();
    let mut state = vec![UNDECIDED; n];
    // Buckets of undecided unknowns by λ: doubly linked lists.
    let top0 = lambda.iter().copied().max().unwrap_or(0) as usize;
    let mut cap = (top0 + 1).max(16);
    let mut head = vec![NONE; cap];
    let mut next = vec![NONE; n];
    let mut prev = vec![NONE; n];
    // Insert in reverse so that each bucket lists unknowns in ascending order.
    for i in (0..n).rev() {
        let l = lambda[i] as usize;
        next[i] = head[l];
        if head[l] != NONE {
            prev[head[l] as usize] = i as u32;
        }
        head[l] = i as u32;
    }
    let unlink = |i: usize, l: usize, head: &mut [u32], next: &mut [u32], prev: &mut [u32]| {
        let (pv, nx) = (prev[i], next[i]);
        if pv != NONE {
            next[pv as usize] = nx;
        } else {
            head[l] = nx;
        }
        if nx != NONE {
            prev[nx as usize] = pv;
        }
        prev[i] = NONE;
        next[i] = NONE;
    };
    let mut top = top0;
    loop {
        while top > 0 && head[top] == NONE {
            top -= 1;
        }
        let i = head[top];
        if i == NONE {
            break;
        }
        let i = i as usize;
        unlink(i, top, &mut head, &mut next, &mut prev);
        state[i] = C;
        // Strong dependents of i become F; their strong influencers gain weight.
        for p in g.ptr[i]..g.ptr[i + 1] {
            let j = g.col[p] as usize;
            if state[j] != UNDECIDED || !strong(g.w[p], wmax[j]) {
                continue;
            }
            unlink(j, lambda[j] as usize, &mut head, &mut next, &mut prev);
            state[j] = F;
            for q in g.ptr[j]..g.ptr[j + 1] {
                let k = g.col[q] as usize;
                if state[k] != UNDECIDED || !strong(g.w[q], wmax[j]) {
                    continue;
                }
                let l = lambda[k] as usize;
                unlink(k, l, &mut head, &mut next, &mut prev);
                lambda[k] += 1;
                let l = l + 1;
                if l >= cap {
                    cap *= 2;
                    head.resize(cap, NONE);
                }
                next[k] = head[l];
                if head[l] != NONE {
                    prev[head[l] as usize] = k as u32;
                }
                head[l] = k as u32;
                top = top.max(l);
            }
        }
        // Unknowns that strongly influence i lose weight.
        for p in g.ptr[i]..g.ptr[i + 1] {
            let k = g.col[p] as usize;
            if state[k] != UNDECIDED || !strong(g.w[p], wmax[i]) {
                continue;
            }
            let l = lambda[k] as usize;
            if l == 0 {
                continue;
            }
            unlink(k, l, &mut head, &mut next, &mut prev);
            lambda[k] -= 1;
            let l = l - 1;
            next[k] = head[l];
            if head[l] != NONE {
                prev[head[l] as usize] = k as u32;
            }
            head[l] = k as u32;
        }
    }
    // Second pass, in unknown order: a strong F neighbour `k` of an F unknown `i` that is
    // joined to none of the strong C neighbours of `i` becomes C (else the interpolation to
    // `i` would have to lump `w_ik` into its diagonal).
    let mut ci: Vec<u32> = Vec::new();
    for i in 0..n {
        if state[i] != F {
            continue;
        }
        ci.clear();
        for p in g.ptr[i]..g.ptr[i + 1] {
            let j = g.col[p] as usize;
            if state[j] == C && strong(g.w[p], wmax[i]) {
                ci.push(j as u32);
            }
        }
        for p in g.ptr[i]..g.ptr[i + 1] {
            let k = g.col[p] as usize;
            if state[k] != F || !strong(g.w[p], wmax[i]) {
                continue;
            }
            if !ci.iter().any(|&m| g.weight(k, m) > 0.0) {
                state[k] = C;
                ci.push(k as u32);
            }
        }
    }
    let mut cidx = vec![NONE; n];
    let mut nc = 0u32;
    for i in 0..n {
        if state[i] == C {
            cidx[i] = nc;
            nc += 1;
        }
    }
    (cidx, nc as usize)
}

/// Classical interpolation (module docs) and the row-sum deficits `δ_i = dir_i / den`.
fn interpolation(g: &Graph, wmax: &[f64], cidx: &[u32], nc: usize) -> (Interp, Vec<f64>) {
    let n = g.n;
    type Block = (Vec<usize>, Vec<u32>, Vec<f64>, Vec<f64>);
    let blocks: Vec<Block> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|blk| {
            let rows = blk * CHUNK..((blk + 1) * CHUNK).min(n);
            let mut len = Vec::with_capacity(rows.len());
            let mut col = Vec::new();
            let mut val = Vec::new();
            let mut delta = Vec::with_capacity(rows.len());
            let mut row: Vec<(u32, f64)> = Vec::new();
            for i in rows {
                if cidx[i] != NONE {
                    len.push(1);
                    col.push(cidx[i]);
                    val.push(1.0);
                    delta.push(0.0);
                    continue;
                }
                row.clear();
                let mut den = g.dir[i];
                // Strong C neighbours first (their fine index and w_ij).
                for p in g.ptr[i]..g.ptr[i + 1] {
                    let j = g.col[p] as usize;
                    if strong(g.w[p], wmax[i]) && cidx[j] != NONE {
                        row.push((j as u32, g.w[p]));
                        den += g.w[p];
                    }
                }
                if row.is_empty() {
                    len.push(0);
                    delta.push(1.0);
                    continue;
                }
                // Strong F neighbours: distributed over the strong C neighbours of i.
                for p in g.ptr[i]..g.ptr[i + 1] {
                    let k = g.col[p] as usize;
                    let wik = g.w[p];
                    if !strong(wik, wmax[i]) || cidx[k] != NONE {
                        continue;
                    }
                    let mut sum = 0.0;
                    for e in row.iter() {
                        let wkm = g.weight(k, e.0);
                        if wkm > 0.0 {
                            sum += wkm;
                        }
                    }
                    if sum > 0.0 {
                        den += wik;
                        let share = wik / sum;
                        for e in row.iter_mut() {
                            let wkm = g.weight(k, e.0);
                            if wkm > 0.0 {
                                e.1 += share * wkm;
                            }
                        }
                    }
                }
                len.push(row.len());
                for &(j, v) in row.iter() {
                    col.push(cidx[j as usize]);
                    val.push(v / den);
                }
                delta.push(g.dir[i] / den);
            }
            (len, col, val, delta)
        })
        .collect();
    let mut deltas = Vec::with_capacity(n);
    let blocks: Vec<(Vec<usize>, Vec<u32>, Vec<f64>)> = blocks
        .into_iter()
        .map(|(l, c, v, d)| {
            deltas.extend_from_slice(&d);
            (l, c, v)
        })
        .collect();
    let (ptr, col, val) = concat(blocks);
    // Transpose by counting (rows of each coarse column ascending).
    let mut tptr = vec![0usize; nc + 1];
    for &c in &col {
        tptr[c as usize + 1] += 1;
    }
    for c in 0..nc {
        tptr[c + 1] += tptr[c];
    }
    let mut fill = tptr[..nc].to_vec();
    let mut trow = vec![0u32; col.len()];
    let mut tval = vec![0.0; col.len()];
    for i in 0..n {
        for p in ptr[i]..ptr[i + 1] {
            let c = col[p] as usize;
            trow[fill[c]] = i as u32;
            tval[fill[c]] = val[p];
            fill[c] += 1;
        }
    }
    (
        Interp {
            ptr,
            col,
            val,
            tptr,
            trow,
            tval,
        },
        deltas,
    )
}

/// Galerkin coarse operator `Pᵀ A P` in conductance form (module docs).
fn galerkin(g: &Graph, ip: &Interp, delta: &[f64], nc: usize) -> Graph {
    // (A (P 1))_i = dir_i (1 − δ_i) − Σ_k w_ik (δ_i − δ_k): exactly 0 away from reservoirs.
    let a1: Vec<f64> = (0..g.n)
        .into_par_iter()
        .with_min_len(CHUNK)
        .map(|i| {
            let mut v = g.dir[i] * (1.0 - delta[i]);
            for p in g.ptr[i]..g.ptr[i + 1] {
                let k = g.col[p] as usize;
                if delta[i] != delta[k] {
                    v -= g.w[p] * (delta[i] - delta[k]);
                }
            }
            v
        })
        .collect();
    type Block = (Vec<usize>, Vec<u32>, Vec<f64>, Vec<f64>);
    // Each task's row accumulator: `slot[c]` is the position of coarse column `c` in the
    // row being built (NONE when absent); the row's entries keep the order of first touch,
    // so every sum is taken in an order fixed by the matrices, not by the threads.
    let nblocks = nc.div_ceil(CHUNK);
    // Few splits: each allocates an accumulator of the coarse size (rows are independent,
    // so the split does not change any value).
    let per = nblocks.div_ceil(4 * rayon::current_num_threads()).max(1);
    let blocks: Vec<Block> = (0..nblocks)
        .into_par_iter()
        .with_min_len(per)
        .map_init(
            || vec![NONE; nc],
            |slot, blk| {
                let rows = blk * CHUNK..((blk + 1) * CHUNK).min(nc);
                let mut len = Vec::with_capacity(rows.len());
                let mut col = Vec::new();
                let mut w = Vec::new();
                let mut dir = Vec::with_capacity(rows.len());
                let mut acc: Vec<(u32, f64)> = Vec::new();
                for ci in rows {
                    acc.clear();
                    let mut res = 0.0;
                    let mut add = |acc: &mut Vec<(u32, f64)>, c: u32, v: f64| {
                        let s = &mut slot[c as usize];
                        if *s == NONE {
                            *s = acc.len() as u32;
                            acc.push((c, v));
                        } else {
                            acc[*s as usize].1 += v;
                        }
                    };
                    for t in ip.tptr[ci]..ip.tptr[ci + 1] {
                        let i = ip.trow[t] as usize;
                        let pi = ip.tval[t];
                        res += pi * a1[i];
                        // (A P)(i, J) = d_i P_iJ − Σ_k w_ik P_kJ, for J ≠ ci.
                        for p in ip.ptr[i]..ip.ptr[i + 1] {
                            let cj = ip.col[p];
                            if cj as usize != ci {
                                add(&mut acc, cj, pi * g.d[i] * ip.val[p]);
                            }
                        }
                        for q in g.ptr[i]..g.ptr[i + 1] {
                            let k = g.col[q] as usize;
                            let f = pi * g.w[q];
                            for p in ip.ptr[k]..ip.ptr[k + 1] {
                                let cj = ip.col[p];
                                if cj as usize != ci {
                                    add(&mut acc, cj, -f * ip.val[p]);
                                }
                            }
                        }
                    }
                    for e in acc.iter() {
                        slot[e.0 as usize] = NONE;
                    }
                    acc.retain(|e| e.1 != 0.0);
                    acc.sort_unstable_by_key(|e| e.0);
                    len.push(acc.len());
                    for &(c, v) in acc.iter() {
                        col.push(c);
                        w.push(-v);
                    }
                    dir.push(res.max(0.0));
                }
                (len, col, w, dir)
            },
        )
        .collect();
    let mut dir = Vec::with_capacity(nc);
    let blocks: Vec<(Vec<usize>, Vec<u32>, Vec<f64>)> = blocks
        .into_iter()
        .map(|(l, c, v, r)| {
            dir.extend_from_slice(&r);
            (l, c, v)
        })
        .collect();
    let (ptr, col, w) = concat(blocks);
    let d: Vec<f64> = (0..nc)
        .into_par_iter()
        .with_min_len(CHUNK)
        .map(|i| {
            let s = dir[i] + w[ptr[i]..ptr[i + 1]].iter().sum::<f64>();
            // A positive definite operator has a positive diagonal; guard round-off.
            if s > 0.0 {
                s
            } else {
                w[ptr[i]..ptr[i + 1]].iter().map(|v| v.abs()).sum::<f64>() + dir[i]
            }
        })
        .collect();
    Graph {
        n: nc,
        ptr,
        col,
        w,
        dir,
        d,
    }
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

#[derive(Clone, Copy)]
struct SharedMut(*mut f64);
// SAFETY: see `Multigrid::apply`: concurrent tasks write disjoint elements.
unsafe impl Send for SharedMut {}
unsafe impl Sync for SharedMut {}

/// The finest level applied from the grid stencil: unknown `i` is cell `cells[i]`, its
/// faces those of the stencil (to cells with unknowns only).
struct Fine<'a> {
    st: &'a Stencil,
    cells: &'a [u32],
    index: &'a [u32],
}

impl Fine<'_> {
    /// `Σ_j w_ij x_j` of unknown `i` (cell `k`), `x_j` from `inside` for unknowns of the
    /// block `i0..i0 + inside.len()` and from `outside` otherwise, and `Σ |w_ij|` over the
    /// faces outside the block.
    #[inline(always)]
    fn row(&self, k: usize, i0: usize, inside: &[f64], outside: &[f64]) -> (f64, f64) {
        let i1 = i0 + inside.len();
        let (mut v, mut out) = (0.0, 0.0);
        self.st.for_each_face(k, |l, c| {
            let j = self.index[l];
            if j == NONE {
                return;
            }
            let j = j as usize;
            let xj = if j >= i0 && j < i1 {
                inside[j - i0]
            } else {
                out += c;
                outside[j]
            };
            v += c * xj;
        });
        (v, out)
    }

    /// [`Graph::residual`] on the finest level.
    fn residual(&self, x: &[f64], b: &[f64], r: &mut [f64]) {
        r.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, rc)| {
            let i0 = blk * CHUNK;
            for (t, rv) in rc.iter_mut().enumerate() {
                let i = i0 + t;
                let k = self.cells[i] as usize;
                let (v, _) = self.row(k, 0, &[], x);
                *rv = b[i] - self.st.d[k] * x[i] + v;
            }
        });
    }

    /// [`Graph::smooth`] on the finest level.
    fn smooth(&self, b: &[f64], x: &mut [f64], old: &mut [f64], reverse: bool) {
        old.copy_from_slice(x);
        let old = &*old;
        x.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, xc)| {
            let i0 = blk * CHUNK;
            let m = xc.len();
            let update = |t: usize, xc: &mut [f64]| {
                let i = i0 + t;
                let k = self.cells[i] as usize;
                let (v, out) = self.row(k, i0, xc, old);
                let d = self.st.d[k];
                xc[t] += (b[i] - d * xc[t] + v) / (d + out);
            };
            if reverse {
                for t in (0..m).rev() {
                    update(t, xc);
                }
            } else {
                for t in 0..m {
                    update(t, xc);
                }
            }
        });
    }
}

/// One V-cycle on `levels[0]` for `bufs[0].b` into `bufs[0].x`; `fine`: `levels[0]` is the
/// finest level, applied from the stencil.
fn vcycle(
    levels: &[Graph],
    interps: &[Interp],
    bufs: &mut [Buffers],
    coarse: &DenseCholesky,
    fine: Option<&Fine<'_>>,
) {
    let (here, rest) = bufs.split_first_mut().expect("a level");
    if levels.len() == 1 {
        coarse.solve(&here.b, &mut here.x);
        return;
    }
    let g = &levels[0];
    let ip = &interps[0];
    let Buffers { x, b, r, old } = here;
    x.par_iter_mut().for_each(|v| *v = 0.0);
    match fine {
        Some(f) => {
            f.smooth(b, x, old, false);
            f.residual(x, b, r);
        }
        None => {
            g.smooth(b, x, old, false);
            g.residual(x, b, r);
        }
    }
    {
        let below = &mut rest[0];
        below
            .b
            .par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(blk, bc)| {
                for (t, bv) in bc.iter_mut().enumerate() {
                    let c = blk * CHUNK + t;
                    let mut s = 0.0;
                    for q in ip.tptr[c]..ip.tptr[c + 1] {
                        s += ip.tval[q] * r[ip.trow[q] as usize];
                    }
                    *bv = s;
                }
            });
    }
    vcycle(&levels[1..], &interps[1..], rest, coarse, None);
    let xc = &rest[0].x;
    x.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, xs)| {
        for (t, v) in xs.iter_mut().enumerate() {
            let i = blk * CHUNK + t;
            let mut s = 0.0;
            for p in ip.ptr[i]..ip.ptr[i + 1] {
                s += ip.val[p] * xc[ip.col[p] as usize];
            }
            *v += s;
        }
    });
    match fine {
        Some(f) => f.smooth(b, x, old, true),
        None => g.smooth(b, x, old, true),
    }
}

/// Dense Cholesky factor of the coarsest level (at most a few hundred unknowns).
struct DenseCholesky {
    n: usize,
    /// Lower triangle, row-major `n × n`.
    l: Vec<f64>,
}

impl DenseCholesky {
    fn new(g: &Graph) -> Self {
        let n = g.n;
        let mut l = vec![0.0; n * n];
        for i in 0..n {
            l[i * n + i] = g.d[i];
            for p in g.ptr[i]..g.ptr[i + 1] {
                let j = g.col[p] as usize;
                l[i * n + j] -= g.w[p];
            }
        }
        for k in 0..n {
            for m in 0..=k {
                let mut v = l[k * n + m];
                for p in 0..m {
                    v -= l[k * n + p] * l[m * n + p];
                }
                if m == k {
                    // SPD by construction; a pivot lost to round-off (a coarse unknown joined
                    // to the rest and the reservoirs by faces below ε of its own) solves as
                    // decoupled.
                    let piv = if v > f64::EPSILON * g.d[k] { v } else { g.d[k] };
                    l[k * n + k] = piv.sqrt();
                } else {
                    l[k * n + m] = v / l[m * n + m];
                }
            }
        }
        DenseCholesky { n, l }
    }

    #[allow(clippy::needless_range_loop)]
    fn solve(&self, b: &[f64], x: &mut [f64]) {
        let n = self.n;
        for k in 0..n {
            let mut v = b[k];
            for p in 0..k {
                v -= self.l[k * n + p] * x[p];
            }
            x[k] = v / self.l[k * n + k];
        }
        for k in (0..n).rev() {
            let mut v = x[k];
            for q in k + 1..n {
                v -= self.l[q * n + k] * x[q];
            }
            x[k] = v / self.l[k * n + k];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flow::assemble::fine_stencil;

    /// Uniform numbers in `[0, 1)` from a fixed linear congruential sequence.
    fn uniform(seed: u64, n: usize) -> Vec<f64> {
        let mut s = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 53) as f64
            })
            .collect()
    }

    /// A periodic `ny × nx` stencil with cell conductances spanning six decades.
    fn rough(seed: u64, ny: usize, nx: usize) -> Stencil {
        let c: Vec<f64> = uniform(seed, ny * nx)
            .iter()
            .map(|u| 10f64.powf(-6.0 * u))
            .collect();
        fine_stencil(&c, ny, nx, true).0
    }

    #[test]
    fn every_strong_f_pair_shares_a_c_neighbour() {
        for seed in 0..3 {
            let st = rough(seed, 60, 50);
            let (g, _, _) = fine_graph(&st);
            let wmax = strongest(&g);
            let (cidx, nc) = split(&g, &wmax);
            assert!(nc > 0 && nc < g.n);
            for i in (0..g.n).filter(|&i| cidx[i] == NONE) {
                let row = g.ptr[i]..g.ptr[i + 1];
                let ci: Vec<u32> = row
                    .clone()
                    .filter(|&p| strong(g.w[p], wmax[i]) && cidx[g.col[p] as usize] != NONE)
                    .map(|p| g.col[p])
                    .collect();
                assert!(!ci.is_empty(), "F unknown {i} has no strong C neighbour");
                for p in row {
                    let k = g.col[p] as usize;
                    if cidx[k] == NONE && strong(g.w[p], wmax[i]) {
                        assert!(
                            ci.iter().any(|&m| g.weight(k, m) > 0.0),
                            "strong F pair {i}, {k} without a common C neighbour"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn cycle_is_symmetric_and_positive() {
        let (ny, nx) = (60, 50);
        let mg = Multigrid::new(rough(7, ny, nx));
        assert!(mg.n_levels() >= 2);
        let n = ny * nx;
        let u: Vec<f64> = uniform(1, n).iter().map(|v| v - 0.5).collect();
        let v: Vec<f64> = uniform(2, n).iter().map(|v| v - 0.5).collect();
        let (mut mu, mut mv) = (vec![0.0; n], vec![0.0; n]);
        mg.apply(&u, &mut mu);
        mg.apply(&v, &mut mv);
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let (a, b) = (dot(&u, &mv), dot(&v, &mu));
        let scale = dot(&u, &u).sqrt() * dot(&mv, &mv).sqrt();
        assert!((a - b).abs() <= 1e-12 * scale, "u·Mv = {a}, v·Mu = {b}");
        assert!(dot(&u, &mu) > 0.0 && dot(&v, &mv) > 0.0);
    }
}
