//! Preconditioned conjugate gradients with reductions that do not depend on the thread count.

use std::sync::OnceLock;
use std::time::Instant;

use rayon::prelude::*;

use super::assemble::two_sum;
use crate::error::{Error, Result};

/// Whether `LEAKPATH_FLOW_PROFILE` is set: stage timings of the flow solvers (the factor's
/// analysis and factorisation, the multigrid's setup and cycles) are then printed to standard
/// error (a development aid; no result depends on it).
pub(crate) fn profiling() -> bool {
    static ON: OnceLock<bool> = OnceLock::new();
    *ON.get_or_init(|| std::env::var_os("LEAKPATH_FLOW_PROFILE").is_some())
}

/// Seconds since `t`.
pub(crate) fn secs(t: Instant) -> f64 {
    t.elapsed().as_secs_f64()
}

/// Reductions sum fixed chunks of this many entries, each in index order, then the chunk
/// sums in chunk order: the same bits for any number of threads.
pub const CHUNK: usize = 8192;

/// `Σ a_k b_k`, deterministic.
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    let parts: Vec<f64> = a
        .par_chunks(CHUNK)
        .zip(b.par_chunks(CHUNK))
        .map(|(x, y)| x.iter().zip(y).map(|(u, v)| u * v).sum::<f64>())
        .collect();
    parts.iter().sum()
}

/// `Σ a_k`, deterministic.
pub fn sum(a: &[f64]) -> f64 {
    let parts: Vec<f64> = a.par_chunks(CHUNK).map(|x| x.iter().sum::<f64>()).collect();
    parts.iter().sum()
}

/// `y += α x`.
pub fn axpy(alpha: f64, x: &[f64], y: &mut [f64]) {
    y.par_chunks_mut(CHUNK)
        .zip(x.par_chunks(CHUNK))
        .for_each(|(yc, xc)| yc.iter_mut().zip(xc).for_each(|(v, u)| *v += alpha * u));
}

/// What the iteration reached.
#[derive(Clone, Copy, Debug)]
pub struct Outcome {
    pub iterations: usize,
    /// `‖b − A x‖₂ / ‖b‖₂` of the returned `x`, recomputed from scratch.
    pub residual: f64,
    /// Both stopping tests were met on the true residual.
    pub converged: bool,
}

/// Checks of the true residual allowed without a new smallest `measure` once
/// `‖r‖ ≤ tol ‖b‖` holds but `measure ≤ 1` does not (round-off may keep it out of reach).
const STALL: usize = 20;

/// After a stall, `measure ≤ STALL_ACCEPT` still counts as converged: the caller's measure
/// asks for a digit or three more than round-off may allow (it estimates an error of order
/// `10⁻⁹` at the default tolerance), and the caller checks the result independently.
const STALL_ACCEPT: f64 = 1e3;

/// `r = b − A x` from `residual(x, b, r)`.
fn true_residual(residual: Residual<'_>, b: &[f64], x: &[f64], r: &mut [f64]) {
    residual(x, b, r);
}

/// `residual(x, b, r)` sets `r = b − A x` (e.g. summed exactly, so that it is not swamped by
/// the rounding of `A x` where the conductances are large).
pub type Residual<'a> = &'a dyn Fn(&[f64], &[f64], &mut [f64]);

/// `r = b − A Σ parts` for a solution given in parts (`[x]` or `[hi, lo]`).
pub type PartsResidual<'a> = &'a dyn Fn(&[&[f64]], &[f64], &mut [f64]);

