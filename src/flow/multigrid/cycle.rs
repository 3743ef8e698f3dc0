//! The multigrid cycle (ℓ1 hybrid Gauss–Seidel smoothing; a W-cycle on the top levels, a
//! V-cycle below) on the compressed levels, and the finest level's product from the grid
//! stencil.

use rayon::prelude::*;

use super::{Buffers, DenseCholesky, Graph, Interp, Stencil, CHUNK, NONE};

#[derive(Clone, Copy)]
pub(super) struct SharedMut(pub(super) *mut f64);
// SAFETY: see `Multigrid::apply`: concurrent tasks write disjoint elements.
unsafe impl Send for SharedMut {}
unsafe impl Sync for SharedMut {}

/// The finest level applied from the grid stencil: unknown `i` is cell `cells[i]`, its
/// faces those of the stencil (to cells with unknowns only).
pub(super) struct Fine<'a> {
    pub(super) st: &'a Stencil,
    pub(super) cells: &'a [u32],
    pub(super) index: &'a [u32],
}

impl Fine<'_> {
    /// `y = A x` on the finest level.
    pub(super) fn product(&self, x: &[f64], y: &mut [f64]) {
        y.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, yc)| {
            for (t, o) in yc.iter_mut().enumerate() {
                let i = blk * CHUNK + t;
                let k = self.cells[i] as usize;
                let mut v = 0.0;
                self.st.for_each_face(k, |l, c| {
                    let j = self.index[l];
                    if j != NONE {
                        v += c * x[j as usize];
                    }
                });
                *o = self.st.d[k] * x[i] - v;
            }
        });
    }
}

/// The top levels whose coarse correction is two cycles of the level below, not one:
/// `S` and the level below it (a W-cycle there, a V-cycle further down). On near-threshold
/// contact gaps this took the CG iterations at 4097² from 51 to 23 (docs/flow.md).
pub(super) const W_LEVELS: usize = 2;

/// One cycle on `levels[0]` (the `depth`-th level below `S`, `S` being 0) for `b` into `x`:
/// from `x = 0`, or from the `x` given when `warm` (then the result is
/// `x + M (b − A x)`, the same cycle applied to the residual: the sweeps and the coarse
/// correction are linear stationary steps). `bufs[0].r` is this level's scratch and
/// `bufs[1..]` hold the vectors of the levels below.
#[allow(clippy::too_many_arguments)]
pub(super) fn level_cycle(
    levels: &[Graph],
    interps: &[Interp],
    b: &[f64],
    x: &mut [f64],
    bufs: &mut [Buffers],
    coarse: &DenseCholesky,
    depth: usize,
    warm: bool,
) {
    if levels.len() == 1 {
        // Exact: the same from any start.
        coarse.solve(b, x);
        return;
    }
    let (here, rest) = bufs.split_first_mut().expect("a level");
    let g = &levels[0];
    let ip = &interps[0];
    // `r` is the sweeps' scratch too: the residual is dead once restricted.
    let r = &mut here.r;
    if warm {
        g.smooth(b, x, r, false);
        g.residual(x, b, r);
    } else {
        // From 0 the sweep and the residual together read each face once.
        g.smooth_from_zero(b, x);
        g.residual_after_zero_sweep(x, r);
    }
    // The level below's right-hand side and solution, taken out of its buffers for the
    // recursion (no copy) and put back after.
    let mut bc = std::mem::take(&mut rest[0].b);
    let mut xc = std::mem::take(&mut rest[0].x);
    let (n, nc) = (x.len(), bc.len());
    assert!(
        ip.ptr.len() == n + 1 && r.len() == n && ip.tptr.len() == nc + 1 && xc.len() == nc,
        "transfers between vectors of the levels' sizes"
    );
    // SAFETY (both transfers): the chunks cover vectors of the lengths just checked, and
    // the interpolation's rows both ways were checked when it was built (`check_rows`).
    bc.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, bs)| {
        for (t, bv) in bs.iter_mut().enumerate() {
            let c = blk * CHUNK + t;
            let mut s = 0.0;
            unsafe {
                for q in *ip.tptr.get_unchecked(c)..*ip.tptr.get_unchecked(c + 1) {
                    s += f64::from(*ip.tval.get_unchecked(q))
                        * r.get_unchecked(*ip.trow.get_unchecked(q) as usize);
                }
            }
            *bv = s;
        }
    });
    // The coarse correction: one cycle from 0, and on the top levels a second one from its
    // result (symmetric: two steps of an A-symmetric convergent iteration); not when the
    // level below is the coarsest, whose exact solve a second one would only repeat.
    let (below, down) = (&levels[1..], &interps[1..]);
    let cycles = if depth < W_LEVELS && below.len() > 1 {
        2
    } else {
        1
    };
    for k in 0..cycles {
        level_cycle(below, down, &bc, &mut xc, rest, coarse, depth + 1, k > 0);
    }
    let xcr = &xc;
    // The interpolated correction added, and the result copied into `r` (the residual is
    // dead): the reversed sweep's values from before it, without a pass of its own.
    x.par_chunks_mut(CHUNK)
        .zip(r.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(blk, (xs, olds))| {
            for (t, (v, o)) in xs.iter_mut().zip(olds.iter_mut()).enumerate() {
                let i = blk * CHUNK + t;
                let mut s = 0.0;
                unsafe {
                    for p in *ip.ptr.get_unchecked(i)..*ip.ptr.get_unchecked(i + 1) {
                        s += f64::from(*ip.val.get_unchecked(p))
                            * xcr.get_unchecked(*ip.col.get_unchecked(p) as usize);
                    }
                }
                *v += s;
                *o = *v;
            }
        });
    rest[0].b = bc;
    rest[0].x = xc;
    g.smooth_from_copy(b, x, r, true);
}
