//! Aggregation multigrid preconditioner for the 5-point Reynolds operator.
//!
//! # Coarsening that follows the conductances
//!
//! Near the percolation threshold the spanning cluster is a tortuous maze of necks, dead ends
//! and walls one cell thick, with conductances `g³` spanning many decades. Fixed 2 × 2 blocks
//! of the grid then lump together cells on both sides of a wall, or a wide channel with the
//! neck that throttles it, and the coarse space cannot represent the pressure drop across
//! them: conjugate gradients stall. So the aggregates are built from the matrix, by
//! *double pairwise aggregation* (Notay, ETNA 37, 2010): every unknown is paired with its
//! strongest unpaired neighbour `j`, provided the face is strong,
//!
//! ```text
//! w_ij ≥ β max(max_k w_ik, max_k w_jk),   β = 1/4,
//! ```
//!
//! else it stays alone; two such passes give aggregates of up to four connected cells.
//! Prolongation is piecewise constant on the aggregates and the coarse operator is the
//! Galerkin `Pᵀ A P`, which for a conductance operator is again one: coarse face weights are
//! sums of the fine faces between two aggregates, reservoir conductances add up, and the
//! diagonal is rebuilt as reservoir + Σ faces (no cancellation), so every level is a
//! symmetric M-matrix. Aggregates never join cells that are not joined by a face.
//!
//! # Cycle
//!
//! The finest level keeps the structured stencil and red–black Gauss–Seidel (parallel over
//! rows); the coarse levels are sparse (compressed rows) and use a hybrid Gauss–Seidel: rows
//! in fixed blocks of [`CHUNK`], Gauss–Seidel inside a block, the other blocks' values from
//! before the sweep. Post-smoothing runs everything in reverse, so each cycle is a symmetric
//! operator. Coarse levels are solved by two steps of Krylov acceleration of the next cycle
//! (the K-cycle of Notay and Vassilevski), the coarsest (≤ [`COARSEST`] unknowns) by a
//! dense Cholesky factor. Block boundaries do not depend on the thread count and every value
//! is computed by the same arithmetic, so the preconditioner is deterministic.

use std::sync::Mutex;

use rayon::prelude::*;

use super::assemble::{Stencil, ROWS_PER_TASK};
use super::cg::{dot, CHUNK};

/// Coarsening stops at this many unknowns; the coarsest level is factored (dense).
const COARSEST: usize = 400;

/// Strength threshold β of the pairing.
const STRONG: f64 = 0.25;

/// Most levels built (a guard; coarsening by about four gives far fewer).
const MAX_LEVELS: usize = 40;

/// No aggregate (cells without unknowns).
const NONE: u32 = u32::MAX;

/// A conductance operator in compressed rows: `(A x)_i = d_i x_i − Σ_j w_ij x_j`,
/// `d_i = dir_i + Σ_j w_ij`.
pub struct Graph {
    n: usize,
    ptr: Vec<usize>,
    col: Vec<u32>,
    w: Vec<f64>,
    dir: Vec<f64>,
    d: Vec<f64>,
}

/// Fine cells of every aggregate (counting-sorted, ascending).
struct Members {
    ptr: Vec<usize>,
    list: Vec<u32>,
}

/// The map from one level to the next.
struct Map {
    agg: Vec<u32>,
    members: Members,
}

/// Work vectors of one coarse level.
struct Buffers {
    x: Vec<f64>,
    b: Vec<f64>,
    r: Vec<f64>,
    c1: Vec<f64>,
    v1: Vec<f64>,
    c2: Vec<f64>,
    v2: Vec<f64>,
    old: Vec<f64>,
}

/// The multigrid hierarchy (one cycle per application).
pub struct Multigrid {
    fine: Stencil,
    /// `maps[0]`: fine cells → `levels[0]`; `maps[l]`: `levels[l − 1]` → `levels[l]`.
    maps: Vec<Map>,
    levels: Vec<Graph>,
    bufs: Mutex<Vec<Buffers>>,
    coarse: DenseCholesky,
}

/// Bytes of the hierarchy below a finest level of `cells` cells.
pub fn memory_estimate(cells: usize) -> u64 {
    // Fine map: aggregate 4 B + member 4 B per cell. Coarse levels (together under a third of
    // the fine cells): per unknown 8 work vectors (64 B), dir and d (16 B), row pointer 8 B,
    // about 8 face entries of 12 B, two maps (16 B); plus the intermediate pairwise level
    // while building (half the fine size, ≈ 120 B per unknown).
    let c = cells as u64;
    8 * c + c.div_ceil(3) * (64 + 16 + 8 + 96 + 16) + c.div_ceil(2) * 120
}

