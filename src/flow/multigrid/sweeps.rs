//! The level's sweeps and residuals in its compressed rows: the ℓ1 hybrid Gauss–Seidel
//! sweep (forward, reversed, from zero) and `r = b − A x` (in full, or after a sweep from
//! zero), each loop written once over either column storage ([`super::columns`]).

use rayon::prelude::*;

use super::columns::{Absolute, Columns, Offsets};
use super::{Graph, CHUNK};

/// `$body` with `$cols` bound to the level's column storage ([`columns`]): one
/// monomorphised copy of a loop per storage, chosen once per call.
macro_rules! with_columns {
    ($g:expr, $cols:ident => $body:expr) => {
        if $g.near.is_empty() {
            let $cols = &Absolute(&$g.col);
            $body
        } else {
            let $cols = &Offsets(&$g.near);
            $body
        }
    };
}

impl Graph {
    /// `r = b − A x`.
    pub(super) fn residual(&self, x: &[f64], b: &[f64], r: &mut [f64]) {
        with_columns!(self, cols => self.residual_with(cols, x, b, r));
    }

    pub(super) fn residual_with(&self, cols: &impl Columns, x: &[f64], b: &[f64], r: &mut [f64]) {
        self.check_vectors(&[x, b, &*r]);
        r.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, rc)| {
            let i0 = blk * CHUNK;
            for (t, rv) in rc.iter_mut().enumerate() {
                let i = i0 + t;
                // SAFETY: `i < n` (the chunks cover `r`, of length `n`); the rows were checked
                // when the level was built (`check_rows`: pointers within the entries, columns
                // below `n`) and the vectors' lengths above.
                unsafe {
                    let mut v = b.get_unchecked(i) - self.d.get_unchecked(i) * x.get_unchecked(i);
                    for p in *self.ptr.get_unchecked(i)..*self.ptr.get_unchecked(i + 1) {
                        v += f64::from(*self.w.get_unchecked(p)) * x.get_unchecked(cols.at(p, i));
                    }
                    *rv = v;
                }
            }
        });
    }

    /// `y = A x` from the stored faces.
    pub(super) fn product(&self, x: &[f64], y: &mut [f64]) {
        with_columns!(self, cols => self.product_with(cols, x, y));
    }

    fn product_with(&self, cols: &impl Columns, x: &[f64], y: &mut [f64]) {
        self.check_vectors(&[x, &*y]);
        y.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, yc)| {
            let i0 = blk * CHUNK;
            for (t, yv) in yc.iter_mut().enumerate() {
                let i = i0 + t;
                // SAFETY: as in `residual`.
                unsafe {
                    let mut v = 0.0;
                    for p in *self.ptr.get_unchecked(i)..*self.ptr.get_unchecked(i + 1) {
                        v += f64::from(*self.w.get_unchecked(p)) * x.get_unchecked(cols.at(p, i));
                    }
                    *yv = self.d.get_unchecked(i) * x.get_unchecked(i) - v;
                }
            }
        });
    }

    /// What the unchecked loops rely on beyond `check_rows`: stored rows (not a level
    /// applied from the stencil) and vectors of the level's size.
    pub(super) fn check_vectors(&self, vs: &[&[f64]]) {
        assert!(
            self.ptr.len() == self.n + 1 && self.d.len() == self.n && self.out.len() == self.n,
            "a level with stored rows"
        );
        assert!(
            self.near.len() == self.w.len()
                || (self.near.is_empty() && self.col.len() == self.w.len()),
            "a column per face, in one of the two storages"
        );
        assert!(
            vs.iter().all(|v| v.len() == self.n),
            "vectors of the level's size"
        );
    }

    /// ℓ1 hybrid Gauss–Seidel sweep (module docs); `old` is scratch of size `n`.
    ///
    /// The face to the row swept just before (`i − 1`, or `i + 1` when `reverse`) is added
    /// last and the divisor is applied as its reciprocal: the only dependence from one row
    /// to the next is then one multiply-add and one multiply, not the whole row's sum and a
    /// division. The loops index without bounds checks (what they rely on is checked once
    /// per level by `check_rows`, and the vectors' lengths here), which would otherwise add
    /// a compare and a branch to every read of a column, a weight and a value.
    pub(super) fn smooth(&self, b: &[f64], x: &mut [f64], old: &mut [f64], reverse: bool) {
        self.check_vectors(&[&*x, b, &*old]);
        old.copy_from_slice(x);
        self.smooth_from_copy(b, x, old, reverse);
    }

    /// [`Graph::smooth`] with `old` already a copy of `x` (written by the pass before it).
    pub(super) fn smooth_from_copy(&self, b: &[f64], x: &mut [f64], old: &[f64], reverse: bool) {
        with_columns!(self, cols => self.smooth_with(cols, b, x, old, reverse));
    }

    pub(super) fn smooth_with(
        &self,
        cols: &impl Columns,
        b: &[f64],
        x: &mut [f64],
        old: &[f64],
        reverse: bool,
    ) {
        self.check_vectors(&[&*x, b, old]);
        x.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, xc)| {
            let i0 = blk * CHUNK;
            let len = xc.len();
            let xp = xc.as_mut_ptr();
            let zero = 0.0f64;
            let update = |t: usize| {
                let i = i0 + t;
                // The row swept just before this one (none at the block's edge).
                let prev = if reverse { i + 1 } else { i.wrapping_sub(1) };
                // SAFETY: `i0 ≤ i < i0 + len ≤ n`; columns are below `n` and pointers within
                // the entries (`check_rows`); a column in the block indexes `xc` at `j − i0`.
                unsafe {
                    let mut v = b.get_unchecked(i) - self.d.get_unchecked(i) * *xp.add(t);
                    let mut w_prev = 0.0;
                    // Each face's value chosen by selects, not branches: where a face lies
                    // (this block, another, the row just swept) follows no pattern a branch
                    // predictor learns on a contact gap. The row just swept reads a zero
                    // here and is added last.
                    for p in *self.ptr.get_unchecked(i)..*self.ptr.get_unchecked(i + 1) {
                        let j = cols.at(p, i);
                        let w = f64::from(*self.w.get_unchecked(p));
                        let rel = j.wrapping_sub(i0);
                        let inside = rel < len;
                        let is_prev = inside && j == prev;
                        let src: *const f64 = if is_prev {
                            &zero
                        } else if inside {
                            xp.add(rel)
                        } else {
                            old.as_ptr().add(j)
                        };
                        w_prev = if is_prev { w } else { w_prev };
                        v += w * *src;
                    }
                    let inv = 1.0 / (self.d.get_unchecked(i) + self.out.get_unchecked(i));
                    let prel = prev.wrapping_sub(i0);
                    if prel < len {
                        v += w_prev * *xp.add(prel);
                    }
                    *xp.add(t) += v * inv;
                }
            };
            if reverse {
                for t in (0..len).rev() {
                    update(t);
                }
            } else {
                for t in 0..len {
                    update(t);
                }
            }
        });
    }

    /// The forward sweep of [`Graph::smooth`] from `x = 0`, written into `x`: every value a
    /// row reads that is not yet swept is 0, so only its faces to the rows before it in its
    /// block are read (columns ascending: the row's leading part),
    /// `x_i = (b_i + Σ_{i0 ≤ j < i} w_ij x_j) / (d_i + out_i)`.
    pub(super) fn smooth_from_zero(&self, b: &[f64], x: &mut [f64]) {
        with_columns!(self, cols => self.smooth_from_zero_with(cols, b, x));
    }

    pub(super) fn smooth_from_zero_with(&self, cols: &impl Columns, b: &[f64], x: &mut [f64]) {
        self.check_vectors(&[&*x, b]);
        x.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, xc)| {
            let i0 = blk * CHUNK;
            for t in 0..xc.len() {
                let i = i0 + t;
                // SAFETY: as in `smooth`; a column in `[i0, i)` indexes `xc` at `j − i0 < t`.
                unsafe {
                    let (p0, p1) = (*self.ptr.get_unchecked(i), *self.ptr.get_unchecked(i + 1));
                    let mut p = p0;
                    // Faces to earlier blocks read old values, which are 0.
                    while p < p1 && cols.at(p, i) < i0 {
                        p += 1;
                    }
                    let mut v = *b.get_unchecked(i);
                    while p < p1 {
                        let j = cols.at(p, i);
                        if j >= i {
                            break;
                        }
                        v += f64::from(*self.w.get_unchecked(p)) * xc.get_unchecked(j - i0);
                        p += 1;
                    }
                    *xc.get_unchecked_mut(t) =
                        v / (self.d.get_unchecked(i) + self.out.get_unchecked(i));
                }
            }
        });
    }

    /// `r = b − A x` right after [`Graph::smooth_from_zero`] gave `x`, without reading `b`
    /// or the faces that sweep read: row `i` was solved with the faces to rows before it in
    /// its block, so `r_i = out_i x_i + Σ_{j ∉ [i0, i)} w_ij x_j`.
    pub(super) fn residual_after_zero_sweep(&self, x: &[f64], r: &mut [f64]) {
        with_columns!(self, cols => self.residual_after_zero_sweep_with(cols, x, r));
    }

    pub(super) fn residual_after_zero_sweep_with(
        &self,
        cols: &impl Columns,
        x: &[f64],
        r: &mut [f64],
    ) {
        self.check_vectors(&[x, &*r]);
        r.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, rc)| {
            let i0 = blk * CHUNK;
            for (t, rv) in rc.iter_mut().enumerate() {
                let i = i0 + t;
                // SAFETY: as in `residual`.
                unsafe {
                    let mut v = self.out.get_unchecked(i) * x.get_unchecked(i);
                    // The faces the sweep read give a zero term by a select, not a branch
                    // (as in `smooth_with`).
                    for p in *self.ptr.get_unchecked(i)..*self.ptr.get_unchecked(i + 1) {
                        let j = cols.at(p, i);
                        let term = f64::from(*self.w.get_unchecked(p)) * x.get_unchecked(j);
                        v += if j.wrapping_sub(i0) < i - i0 {
                            0.0
                        } else {
                            term
                        };
                    }
                    *rv = v;
                }
            }
        });
    }
}
