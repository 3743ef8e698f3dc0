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
}

/// Iterations allowed past `‖r‖ ≤ tol ‖b‖` without a new smallest `balanced` measure while
/// that is not yet met (round-off may keep it out of reach).
const STALL: usize = 10;

/// Solves `A x = b` from `x = 0` to `‖r‖ ≤ tol ‖b‖` and `balanced(x, r) ≤ 1`, with
/// preconditioner `precond(r, z)`. `b = 0` gives `x = 0` exactly.
#[allow(clippy::too_many_arguments)]
pub fn pcg(
    apply: &dyn Fn(&[f64], &mut [f64]),
    precond: &mut dyn FnMut(&[f64], &mut [f64]),
    balanced: &dyn Fn(&[f64], &[f64]) -> f64,
    b: &[f64],
    x: &mut [f64],
    tol: f64,
    max_iter: usize,
    should_stop: Option<&(dyn Fn() -> bool + Sync)>,
) -> Result<Outcome> {
    let n = b.len();
    x.iter_mut().for_each(|v| *v = 0.0);
    let bnorm = dot(b, b).sqrt();
    if bnorm == 0.0 {
        return Ok(Outcome {
            iterations: 0,
            residual: 0.0,
        });
    }
    let mut r = b.to_vec();
    let mut z = vec![0.0; n];
    let mut q = vec![0.0; n];
    precond(&r, &mut z);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let mut it = 0;
    let mut rnorm = bnorm;
    let mut best = f64::INFINITY;
    let mut since_best = 0;
    loop {
        if it >= max_iter {
            return Err(Error::NotConverged {
                iterations: it,
                residual: rnorm / bnorm,
                what: "reynolds-flow".into(),
            });
        }
        if let Some(stop) = should_stop {
            if stop() {
                return Err(Error::Interrupted);
            }
        }
        apply(&p, &mut q);
        let pq = dot(&p, &q);
        if pq <= 0.0 || !pq.is_finite() {
            break; // exact solution reached (or a breakdown that the final check reports)
        }
        let alpha = rz / pq;
        axpy(alpha, &p, x);
        axpy(-alpha, &q, &mut r);
        rnorm = dot(&r, &r).sqrt();
        it += 1;
        if rnorm <= tol * bnorm {
            // Residual replacement: the recurrence drifts from b − A x, so test (and go on
            // from) the true residual.
            apply(x, &mut q);
            r.par_chunks_mut(CHUNK)
                .zip(b.par_chunks(CHUNK).zip(q.par_chunks(CHUNK)))
                .for_each(|(rc, (bc, qc))| {
                    rc.iter_mut()
                        .zip(bc.iter().zip(qc))
                        .for_each(|(rv, (bv, qv))| *rv = bv - qv)
                });
            rnorm = dot(&r, &r).sqrt();
            let measure = balanced(x, &r);
            if rnorm <= tol * bnorm && measure <= 1.0 {
                break;
            }
            if measure < best {
                best = measure;
                since_best = 0;
            } else {
                since_best += 1;
                if since_best >= STALL {
                    break;
                }
            }
        }
        // Flexible (Polak–Ribière) β: the K-cycle preconditioner is not a fixed linear map.
        let rz_old_new = dot(&r, &z);
        precond(&r, &mut z);
        let rz_new = dot(&r, &z);
        let beta = (rz_new - rz_old_new) / rz;
        rz = rz_new;
        p.par_chunks_mut(CHUNK)
            .zip(z.par_chunks(CHUNK))
            .for_each(|(pc, zc)| {
                pc.iter_mut()
                    .zip(zc)
                    .for_each(|(pv, zv)| *pv = zv + beta * *pv)
            });
    }
    // The recurrence drifts from the true residual; report the true one.
    apply(x, &mut q);
    r.iter_mut()
        .zip(b.iter().zip(&q))
        .for_each(|(rv, (bv, qv))| *rv = bv - qv);
    let residual = dot(&r, &r).sqrt() / bnorm;
    Ok(Outcome {
        iterations: it,
        residual,
    })
}
