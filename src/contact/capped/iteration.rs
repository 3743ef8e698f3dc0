//! The capped iteration at a fixed approach: conjugate gradients on the points strictly
//! between the bounds, projection onto `[0, H]`, entry of overlapping free points and release
//! of capped points whose gap opens, and its fused chunked reductions.

use std::time::Instant;

use rayon::prelude::*;

use crate::alloc;
use crate::contact::polonsky_keer::{self as pk, default_max_iter, CHUNK};
use crate::contact::problem::{CoarseCost, Options, Problem, Solution, Solver};
use crate::elastic::operator::Operator;
use crate::error::{Error, Result};
use crate::grid::Boundary;

/// `x > 0` and not NaN.
#[inline]
pub(super) fn positive(x: f64) -> bool {
    x > 0.0
}

/// Partial reductions of one chunk.
#[derive(Clone, Copy, Debug)]
pub(super) struct Red {
    pub(super) n_c: usize,
    pub(super) n_pl: usize,
    pub(super) sum_p: f64,
    pub(super) sum_pg: f64,
    pub(super) gg: f64,
    pub(super) viol: f64,
    pub(super) bad: usize,
    pub(super) gt: f64,
    pub(super) rt: f64,
    pub(super) n_ol: usize,
    pub(super) n_ul: usize,
    pub(super) n_nl: usize,
}

impl Red {
    pub(super) const ZERO: Red = Red {
        n_c: 0,
        n_pl: 0,
        sum_p: 0.0,
        sum_pg: 0.0,
        gg: 0.0,
        viol: 0.0,
        bad: 0,
        gt: 0.0,
        rt: 0.0,
        n_ol: 0,
        n_ul: 0,
        n_nl: 0,
    };

    pub(super) fn merge(self, o: &Red) -> Red {
        Red {
            n_c: self.n_c + o.n_c,
            n_pl: self.n_pl + o.n_pl,
            sum_p: self.sum_p + o.sum_p,
            sum_pg: self.sum_pg + o.sum_pg,
            gg: self.gg + o.gg,
            viol: self.viol.max(o.viol),
            bad: self.bad + o.bad,
            gt: self.gt + o.gt,
            rt: self.rt + o.rt,
            n_ol: self.n_ol + o.n_ol,
            n_ul: self.n_ul + o.n_ul,
            n_nl: self.n_nl + o.n_nl,
        }
    }

    /// One point's share of the certificate, `G` and the set counts.
    #[inline(always)]
    pub(super) fn observe(&mut self, p: f64, g: f64, cap: f64) {
        if !g.is_finite() {
            self.bad += 1;
        }
        if p <= 0.0 {
            self.viol = self.viol.max(-g);
        } else if p >= cap {
            self.n_c += 1;
            self.n_pl += 1;
            self.sum_p += p;
            self.viol = self.viol.max(g);
        } else {
            let ag = g.abs();
            self.n_c += 1;
            self.sum_p += p;
            self.sum_pg += p * ag;
            self.gg += g * g;
            self.viol = self.viol.max(ag);
        }
    }

    /// Unscaled certificate (NaN on a non-finite gap).
    pub(super) fn certificate(&self) -> f64 {
        if self.bad > 0 {
            return f64::NAN;
        }
        let mut c = self.viol.max(0.0);
        if self.sum_p > 0.0 {
            c = c.max(self.sum_pg / self.sum_p);
        }
        c
    }
}

/// Map every chunk `[lo, hi)` to a partial result and combine them in chunk order.
pub(super) fn reduce(n: usize, f: impl Fn(usize, usize) -> Red + Sync) -> Red {
    let parts: Vec<Red> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| f(c * CHUNK, ((c + 1) * CHUNK).min(n)))
        .collect();
    parts.iter().fold(Red::ZERO, |a, b| a.merge(b))
}

