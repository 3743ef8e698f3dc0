//! The updatable Cholesky factor `L Lᵀ = C_PP` of the contact block that the exact solvers
//! ([`crate::contact::lawson_hanson`]) keep across iterations and solves.
//!
//! `C_PP` rows come from the Love kernel table. The factor is updated, not recomputed, when
//! points enter (a forward solve per point, or a blocked TRSM + Cholesky of the new block) or
//! leave (a row-wise rank-one update, O(k²)). The forward half of each solve, `L⁻¹ b_P`, is
//! kept: rows of `L` depend only on the points before them, so after an append only the new
//! rows are forward-substituted.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch};
use faer::linalg::matmul::matmul;
use faer::linalg::matmul::triangular::{matmul as matmul_tri, BlockStructure};
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::{Accum, Mat, MatMut, MatRef, Par};
use rayon::prelude::*;

use crate::alloc;
use crate::dense_scratch;
use crate::elastic::kernel::Kernel;
use crate::elastic::memory;
use crate::error::{Error, Result};

const NOT_IN_P: usize = usize::MAX;

/// Threads for a dense kernel of about `work` multiply-adds: below ~1/4 M the cost of waking
/// a second thread exceeds the gain (small grids do hundreds of such calls per solve).
/// Above, a fixed split into [`DENSE_TASKS`] tasks, not one per available thread: faer
/// partitions (and so sums) by the task count, and a count that followed the machine would
/// make the last bits of the pressures depend on it.
fn par_for(work: usize) -> Par {
    if work < (1 << 18) {
        Par::Seq
    } else {
        Par::rayon(DENSE_TASKS)
    }
}

/// Tasks of a large dense kernel (see [`par_for`]).
const DENSE_TASKS: usize = 4;

/// Cholesky factor `L Lᵀ = C_PP` of the passive block, stored row-major with a row stride of
/// `cap` (only the lower triangle of each row is meaningful).
pub struct Factor {
    cap: usize,
    l: Vec<f64>,
    /// Flat grid indices of `P`, in factor order.
    pub idx: Vec<usize>,
    /// `pos[i]` = position of grid point `i` in `idx`, or `NOT_IN_P`.
    pos: Vec<usize>,
    memory_limit: u64,
    /// The last appended block's `R = L⁻¹ C_PJ` (column-major) and `S = C_JJ − RᵀR`, so
    /// points of that block can be dropped again without redoing the TRSM.
    tail: Option<Tail>,
    /// `y = L⁻¹ b_P` for the current right-hand side; its first `fwd_ok` entries are valid.
    /// Row `i` of `L` only depends on the points up to `i`, so appending keeps that prefix
    /// and a solve then only forward-substitutes the new rows.
    fwd: Vec<f64>,
    fwd_ok: usize,
    /// The threads the dense products run on have their packing scratch
    /// ([`dense_scratch::ensure`]).
    scratch_ready: bool,
}

struct Tail {
    k0: usize,
    r: Vec<f64>,
    s: Mat<f64>,
}

impl Factor {
    /// An empty factor for a grid of `n_points`; `Error::TooLarge` when its index map cannot
    /// be allocated.
    pub fn try_new(n_points: usize, memory_limit: u64) -> Result<Self> {
        Ok(Factor {
            cap: 0,
            l: Vec::new(),
            idx: Vec::new(),
            pos: alloc::try_filled(n_points, NOT_IN_P, "the contact-set index map")?,
            memory_limit,
            tail: None,
            fwd: Vec::new(),
            fwd_ok: 0,
            scratch_ready: false,
        })
    }

    /// [`Factor::try_new`] for tests, where the sizes are small.
    #[cfg(test)]
    pub fn new(n_points: usize, memory_limit: u64) -> Self {
        Self::try_new(n_points, memory_limit).expect("test grids are small")
    }