/// Solves `A x = b` from the initial guess in `x`, with preconditioner `precond(r, z)`,
/// until the *true* residual `r = b − A x` (recomputed by `residual`) has `‖r‖₂ ≤ tol ‖b‖₂` and `measure(x, r) ≤ 1`
/// (a caller's test, e.g. on the error of a flux). The recurrence residual only decides when
/// to look: it drifts from `b − A x` in floating point, so the iteration goes on from the
/// recomputed one (residual replacement). Never stops early silently: `converged` is false
/// when `max_iter` is reached or the measure stops improving. `b = 0` gives `x = 0` exactly.
#[allow(clippy::too_many_arguments)]
pub fn pcg(
    apply: &dyn Fn(&[f64], &mut [f64]),
    residual: Residual<'_>,
    precond: &mut dyn FnMut(&[f64], &mut [f64]),
    measure: &dyn Fn(&[f64], &[f64]) -> f64,
    b: &[f64],
    x: &mut [f64],
    tol: f64,
    max_iter: usize,
    should_stop: Option<&(dyn Fn() -> bool + Sync)>,
) -> Result<Outcome> {
    let n = b.len();
    let bnorm = dot(b, b).sqrt();
    if bnorm == 0.0 {
        x.iter_mut().for_each(|v| *v = 0.0);
        return Ok(Outcome {
            iterations: 0,
            residual: 0.0,
            converged: true,
        });
    }
    let mut r = vec![0.0; n];
    true_residual(residual, b, x, &mut r);
    let mut z = vec![0.0; n];
    let mut q = vec![0.0; n];
    let mut rnorm = dot(&r, &r).sqrt();
    let mut it = 0;
    let mut best = f64::INFINITY;
    let mut since_best = 0;
    let mut converged = false;
    let mut checked = true; // r is the true residual
    let mut p = vec![0.0; n];
    let mut rz = 0.0;
    let prof = profiling();
    let (mut t_pre, mut t_apply) = (0.0, 0.0);
    let t_all = Instant::now();
    loop {
        if checked && rnorm <= tol * bnorm {
            let m = measure(x, &r);
            if m <= 1.0 {
                converged = true;
                break;
            }
            if m < best {
                best = m;
                since_best = 0;
            } else {
                since_best += 1;
                if since_best >= STALL {
                    // Round-off floor: accept a measure within STALL_ACCEPT of the target.
                    converged = m <= STALL_ACCEPT;
                    break;
                }
            }
        }
        if it >= max_iter {
            break;
        }
        if let Some(stop) = should_stop {
            if stop() {
                return Err(Error::Interrupted);
            }
        }
        // Flexible (Polak–Ribière) β: the K-cycle preconditioner is not a fixed linear map.
        let rz_old_new = dot(&r, &z);
        let t0 = Instant::now();
        precond(&r, &mut z);
        t_pre += secs(t0);
        let rz_new = dot(&r, &z);
        let beta = if it == 0 {
            0.0
        } else {
            (rz_new - rz_old_new) / rz
        };
        rz = rz_new;
        p.par_chunks_mut(CHUNK)
            .zip(z.par_chunks(CHUNK))
            .for_each(|(pc, zc)| {
                pc.iter_mut()
                    .zip(zc)
                    .for_each(|(pv, zv)| *pv = zv + beta * *pv)
            });
        let t0 = Instant::now();
        apply(&p, &mut q);
        t_apply += secs(t0);
        let pq = dot(&p, &q);
        if pq <= 0.0 || !pq.is_finite() || rz <= 0.0 {
            // Exact solution reached, or a breakdown: the check below reports which.
            true_residual(residual, b, x, &mut r);
            rnorm = dot(&r, &r).sqrt();
            converged = rnorm <= tol * bnorm && measure(x, &r) <= 1.0;
            break;
        }
        // α = r·p / p·Ap minimises the energy norm of the error along p even when p has
        // lost its conjugacy (flexible preconditioner, replaced residuals): never a
        // growing error. In exact arithmetic it equals r·z / p·Ap.
        let alpha = dot(&r, &p) / pq;
        axpy(alpha, &p, x);
        axpy(-alpha, &q, &mut r);
        rnorm = dot(&r, &r).sqrt();
        it += 1;
        if !rnorm.is_finite() {
            break;
        }
        checked = false;
        if rnorm <= tol * bnorm {
            true_residual(residual, b, x, &mut r);
            rnorm = dot(&r, &r).sqrt();
            checked = true;
        }
    }
    if !checked {
        true_residual(residual, b, x, &mut r);
        rnorm = dot(&r, &r).sqrt();
    }
    if prof {
        let sub = |v: &[f64]| v.iter().filter(|x| x.is_subnormal()).count();
        eprintln!(
            "[flow profile] cg: {it} iterations, {:.3} s: preconditioner {t_pre:.3} s, \
             operator {t_apply:.3} s, rest {:.3} s; residual {:.2e}; subnormal entries \
             x {} r {} z {} p {} q {}",
            secs(t_all),
            secs(t_all) - t_pre - t_apply,
            rnorm / bnorm,
            sub(x),
            sub(&r),
            sub(&z),
            sub(&p),
            sub(&q)
        );
    }
    Ok(Outcome {
        iterations: it,
        residual: rnorm / bnorm,
        converged,
    })
}

/// Relative residual each inner solve of [`refined`] reaches.
pub const INNER_TOL: f64 = 1e-6;

/// A refinement step whose true residual is below `tol` but no longer halves is at the
/// round-off floor of `x`: its measure is accepted up to this.
const FLOOR_ACCEPT: f64 = 1e2;

/// Refinement steps at most in [`refined`].
const REFINE_STEPS: usize = 8;

