//! Preconditioned conjugate gradients with reductions that do not depend on the thread count.

use std::sync::OnceLock;
use std::time::Instant;

use rayon::prelude::*;

use super::compensated::two_sum;
use crate::alloc::ZeroedAhead;
use crate::error::{Error, Result};

/// Whether `LEAKPATH_FLOW_PROFILE` is set: stage timings of the flow solvers (the factor's
/// analysis and factorisation, the multigrid's setup and cycles) are then printed to standard
/// error (a development aid; no result depends on it).
pub(crate) fn profiling() -> bool {
    static ON: OnceLock<bool> = OnceLock::new();
    *ON.get_or_init(|| std::env::var_os("LEAKPATH_FLOW_PROFILE").is_some())
}

/// Minor page faults of the process so far (`/proc/self/stat`; 0 where it cannot be read).
pub(crate) fn page_faults() -> u64 {
    std::fs::read_to_string("/proc/self/stat")
        .ok()
        .and_then(|s| {
            let rest = &s[s.rfind(')')? + 2..];
            rest.split_whitespace().nth(7)?.parse().ok()
        })
        .unwrap_or(0)
}

/// CPU time of every thread of the process so far, in nanoseconds (the first field of each
/// `/proc/self/task/*/schedstat`; 0 where it cannot be read).
pub(crate) fn cpu_nanos() -> u64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return 0;
    };
    tasks
        .flatten()
        .filter_map(|t| std::fs::read_to_string(t.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum()
}

/// With profiling on, prints `what` with the wall time, the page faults and the CPU time of
/// all threads since the previous mark (a timeline of one call's stages, and how many cores
/// each kept busy; `what` empty only resets it).
pub(crate) fn mark(what: &str) {
    static LAST: std::sync::Mutex<Option<(Instant, u64, u64)>> = std::sync::Mutex::new(None);
    if !profiling() {
        return;
    }
    let now = (Instant::now(), page_faults(), cpu_nanos());
    let mut last = LAST.lock().unwrap_or_else(|e| e.into_inner());
    if let (Some((t, f, c)), false) = (*last, what.is_empty()) {
        eprintln!(
            "mark: {what}: {:.1} ms, {} page faults, {:.1} ms CPU",
            1e3 * (now.0 - t).as_secs_f64(),
            now.1.saturating_sub(f),
            1e-6 * now.2.saturating_sub(c) as f64
        );
    }
    *last = Some(now);
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
        .map(|(x, y)| chunk_dot(x, y))
        .collect();
    parts.iter().sum()
}

/// `Σ x_k y_k` in four interleaved partial sums (one chain of dependent additions would
/// wait on each before the next).
fn chunk_dot(x: &[f64], y: &[f64]) -> f64 {
    let mut p = [0.0; 4];
    let (x4, xr) = x.split_at(x.len() & !3);
    for (a, b) in x4.chunks_exact(4).zip(y.chunks_exact(4)) {
        for q in 0..4 {
            p[q] += a[q] * b[q];
        }
    }
    let rest: f64 = xr.iter().zip(&y[x4.len()..]).map(|(u, v)| u * v).sum();
    (p[0] + p[1]) + (p[2] + p[3]) + rest
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
    /// `‖b − A x‖₂ / ‖b‖₂` of the returned `x`: recomputed exactly by [`refined`], the
    /// recurrence's in [`pcg`].
    pub residual: f64,
    /// The stopping tests were met.
    pub converged: bool,
}

/// The vectors of [`refined`], allocated once for a whole solve (like [`Inner`]'s):
/// allocated afresh for every step, a 10-million-unknown grid faulted in and zeroed some
/// 0.5 GB each time. Faulted in when allocated ([`crate::alloc::zeroed_now`]) or made
/// ahead ([`ZeroedAhead`]), not inside the solve.
pub struct Work {
    /// The residual (the inner solve's right-hand side) and the correction.
    r: Vec<f64>,
    d: Vec<f64>,
}

impl Work {
    /// The vectors for systems of `n` unknowns, taken from `ahead` (made there or now).
    pub fn new(ahead: &mut ZeroedAhead, n: usize) -> Self {
        Work {
            r: ahead.take(n),
            d: ahead.take(n),
        }
    }
}

/// The vectors of [`pcg`] besides its residual and solution: the preconditioned residual,
/// the search direction and its product.
pub struct Inner {
    z: Vec<f64>,
    p: Vec<f64>,
    q: Vec<f64>,
}

impl Inner {
    /// The vectors for systems of `n` unknowns, taken from `ahead` (made there or now).
    pub fn new(ahead: &mut ZeroedAhead, n: usize) -> Self {
        Inner {
            z: ahead.take(n),
            p: ahead.take(n),
            q: ahead.take(n),
        }
    }
}

/// Whether every entry of `x` is zero (then `b − A x = b` exactly).
fn all_zero(x: &[f64]) -> bool {
    x.par_chunks(CHUNK).all(|c| c.iter().all(|&v| v == 0.0))
}

/// After a stall, `measure ≤ STALL_ACCEPT` still counts as converged: the caller's measure
/// asks for a digit or three more than round-off may allow (it estimates an error of order
/// `10⁻⁹` at the default tolerance), and the caller checks the result independently.
const STALL_ACCEPT: f64 = 1e3;

/// `r = b − A Σ parts` for a solution given in parts (`[x]` or `[hi, lo]`).
pub type PartsResidual<'a> = &'a dyn Fn(&[&[f64]], &[f64], &mut [f64]);

/// Solves `A x = b` from `x = 0` with preconditioner `precond(r, z)` until the recurrence
/// residual has `‖r‖₂ ≤ tol ‖b‖₂`: the inner solve of [`refined`] (on the fine system or on
/// a reduced one), whose exact residual after the correction is the check (the recurrence
/// drifts from `b − A x` in floating point; a correction short of `tol` only makes the next
/// refinement step gain less).
/// `r` holds `b` on entry and the recurrence residual on return (the caller needs `b` no
/// more: one vector less); `bnorm` is `‖r‖₂` on entry (the caller has it already).
/// `converged` is false when `max_iter` is reached first, `residual` is the recurrence's.
/// `b = 0` gives `x = 0`.
#[allow(clippy::too_many_arguments)]
pub fn pcg(
    apply: &mut dyn FnMut(&[f64], &mut [f64]),
    precond: &mut dyn FnMut(&[f64], &mut [f64]),
    r: &mut [f64],
    bnorm: f64,
    x: &mut [f64],
    tol: f64,
    max_iter: usize,
    should_stop: Option<&(dyn Fn() -> bool + Sync)>,
    work: &mut Inner,
) -> Result<Outcome> {
    let n = r.len();
    x.par_iter_mut().for_each(|v| *v = 0.0);
    if bnorm == 0.0 {
        return Ok(Outcome {
            iterations: 0,
            residual: 0.0,
            converged: true,
        });
    }
    let Inner { z, p, q } = work;
    let (z, p, q) = (&mut z[..n], &mut p[..n], &mut q[..n]);
    let mut rnorm = bnorm;
    let mut it = 0;
    let mut rz = 0.0;
    let prof = profiling();
    let (mut t_pre, mut t_apply) = (0.0, 0.0);
    let t_all = Instant::now();
    while rnorm > tol * bnorm && it < max_iter {
        if let Some(stop) = should_stop {
            if stop() {
                return Err(Error::Interrupted);
            }
        }
        // Flexible (Polak–Ribière) β: the cycle is applied in floating point, not exactly
        // the same linear map each time. The first direction is `z` itself (the vectors
        // hold the last solve's values).
        let rz_old_new = if it == 0 { 0.0 } else { dot(r, z) };
        let t0 = Instant::now();
        precond(r, z);
        t_pre += secs(t0);
        let rz_new = dot(r, z);
        if it == 0 {
            p.copy_from_slice(z);
        } else {
            let beta = (rz_new - rz_old_new) / rz;
            p.par_chunks_mut(CHUNK)
                .zip(z.par_chunks(CHUNK))
                .for_each(|(pc, zc)| {
                    pc.iter_mut()
                        .zip(zc)
                        .for_each(|(pv, zv)| *pv = zv + beta * *pv)
                });
        }
        rz = rz_new;
        let t0 = Instant::now();
        apply(p, q);
        t_apply += secs(t0);
        let pq = dot(p, q);
        if pq <= 0.0 || !pq.is_finite() || rz <= 0.0 {
            // Exact solution reached, or a breakdown: the caller's exact residual says which.
            break;
        }
        // α = r·p / p·Ap minimises the energy norm of the error along p even when p has
        // lost its conjugacy (flexible preconditioner): never a growing error. In exact
        // arithmetic it equals r·z / p·Ap.
        let alpha = dot(r, p) / pq;
        axpy(alpha, p, x);
        axpy(-alpha, q, r);
        rnorm = dot(r, r).sqrt();
        it += 1;
        if !rnorm.is_finite() {
            break;
        }
    }
    if prof {
        eprintln!(
            "[flow profile] cg: {it} iterations, {:.3} s: preconditioner {t_pre:.3} s, \
             operator {t_apply:.3} s, rest {:.3} s; recurrence residual {:.2e}",
            secs(t_all),
            secs(t_all) - t_pre - t_apply,
            rnorm / bnorm,
        );
    }
    Ok(Outcome {
        iterations: it,
        residual: rnorm / bnorm,
        converged: rnorm <= tol * bnorm,
    })
}

/// Relative residual each inner solve of [`refined`] reaches.
const INNER_TOL: f64 = 1e-6;

/// A refinement step whose true residual is below `tol` but no longer halves is at the
/// round-off floor of `x`: its measure is accepted up to this.
const FLOOR_ACCEPT: f64 = 1e2;

/// Refinement steps at most in [`refined`].
const REFINE_STEPS: usize = 8;

/// A lean step of [`refined`] asks its inner solve for this fraction of `1/measure` (ten
/// times the reduction the rate tests still ask for), at most [`LEAN_MAX`].
const LEAN_MARGIN: f64 = 0.1;

/// The largest relative residual a lean step asks for (its least reduction).
const LEAN_MAX: f64 = 0.1;

/// The inner solve of [`refined`]: `correct(r, ‖r‖₂, δ, rtol, max_iter)` sets `δ` to an
/// approximate solution of `A δ = r` (preconditioned CG from 0 to a relative residual
/// `rtol` in plain arithmetic, on `A` or on a reduced system; `r` may be overwritten)
/// within `max_iter` iterations.
pub type Correct<'a> =
    &'a mut dyn FnMut(&mut [f64], f64, &mut [f64], f64, usize) -> Result<Outcome>;

/// Iterative refinement around an inner solve ([`pcg`] through `correct`): from `x`,
/// repeatedly the residual `r = b − A x` recomputed by `exact` (summed exactly: not swamped
/// by the rounding of the large conductances' rows), then the correction `A δ = r` by
/// `correct` (in plain arithmetic: its rounding is relative to the correction, not to `x`),
/// `x += δ`; until `‖r‖₂ ≤ tol ‖b‖₂` and `measure(x, r) ≤ 1`.
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
/// Each inner solve reduces its residual by [`INNER_TOL`]. With `lean`, a step taken when
/// the residual test is already met (only the rate tests are left) reduces it by
/// `LEAN_MARGIN / measure` instead (at most [`LEAN_MAX`]; a step for which that is below
/// `INNER_TOL` is a full one); the step after a lean one that did not end the refinement
/// is a full one, and neither the stall nor the floor acceptance follows a lean step. For
/// a solve that starts close to its answer (the reversed pressure from `1 − φ`), whose
/// rate test asks for a factor of 10 to 1000 where a full step gives 10⁶.
#[allow(clippy::too_many_arguments)]
pub fn refined(
    exact: PartsResidual<'_>,
    correct: Correct<'_>,
    measure: &dyn Fn(&[f64], &[f64]) -> f64,
    b: &[f64],
    x: &mut [f64],
    mut lo: Option<&mut [f64]>,
    lean: bool,
    tol: f64,
    max_iter: usize,
    work: &mut Work,
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
    let Work { r, d } = work;
    let (r, d) = (&mut r[..n], &mut d[..n]);
    let mut it = 0;
    let mut last = f64::INFINITY;
    let mut last_rel = f64::INFINITY;
    let mut step = 0;
    let mut last_lean = false;
    loop {
        let t0 = Instant::now();
        // `lo` is zero until the first correction: the residual of `x` alone is the same,
        // and from `x = 0` it is `b` exactly, of relative norm 1: the measure is then not
        // needed unless `tol ≥ 1` (only the convergence test reads the first step's).
        let from_zero = step == 0 && bnorm.is_finite() && all_zero(x);
        match lo.as_deref() {
            Some(lo) if step > 0 => exact(&[x, lo], b, r),
            _ if from_zero => r.copy_from_slice(b),
            _ => exact(&[x], b, r),
        }
        let (r_norm, rel) = if from_zero {
            (bnorm, 1.0)
        } else {
            let r_norm = dot(r, r).sqrt();
            (r_norm, r_norm / bnorm)
        };
        let m = if from_zero && rel > tol {
            f64::INFINITY
        } else {
            measure(x, r)
        };
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
        if step >= 2 && !last_lean && rel <= tol && rel > 0.5 * last_rel && m <= FLOOR_ACCEPT {
            return Ok(Outcome {
                iterations: it,
                residual: rel,
                converged: true,
            });
        }
        let stalled = step >= 2 && !last_lean && m > 0.5 * last && rel <= tol;
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
        // Lean only where it asks for less than a full step.
        let lean_rtol = LEAN_MARGIN / m;
        last_lean = lean && !last_lean && rel <= tol && lean_rtol > INNER_TOL;
        let rtol = if last_lean {
            lean_rtol.min(LEAN_MAX)
        } else {
            INNER_TOL
        };
        it += correct(r, r_norm, d, rtol, max_iter - it)?.iterations;
        match lo.as_deref_mut() {
            Some(lo) => add_split(d, x, lo),
            None => axpy(1.0, d, x),
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

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::RefCell;

    /// The profile's page-fault count is the process's minor faults: writing 16 MiB of
    /// fresh memory raises it by 4,096 (small pages) or at least 8 (where the kernel backs
    /// it by huge pages); the neighbouring fields of `/proc/self/stat` (children's and major
    /// faults, CPU ticks) do not move by that much.
    #[cfg(target_os = "linux")]
    #[test]
    fn page_faults_count_fresh_pages() {
        let before = page_faults();
        assert!(before > 0, "no faults read from /proc/self/stat");
        let mut v: Vec<u8> = std::hint::black_box(Vec::with_capacity(16 << 20));
        v.resize(16 << 20, 1);
        let v = std::hint::black_box(v);
        let after = page_faults();
        assert!(after >= before + 8, "{before} → {after} faults");
        assert_eq!(
            v.iter().step_by(4096).map(|&b| b as usize).sum::<usize>(),
            4096
        );
    }

    /// The profile's CPU time is every thread's: work on this thread raises it, and it
    /// reads more than 0 (`/proc/self/task/*/schedstat`).
    #[cfg(target_os = "linux")]
    #[test]
    fn cpu_nanos_count_this_threads_work() {
        let before = cpu_nanos();
        assert!(before > 0, "no CPU time read from /proc/self/task");
        let start = Instant::now();
        let mut x = 1.0f64;
        while cpu_nanos() < before + 5_000_000 && start.elapsed().as_secs() < 60 {
            for _ in 0..100_000 {
                x = std::hint::black_box(x * 1.000_000_1);
            }
        }
        assert!(cpu_nanos() >= before + 5_000_000, "{x}");
    }

    /// [`refined`] on `diag(a) x = b` with an inner solve that reduces the residual by
    /// `achieved(rtol)` exactly and the measure `scale · ‖r‖₂ / ‖b‖₂` (residual test
    /// `tol = 1`, met from the start): the relative tolerances the inner solves were asked
    /// for, whether it converged, and the final measure.
    fn run(lean: bool, achieved: fn(f64) -> f64, scale: f64) -> (Vec<f64>, bool, f64) {
        let a = [1.0, 2.0, 4.0, 8.0];
        let b = [1.0, 2.0, 3.0, 4.0];
        let bnorm = dot(&b, &b).sqrt();
        let exact = |parts: &[&[f64]], b: &[f64], r: &mut [f64]| {
            for i in 0..b.len() {
                let x: f64 = parts.iter().map(|p| p[i]).sum();
                r[i] = b[i] - a[i] * x;
            }
        };
        let asked = RefCell::new(Vec::new());
        let mut correct = |r: &mut [f64], _: f64, d: &mut [f64], rtol: f64, _: usize| {
            asked.borrow_mut().push(rtol);
            let keep = achieved(rtol);
            for i in 0..r.len() {
                d[i] = (1.0 - keep) * r[i] / a[i];
            }
            Ok(Outcome {
                iterations: 1,
                residual: keep,
                converged: true,
            })
        };
        let measure = |_: &[f64], r: &[f64]| scale * dot(r, r).sqrt() / bnorm;
        let mut x = vec![0.0; 4];
        let mut work = Work::new(&mut ZeroedAhead::none(), 4);
        let out = refined(
            &exact,
            &mut correct,
            &measure,
            &b,
            &mut x,
            None,
            lean,
            1.0,
            100,
            &mut work,
        )
        .unwrap();
        let mut r = vec![0.0; 4];
        exact(&[&x], &b, &mut r);
        let asked = asked.into_inner();
        (asked, out.converged, measure(&x, &r))
    }

    fn close(a: &[f64], b: &[f64]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x / y - 1.0).abs() < 1e-9)
    }

    /// A lean step asks for `LEAN_MARGIN / measure`: one step of 1e-4 for a measure of 1000
    /// where a full step asks for `INNER_TOL`; both end below 1.
    #[test]
    fn a_lean_step_asks_for_what_the_measure_needs() {
        let exact_solve = |rtol: f64| rtol;
        let (asked, ok, m) = run(true, exact_solve, 1e3);
        assert!(ok && m <= 1.0 && close(&asked, &[1e-4]), "{asked:?} {m:e}");
        let (asked, ok, m) = run(false, exact_solve, 1e3);
        assert!(
            ok && m <= 1.0 && close(&asked, &[INNER_TOL]),
            "{asked:?} {m:e}"
        );
    }

    /// A lean step that falls short (its solve reaches only the square root of what was
    /// asked) is followed by a full step, not by another lean one nor a stall; a measure
    /// whose lean step would ask for less than `INNER_TOL` gets a full step first.
    #[test]
    fn a_short_lean_step_is_followed_by_a_full_one() {
        let short = |rtol: f64| if rtol > INNER_TOL { rtol.sqrt() } else { rtol };
        let (asked, ok, m) = run(true, short, 1e3);
        assert!(
            ok && m <= 1.0 && close(&asked, &[1e-4, INNER_TOL]),
            "{asked:?} {m:e}"
        );
        let (asked, ok, m) = run(true, |rtol| rtol, 1e9);
        assert!(
            ok && m <= 1.0 && close(&asked, &[INNER_TOL, 1e-4]),
            "{asked:?} {m:e}"
        );
    }
}