/// Neighbour access for the pairing and the Galerkin product.
trait Neighbours: Sync {
    fn len(&self) -> usize;
    fn active(&self, i: usize) -> bool;
    fn reservoir(&self, i: usize) -> f64;
    /// Calls `f(j, w_ij)` for the faces of `i` with `w_ij > 0`.
    fn for_each(&self, i: usize, f: impl FnMut(usize, f64));
}

impl Neighbours for Stencil {
    fn len(&self) -> usize {
        self.ny * self.nx
    }
    fn active(&self, i: usize) -> bool {
        self.active[i]
    }
    fn reservoir(&self, i: usize) -> f64 {
        self.dir[i]
    }
    #[inline(always)]
    fn for_each(&self, k: usize, f: impl FnMut(usize, f64)) {
        self.for_each_face(k, f);
    }
}

impl Neighbours for Graph {
    fn len(&self) -> usize {
        self.n
    }
    fn active(&self, _i: usize) -> bool {
        true
    }
    fn reservoir(&self, i: usize) -> f64 {
        self.dir[i]
    }
    #[inline(always)]
    fn for_each(&self, i: usize, mut f: impl FnMut(usize, f64)) {
        for p in self.ptr[i]..self.ptr[i + 1] {
            f(self.col[p] as usize, self.w[p]);
        }
    }
}

/// One pairwise pass: aggregate index per unknown (`NONE` when inactive) and their number.
fn pair<G: Neighbours>(g: &G, beta: f64) -> (Vec<u32>, usize) {
    let n = g.len();
    let wmax: Vec<f64> = (0..n)
        .into_par_iter()
        .with_min_len(CHUNK)
        .map(|i| {
            let mut m: f64 = 0.0;
            g.for_each(i, |_, w| m = m.max(w));
            m
        })
        .collect();
    let mut agg = vec![NONE; n];
    let mut nc: u32 = 0;
    for i in 0..n {
        if agg[i] != NONE || !g.active(i) {
            continue;
        }
        let (mut best, mut bw) = (usize::MAX, 0.0);
        let (mut near, mut nw) = (usize::MAX, 0.0);
        g.for_each(i, |j, w| {
            if j == i || w < beta * wmax[i].max(wmax[j]) {
                return;
            }
            if agg[j] == NONE && w > bw {
                best = j;
                bw = w;
            }
            if agg[j] != NONE && w > nw {
                near = j;
                nw = w;
            }
        });
        if best == usize::MAX && near != usize::MAX {
            // Every strong neighbour is taken (a dead end off a junction): join the strongest
            // one's aggregate rather than stay alone, or a star never coarsens.
            agg[i] = agg[near];
            continue;
        }
        agg[i] = nc;
        if best != usize::MAX {
            agg[best] = nc;
        }
        nc += 1;
    }
    (agg, nc as usize)
}

fn members(agg: &[u32], nc: usize) -> Members {
    let mut ptr = vec![0usize; nc + 1];
    for &a in agg {
        if a != NONE {
            ptr[a as usize + 1] += 1;
        }
    }
    for i in 0..nc {
        ptr[i + 1] += ptr[i];
    }
    let mut next = ptr[..nc].to_vec();
    let mut list = vec![0u32; ptr[nc]];
    for (i, &a) in agg.iter().enumerate() {
        if a != NONE {
            list[next[a as usize]] = i as u32;
            next[a as usize] += 1;
        }
    }
    Members { ptr, list }
}

