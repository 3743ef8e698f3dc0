//! Lawson–Hanson NNLS on the normal equations of the contact problem.
//!
//! The frictionless contact of an elastic surface with a rigid flat is the convex QP
//!
//! ```text
//! min ½ pᵀ C p − bᵀ p,  p ≥ 0,    b_i = Δ − (max h − h_i),
//! ```
//!
//! whose gradient is `C p − b = −w = g` (the gap). Lawson & Hanson's active-set method, as used
//! by Bemporad & Paggi (IJSS 2015) and the percolation paper, keeps a passive (contact) set `P`,
//! the Cholesky factor `L Lᵀ = C_PP` and a feasible `p`:
//!
//! 1. `w = b − C p` (by FFT); stop when no free point has `w_i > tol·h_s`;
//! 2. add the free point with the largest interpenetration `w_j` to `P`;
//! 3. solve `C_PP z = b_P`; if some `z_i ≤ 0`, step back to the boundary of the feasible
//!    region, `p ← p + α (z − p)`, drop the points whose pressure reaches 0, repeat 3.
//!
//! `C` is never stored: `C_PP` rows come from the Love kernel table, `w` from the FFT operator.
//! The factor and its updates live in [`crate::contact::factor`].
//!
//! `Pivoting::Block` adds many of the most-interpenetrating free points per outer iteration
//! (dropping those whose trial pressure is not positive, falling back to a single Lawson–Hanson
//! step when none survives). Each outer iteration still ends at the exact minimiser on its
//! passive set with a strictly lower objective, so it terminates at the same unique minimiser
//! (C is SPD) — with far fewer, cache-friendly factor updates.

use rayon::prelude::*;

use crate::alloc;
use crate::contact::factor::Factor;
use crate::contact::kkt::kkt_certificate;
use crate::contact::problem::{CoarseCost, Solution, Solver};
use crate::elastic::kernel::Kernel;
use crate::elastic::operator::Operator;
use crate::error::{Error, Result};

/// How many free points enter the passive set per outer iteration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pivoting {
    /// Classic Lawson–Hanson: the single most-interpenetrating point (the paper's method).
    Single,
    /// Blocks of the most-interpenetrating points; same minimiser, far fewer updates.
    Block,
}

/// Options of a Lawson–Hanson solve.
#[derive(Clone, Debug)]
pub struct Options {
    /// Interpenetration tolerance relative to the height range `h_s`.
    pub tol: f64,
    pub max_iter: usize,
    pub pivoting: Pivoting,
    /// Upper bound on the bytes of the Cholesky factor.
    pub memory_limit: u64,
}

/// Where a solve starts.
pub enum Start<'a> {
    /// `p = 0`, empty passive set (the paper: "without warm starting").
    Cold,
    /// Keep the passive set (and its factor) of the previous solve.
    Previous,
    /// A given contact set (flat indices), e.g. from another solver or another level.
    Set(&'a [usize]),
}

/// `(max h, h_s)` of a height field.
pub fn height_stats(h: &[f64]) -> (f64, f64) {
    let (lo, hi) = h
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    (hi, hi - lo)
}

/// Lawson–Hanson contact solver bound to one surface; keeps its factor across solves so a
/// sweep over approaches can warm-start from the previous level.
pub struct LawsonHanson<'a> {
    kernel: &'a Kernel,
    op: &'a Operator,
    h: &'a [f64],
    pub factor: &'a mut Factor,
}

impl<'a> LawsonHanson<'a> {
    pub fn new(kernel: &'a Kernel, op: &'a Operator, h: &'a [f64], factor: &'a mut Factor) -> Self {
        LawsonHanson {
            kernel,
            op,
            h,
            factor,
        }
    }

