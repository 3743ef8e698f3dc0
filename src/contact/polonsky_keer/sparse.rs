//! Sparse corrections: a few non-linear pressure changes `d` of an update (truncations,
//! `I_ol` entries) applied to the gap or the displacement by direct summation with the
//! influence table `C e_0`, instead of a fresh FFT product `C p`.

use std::borrow::Cow;

use rayon::prelude::*;

use super::passes::{combine, Acc, Work};
use super::{CHUNK, SPARSE_MAX};

impl Work<'_> {
    /// Gather the last update's changes `(index, d)` in index order (valid when
    /// `n_nl ≤ SPARSE_MAX`, so no chunk overflowed its slots).
    pub(super) fn gather_changes(&mut self) {
        self.changes.clear();
        for (c, a) in self.parts.iter().enumerate() {
            let k = a.n_nl.min(SPARSE_MAX);
            self.changes
                .extend_from_slice(&self.slots[c * SPARSE_MAX..c * SPARSE_MAX + k]);
        }
        // These changes are applied here: the changes field goes back to zero.
        if !self.changes_field.is_empty() {
            for &(i, _) in &self.changes {
                self.changes_field[i] = 0.0;
            }
        }
    }

    /// Build the influence table `C e_0` on first use (one operator application, into `r`,
    /// which is scratch between an update and the next direction).
    pub(super) fn ensure_table(&mut self) {
        if self.table.is_empty() {
            self.r.fill(0.0);
            self.r[0] = 1.0;
            // Its capacity was reserved (fallibly) with the other work arrays.
            let mut table = std::mem::take(&mut self.table).into_owned();
            table.resize(self.r.len(), 0.0);
            self.op.apply(&self.r, &mut table);
            self.applies += 1;
            self.table = Cow::Owned(table);
        }
    }

    /// Displacement control: `g ← g + C d` for the gathered changes, and the reductions of
    /// the corrected gap.
    pub(super) fn correct_gap(&mut self) -> Acc {
        let (ny, nx, periodic) = (self.ny, self.nx, self.periodic);
        let Work {
            p,
            g,
            table,
            changes,
            parts,
            ..
        } = self;
        let (p, table, changes) = (&*p, &**table, &*changes);
        parts
            .par_iter_mut()
            .zip(g.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, (acc, gc))| {
                let lo = c * CHUNK;
                add_sparse(gc, lo, changes, table, ny, nx, periodic);
                let mut a = Acc::ZERO;
                for (&pi, &gi) in p[lo..lo + gc.len()].iter().zip(gc.iter()) {
                    a.observe(pi, gi);
                }
                *acc = a;
            });
        combine(parts)
    }

    /// Load control: `u ← u + C d` for the gathered changes, and `Σ p`, `Σ_{I_c} (max h − h)`,
    /// `Σ_{I_c} u` of the corrected state.
    pub(super) fn correct_u(&mut self) -> Acc {
        let (ny, nx, periodic, h, hmax) = (self.ny, self.nx, self.periodic, self.h, self.hmax);
        let Work {
            p,
            u,
            table,
            changes,
            parts,
            ..
        } = self;
        let (p, table, changes) = (&*p, &**table, &*changes);
        parts
            .par_iter_mut()
            .zip(u.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, (acc, uc))| {
                let lo = c * CHUNK;
                add_sparse(uc, lo, changes, table, ny, nx, periodic);
                let mut a = Acc::ZERO;
                for (i, &ui) in uc.iter().enumerate() {
                    a.observe_load(p[lo + i], hmax - h[lo + i], ui);
                }
                *acc = a;
            });
        combine(parts)
    }
}

/// `out[k − lo] += Σ_(b, d) C_{k b} d` for the flat indices `k` of the chunk `out` starting at
/// `lo`, with `C` given by the table of [`Work::table`]. Each row segment is split where the
/// table index wraps or reflects so the inner loops run over contiguous slices; every element
/// adds the changes in their (index) order, whatever the thread count.
pub(crate) fn add_sparse(
    out: &mut [f64],
    lo: usize,
    changes: &[(usize, f64)],
    table: &[f64],
    ny: usize,
    nx: usize,
    periodic: bool,
) {
    let hi = lo + out.len();
    let mut start = lo;
    while start < hi {
        let i = start / nx;
        let ja = start % nx;
        let end = ((i + 1) * nx).min(hi);
        let jb = ja + (end - start);
        let seg = &mut out[start - lo..end - lo];
        for &(b, d) in changes {
            let (i0, j0) = (b / nx, b % nx);
            let row = if periodic {
                (i + ny - i0) % ny
            } else {
                i.abs_diff(i0)
            };
            let krow = &table[row * nx..(row + 1) * nx];
            // Columns j < j0 and j ≥ j0 of this segment.
            let split = j0.clamp(ja, jb);
            let (left, right) = seg.split_at_mut(split - ja);
            if !left.is_empty() {
                // Here ja < j0.
                if periodic {
                    // Table column j − j0 + nx.
                    let k0 = ja + nx - j0;
                    let n_left = left.len();
                    for (v, &k) in left.iter_mut().zip(&krow[k0..k0 + n_left]) {
                        *v += d * k;
                    }
                } else {
                    // Table column j0 − j, decreasing along the segment.
                    let k_hi = j0 - ja;
                    let k_lo = k_hi + 1 - left.len();
                    for (v, &k) in left.iter_mut().zip(krow[k_lo..=k_hi].iter().rev()) {
                        *v += d * k;
                    }
                }
            }
            if !right.is_empty() {
                // Here split ≥ j0: table column j − j0.
                let k0 = split - j0;
                let n_right = right.len();
                for (v, &k) in right.iter_mut().zip(&krow[k0..k0 + n_right]) {
                    *v += d * k;
                }
            }
        }
        start = end;
    }
}