/// Galerkin coarse operator `Pᵀ A P` for the aggregates `agg` (their members `mem`).
fn galerkin<G: Neighbours>(g: &G, agg: &[u32], mem: &Members) -> Graph {
    let nc = mem.ptr.len() - 1;
    // Rows in fixed blocks: each block's entries in row order, blocks concatenated in order.
    // Per block: row lengths, columns, weights, reservoir conductances.
    type Block = (Vec<usize>, Vec<u32>, Vec<f64>, Vec<f64>);
    let blocks: Vec<Block> = (0..nc.div_ceil(CHUNK))
        .into_par_iter()
        .map(|blk| {
            let rows = blk * CHUNK..((blk + 1) * CHUNK).min(nc);
            let mut len = Vec::with_capacity(rows.len());
            let mut col = Vec::new();
            let mut w = Vec::new();
            let mut dir = Vec::with_capacity(rows.len());
            let mut row: Vec<(u32, f64)> = Vec::new();
            for ci in rows {
                row.clear();
                let mut dsum = 0.0;
                for &m in &mem.list[mem.ptr[ci]..mem.ptr[ci + 1]] {
                    dsum += g.reservoir(m as usize);
                    g.for_each(m as usize, |j, wj| {
                        let cj = agg[j];
                        if cj as usize != ci && cj != NONE {
                            match row.iter_mut().find(|e| e.0 == cj) {
                                Some(e) => e.1 += wj,
                                None => row.push((cj, wj)),
                            }
                        }
                    });
                }
                row.sort_unstable_by_key(|e| e.0);
                len.push(row.len());
                for &(c, v) in &row {
                    col.push(c);
                    w.push(v);
                }
                dir.push(dsum);
            }
            (len, col, w, dir)
        })
        .collect();
    let nnz: usize = blocks.iter().map(|b| b.1.len()).sum();
    let mut ptr = Vec::with_capacity(nc + 1);
    let mut col = Vec::with_capacity(nnz);
    let mut w = Vec::with_capacity(nnz);
    let mut dir = Vec::with_capacity(nc);
    ptr.push(0);
    for (l, c, v, d) in blocks {
        for len in l {
            ptr.push(ptr.last().copied().unwrap_or(0) + len);
        }
        col.extend_from_slice(&c);
        w.extend_from_slice(&v);
        dir.extend_from_slice(&d);
    }
    let d = (0..nc)
        .into_par_iter()
        .with_min_len(CHUNK)
        .map(|i| dir[i] + w[ptr[i]..ptr[i + 1]].iter().sum::<f64>())
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

/// Two pairwise passes on `g`: the map to the coarse level and the coarse operator.
fn coarsen<G: Neighbours>(g: &G) -> (Map, Graph) {
    let active = (0..g.len()).filter(|&i| g.active(i)).count();
    // Relax the strength test when strong pairs are too few to coarsen (a chain of faces
    // alternating strong and weak): convergence needs the levels to shrink.
    let pass = |h: &dyn Fn(f64) -> (Vec<u32>, usize), n: usize| {
        let (a, nc) = h(STRONG);
        if nc * 10 > n * 9 {
            h(0.0)
        } else {
            (a, nc)
        }
    };
    let (a1, n1) = pass(&|beta| pair(g, beta), active);
    let m1 = members(&a1, n1);
    let g1 = galerkin(g, &a1, &m1);
    drop(m1);
    let (a2, n2) = pass(&|beta| pair(&g1, beta), n1);
    let agg: Vec<u32> = a1
        .par_iter()
        .with_min_len(CHUNK)
        .map(|&a| if a == NONE { NONE } else { a2[a as usize] })
        .collect();
    let m2 = members(&a2, n2);
    let coarse = galerkin(&g1, &a2, &m2);
    drop(m2);
    let members = members(&agg, n2);
    (Map { agg, members }, coarse)
}

impl Graph {
    /// `y = A x`.
    fn apply(&self, x: &[f64], y: &mut [f64]) {
        y.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, yc)| {
            let i0 = blk * CHUNK;
            for (t, yv) in yc.iter_mut().enumerate() {
                let i = i0 + t;
                let mut v = self.d[i] * x[i];
                for p in self.ptr[i]..self.ptr[i + 1] {
                    v -= self.w[p] * x[self.col[p] as usize];
                }
                *yv = v;
            }
        });
    }

    /// `r = b − A x`.
    fn residual(&self, x: &[f64], b: &[f64], r: &mut [f64]) {
        self.apply(x, r);
        r.par_chunks_mut(CHUNK)
            .zip(b.par_chunks(CHUNK))
            .for_each(|(rc, bc)| rc.iter_mut().zip(bc).for_each(|(rv, bv)| *rv = bv - *rv));
    }

    /// Hybrid Gauss–Seidel sweep (module docs); `old` is scratch of size `n`.
    fn smooth(&self, b: &[f64], x: &mut [f64], old: &mut [f64], reverse: bool) {
        old.copy_from_slice(x);
        let old = &*old;
        x.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, xc)| {
            let i0 = blk * CHUNK;
            let i1 = i0 + xc.len();
            let mut update = |t: usize| {
                let i = i0 + t;
                let mut v = b[i];
                for p in self.ptr[i]..self.ptr[i + 1] {
                    let j = self.col[p] as usize;
                    let xj = if j >= i0 && j < i1 {
                        xc[j - i0]
                    } else {
                        old[j]
                    };
                    v += self.w[p] * xj;
                }
                xc[t] = v / self.d[i];
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
}

impl Multigrid {
    /// Builds the hierarchy below the fine operator `fine` (moved in).
    pub fn new(fine: Stencil) -> Self {
        let mut maps = Vec::new();
        let mut levels: Vec<Graph> = Vec::new();
        let (m, g) = coarsen(&fine);
        maps.push(m);
        levels.push(g);
        loop {
            let g = levels.last().expect("non-empty");
            if g.n <= COARSEST || levels.len() >= MAX_LEVELS {
                break;
            }
            let (m, c) = coarsen(g);
            maps.push(m);
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
                    c1: vec![0.0; n],
                    v1: vec![0.0; n],
                    c2: vec![0.0; n],
                    v2: vec![0.0; n],
                    old: vec![0.0; n],
                }
            })
            .collect();
        let coarse = DenseCholesky::new(levels.last().expect("non-empty"));
        Multigrid {
            fine,
            maps,
            levels,
            bufs: Mutex::new(bufs),
            coarse,
        }
    }

    /// The finest operator.
    pub fn fine(&self) -> &Stencil {
        &self.fine
    }

    /// Unknowns per coarse level.
    pub fn sizes(&self) -> Vec<usize> {
        self.levels.iter().map(|g| g.n).collect()
    }

    /// The finest operator, the hierarchy dropped.
    pub fn into_fine(self) -> Stencil {
        self.fine
    }

    /// Number of levels, the finest included.
    pub fn n_levels(&self) -> usize {
        self.levels.len() + 1
    }

    /// `z = M⁻¹ r`: one symmetric cycle from `z = 0`; `work` has the fine level's size.
    pub fn apply(&self, r: &[f64], z: &mut [f64], work: &mut [f64]) {
        let mut bufs = self.bufs.lock().unwrap_or_else(|e| e.into_inner());
        let st = &self.fine;
        z.par_iter_mut().for_each(|v| *v = 0.0);
        sweep(st, r, z, 0, false);
        sweep(st, r, z, 1, false);
        st.residual(z, r, work);
        let (here, rest) = bufs.split_first_mut().expect("a coarse level");
        restrict(&self.maps[0].members, work, &mut here.b);
        kcycle(&self.levels, &self.maps[1..], here, rest, &self.coarse);
        prolong_add(&self.maps[0].agg, &here.x, z);
        sweep(st, r, z, 1, true);
        sweep(st, r, z, 0, true);
    }
}