/// The certificate's scale: `max(h_s, |Δ|)`, or `H · C_00` for a flat surface at `Δ = 0`.
pub(super) fn scale(hs: f64, delta: f64, cap: f64, c00: f64) -> f64 {
    let s = hs.max(delta.abs());
    if s > 0.0 {
        s
    } else {
        (cap * c00).max(f64::MIN_POSITIVE)
    }
}

/// The capped iteration at the approach `delta` from `p0` (clamped into `[0, H]`), with the
/// preconditioner `pre` when given. A preconditioned iteration that stalls (no new best
/// certificate in [`super::PRECONDITION_STALL`] iterations) or does not converge is started
/// over from `p0` with plain steps; the returned counts include both attempts.
#[allow(clippy::too_many_arguments)]
pub(super) fn run(
    op: &Operator,
    table: Option<&[f64]>,
    problem: &Problem,
    hmax: f64,
    hs: f64,
    c00: f64,
    delta: f64,
    cap: f64,
    opts: &Options,
    pre: Option<&Operator>,
    p0: Option<Vec<f64>>,
) -> Result<Solution> {
    if pre.is_none() {
        let mut spent = [0; 2];
        return run_steps(
            op, table, problem, hmax, hs, c00, delta, cap, opts, None, p0, &mut spent,
        );
    }
    let again = p0.clone();
    let mut spent = [0; 2];
    let first = run_steps(
        op, table, problem, hmax, hs, c00, delta, cap, opts, pre, p0, &mut spent,
    );
    match first {
        Err(Error::NotConverged { iterations, .. }) => {
            let mut unused = [0; 2];
            let mut sol = run_steps(
                op,
                table,
                problem,
                hmax,
                hs,
                c00,
                delta,
                cap,
                opts,
                None,
                again,
                &mut unused,
            )?;
            sol.iterations += iterations;
            sol.fft_products += spent[0];
            sol.preconditioner_products += spent[1];
            Ok(sol)
        }
        other => other,
    }
}

