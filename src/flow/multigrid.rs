//! Aggregation multigrid preconditioner for the 5-point Reynolds operator.
//!
//! Coarsening: 2 × 2 aggregates of the structured grid (the last row or column alone when the
//! size is odd), piecewise-constant prolongation `P` restricted to cells with unknowns, and
//! the Galerkin coarse operator `Pᵀ A P`. For a conductance (graph-Laplacian) operator this
//! is again a 5-point conductance operator: a coarse face is the sum of the fine faces that
//! cross between two aggregates, the reservoir conductances add up, and faces inside an
//! aggregate drop out. So every level keeps the structured layout, the coefficients follow
//! the jumps of `g³` exactly (nothing is interpolated across a contact), and the coarse
//! operators stay symmetric M-matrices.
//!
//! Smoother: red–black Gauss–Seidel, parallel over rows; the post-smoother runs the colours
//! (and the cells of a row) in reverse order, so the V-cycle is a symmetric operator and can
//! precondition conjugate gradients. The coarsest level is solved exactly with a banded
//! Cholesky factor. Every cell is updated by the same arithmetic whatever the thread count,
//! so the preconditioner is deterministic.

use std::sync::Mutex;

use rayon::prelude::*;

use super::assemble::{Stencil, ROWS_PER_TASK};
use super::cg::{dot, CHUNK};

/// Coarsening stops at this many cells; the coarsest level is factored.
const COARSEST_CELLS: usize = 2048;

/// Work vectors of one level.
struct Buffers {
    x: Vec<f64>,
    b: Vec<f64>,
    r: Vec<f64>,
    c1: Vec<f64>,
    v1: Vec<f64>,
    c2: Vec<f64>,
    v2: Vec<f64>,
}

/// The multigrid hierarchy (one V-cycle per application).
pub struct Multigrid {
    /// Operators, finest first.
    ops: Vec<Stencil>,
    bufs: Mutex<Vec<Buffers>>,
    coarse: BandCholesky,
    /// Pre- and post-smoothing sweeps (each a red and a black half-sweep).
    pub sweeps: usize,
}

/// Bytes of the coarse levels below a finest level of `cells` cells.
pub fn memory_estimate(cells: usize) -> u64 {
    // Per coarse level: x, b, r and the K-cycle's c1, v1, c2, v2 (56 B) and the operator (e, s, dir, d: 32 B, mask 1 B); the
    // coarse levels add up to a third of the fine one.
    (cells as u64).div_ceil(3) * (56 + 33)
}

impl Multigrid {
    /// Builds the hierarchy below the fine operator `fine` (moved in).
    pub fn new(fine: Stencil) -> Self {
        let mut ops = vec![fine];
        loop {
            let st = ops.last().expect("non-empty");
            if st.ny * st.nx <= COARSEST_CELLS || (st.ny == 1 && st.nx == 1) {
                break;
            }
            let c = coarsen(st);
            ops.push(c);
        }
        // The finest level works in the caller's vectors; buffers for the coarse ones.
        let bufs = ops[1..]
            .iter()
            .map(|st| {
                let n = st.ny * st.nx;
                Buffers {
                    x: vec![0.0; n],
                    b: vec![0.0; n],
                    r: vec![0.0; n],
                    c1: vec![0.0; n],
                    v1: vec![0.0; n],
                    c2: vec![0.0; n],
                    v2: vec![0.0; n],
                }
            })
            .collect();
        let coarse = BandCholesky::new(ops.last().expect("non-empty"));
        Multigrid {
            ops,
            bufs: Mutex::new(bufs),
            coarse,
            sweeps: 1,
        }
    }

    /// The finest operator.
    pub fn fine(&self) -> &Stencil {
        &self.ops[0]
    }

    /// Number of levels.
    pub fn n_levels(&self) -> usize {
        self.ops.len()
    }

    /// `z = M⁻¹ r`: one symmetric V-cycle from `z = 0`; `work` has the fine level's size.
    pub fn apply(&self, r: &[f64], z: &mut [f64], work: &mut [f64]) {
        let mut bufs = self.bufs.lock().unwrap_or_else(|e| e.into_inner());
        if self.ops.len() == 1 {
            self.coarse.solve(r, z);
            return;
        }
        cycle(&self.ops, &mut bufs, &self.coarse, self.sweeps, r, z, work);
    }
}