/// Approximate solve of `levels[0] x = b` (in `here`): exact on the coarsest, else two steps
/// of Krylov acceleration of the next cycle (the K-cycle), the second skipped when the first
/// reduced the residual 4-fold.
fn kcycle(
    levels: &[Graph],
    maps: &[Map],
    here: &mut Buffers,
    rest: &mut [Buffers],
    coarse: &DenseCholesky,
) {
    if levels.len() == 1 {
        coarse.solve(&here.b, &mut here.x);
        return;
    }
    let g = &levels[0];
    let Buffers {
        x,
        b,
        r,
        c1,
        v1,
        c2,
        v2,
        old,
    } = here;
    cycle(levels, maps, rest, coarse, b, c1, r, old);
    g.apply(c1, v1);
    let rho1 = dot(c1, v1);
    let alpha1 = dot(c1, b);
    if rho1.is_nan() || rho1 <= 0.0 {
        x.iter_mut().for_each(|v| *v = 0.0);
        return;
    }
    let t1 = alpha1 / rho1;
    r.par_chunks_mut(CHUNK)
        .zip(b.par_chunks(CHUNK).zip(v1.par_chunks(CHUNK)))
        .for_each(|(rc, (bc, vc))| {
            rc.iter_mut()
                .zip(bc.iter().zip(vc))
                .for_each(|(rv, (bv, vv))| *rv = bv - t1 * vv)
        });
    let bnorm2 = dot(b, b);
    let rnorm2 = dot(r, r);
    if rnorm2 <= 0.0625 * bnorm2 {
        x.par_chunks_mut(CHUNK)
            .zip(c1.par_chunks(CHUNK))
            .for_each(|(xc, cc)| xc.iter_mut().zip(cc).for_each(|(xv, cv)| *xv = t1 * cv));
        return;
    }
    // The second cycle's own residual buffer: x is free until the combination below.
    cycle(levels, maps, rest, coarse, r, c2, x, old);
    g.apply(c2, v2);
    let gamma = dot(c2, v1);
    let beta = dot(c2, v2);
    let alpha2 = dot(c2, r);
    let rho2 = beta - gamma * gamma / rho1;
    let (a1, a2) = if rho2 > 0.0 {
        (t1 - gamma * alpha2 / (rho1 * rho2), alpha2 / rho2)
    } else {
        (t1, 0.0)
    };
    x.par_chunks_mut(CHUNK)
        .zip(c1.par_chunks(CHUNK).zip(c2.par_chunks(CHUNK)))
        .for_each(|(xc, (ac, bc))| {
            xc.iter_mut()
                .zip(ac.iter().zip(bc))
                .for_each(|(xv, (u, w))| *xv = a1 * u + a2 * w)
        });
}