/// One attempt of [`run`]; a stalled attempt leaves its FFT products and preconditioner
/// applications in `spent`.
#[allow(clippy::too_many_arguments)]
fn run_steps(
    op: &Operator,
    table: Option<&[f64]>,
    problem: &Problem,
    hmax: f64,
    hs: f64,
    c00: f64,
    delta: f64,
    cap: f64,
    opts: &Options,
    pre: Option<&Operator>,
    p0: Option<Vec<f64>>,
    spent: &mut [usize; 2],
) -> Result<Solution> {
    let (ny, nx) = (problem.ny, problem.nx);
    let n = ny * nx;
    let h = problem.heights;
    let top = hmax - delta;
    let sc = scale(hs, delta, cap, c00);
    let max_iter = opts.max_iter.unwrap_or_else(|| default_max_iter(n));
    let mut p: Vec<f64> = match p0 {
        Some(v) if v.len() == n => v,
        _ => alloc::try_zeroed(n, "the pressure field")?,
    };
    p.par_iter_mut().for_each(|v| *v = v.clamp(0.0, cap));
    let mut u: Vec<f64> = alloc::try_zeroed(n, "the displacement field")?;
    let mut g: Vec<f64> = alloc::try_zeroed(n, "the gap field")?;
    let mut t: Vec<f64> = alloc::try_zeroed(n, "the conjugate direction")?;
    let mut r: Vec<f64> = alloc::try_zeroed(n, "the operator work field")?;
    let mut applies = 0usize;
    // The preconditioner `M = E*|q|/2`; its residual `z = M g` on the free set lives in `r`.
    let mut pre = pre;
    let mut pre_applies = 0usize;
    let mut last_pre = false;
    let mut best_cert = f64::INFINITY;
    let mut best_at = 0usize;
    // Influence table of the sparse corrections (built on first use when not given).
    let periodic = op.boundary == Boundary::Periodic;
    let sparse_max = pk::sparse_limit(op.boundary);
    let mut own_table: Vec<f64> = Vec::new();

    // Fresh product and gap.
    let fresh_gap = |p: &[f64], u: &mut [f64], g: &mut [f64], applies: &mut usize| -> Red {
        if p.par_iter().any(|&v| v > 0.0) {
            op.apply(p, u);
            *applies += 1;
        } else {
            u.par_iter_mut().for_each(|v| *v = 0.0);
        }
        g.par_chunks_mut(CHUNK)
            .zip(u.par_chunks(CHUNK))
            .enumerate()
            .for_each(|(c, (gc, uc))| {
                let lo = c * CHUNK;
                for i in 0..gc.len() {
                    gc[i] = top - h[lo + i] + uc[i];
                }
            });
        reduce(n, |lo, hi| {
            let mut a = Red::ZERO;
            for i in lo..hi {
                a.observe(p[i], g[i], cap);
            }
            a
        })
    };
    let mut state = fresh_gap(&p, &mut u, &mut g, &mut applies);
    let mut fresh = true;
    let mut it = 0usize;
    let mut cg = false;
    let mut g_old = 1.0;
    let mut last_poll = Instant::now();
    loop {
        let cert = state.certificate() / sc;
        if cert < best_cert {
            best_cert = cert;
            best_at = it;
        }
        if pre.is_some() && it - best_at > super::PRECONDITION_STALL {
            // The preconditioned iteration stalls: the caller starts over with plain steps.
            *spent = [applies, pre_applies];
            return Err(Error::NotConverged {
                iterations: it,
                residual: cert,
                what: "Polonsky–Keer with hardness (preconditioned steps stalled)".into(),
            });
        }
        if pre.is_some() && cert > super::PRECONDITION_SAFEGUARD * best_cert {
            // The preconditioned iteration is not contracting: finish with plain steps.
            pre = None;
            cg = false;
        }
        if cert <= opts.tol {
            if fresh {
                break;
            }
            state = fresh_gap(&p, &mut u, &mut g, &mut applies);
            fresh = true;
            continue;
        }
        if it >= max_iter || !cert.is_finite() {
            return Err(Error::NotConverged {
                iterations: it,
                residual: cert,
                what: "Polonsky–Keer with hardness".into(),
            });
        }
        if let Some(stop) = opts.should_stop {
            if it % 10 == 0 || last_poll.elapsed().as_millis() >= 250 {
                last_poll = Instant::now();
                if stop() {
                    return Err(Error::Interrupted);
                }
            }
        }
        // Step 2: preconditioned on a free set of at most half the points, plain otherwise.
        let n_free = state.n_c - state.n_pl;
        let mut steepest = n_free == 0;
        let mut preconditioned = false;
        let mut gt = 0.0;
        if let Some(m) = pre {
            if !steepest && n_free as f64 <= pk::PRECONDITION_MAX_FRACTION * n as f64 {
                let gz = precondition(m, &mut r, &p, &g, cap);
                pre_applies += 1;
                // β continues only a preconditioned sequence.
                let beta = if cg && last_pre && g_old > 0.0 {
                    gz / g_old
                } else {
                    0.0
                };
                gt = direction_preconditioned(&mut t, &r, &p, &g, cap, beta);
                if positive(gt) && positive(gz) {
                    preconditioned = true;
                    g_old = gz;
                }
            }
        }
        if !preconditioned {
            if !steepest {
                let beta = if cg && !last_pre && g_old > 0.0 {
                    state.gg / g_old
                } else {
                    0.0
                };
                gt = direction(&mut t, &p, &g, cap, beta, false);
                if !positive(gt) {
                    steepest = true;
                }
            }
            if steepest {
                gt = direction(&mut t, &p, &g, cap, 0.0, true);
            }
            if !positive(gt) {
                return Err(Error::NotConverged {
                    iterations: it,
                    residual: cert,
                    what: "Polonsky–Keer with hardness (no descent direction)".into(),
                });
            }
            g_old = if steepest { gt } else { state.gg };
        }
        last_pre = preconditioned;
        // Step 3.
        op.apply(&t, &mut r);
        applies += 1;
        let rt = reduce(n, |lo, hi| {
            let mut a = Red::ZERO;
            a.rt = r[lo..hi]
                .iter()
                .zip(&t[lo..hi])
                .fold(0.0, |s, (x, y)| s + x * y);
            a
        })
        .rt;
        let mut tau = gt / rt;
        if !positive(rt) || !tau.is_finite() {
            tau = ratio_test(&p, &t, cap);
            if !tau.is_finite() {
                return Err(Error::NotConverged {
                    iterations: it,
                    residual: cert,
                    what: "Polonsky–Keer with hardness (unbounded direction)".into(),
                });
            }
        }
        // Steps 4–5, with the incremental gap. A preconditioned `τ` is dimensionless: entries
        // and releases move by `τ g / C_00` (the pressure that closes the gap of that point
        // alone), as in the elastic solver.
        let tau_ol = if preconditioned { tau / c00 } else { tau };
        let (up, changes) = {
            let (t, r) = (&t, &r);
            let parts: Vec<(Red, Vec<(usize, f64)>)> = p
                .par_chunks_mut(CHUNK)
                .zip(g.par_chunks_mut(CHUNK))
                .enumerate()
                .map(|(c, (pc, gc))| {
                    let lo = c * CHUNK;
                    let mut a = Red::ZERO;
                    let mut ch = Vec::new();
                    for i in 0..pc.len() {
                        let gi = gc[i];
                        let lin = pc[i] - tau * t[lo + i];
                        let mut pn = lin.clamp(0.0, cap);
                        if pn == 0.0 && gi < 0.0 {
                            pn = (-tau_ol * gi).min(cap);
                            a.n_ol += 1;
                        } else if pn == cap && gi > 0.0 {
                            pn = (cap - tau_ol * gi).max(0.0);
                            a.n_ul += 1;
                        }
                        if pn != lin {
                            a.n_nl += 1;
                            if ch.len() < sparse_max {
                                ch.push((lo + i, pn - lin));
                            }
                        }
                        pc[i] = pn;
                        let gn = gi - tau * r[lo + i];
                        gc[i] = gn;
                        a.observe(pn, gn, cap);
                    }
                    (a, ch)
                })
                .collect();
            let red = parts.iter().fold(Red::ZERO, |a, b| a.merge(&b.0));
            let mut changes = Vec::new();
            if red.n_nl <= sparse_max {
                for (_, ch) in &parts {
                    changes.extend_from_slice(ch);
                }
            }
            (red, changes)
        };
        it += 1;
        // As the elastic iteration: only entries (through I_ol or from the cap) of more than
        // pk::OL_KEEP_FRACTION of the free set reset the conjugate direction.
        cg = pk::keeps_conjugacy(up.n_ol + up.n_ul, up.n_c - up.n_pl);
        if up.n_nl == 0 {
            state = up;
            fresh = false;
        } else if up.n_nl <= sparse_max {
            // A few non-linear changes d: g += C d by direct summation with the table.
            if table.is_none() && own_table.is_empty() {
                let mut e0 = alloc::try_zeroed(n, "a unit load")?;
                e0[0] = 1.0;
                own_table = alloc::try_zeroed(n, "the influence table")?;
                op.apply(&e0, &mut own_table);
                applies += 1;
            }
            let tab: &[f64] = table.unwrap_or(&own_table);
            let p = &p;
            state = {
                let parts: Vec<Red> = g
                    .par_chunks_mut(CHUNK)
                    .enumerate()
                    .map(|(c, gc)| {
                        let lo = c * CHUNK;
                        pk::add_sparse(gc, lo, &changes, tab, ny, nx, periodic);
                        let mut a = Red::ZERO;
                        for (i, &gi) in gc.iter().enumerate() {
                            a.observe(p[lo + i], gi, cap);
                        }
                        a
                    })
                    .collect();
                parts.iter().fold(Red::ZERO, |a, b| a.merge(b))
            };
            fresh = false;
        } else {
            state = fresh_gap(&p, &mut u, &mut g, &mut applies);
            fresh = true;
        }
    }
    let sum_p = state.sum_p;
    Ok(Solution {
        solver: Solver::PolonskyKeer,
        pressure: p,
        displacement: u,
        gap: g,
        approach: delta,
        iterations: it,
        fft_products: applies,
        preconditioner_products: pre_applies,
        chord_steps: 0,
        single_products: 0,
        kkt: state.certificate() / sc,
        contact_points: state.n_c,
        plastic_points: state.n_pl,
        load: sum_p * problem.dx * problem.dx,
        mean_pressure: sum_p / n as f64,
        coarse: CoarseCost::default(),
    })
}