/// One cycle on `ops[0]` for right-hand side `b` into `x`, `r` a work vector; the coarser
/// levels use `bufs` (one per level below).
#[allow(clippy::too_many_arguments)]
fn cycle(
    ops: &[Stencil],
    bufs: &mut [Buffers],
    coarse: &BandCholesky,
    sweeps: usize,
    b: &[f64],
    x: &mut [f64],
    r: &mut [f64],
) {
    let st = &ops[0];
    x.iter_mut().for_each(|v| *v = 0.0);
    for _ in 0..sweeps {
        sweep(st, b, x, 0, false);
        sweep(st, b, x, 1, false);
    }
    st.residual(x, b, r);
    let (below, rest) = bufs.split_first_mut().expect("a coarser level");
    restrict(st, r, &ops[1], &mut below.b);
    coarse_solve(&ops[1..], below, rest, coarse, sweeps);
    prolong_add(st, &below.x, ops[1].nx, x);
    for _ in 0..sweeps {
        sweep(st, b, x, 1, true);
        sweep(st, b, x, 0, true);
    }
}

/// Approximate solve of a coarse level `ops[0] x = b` (in `here`): exact on the coarsest,
/// else two steps of Krylov acceleration of the next cycle (the K-cycle of Notay and
/// Vassilevski), which keeps plain aggregation's convergence independent of the number of
/// levels. The second step is skipped when the first one reduced the residual 4-fold.
fn coarse_solve(
    ops: &[Stencil],
    here: &mut Buffers,
    rest: &mut [Buffers],
    coarse: &BandCholesky,
    sweeps: usize,
) {
    if ops.len() == 1 {
        coarse.solve(&here.b, &mut here.x);
        return;
    }
    let st = &ops[0];
    let Buffers {
        x,
        b,
        r,
        c1,
        v1,
        c2,
        v2,
    } = here;
    cycle(ops, rest, coarse, sweeps, b, c1, r);
    st.apply(c1, v1);
    let rho1 = dot(c1, v1);
    let alpha1 = dot(c1, b);
    if rho1.is_nan() || rho1 <= 0.0 {
        x.iter_mut().for_each(|v| *v = 0.0);
        return;
    }
    let t1 = alpha1 / rho1;
    // r = b − t1 v1
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
    cycle(ops, rest, coarse, sweeps, r, c2, x);
    st.apply(c2, v2);
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

#[derive(Clone, Copy)]
struct SharedMut(*mut f64);
// SAFETY: see `sweep`: concurrent tasks never touch the same element while one writes it.
unsafe impl Send for SharedMut {}
unsafe impl Sync for SharedMut {}

/// One Gauss–Seidel half-sweep over the cells with `(i + j) % 2 == colour`, in row order and,
/// with `reverse`, from the last column to the first.
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

/// Galerkin coarse operator `Pᵀ A P` of 2 × 2 aggregates.
pub fn coarsen(f: &Stencil) -> Stencil {
    let (ny, nx) = (f.ny, f.nx);
    let (cy, cx) = (ny.div_ceil(2), nx.div_ceil(2));
    let n = cy * cx;
    let mut e = vec![0.0; n];
    let mut s = vec![0.0; n];
    let mut dir = vec![0.0; n];
    let periodic = f.periodic && cx > 1;
    e.par_chunks_mut(cx)
        .zip(s.par_chunks_mut(cx).zip(dir.par_chunks_mut(cx)))
        .enumerate()
        .for_each(|(ci, (erow, (srow, drow)))| {
            let rows = 2 * ci..(2 * ci + 2).min(ny);
            let last_row = rows.end - 1;
            for cj in 0..cx {
                let cols = 2 * cj..(2 * cj + 2).min(nx);
                let last_col = cols.end - 1;
                let mut sum_dir = 0.0;
                for i in rows.clone() {
                    for j in cols.clone() {
                        if f.active[i * nx + j] {
                            sum_dir += f.dir[i * nx + j];
                        }
                    }
                }
                drow[cj] = sum_dir;
                // The fine e of the aggregate's last column crosses to the next aggregate
                // (through the wrap on the last one when periodic).
                if cj + 1 < cx || periodic {
                    erow[cj] = rows.clone().map(|i| f.e[i * nx + last_col]).sum();
                }
                if ci + 1 < cy {
                    srow[cj] = cols.clone().map(|j| f.s[last_row * nx + j]).sum();
                }
            }
        });
    let mut st = Stencil {
        ny: cy,
        nx: cx,
        periodic,
        e,
        s,
        dir,
        d: vec![0.0; n],
        active: vec![false; n],
    };
    st.finish_diagonal();
    st
}

/// Coarse right-hand side: sums of the fine residuals over each aggregate.
fn restrict(f: &Stencil, r: &[f64], c: &Stencil, b: &mut [f64]) {
    let (ny, nx, cx) = (f.ny, f.nx, c.nx);
    b.par_chunks_mut(cx)
        .enumerate()
        .with_min_len(ROWS_PER_TASK / 2)
        .for_each(|(ci, brow)| {
            brow.iter_mut().for_each(|v| *v = 0.0);
            for i in 2 * ci..(2 * ci + 2).min(ny) {
                for j in 0..nx {
                    brow[j / 2] += r[i * nx + j];
                }
            }
        });
}

/// `x += P x_c` on the cells with unknowns.
fn prolong_add(f: &Stencil, xc: &[f64], cx: usize, x: &mut [f64]) {
    let nx = f.nx;
    x.par_chunks_mut(nx)
        .enumerate()
        .with_min_len(ROWS_PER_TASK)
        .for_each(|(i, row)| {
            let crow = &xc[(i / 2) * cx..(i / 2 + 1) * cx];
            let arow = &f.active[i * nx..(i + 1) * nx];
            for j in 0..nx {
                if arow[j] {
                    row[j] += crow[j / 2];
                }
            }
        });
}

/// Banded Cholesky factor of a small stencil operator (raster order, half-bandwidth `nx`).
struct BandCholesky {
    n: usize,
    bw: usize,
    /// Row k holds `L[k][k − t]` at `l[k (bw + 1) + t]`, t = 0..=bw.
    l: Vec<f64>,
}

impl BandCholesky {
    fn new(st: &Stencil) -> Self {
        let (ny, nx) = (st.ny, st.nx);
        let n = ny * nx;
        let bw = nx.min(n.saturating_sub(1));
        let w = bw + 1;
        let mut l = vec![0.0; n * w];
        for i in 0..ny {
            for j in 0..nx {
                let k = i * nx + j;
                l[k * w] = st.d[k];
                if j > 0 {
                    l[k * w + 1] -= st.e[k - 1];
                }
                if st.periodic && nx > 1 && j == nx - 1 {
                    l[k * w + (nx - 1)] -= st.e[k];
                }
                if i > 0 {
                    l[k * w + nx] -= st.s[k - nx];
                }
            }
        }
        for k in 0..n {
            for m in k.saturating_sub(bw)..=k {
                let lo = k.saturating_sub(bw).max(m.saturating_sub(bw));
                let mut v = l[k * w + (k - m)];
                for p in lo..m {
                    v -= l[k * w + (k - p)] * l[m * w + (m - p)];
                }
                if m == k {
                    // SPD by construction; guard against round-off on a tiny pivot.
                    l[k * w] = v.max(f64::MIN_POSITIVE).sqrt();
                } else {
                    l[k * w + (k - m)] = v / l[m * w];
                }
            }
        }
        BandCholesky { n, bw, l }
    }

    #[allow(clippy::needless_range_loop)]
    fn solve(&self, b: &[f64], x: &mut [f64]) {
        let (n, bw, w) = (self.n, self.bw, self.bw + 1);
        for k in 0..n {
            let mut v = b[k];
            for p in k.saturating_sub(bw)..k {
                v -= self.l[k * w + (k - p)] * x[p];
            }
            x[k] = v / self.l[k * w];
        }
        for k in (0..n).rev() {
            let mut v = x[k];
            for q in k + 1..(k + bw + 1).min(n) {
                v -= self.l[q * w + (q - k)] * x[q];
            }
            x[k] = v / self.l[k * w];
        }
    }
}
