//! The V-cycle: ℓ1 hybrid Gauss–Seidel smoothing, the finest level from the grid stencil.

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

    /// `out_i = f(i, d_i x_i, Σ_j w_ij x_j)` over the finest level's rows, in parallel chunks.
    fn map_rows(&self, x: &[f64], out: &mut [f64], f: impl Fn(usize, f64, f64) -> f64 + Sync) {
        out.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, oc)| {
            let i0 = blk * CHUNK;
            for (t, o) in oc.iter_mut().enumerate() {
                let i = i0 + t;
                let k = self.cells[i] as usize;
                let (v, _) = self.row(k, 0, &[], x);
                *o = f(i, self.st.d[k] * x[i], v);
            }
        });
    }

    /// [`Graph::residual`] on the finest level.
    pub(super) fn residual(&self, x: &[f64], b: &[f64], r: &mut [f64]) {
        self.map_rows(x, r, |i, dx, v| b[i] - dx + v);
    }

    /// `y = A x` on the finest level.
    pub(super) fn product(&self, x: &[f64], y: &mut [f64]) {
        self.map_rows(x, y, |_, dx, v| dx - v);
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

/// One V-cycle on `levels[0]` for `b` into `x`; `bufs[0].r` is this level's scratch and
/// `bufs[1..]` hold the vectors of the levels below; `fine`: `levels[0]` is the finest
/// level, applied from the stencil.
pub(super) fn vcycle(
    levels: &[Graph],
    interps: &[Interp],
    b: &[f64],
    x: &mut [f64],
    bufs: &mut [Buffers],
    coarse: &DenseCholesky,
    fine: Option<&Fine<'_>>,
) {
    if levels.len() == 1 {
        coarse.solve(b, x);
        return;
    }
    let (here, rest) = bufs.split_first_mut().expect("a level");
    let g = &levels[0];
    let ip = &interps[0];
    // `r` is the sweeps' scratch too: the residual is dead once restricted.
    let r = &mut here.r;
    x.par_iter_mut().for_each(|v| *v = 0.0);
    match fine {
        Some(f) => {
            f.smooth(b, x, r, false);
            f.residual(x, b, r);
        }
        None => {
            g.smooth(b, x, r, false);
            g.residual(x, b, r);
        }
    }
    // The level below's right-hand side and solution, taken out of its buffers for the
    // recursion (no copy) and put back after.
    let mut bc = std::mem::take(&mut rest[0].b);
    let mut xc = std::mem::take(&mut rest[0].x);
    bc.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, bs)| {
        for (t, bv) in bs.iter_mut().enumerate() {
            let c = blk * CHUNK + t;
            let mut s = 0.0;
            for q in ip.tptr[c]..ip.tptr[c + 1] {
                s += f64::from(ip.tval[q]) * r[ip.trow[q] as usize];
            }
            *bv = s;
        }
    });
    vcycle(
        &levels[1..],
        &interps[1..],
        &bc,
        &mut xc,
        rest,
        coarse,
        None,
    );
    let xcr = &xc;
    x.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, xs)| {
        for (t, v) in xs.iter_mut().enumerate() {
            let i = blk * CHUNK + t;
            let mut s = 0.0;
            for p in ip.ptr[i]..ip.ptr[i + 1] {
                s += f64::from(ip.val[p]) * xcr[ip.col[p] as usize];
            }
            *v += s;
        }
    });
    rest[0].b = bc;
    rest[0].x = xc;
    match fine {
        Some(f) => f.smooth(b, x, r, true),
        None => g.smooth(b, x, r, true),
    }
}