/// Step 2: `t = g + β t` on the free set (`steepest`: `t = g` on the working set); returns
/// `Σ g t`.
fn direction(t: &mut [f64], p: &[f64], g: &[f64], cap: f64, beta: f64, steepest: bool) -> f64 {
    let parts: Vec<f64> = t
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(c, tc)| {
            let lo = c * CHUNK;
            let mut s = 0.0;
            for (i, ti) in tc.iter_mut().enumerate() {
                let (pk, gk) = (p[lo + i], g[lo + i]);
                let v = if pk > 0.0 && pk < cap {
                    gk + beta * *ti
                } else if steepest && ((pk <= 0.0 && gk < 0.0) || (pk >= cap && gk > 0.0)) {
                    gk
                } else {
                    0.0
                };
                *ti = v;
                s += gk * v;
            }
            s
        })
        .collect();
    parts.iter().sum()
}

/// The preconditioned residual `z = M (g on F)` restricted to the free set `F = {0 < p < H}`,
/// written into `r` (zero off `F`); returns `Σ_F g z`. Rows without a free point skip their
/// FFTs.
fn precondition(m: &Operator, r: &mut [f64], p: &[f64], g: &[f64], cap: f64) -> f64 {
    m.apply_restricted(g, p, |v: f64| v > 0.0 && v < cap, r);
    let r = &*r;
    let parts: Vec<f64> = g
        .par_chunks(CHUNK)
        .zip(r.par_chunks(CHUNK))
        .map(|(gc, zc)| gc.iter().zip(zc).fold(0.0, |s, (x, y)| s + x * y))
        .collect();
    parts.iter().sum()
}