/// Iterative refinement around [`pcg`]: from `x`, repeatedly the residual `r = b − A x`
/// recomputed by `exact` (summed exactly: not swamped by the rounding of the large
/// conductances' rows), then the correction `A δ = r` by preconditioned CG from 0 to a
/// relative residual [`INNER_TOL`] (in plain arithmetic: its rounding is relative to the
/// correction, not to `x`), `x += δ`; until `‖r‖₂ ≤ tol ‖b‖₂` and `measure(x, r) ≤ 1`.
/// With `lo`, the solution is carried as two doubles `x + lo` (zero `lo` to start): each
/// correction is added without rounding error and the residual is that of `x + lo`
/// (`exact` receives both parts), so `x + lo` keeps the digits below the last one of `x`
/// (what `1 − x` needs where `x` is near 1).
/// Each step gains the inner solve's factor on every part of the error, however far below
/// the rounding of `A x` in the large rows it lies (a flow rate many decades below the
/// conductances near the percolation threshold), where one long CG run stalls at that
/// rounding. `converged` is false after `max_iter` inner iterations in total, or when a step
/// no longer halves the measure (then accepted within [`STALL_ACCEPT`] of the target); a
/// step whose true residual, already below `tol`, no longer halves either ends it with a
/// measure up to [`FLOOR_ACCEPT`] accepted.
#[allow(clippy::too_many_arguments)]
pub fn refined(
    apply: &dyn Fn(&[f64], &mut [f64]),
    exact: PartsResidual<'_>,
    precond: &mut dyn FnMut(&[f64], &mut [f64]),
    measure: &dyn Fn(&[f64], &[f64]) -> f64,
    b: &[f64],
    x: &mut [f64],
    mut lo: Option<&mut [f64]>,
    tol: f64,
    max_iter: usize,
    should_stop: Option<&(dyn Fn() -> bool + Sync)>,
) -> Result<Outcome> {
    let n = b.len();
    let bnorm = dot(b, b).sqrt();
    if bnorm == 0.0 {
        x.iter_mut().for_each(|v| *v = 0.0);
        return Ok(Outcome {
            iterations: 0,
            residual: 0.0,
            converged: true,
        });
    }
    let plain = |x: &[f64], b: &[f64], r: &mut [f64]| {
        apply(x, r);
        r.par_chunks_mut(CHUNK)
            .zip(b.par_chunks(CHUNK))
            .for_each(|(rc, bc)| rc.iter_mut().zip(bc).for_each(|(rv, bv)| *rv = bv - *rv));
    };
    let mut r = vec![0.0; n];
    let mut d = vec![0.0; n];
    let mut it = 0;
    let mut last = f64::INFINITY;
    let mut last_rel = f64::INFINITY;
    let mut step = 0;
    loop {
        let t0 = Instant::now();
        // `lo` is zero until the first correction: the residual of `x` alone is the same.
        match lo.as_deref() {
            Some(lo) if step > 0 => exact(&[x, lo], b, &mut r),
            _ => exact(&[x], b, &mut r),
        }
        let rel = dot(&r, &r).sqrt() / bnorm;
        let m = measure(x, &r);
        if profiling() {
            eprintln!(
                "[flow profile] refinement step {step}: residual {rel:.2e}, measure {m:.2e}, \
                 exact residual and measure {:.3} s",
                secs(t0)
            );
        }
        if rel <= tol && m <= 1.0 {
            return Ok(Outcome {
                iterations: it,
                residual: rel,
                converged: true,
            });
        }
        // At the round-off floor: the true residual no longer halves (it is the rounding
        // of `x` itself, which no correction removes) and the rate is within FLOOR_ACCEPT
        // of its target; further steps only trade the measure's round-off.
        if step >= 2 && rel <= tol && rel > 0.5 * last_rel && m <= FLOOR_ACCEPT {
            return Ok(Outcome {
                iterations: it,
                residual: rel,
                converged: true,
            });
        }
        let stalled = step >= 2 && m > 0.5 * last && rel <= tol;
        if stalled || step >= REFINE_STEPS || it >= max_iter || !rel.is_finite() {
            return Ok(Outcome {
                iterations: it,
                residual: rel,
                converged: stalled && m <= STALL_ACCEPT,
            });
        }
        last = m;
        last_rel = rel;
        step += 1;
        d.iter_mut().for_each(|v| *v = 0.0);
        let inner = pcg(
            apply,
            &plain,
            precond,
            &|_, _| 0.0,
            &r,
            &mut d,
            INNER_TOL,
            max_iter - it,
            should_stop,
        )?;
        it += inner.iterations;
        match lo.as_deref_mut() {
            Some(lo) => add_split(&d, x, lo),
            None => axpy(1.0, &d, x),
        }
    }
}

/// `hi + lo += d` element by element, the sum split again into a double and its rounding
/// error ([`two_sum`]).
fn add_split(d: &[f64], hi: &mut [f64], lo: &mut [f64]) {
    hi.par_chunks_mut(CHUNK)
        .zip(lo.par_chunks_mut(CHUNK))
        .zip(d.par_chunks(CHUNK))
        .for_each(|((hc, lc), dc)| {
            for ((h, l), &dv) in hc.iter_mut().zip(lc.iter_mut()).zip(dc) {
                (*h, *l) = two_sum(*h, *l + dv);
            }
        });
}
