//! Preconditioned conjugate gradients with reductions that do not depend on the thread count.

use rayon::prelude::*;

use crate::error::{Error, Result};

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

/// `r = b − A x`.
fn true_residual(apply: &dyn Fn(&[f64], &mut [f64]), b: &[f64], x: &[f64], r: &mut [f64]) {
    apply(x, r);
    r.par_chunks_mut(CHUNK)
        .zip(b.par_chunks(CHUNK))
        .for_each(|(rc, bc)| rc.iter_mut().zip(bc).for_each(|(rv, bv)| *rv = bv - *rv));
}

/// Solves `A x = b` from the initial guess in `x`, with preconditioner `precond(r, z)`,
/// until the *true* residual `r = b − A x` has `‖r‖₂ ≤ tol ‖b‖₂` and `measure(x, r) ≤ 1`
/// (a caller's test, e.g. on the error of a flux). The recurrence residual only decides when
/// to look: it drifts from `b − A x` in floating point, so the iteration goes on from the
/// recomputed one (residual replacement). Never stops early silently: `converged` is false
/// when `max_iter` is reached or the measure stops improving. `b = 0` gives `x = 0` exactly.
#[allow(clippy::too_many_arguments)]
pub fn pcg(
    apply: &dyn Fn(&[f64], &mut [f64]),
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
    true_residual(apply, b, x, &mut r);
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
        precond(&r, &mut z);
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
        apply(&p, &mut q);
        let pq = dot(&p, &q);
        if pq <= 0.0 || !pq.is_finite() || rz <= 0.0 {
            // Exact solution reached, or a breakdown: the check below reports which.
            true_residual(apply, b, x, &mut r);
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
            true_residual(apply, b, x, &mut r);
            rnorm = dot(&r, &r).sqrt();
            checked = true;
        }
    }
    if !checked {
        true_residual(apply, b, x, &mut r);
        rnorm = dot(&r, &r).sqrt();
    }
    Ok(Outcome {
        iterations: it,
        residual: rnorm / bnorm,
        converged,
    })
}