/// One symmetric cycle on `levels[0]` for `b` into `x` (`r`, `old` work vectors); the
/// coarser levels use `bufs`.
#[allow(clippy::too_many_arguments)]
fn cycle(
    levels: &[Graph],
    maps: &[Map],
    bufs: &mut [Buffers],
    coarse: &DenseCholesky,
    b: &[f64],
    x: &mut [f64],
    r: &mut [f64],
    old: &mut [f64],
) {
    let g = &levels[0];
    x.iter_mut().for_each(|v| *v = 0.0);
    g.smooth(b, x, old, false);
    g.residual(x, b, r);
    let (below, rest) = bufs.split_first_mut().expect("a coarser level");
    restrict(&maps[0].members, r, &mut below.b);
    kcycle(&levels[1..], &maps[1..], below, rest, coarse);
    prolong_add(&maps[0].agg, &below.x, x);
    g.smooth(b, x, old, true);
}

/// Coarse right-hand side: sums of the fine residuals over each aggregate, in cell order.
fn restrict(mem: &Members, r: &[f64], b: &mut [f64]) {
    b.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, bc)| {
        for (t, bv) in bc.iter_mut().enumerate() {
            let ci = blk * CHUNK + t;
            *bv = mem.list[mem.ptr[ci]..mem.ptr[ci + 1]]
                .iter()
                .map(|&m| r[m as usize])
                .sum();
        }
    });
}

/// `x += P x_c` on the unknowns.
fn prolong_add(agg: &[u32], xc: &[f64], x: &mut [f64]) {
    x.par_chunks_mut(CHUNK)
        .zip(agg.par_chunks(CHUNK))
        .for_each(|(xs, ags)| {
            for (v, &a) in xs.iter_mut().zip(ags) {
                if a != NONE {
                    *v += xc[a as usize];
                }
            }
        });
}

#[derive(Clone, Copy)]
struct SharedMut(*mut f64);
// SAFETY: see `sweep`: concurrent tasks never touch the same element while one writes it.
unsafe impl Send for SharedMut {}
unsafe impl Sync for SharedMut {}

/// One Gauss–Seidel half-sweep of the fine stencil over the cells with
/// `(i + j) % 2 == colour`, in row order and, with `reverse`, from the last column to the
/// first.
fn sweep(st: &Stencil, b: &[f64], x: &mut [f64], colour: usize, reverse: bool) {
    let (ny, nx) = (st.ny, st.nx);
    assert_eq!(x.len(), ny * nx);
    let xp = SharedMut(x.as_mut_ptr());
    (0..ny)
        .into_par_iter()
        .with_min_len(ROWS_PER_TASK)
        .for_each(move |i| {
            let xp = xp;
            let x = xp.0;
            let base = i * nx;
            // SAFETY: this task writes only cells of row i of this colour. It reads cells of
            // rows i ± 1 in the same column (the other colour, written by nobody in this
            // half-sweep) and cells of its own row, which no other task writes. All indices
            // are below ny·nx.
            let update = |j: usize| unsafe {
                let k = base + j;
                if !st.active[k] {
                    return;
                }
                let mut v = b[k];
                if j + 1 < nx {
                    v += st.e[k] * *x.add(k + 1);
                } else if st.periodic && nx > 1 {
                    v += st.e[k] * *x.add(base);
                }
                if let Some(w) = st.west(j) {
                    v += st.e[base + w] * *x.add(base + w);
                }
                if i + 1 < ny {
                    v += st.s[k] * *x.add(k + nx);
                }
                if i > 0 {
                    v += st.s[k - nx] * *x.add(k - nx);
                }
                *x.add(k) = v / st.d[k];
            };
            let first = (i + colour) % 2;
            if reverse {
                for j in (first..nx).step_by(2).rev() {
                    update(j);
                }
            } else {
                for j in (first..nx).step_by(2) {
                    update(j);
                }
            }
        });
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
                    // SPD by construction; guard against round-off on a tiny pivot.
                    l[k * n + k] = v.max(f64::MIN_POSITIVE).sqrt();
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