    /// Forget the cached forward solve (the right-hand side changed).
    pub fn new_rhs(&mut self) {
        self.fwd_ok = 0;
    }

    pub fn len(&self) -> usize {
        self.idx.len()
    }

    pub fn is_empty(&self) -> bool {
        self.idx.is_empty()
    }

    pub fn contains(&self, i: usize) -> bool {
        self.pos[i] != NOT_IN_P
    }

    fn lower(&self, k: usize) -> MatRef<'_, f64> {
        if k == 0 {
            return MatRef::from_row_major_slice_with_stride(&[], 0, 0, 1);
        }
        MatRef::from_row_major_slice_with_stride(&self.l[..(k - 1) * self.cap + k], k, k, self.cap)
    }

    fn reserve(&mut self, k: usize, k_bound: usize) -> Result<()> {
        if k <= self.cap {
            return Ok(());
        }
        let grown = (self.cap + self.cap / 2).max(k).max(64).min(k_bound.max(k));
        // While growing, the old factor is copied into the new one: both are held at once.
        let need = memory::dense_factor_growth(grown, self.cap);
        let what = format!(
            "growing the Cholesky factor of the contact block to {grown} rows for {k} contact \
             points (a {grown}² new factor while the {}² old one is copied into it; \
             solver='polonsky-keer' needs no factor)",
            self.cap
        );
        if need > self.memory_limit {
            return Err(Error::TooLarge {
                bytes: need,
                limit: self.memory_limit,
                what,
            });
        }
        let mut l: Vec<f64> = alloc::try_zeroed(grown * grown, &what)?;
        let (old_cap, old_k) = (self.cap, self.idx.len());
        l.par_chunks_mut(grown)
            .take(old_k)
            .enumerate()
            .for_each(|(i, row)| {
                row[..=i].copy_from_slice(&self.l[i * old_cap..i * old_cap + i + 1])
            });
        self.l = l;
        self.cap = grown;
        Ok(())
    }

    pub fn clear(&mut self) {
        self.tail = None;
        self.fwd_ok = 0;
        for &i in &self.idx {
            self.pos[i] = NOT_IN_P;
        }
        self.idx.clear();
    }

    /// Add the points `new` (not yet in `P`) at the end of the factor:
    /// `R = L⁻¹ C_PJ`, `L_JJ L_JJᵀ = C_JJ − Rᵀ R`.
    pub fn append(&mut self, kernel: &Kernel, new: &[usize], k_bound: usize) -> Result<()> {
        let k = self.idx.len();
        let nb = new.len();
        if nb == 0 {
            return Ok(());
        }
        self.reserve(k + nb, k_bound)?;
        let need = memory::dense_factor_update(self.cap, k, nb);
        if need > self.memory_limit {
            return Err(Error::TooLarge {
                bytes: need,
                limit: self.memory_limit,
                what: format!(
                    "adding {nb} points to the Cholesky factor of a {k}-point contact block \
                     (the {}² factor and the update's {k} × {nb} and {nb} × {nb} blocks)",
                    self.cap
                ),
            });
        }
        if !self.scratch_ready && (k + nb).pow(3) > dense_scratch::UNPACKED_PRODUCT {
            // Before the first packed product: a refusal, not an abort, when the CPU-sized
            // scratch does not fit.
            dense_scratch::ensure(Par::rayon(DENSE_TASKS))?;
            self.scratch_ready = true;
        }
        let mut r = kernel.cross_block(&self.idx, new)?;
        if k > 0 {
            let rm = MatMut::from_column_major_slice_mut(&mut r, k, nb);
            solve_lower_triangular_in_place(self.lower(k), rm, par_for(k * nb));
        }
        // Only the lower triangle of S is formed and read (the Cholesky below reads no more).
        let jc = kernel.coords(new);
        let mut s = Mat::<f64>::zeros(nb, nb);
        let fill_col = |(b, mut col): (usize, MatMut<'_, f64>)| {
            for a in b..nb {
                col[(a, 0)] = kernel.coeff_at(jc[a], jc[b]);
            }
        };
        if nb * nb < 1 << 16 {
            (0..nb).for_each(|b| fill_col((b, s.as_mut().subcols_mut(b, 1))));
        } else {
            s.par_col_chunks_mut(1).enumerate().for_each(fill_col);
        }
        if k == 0 {
            // S = C_JJ: dropping points of this block again is a plain re-append (there is no
            // TRSM to save), so S is factored in place rather than kept.
            self.tail = None;
            return self.write_tail(k, new, &r, s);
        }
        let rr = MatRef::from_column_major_slice(&r, k, nb);
        matmul_tri(
            s.as_mut(),
            BlockStructure::TriangularLower,
            Accum::Add,
            rr.transpose(),
            BlockStructure::Rectangular,
            rr,
            BlockStructure::Rectangular,
            -1.0,
            par_for(k * nb),
        );
        self.write_tail(k, new, &r, s.clone())?;
        self.tail = Some(Tail { k0: k, r, s });
        Ok(())
    }

    /// Factor `S` (lower triangle) and write the rows `[Rᵀ, L_JJ]` after position `k`.
    /// `S` is factored in its own contiguous column-major storage: faer 0.24's in-place
    /// Cholesky gives wrong results on a row-major view whose row stride exceeds its width,
    /// which is what the factor's rows are.
    fn write_tail(&mut self, k: usize, new: &[usize], r: &[f64], mut ljj: Mat<f64>) -> Result<()> {
        let nb = new.len();
        let par = par_for(nb * nb);
        let what = format!("the scratch of a {nb}-point Cholesky update");
        let req = cholesky_in_place_scratch::<f64>(nb, par, Default::default());
        let mut mem =
            MemBuffer::try_new(req).map_err(|_| alloc::refused(req.size_bytes() as u64, &what))?;
        cholesky_in_place(
            ljj.as_mut(),
            Default::default(),
            par,
            MemStack::new(&mut mem),
            Default::default(),
        )
        .map_err(|_| Error::NotConverged {
            iterations: 0,
            residual: f64::NAN,
            what: "Cholesky update of the contact block (lost positive definiteness)".into(),
        })?;
        let cap = self.cap;
        self.fwd_ok = self.fwd_ok.min(k);
        let rows = &mut self.l[k * cap..(k + nb) * cap];
        let copy_row = |(t, row): (usize, &mut [f64])| {
            row[..k].copy_from_slice(&r[t * k..(t + 1) * k]);
            for c in 0..=t {
                row[k + c] = ljj[(t, c)];
            }
        };
        if nb * (k + nb) < 1 << 16 {
            rows.chunks_mut(cap).enumerate().for_each(copy_row);
        } else {
            rows.par_chunks_mut(cap).enumerate().for_each(copy_row);
        }
        for &i in &self.idx[k..] {
            self.pos[i] = NOT_IN_P;
        }
        self.idx.truncate(k);
        for (t, &i) in new.iter().enumerate() {
            self.pos[i] = k + t;
        }
        self.idx.extend_from_slice(new);
        Ok(())
    }

    /// Keep only the points of the last appended block with `keep[t]` (t indexes that block):
    /// reuses its `R` and `S`, so this costs a Cholesky of the kept block only.
    pub fn shrink_tail(&mut self, kernel: &Kernel, keep: &[bool], k_bound: usize) -> Result<()> {
        let tail = match self.tail.take() {
            Some(t) if t.k0 + keep.len() == self.idx.len() => t,
            _ => {
                // No cached block (or it no longer matches): truncate and re-append.
                let k0 = self.idx.len() - keep.len();
                let again: Vec<usize> = self.idx[k0..]
                    .iter()
                    .zip(keep)
                    .filter(|(_, &kp)| kp)
                    .map(|(&i, _)| i)
                    .collect();
                self.truncate(k0);
                return self.append(kernel, &again, k_bound);
            }
        };
        let k = tail.k0;
        let sel: Vec<usize> = (0..keep.len()).filter(|&t| keep[t]).collect();
        let new: Vec<usize> = sel.iter().map(|&t| self.idx[k + t]).collect();
        let mut r = Vec::with_capacity(k * sel.len());
        for &t in &sel {
            r.extend_from_slice(&tail.r[t * k..(t + 1) * k]);
        }
        // Lower triangle only, as `append` left it (sel is increasing, so a ≥ b ⇒ sel[a] ≥ sel[b]).
        let s = Mat::<f64>::from_fn(sel.len(), sel.len(), |a, b| {
            if a >= b {
                tail.s[(sel[a], sel[b])]
            } else {
                0.0
            }
        });
        if new.is_empty() {
            self.truncate(k);
            return Ok(());
        }
        self.write_tail(k, &new, &r, s.clone())?;
        self.tail = Some(Tail { k0: k, r, s });
        Ok(())
    }

    /// Drop the trailing points, keeping the first `k`.
    pub fn truncate(&mut self, k: usize) {
        if self.tail.as_ref().is_some_and(|t| t.k0 != k) {
            self.tail = None;
        }
        self.fwd_ok = self.fwd_ok.min(k);
        for &i in &self.idx[k..] {
            self.pos[i] = NOT_IN_P;
        }
        self.idx.truncate(k);
    }

    /// Remove the point at position `t`: the rows below lose column `t` and the trailing
    /// block takes the rank-one update `L₂₂L₂₂ᵀ + v vᵀ` (v = old column t), row by row so
    /// every access is contiguous. O((k − t)·k).
    pub fn remove_at(&mut self, t: usize) {
        self.tail = None;
        self.fwd_ok = self.fwd_ok.min(t);
        let k = self.idx.len();
        let cap = self.cap;
        // Rotations for the trailing columns, computed row by row: for column j, with
        // c = r/l_jj, s = v/l_jj (so c² − s² = 1), l_ij ← (l_ij + s·v)/c and
        // v ← (v − s·l_ij)/c. Kept as (1/c, s/c): the recurrence in v is then one
        // multiply-add per column, with no division on its dependency chain.
        let mut cs: Vec<(f64, f64)> = Vec::with_capacity(k - t);
        for i in t + 1..k {
            let (head, tail) = self.l.split_at_mut(i * cap);
            let row = &mut tail[..=i];
            let mut v = row[t];
            for (x, &(ic, sc)) in row[t + 1..i].iter_mut().zip(&cs) {
                let lij = *x * ic + sc * v;
                v = v * ic - sc * *x;
                *x = lij;
            }
            let lii = row[i];
            let r = lii.hypot(v);
            cs.push((lii / r, v / r));
            row[i] = r;
            // Shift into row i − 1 without column t.
            let dst = &mut head[(i - 1) * cap..(i - 1) * cap + i];
            dst[..t].copy_from_slice(&row[..t]);
            dst[t..i].copy_from_slice(&row[t + 1..=i]);
        }
        let gone = self.idx.remove(t);
        self.pos[gone] = NOT_IN_P;
        for (p, &i) in self.idx.iter().enumerate().skip(t) {
            self.pos[i] = p;
        }
    }

    /// Keep the points for which `keep[position]` is true. Few removals use rank-one updates;
    /// many are cheaper as a truncation and a blocked re-append.
    pub fn retain(&mut self, kernel: &Kernel, keep: &[bool], k_bound: usize) -> Result<()> {
        let k = self.idx.len();
        let n_drop = keep.iter().filter(|&&x| !x).count();
        if n_drop == 0 {
            return Ok(());
        }
        let first = keep.iter().position(|&x| !x).unwrap_or(k);
        let tail = k - first;
        // Rank-one removals cost ~n_drop·tail·k; the re-append ~tail²·k/3 flops at BLAS-3 speed.
        if n_drop <= 4 || (n_drop as f64) * 8.0 < tail as f64 / 3.0 {
            for t in (first..k).rev() {
                if !keep[t] {
                    self.remove_at(t);
                }
            }
        } else {
            let again: Vec<usize> = (first..k)
                .filter(|&t| keep[t])
                .map(|t| self.idx[t])
                .collect();
            self.truncate(first);
            self.append(kernel, &again, k_bound)?;
        }
        Ok(())
    }

    /// `z = C_PP⁻¹ b_P` for the grid vector `b`, reusing the valid prefix of `L⁻¹ b_P`
    /// (callers announce a new `b` with [`Factor::new_rhs`]).
    pub fn solve_rhs(&mut self, b: &[f64], z: &mut Vec<f64>) {
        let k = self.idx.len();
        z.clear();
        if k == 0 {
            return;
        }
        let m = self.fwd_ok.min(k);
        let mut fwd = std::mem::take(&mut self.fwd);
        fwd.resize(k, 0.0);
        for (y, &i) in fwd[m..].iter_mut().zip(&self.idx[m..]) {
            *y = b[i];
        }
        let l = self.lower(k);
        if m < k {
            let (head, tail) = fwd.split_at_mut(m);
            let mut y_new = MatMut::from_column_major_slice_mut(tail, k - m, 1);
            if m > 0 {
                matmul(
                    y_new.as_mut(),
                    Accum::Add,
                    l.submatrix(m, 0, k - m, m),
                    MatRef::from_column_major_slice(head, m, 1),
                    -1.0,
                    par_for((k - m) * m / 64),
                );
            }
            solve_lower_triangular_in_place(
                l.submatrix(m, m, k - m, k - m),
                y_new,
                par_for((k - m) * (k - m) / 64),
            );
        }
        z.extend_from_slice(&fwd);
        solve_upper_triangular_in_place(
            l.transpose(),
            MatMut::from_column_major_slice_mut(z.as_mut_slice(), k, 1),
            par_for(k * k / 64),
        );
        self.fwd = fwd;
        self.fwd_ok = k;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;

    use crate::test_support::lcg;

    /// `C_PP⁻¹ b_P` by a fresh dense Cholesky of the block built directly from the kernel.
    fn dense_solve(ker: &Kernel, idx: &[usize], b: &[f64]) -> Vec<f64> {
        let k = idx.len();
        let c = ker.block(idx).unwrap();
        let cm = Mat::<f64>::from_fn(k, k, |a, bb| c[a + k * bb]);
        let rhs = Mat::<f64>::from_fn(k, 1, |a, _| b[idx[a]]);
        let x = faer::linalg::solvers::Solve::solve(&cm.llt(faer::Side::Lower).unwrap(), &rhs);
        (0..k).map(|a| x[(a, 0)]).collect()
    }

    #[test]
    fn cached_forward_solve_survives_every_update() {
        // Every way the factor changes (block appends, tail shrinks, rank-one removals,
        // truncation, retain by re-append) must leave `solve_rhs` equal to a fresh solve.
        let (ny, nx) = (11, 13);
        let n = ny * nx;
        let ker = Kernel::new(ny, nx, 0.7, 2.0);
        let b = lcg(11, n);
        let order: Vec<usize> = {
            let keys = lcg(12, n);
            let mut o: Vec<usize> = (0..n).collect();
            o.sort_by(|&a, &c| keys[a].total_cmp(&keys[c]));
            o
        };
        let mut f = Factor::new(n, 1 << 30);
        f.new_rhs();
        let mut z = Vec::new();
        let check = |f: &mut Factor, z: &mut Vec<f64>, step: &str| {
            f.solve_rhs(&b, z);
            let want = dense_solve(&ker, &f.idx, &b);
            let scale = want.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            for (t, (x, w)) in z.iter().zip(&want).enumerate() {
                assert!((x - w).abs() <= 1e-10 * scale, "{step}: z[{t}] {x} vs {w}");
            }
        };
        let mut at = 0;
        for (round, nb) in [7usize, 1, 20, 3, 33].into_iter().enumerate() {
            f.append(&ker, &order[at..at + nb], n).unwrap();
            at += nb;
            check(&mut f, &mut z, "append");
            if nb > 2 {
                let keep: Vec<bool> = (0..nb).map(|t| (t + round) % 3 != 0).collect();
                f.shrink_tail(&ker, &keep, n).unwrap();
                check(&mut f, &mut z, "shrink_tail");
            }
            if f.len() > 5 {
                f.remove_at(f.len() / 3);
                check(&mut f, &mut z, "remove_at");
                let keep: Vec<bool> = (0..f.len()).map(|t| t % 5 != 1).collect();
                f.retain(&ker, &keep, n).unwrap();
                check(&mut f, &mut z, "retain");
            }
        }
        let k = f.len();
        f.truncate(k / 2);
        check(&mut f, &mut z, "truncate");
        // A new right-hand side must not reuse the old forward solve.
        let b2: Vec<f64> = b.iter().map(|v| 1.0 - v).collect();
        f.new_rhs();
        f.solve_rhs(&b2, &mut z);
        let want = dense_solve(&ker, &f.idx, &b2);
        for (x, w) in z.iter().zip(&want) {
            assert!((x - w).abs() <= 1e-10 * w.abs().max(1.0));
        }
    }

    #[test]
    fn factor_updates_match_fresh_factorisation() {
        let ker = Kernel::new(9, 9, 1.0, 1.0);
        let mut f = Factor::new(81, 1 << 30);
        let set: Vec<usize> = (0..81).step_by(3).collect();
        f.append(&ker, &set[..10], 81).unwrap();
        for &i in &set[10..] {
            f.append(&ker, &[i], 81).unwrap();
        }
        f.remove_at(3);
        f.remove_at(0);
        f.remove_at(f.len() - 1);
        let b = lcg(5, 81);
        let mut x = Vec::new();
        f.new_rhs();
        f.solve_rhs(&b, &mut x);
        // Residual against the block built directly.
        let c = ker.block(&f.idx).unwrap();
        let k = f.len();
        for r in 0..k {
            let s: f64 = (0..k).map(|cc| c[r + k * cc] * x[cc]).sum();
            let want = b[f.idx[r]];
            assert!((s - want).abs() < 1e-12, "{s} vs {want}");
        }
    }
}

#[cfg(test)]
mod timing {
    use super::*;
    #[test]
    #[ignore]
    fn component_timings() {
        let ker = Kernel::new(129, 129, 1.0, 1.0);
        let mut f = Factor::new(129 * 129, 8 << 30);
        let set: Vec<usize> = (0..129 * 129).step_by(3).take(5000).collect();
        let t = std::time::Instant::now();
        f.append(&ker, &set, 20000).unwrap();
        eprintln!("append 5000 from empty: {:?}", t.elapsed());
        let b = vec![1.0; 129 * 129];
        let mut z = Vec::new();
        let t = std::time::Instant::now();
        for _ in 0..10 {
            f.new_rhs();
            f.solve_rhs(&b, &mut z);
        }
        eprintln!("solve k=5000: {:?} each", t.elapsed() / 10);
        let more: Vec<usize> = (1..129 * 129).step_by(3).take(300).collect();
        let t = std::time::Instant::now();
        f.append(&ker, &more, 20000).unwrap();
        eprintln!("append 300 at k=5000: {:?}", t.elapsed());
        let t = std::time::Instant::now();
        f.remove_at(100);
        eprintln!("remove_at(100) at k=5300: {:?}", t.elapsed());
    }
}