    /// Solve for the imposed approach `approach` (≥ 0).
    pub fn solve(
        &mut self,
        approach: f64,
        start: Start<'_>,
        opts: &Options,
        should_stop: &(dyn Fn() -> bool + Sync),
    ) -> Result<Solution> {
        let n = self.h.len();
        let (hmax, hs) = height_stats(self.h);
        if !(approach.is_finite() && approach >= 0.0) {
            return Err(Error::invalid(
                "approach",
                format!("must be ≥ 0, got {approach}"),
            ));
        }
        let mut b: Vec<f64> = alloc::try_with_capacity(n, "the right-hand side")?;
        b.extend(self.h.iter().map(|&hi| approach - (hmax - hi)));
        let scale = if hs > 0.0 { hs } else { 1.0 };
        let tol_abs = opts.tol * scale;
        // Contact needs u_i = b_i ≥ 0 (free boundary: u ≥ 0), so the passive set never
        // exceeds the overlap count; periodic u can be negative, so no bound there.
        let k_bound = match self.op.boundary {
            crate::grid::Boundary::Free => b.iter().filter(|&&v| v >= 0.0).count(),
            crate::grid::Boundary::Periodic => n,
        };
        let mut p: Vec<f64> = alloc::try_zeroed(n, "the pressure field")?;
        let mut u: Vec<f64> = alloc::try_zeroed(n, "the displacement field")?;
        let mut iterations = 0usize;
        self.factor.new_rhs();
        match start {
            Start::Cold => self.factor.clear(),
            Start::Previous => {}
            Start::Set(set) => {
                self.factor.clear();
                let mut set: Vec<usize> = set.iter().copied().filter(|&i| i < n).collect();
                set.sort_unstable();
                set.dedup();
                self.factor.append(self.kernel, &set, k_bound)?;
            }
        }
        // Make the starting passive set feasible: drop points whose trial pressure is not
        // positive until every pressure on P is positive (from p = 0 these are α = 0 steps).
        loop {
            let k = self.factor.len();
            if k == 0 {
                break;
            }
            let mut z = Vec::new();
            self.factor.solve_rhs(&b, &mut z);
            let keep: Vec<bool> = z.iter().map(|&v| v > 0.0).collect();
            if keep.iter().all(|&x| x) {
                for (&i, &zi) in self.factor.idx.iter().zip(&z) {
                    p[i] = zi;
                }
                break;
            }
            self.factor.retain(self.kernel, &keep, k_bound)?;
            iterations += 1;
        }

        let mut skip: Vec<bool> = alloc::try_zeroed(n, "the skipped-point marks")?;
        let mut skipped: Vec<usize> = Vec::new();
        let mut z: Vec<f64> = Vec::new();
        loop {
            // u = C p. Only points of P carry pressure, so an empty P means p = 0 and u = 0:
            // a cold start needs no product.
            if self.factor.is_empty() {
                u.fill(0.0);
            } else {
                self.op.apply(&p, &mut u);
            }
            // w = b − u = −g on free points; the violators sorted by interpenetration.
            let violation = |i: usize| {
                let w = b[i] - u[i];
                (w > tol_abs && !self.factor.contains(i) && !skip[i]).then_some((w, i))
            };
            let mut viol: Vec<(f64, usize)> = if n < 1 << 14 {
                (0..n).filter_map(violation).collect()
            } else {
                (0..n).into_par_iter().filter_map(violation).collect()
            };
            if viol.is_empty() {
                break;
            }
            iterations += 1;
            if iterations > opts.max_iter {
                let worst = viol.iter().fold(0.0f64, |a, v| a.max(v.0));
                return Err(Error::NotConverged {
                    iterations: opts.max_iter,
                    residual: worst / scale,
                    what: "Lawson–Hanson".into(),
                });
            }
            if should_stop() {
                return Err(Error::Interrupted);
            }
            let k0 = self.factor.len();
            // Blocks grow with the set (k0/2), from 16: a larger floor over-shoots on small
            // grids and cold starts (measured at 33²–129²: floors 64 and 128 took up to 1.8×
            // longer, with more points entering only to leave again).
            let take = match opts.pivoting {
                Pivoting::Single => 1,
                Pivoting::Block => viol.len().min(16.max(k0 / 2)),
            };
            if take < viol.len() {
                viol.select_nth_unstable_by(take - 1, |a, c| {
                    c.0.total_cmp(&a.0).then(a.1.cmp(&c.1))
                });
                viol.truncate(take);
            }
            viol.sort_unstable_by(|a, c| c.0.total_cmp(&a.0).then(a.1.cmp(&c.1)));
            let mut new: Vec<usize> = viol.iter().map(|v| v.1).collect();
            self.factor.append(self.kernel, &new, k_bound)?;
            let mut progressed = false;
            // Inner loop: minimise on P, stepping back to feasibility.
            loop {
                let k = self.factor.len();
                self.factor.solve_rhs(&b, &mut z);
                // New points whose trial pressure is not positive leave first (α = 0 steps).
                let new_start = k - new.len();
                if z[new_start..].iter().any(|&v| v <= 0.0) {
                    let keep: Vec<bool> = z[new_start..].iter().map(|&zv| zv > 0.0).collect();
                    if keep.iter().any(|&kp| kp) {
                        self.factor.shrink_tail(self.kernel, &keep, k_bound)?;
                        new.retain(|&i| self.factor.contains(i));
                        continue;
                    }
                    if new.len() > 1 {
                        // Fall back to a single classic step with the worst point.
                        let mut first = vec![false; new.len()];
                        first[0] = true;
                        self.factor.shrink_tail(self.kernel, &first, k_bound)?;
                        new.truncate(1);
                        continue;
                    }
                    // A lone Lawson–Hanson candidate that cannot carry load: its
                    // interpenetration is at round-off; skip it until p changes.
                    // Finish the minimisation on the old set (earlier steps of this inner
                    // loop may have moved p) before looking for violators again.
                    skip[new[0]] = true;
                    skipped.push(new[0]);
                    self.factor.truncate(new_start);
                    new.clear();
                    continue;
                }
                // Old points: step back to the feasible boundary if some z ≤ 0.
                let mut alpha = 1.0f64;
                let mut blocking = None;
                for (t, &i) in self.factor.idx[..new_start].iter().enumerate() {
                    if z[t] <= 0.0 {
                        let a = p[i] / (p[i] - z[t]);
                        if a < alpha || blocking.is_none() && a <= alpha {
                            alpha = a;
                            blocking = Some(t);
                        }
                    }
                }
                if !new.is_empty() || blocking.is_some() {
                    progressed = true;
                }
                let Some(blocking) = blocking else {
                    for (&i, &zv) in self.factor.idx.iter().zip(&z) {
                        p[i] = zv;
                    }
                    break;
                };
                let mut keep = vec![true; k];
                for (t, &i) in self.factor.idx.iter().enumerate() {
                    let v = p[i] + alpha * (z[t] - p[i]);
                    // The blocking point leaves even if round-off left it a hair positive.
                    if t == blocking || v <= 0.0 {
                        p[i] = 0.0;
                        keep[t] = false;
                    } else {
                        p[i] = v;
                    }
                }
                self.factor.retain(self.kernel, &keep, k_bound)?;
                // After a step the new points carry positive pressure: from here on they are
                // ordinary members of P, handled by the step-back rule.
                new.clear();
                iterations += 1;
                if iterations > opts.max_iter {
                    return Err(Error::NotConverged {
                        iterations: opts.max_iter,
                        residual: f64::NAN,
                        what: "Lawson–Hanson (inner loop)".into(),
                    });
                }
            }
            if progressed {
                for i in skipped.drain(..) {
                    skip[i] = false;
                }
            }
        }
        // The loop ended right after computing u = C p for the final p.
        let mut gap: Vec<f64> = alloc::try_with_capacity(n, "the gap field")?;
        gap.extend((0..n).map(|i| u[i] - b[i]));
        let kkt = kkt_certificate(&p, &gap, scale);
        let contact_points = p.iter().filter(|&&v| v > 0.0).count();
        let sum_p: f64 = p.iter().sum();
        let dx = self.kernel.dx;
        Ok(Solution {
            solver: match opts.pivoting {
                Pivoting::Single => Solver::LawsonHanson,
                Pivoting::Block => Solver::ActiveSet,
            },
            pressure: p,
            displacement: u,
            gap,
            approach,
            iterations,
            fft_products: 0,
            preconditioner_products: 0,
            chord_steps: 0,
            single_products: 0,
            kkt,
            contact_points,
            plastic_points: 0,
            load: sum_p * dx * dx,
            mean_pressure: sum_p / n as f64,
            coarse: CoarseCost::default(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::elastic::operator::Operator;

    use crate::test_support::lcg;

    /// Projected Gauss–Seidel on the dense matrix: an independent reference.
    fn pgs(kernel: &Kernel, b: &[f64]) -> Vec<f64> {
        let n = b.len();
        let mut p = vec![0.0; n];
        for _ in 0..20000 {
            let mut change = 0.0f64;
            for i in 0..n {
                let mut r = b[i];
                for (j, &pj) in p.iter().enumerate() {
                    if j != i {
                        r -= kernel.coeff(i, j) * pj;
                    }
                }
                let v = (r / kernel.coeff(i, i)).max(0.0);
                change = change.max((v - p[i]).abs());
                p[i] = v;
            }
            if change < 1e-15 {
                break;
            }
        }
        p
    }

    fn run(ny: usize, nx: usize, seed: u64, frac: f64, pivoting: Pivoting) {
        let h = lcg(seed, ny * nx);
        let ker = Kernel::new(ny, nx, 1.0, 1.0);
        let op = Operator::free(&ker);
        let (hmax, hs) = height_stats(&h);
        let approach = frac * hs;
        let mut f = Factor::new(h.len(), 1 << 30);
        let mut lh = LawsonHanson::new(&ker, &op, &h, &mut f);
        let opts = Options {
            tol: 1e-12,
            max_iter: 100000,
            pivoting,
            memory_limit: 1 << 30,
        };
        let sol = lh.solve(approach, Start::Cold, &opts, &|| false).unwrap();
        let b: Vec<f64> = h.iter().map(|&v| approach - (hmax - v)).collect();
        let reference = pgs(&ker, &b);
        let pmax = reference.iter().fold(0.0f64, |a, &v| a.max(v));
        for (a, r) in sol.pressure.iter().zip(&reference) {
            assert!((a - r).abs() <= 1e-9 * pmax, "{a} vs {r}");
        }
        assert!(sol.kkt < 1e-11, "kkt {}", sol.kkt);
    }

    #[test]
    fn matches_projected_gauss_seidel() {
        for (s, &(ny, nx, f)) in [(6, 6, 0.3), (7, 5, 0.6), (8, 8, 0.9), (5, 9, 1.0)]
            .iter()
            .enumerate()
        {
            run(ny, nx, s as u64 + 1, f, Pivoting::Single);
            run(ny, nx, s as u64 + 1, f, Pivoting::Block);
        }
    }

    #[test]
    fn zero_approach_gives_zero_pressure() {
        let h = lcg(3, 25);
        let ker = Kernel::new(5, 5, 1.0, 1.0);
        let op = Operator::free(&ker);
        let mut f = Factor::new(h.len(), 1 << 30);
        let mut lh = LawsonHanson::new(&ker, &op, &h, &mut f);
        let opts = Options {
            tol: 1e-12,
            max_iter: 1000,
            pivoting: Pivoting::Single,
            memory_limit: 1 << 30,
        };
        let sol = lh.solve(0.0, Start::Cold, &opts, &|| false).unwrap();
        // Only the highest point touches, with zero pressure.
        assert!(sol.pressure.iter().all(|&v| v == 0.0));
        assert!(sol.gap.iter().all(|&g| g >= 0.0));
        assert!(lh.solve(-1.0, Start::Cold, &opts, &|| false).is_err());
    }

    #[test]
    fn too_large_is_refused() {
        let h = lcg(4, 400);
        let ker = Kernel::new(20, 20, 1.0, 1.0);
        let op = Operator::free(&ker);
        let mut f = Factor::new(h.len(), 1000);
        let mut lh = LawsonHanson::new(&ker, &op, &h, &mut f);
        let opts = Options {
            tol: 1e-12,
            max_iter: 100000,
            pivoting: Pivoting::Block,
            memory_limit: 1000,
        };
        match lh.solve(0.9, Start::Cold, &opts, &|| false) {
            Err(Error::TooLarge { .. }) => {}
            other => panic!("expected TooLarge, got {other:?}"),
        }
    }
}