/// Step 2 with the preconditioned residual: `t = z + β t` on the free set, 0 elsewhere;
/// returns `Σ g t`.
fn direction_preconditioned(
    t: &mut [f64],
    z: &[f64],
    p: &[f64],
    g: &[f64],
    cap: f64,
    beta: f64,
) -> f64 {
    let parts: Vec<f64> = t
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(c, tc)| {
            let lo = c * CHUNK;
            let mut s = 0.0;
            for (i, ti) in tc.iter_mut().enumerate() {
                let k = lo + i;
                let v = if p[k] > 0.0 && p[k] < cap {
                    z[k] + beta * *ti
                } else {
                    0.0
                };
                *ti = v;
                s += g[k] * v;
            }
            s
        })
        .collect();
    parts.iter().sum()
}

/// Largest `τ` with `0 ≤ p − τ t ≤ H`, `∞` if none limits it.
fn ratio_test(p: &[f64], t: &[f64], cap: f64) -> f64 {
    let parts: Vec<f64> = p
        .par_chunks(CHUNK)
        .zip(t.par_chunks(CHUNK))
        .map(|(pc, tc)| {
            let mut m = f64::INFINITY;
            for (&pi, &ti) in pc.iter().zip(tc) {
                if ti > 0.0 {
                    m = m.min(pi / ti);
                } else if ti < 0.0 {
                    m = m.min((cap - pi) / -ti);
                }
            }
            m
        })
        .collect();
    parts.iter().copied().fold(f64::INFINITY, f64::min)
}
