//! The Polonsky–Keer iteration (the steps of the module documentation) over the fused passes.

use std::borrow::Cow;
use std::time::Instant;

use rayon::prelude::*;

use super::passes::{positive, Acc, Mode, Work};
use super::*;
use crate::alloc;
use crate::contact::problem::Solver;
use crate::elastic::kernel::love_displacement;

/// Step 7 of load control folded into the gap pass: `p` and `u` scaled together by
/// `k = target / Σ p`, the approach `Δ = (Σ_{I_c} (max h − h) + k Σ_{I_c} u) / |I_c|` from the
/// sums `now` of the unscaled state. Returns `Δ` and the new state's reductions.
fn scale_to_load(w: &mut Work<'_>, target: f64, now: Acc) -> (f64, Acc) {
    let k = target / now.sum_p;
    let delta = (now.sh + k * now.su) / now.n_c.max(1) as f64;
    (delta, w.gap_pass(delta, Some(k)))
}

/// Rescaled load steps (module documentation): the state scaled to the imposed approach
/// `delta` by [`Work::rescale`], or `None` with nothing changed when the steps are the plain
/// ones (`rescaled` false) or `k` is not usable, which ends the rescaled steps for this solve
/// (and the conjugate sequence, `cg`).
fn rescale_state(w: &mut Work<'_>, delta: f64, rescaled: &mut bool, cg: &mut bool) -> Option<Acc> {
    if !*rescaled {
        return None;
    }
    let next = w.rescale(delta);
    if next.is_none() {
        *rescaled = false;
        *cg = false;
    }
    next
}

/// Deterministic `(max, min, Σ)` of the heights.
pub(crate) fn height_stats(h: &[f64]) -> (f64, f64, f64) {
    let parts: Vec<(f64, f64, f64)> = h
        .par_chunks(CHUNK)
        .map(|c| {
            c.iter().fold(
                (f64::NEG_INFINITY, f64::INFINITY, 0.0),
                |(mx, mn, s), &v| (mx.max(v), mn.min(v), s + v),
            )
        })
        .collect();
    parts.iter().fold(
        (f64::NEG_INFINITY, f64::INFINITY, 0.0),
        |(mx, mn, s), &(a, b, c)| (mx.max(a), mn.min(b), s + c),
    )
}

/// Where the iteration starts.
pub(super) enum Begin<'a> {
    /// `p = 0` (displacement control) or the uniform `p̄` (load control, the paper's).
    Zero,
    /// A caller's pressure field (`N` finite values; negative ones are clipped to 0).
    Warm(&'a [f64]),
    /// The coarse start's prolonged pressure (`≥ 0`, `N` values), taken over as the iterate.
    Coarse(Vec<f64>),
}

/// Below the switch level, `u = C p` is refreshed in `f64` once the certificate has fallen
/// this factor below its value at the previous refresh (the `f32` increments between two
/// refreshes move `g` by about `1e-6` of their own size).
pub(super) const REFRESH_RATIO: f64 = 1e-2;

/// The iteration from `begin`.
pub(super) fn run(
    op: &Operator,
    table: Option<&[f64]>,
    problem: &Problem,
    control: Control,
    opts: &Options,
    begin: Begin<'_>,
    finish: Finish,
) -> Result<Solution> {
    let (start, initial) = match begin {
        Begin::Zero => (None, None),
        Begin::Warm(p0) => (None, Some(p0)),
        Begin::Coarse(p0) => (Some(p0), None),
    };
    let (ny, nx) = (problem.ny, problem.nx);
    let n = ny * nx;
    let h = problem.heights;
    let (hmax, hmin, hsum) = height_stats(h);
    let hs = hmax - hmin;
    let c00 = love_displacement(0.0, 0.0, problem.dx, problem.e_star);
    let periodic = op.boundary == Boundary::Periodic;

    let mut at_limit = false;
    let mode = match control {
        Control::Approach(mut delta) => {
            if periodic {
                // Full contact of a periodic surface with zero-mean u: Σ g = N(max h − Δ − mean h).
                let limit = hmax - hsum / n as f64;
                let slack = 1e-12 * hs.max(hmax.abs()).max(hmin.abs());
                if delta > limit + slack {
                    return Err(Error::invalid(
                        "approach",
                        format!(
                            "{delta} exceeds the full-contact approach max h − mean h = {limit} of \
                             a periodic surface (u has zero mean, so the flat cannot move further)"
                        ),
                    ));
                }
                if delta >= limit {
                    delta = limit;
                    at_limit = true;
                }
            }
            Mode::Displacement(delta)
        }
        Control::MeanPressure(m) => Mode::Load(m * n as f64),
    };
    // The certificate's scale. A patch pressed far past its height range has gaps and
    // displacements of the order of Δ (or, in load control, of the displacement `p̄·C_00` that
    // the mean pressure makes at its own cell), so round-off is relative to those, not h_s:
    // at p̄ = 10⁴ E* on a 33² free patch Δ ≈ 10³ h_s, and a certificate relative to h_s
    // cannot go below ~1e-12. In load control Δ is an output, so the scale follows the
    // current Δ.
    let scale_at = |delta: f64| -> f64 {
        match control {
            Control::Approach(d) if hs > 0.0 => hs.max(d),
            Control::Approach(d) if d > 0.0 => d,
            Control::Approach(_) => 1.0,
            Control::MeanPressure(m) => {
                let s = hs.max(m * c00);
                if delta.is_finite() {
                    s.max(delta.abs())
                } else {
                    s
                }
            }
        }
    };
    let max_iter = opts.max_iter.unwrap_or_else(|| default_max_iter(n));
    // Displacement control of a free surface from a start with pressure (the coarse start's
    // or a caller's) takes rescaled load steps (module documentation; on periodic surfaces
    // they did not pay).
    let start_loaded = start
        .as_deref()
        .or(initial)
        .is_some_and(|p0| p0.par_iter().any(|&v| v > 0.0));
    let mut rescaled =
        opts.rescaled_steps && matches!(mode, Mode::Displacement(_)) && !periodic && start_loaded;

    let n_chunks = n.div_ceil(CHUNK);
    let sparse_max = sparse_limit(op.boundary);
    let u_in_r = matches!(mode, Mode::Displacement(_));
    // Products in f32 while the certificate is above the switch level (not worth it when the
    // tolerance is already above it: the confirming f64 product would be an extra one).
    let switch = opts.single_precision_above;
    let single = if switch > opts.tol && switch.is_finite() {
        Some(op.single()?)
    } else {
        None
    };
    let mut w = Work {
        op,
        single_full: single.is_some(),
        single,
        single_applies: 0,
        h,
        hmax,
        p: match start {
            Some(p0) if p0.len() == n => p0,
            _ => alloc::try_zeroed(n, "the pressure field")?,
        },
        u: if u_in_r {
            Vec::new()
        } else {
            alloc::try_zeroed(n, "the displacement field")?
        },
        u_in_r,
        g: alloc::try_zeroed(n, "the gap field")?,
        t: alloc::try_zeroed(n, "the conjugate direction")?,
        r: alloc::try_zeroed(n, "the operator work field")?,
        table: match table {
            Some(k) => Cow::Borrowed(k),
            None => Cow::Owned(alloc::try_with_capacity(n, "the influence table")?),
        },
        slots: alloc::try_filled(
            n_chunks * SPARSE_MAX,
            (0, 0.0),
            "the sparse-correction slots",
        )?,
        changes: Vec::with_capacity(SPARSE_MAX),
        changes_field: Vec::new(),
        ny,
        nx,
        periodic,
        parts: vec![Acc::ZERO; n_chunks],
        applies: 0,
        pre: None,
        pre_applies: 0,
    };
    if opts.precondition {
        let pre = Operator::inverse_compliance(ny, nx, problem.dx, problem.e_star)?;
        if w.single.is_some() {
            // Its f32 twin, used beside the operator's (`Work::precondition`).
            pre.single()?;
        }
        w.pre = Some(pre);
    }

    // Initial pressure: the warm start, or p = 0 (displacement) / uniform p̄ (load, the paper's).
    if let Some(p0) = initial {
        w.p.par_iter_mut()
            .zip(p0.par_iter())
            .for_each(|(p, &v)| *p = v.max(0.0));
    }
    if let Mode::Load(target) = mode {
        let sum = w.contact_sums().sum_p;
        if sum > 0.0 {
            w.scale_p(target / sum);
        } else {
            let pbar = target / n as f64;
            w.p.par_iter_mut().for_each(|v| *v = pbar);
        }
    }
    let any_p = w.p.par_iter().any(|&v| v > 0.0);
    if any_p {
        w.refresh_u();
    }
    let mut cg = false; // the paper's δ
    let (mut state, mut delta) = w.evaluate(mode);
    // After a rescale `u = C p` (kept in `r`) is no longer fresh.
    let mut fresh = true;
    if let Some(next) = rescale_state(&mut w, delta, &mut rescaled, &mut cg) {
        state = next;
        fresh = false;
    }
    // Below the switch level the increments C t stay in f32 and u = C p is refreshed in f64
    // each time the certificate has fallen REFRESH_RATIO below its value at the last refresh.
    let mut refreshed_at = f64::INFINITY;

    let mut it = 0usize;
    let mut g_old = 1.0;
    // The last step was a preconditioned one (its `G = Σ g z` is what β continues from).
    let mut last_pre = false;
    let mut last_poll = Instant::now();
    let mut best_cert = f64::INFINITY;
    // Chord steps (and the β = 0 that goes with them) only where they are taken.
    let chords_on = opts.chord_steps;
    let mut chord = false;
    let mut chord_steps = 0usize;
    let (mut tau_pre, mut tau_plain) = (f64::NAN, f64::NAN);
    loop {
        let cert = state.certificate() / scale_at(delta);
        if w.pre.is_some() && cert > SAFEGUARD * best_cert {
            // The preconditioned iteration is not contracting: finish with plain steps.
            w.pre = None;
            cg = false;
        }
        best_cert = best_cert.min(cert);
        let converged = cert <= opts.tol;
        if converged && ((fresh && !w.full_in_single()) || finish == Finish::Incremental) {
            break;
        }
        // A fresh f64 product u = C p, and f64 full products from here on: to confirm
        // convergence reached on an incrementally updated u (or on f32 products), at the
        // switch level, and below it each time the certificate has fallen REFRESH_RATIO below
        // its value at the last fresh product (the f32 increments' drift).
        let at_switch = w.full_in_single() && cert <= switch;
        let drifted =
            w.single.is_some() && !w.single_full && !fresh && cert <= REFRESH_RATIO * refreshed_at;
        if converged || at_switch || drifted {
            w.single_full = false;
            if w.single.is_some() && w.changes_field.is_empty() {
                w.changes_field = alloc::try_zeroed(n, "the non-linear changes field")?;
            }
            w.refresh_u();
            (state, delta) = w.evaluate(mode);
            fresh = true;
            // Not on the confirming product: the returned `u` must be `C p` of the answer.
            if !converged {
                if let Some(next) = rescale_state(&mut w, delta, &mut rescaled, &mut cg) {
                    state = next;
                    fresh = false;
                }
            }
            refreshed_at = state.certificate() / scale_at(delta);
            continue;
        }
        if it >= max_iter || !cert.is_finite() {
            return Err(Error::NotConverged {
                iterations: it,
                residual: cert,
                what: "Polonsky–Keer".into(),
            });
        }
        if let Some(stop) = opts.should_stop {
            if it % STOP_EVERY == 0 || last_poll.elapsed() >= STOP_INTERVAL {
                last_poll = Instant::now();
                if stop() {
                    return Err(Error::Interrupted);
                }
            }
        }

        // Step 2: the conjugate direction, or a steepest-descent step on I_c ∪ {g < 0} when
        // there is no contact set or the direction carries no descent.
        let mut steepest = state.n_c == 0;
        let mut preconditioned = false;
        let mut dir = Acc::ZERO;
        // Past half contact the preconditioned steps stop paying (measured: the same or more
        // iterations); the first steepest step from p = 0 can pass it briefly.
        if w.pre.is_some() && !steepest && state.n_c as f64 <= PRECONDITION_MAX_FRACTION * n as f64
        {
            // G = Σ_{I_c} g z; β continues only a preconditioned sequence.
            let gz = w.precondition().gt;
            let beta = if cg && !chord && last_pre && g_old > 0.0 {
                gz / g_old
            } else {
                0.0
            };
            dir = w.direction_preconditioned(beta);
            if positive(dir.gt) && positive(gz) {
                preconditioned = true;
                g_old = gz;
            }
        }
        if !preconditioned {
            let beta = if cg && !chord && !last_pre && !steepest && g_old > 0.0 {
                state.gg / g_old
            } else {
                0.0
            };
            dir = w.direction(beta, steepest);
            if !positive(dir.gt) && !steepest {
                steepest = true;
                dir = w.direction(0.0, true);
            }
        }
        if !positive(dir.gt) {
            // No descent anywhere: g vanishes on I_c and nothing overlaps, up to round-off
            // below the certificate's resolution.
            return Err(Error::NotConverged {
                iterations: it,
                residual: cert,
                what: "Polonsky–Keer".into(),
            });
        }
        if !preconditioned {
            g_old = if steepest { dir.gt } else { state.gg };
        }
        last_pre = preconditioned;

        // A chord step while the contact set is changing wholesale (both controls; under load
        // control the trial is scaled to the load, so `Σ d = 0`):
        // the trial projected step `d = p(τ₀) − p` is applied through its own product `C d`,
        // so `g` stays exact with one product per iteration; the step length along `d` is
        // the exact minimiser of the energy on the chord, capped at 1 (feasible).
        if chord && !steepest {
            let tau0 = if preconditioned { tau_pre } else { tau_plain };
            if tau0.is_finite() && tau0 > 0.0 {
                let tau_ol0 = if preconditioned { tau0 / c00 } else { tau0 };
                let trial = match mode {
                    // Rescaled load steps: the trial keeps the current load, as under load
                    // control; the rescale after the step moves it.
                    Mode::Displacement(_) if rescaled => w.chord_load(tau0, tau_ol0, state.sum_p),
                    Mode::Displacement(_) => w.chord(tau0, tau_ol0),
                    Mode::Load(target) => w.chord_load(tau0, tau_ol0, target),
                };
                if trial.gt < 0.0 {
                    w.product_t();
                    let drd = w.curvature(false, false).rt;
                    let s = if positive(drd) {
                        (-trial.gt / drd).min(1.0)
                    } else {
                        1.0
                    };
                    state = match mode {
                        Mode::Displacement(_) => {
                            let next = w.chord_update(s);
                            rescale_state(&mut w, delta, &mut rescaled, &mut cg).unwrap_or(next)
                        }
                        Mode::Load(target) => {
                            // Σ d = 0: the new p keeps the load up to round-off, which the
                            // rescale of step 7 removes.
                            let now = w.chord_update_load(s);
                            let (d, next) = scale_to_load(&mut w, target, now);
                            delta = d;
                            next
                        }
                    };
                    it += 1;
                    fresh = false;
                    cg = false;
                    let next = tau0
                        * if s < 1.0 {
                            s.max(CHORD_SHRINK_MIN)
                        } else {
                            CHORD_GROW
                        };
                    if preconditioned {
                        tau_pre = next;
                    } else {
                        tau_plain = next;
                    }
                    chord_steps += 1;
                    chord = wholesale(trial.n_nl, state.n_c, sparse_max);
                    continue;
                }
                // No descent on the chord: redo the direction, take a regular step.
                dir = if preconditioned {
                    w.direction_preconditioned(0.0)
                } else {
                    w.direction(0.0, false)
                };
            }
        }

        // Steps 3–4.
        w.product_t();
        let curv = w.curvature(steepest, rescaled || matches!(mode, Mode::Load(_)));
        let denom = match mode {
            Mode::Displacement(_) if !rescaled => curv.rt,
            _ => curv.rt - curv.rw / dir.n_w.max(1) as f64 * dir.st,
        };
        let mut tau = dir.gt / denom;
        if !positive(denom) || !tau.is_finite() {
            tau = w.ratio_test();
            if !tau.is_finite() {
                return Err(Error::NotConverged {
                    iterations: it,
                    residual: cert,
                    what: "Polonsky–Keer (unbounded direction)".into(),
                });
            }
        }

        // Steps 5–6 (+ 1 on the incremental u).
        // Points entering through I_ol get `p = −τ g` (the paper's rule) after a plain step.
        // A preconditioned step's `τ` is dimensionless (≈ 1 when M ≈ C⁻¹); its entries get
        // `−τ g / C_00`, the pressure that closes the gap at that point alone, the softer of
        // the two local stiffness estimates (the diagonal of M overshoots and oscillates).
        let tau_ol = if preconditioned { tau / c00 } else { tau };
        // The last line-search lengths start the chord's trial length.
        if preconditioned {
            tau_pre = tau;
        } else if !steepest {
            tau_plain = tau;
        }
        let up = w.update(tau, tau_ol, mode);
        it += 1;
        // The paper resets δ = 0 on any I_ol entry; here only entries of more than
        // OL_KEEP_FRACTION of the contact set reset it (see there). After a steepest step on W,
        // δ = 1 continues CG from that step (G_old = Σ_W g²), which is exact when the set did
        // not change.
        cg = keeps_conjugacy(up.n_ol, up.n_c);
        // Bring u (displacement control: g) up to date with p. A linear step is already done
        // by the update pass; a few non-linear changes d get C d by direct summation; many
        // get a fresh product C p.
        let mut sparse = None;
        if up.n_nl > 0 && up.n_nl <= sparse_max {
            w.gather_changes();
            w.ensure_table();
            sparse = Some(match mode {
                Mode::Displacement(_) => w.correct_gap(),
                Mode::Load(_) => w.correct_u(),
            });
        }
        let mut now = sparse.unwrap_or(up);
        let mut consistent = up.n_nl <= sparse_max;
        if !consistent && !w.changes_field.is_empty() {
            // Below the switch level: the changes by one f32 increment product, not a fresh
            // f64 product C p.
            now = w.correct_dense(mode);
            consistent = true;
        }
        chord = chords_on && wholesale(up.n_nl, up.n_c, sparse_max);
        match mode {
            Mode::Displacement(_) if consistent => {
                fresh = false;
                state = rescale_state(&mut w, delta, &mut rescaled, &mut cg).unwrap_or(now);
            }
            Mode::Load(target) if consistent && now.n_c > 0 => {
                fresh = false;
                (delta, state) = scale_to_load(&mut w, target, now);
            }
            _ => {
                if let Mode::Load(target) = mode {
                    let sum = w.contact_sums().sum_p;
                    if sum > 0.0 {
                        w.scale_p(target / sum);
                    } else {
                        let pbar = target / n as f64;
                        w.p.par_iter_mut().for_each(|v| *v = pbar);
                    }
                }
                w.refresh_u();
                (state, delta) = w.evaluate(mode);
                fresh = true;
                if let Some(next) = rescale_state(&mut w, delta, &mut rescaled, &mut cg) {
                    state = next;
                    fresh = false;
                }
            }
        }
    }

    if at_limit {
        // Δ = max h − mean h of a periodic surface: p is defined up to a constant (C 1 = 0).
        // Return the least-load state, the limit of Δ ↑ max h − mean h, min p = 0.
        let pmin = w.p.par_iter().cloned().reduce(|| f64::INFINITY, f64::min);
        if pmin > 0.0 {
            w.p.par_iter_mut().for_each(|v| *v = (*v - pmin).max(0.0));
            w.refresh_u();
            (state, delta) = w.evaluate(mode);
        }
    }

    let kkt = state.certificate() / scale_at(delta);
    let sum_p = state.sum_p;
    let applies = w.applies;
    let single_applies = w.single_applies;
    let pre_applies = w.pre_applies;
    let pressure = std::mem::take(&mut w.p);
    let gap = std::mem::take(&mut w.g);
    let displacement = if fresh {
        w.into_displacement()
    } else {
        // Finish::Incremental: `u` was updated incrementally (displacement control: `r` holds
        // the last `C t`).
        Vec::new()
    };
    Ok(Solution {
        solver: Solver::PolonskyKeer,
        pressure,
        displacement,
        gap,
        approach: delta,
        iterations: it,
        fft_products: applies,
        single_products: single_applies,
        preconditioner_products: pre_applies,
        chord_steps,
        kkt,
        contact_points: state.n_c,
        plastic_points: 0,
        load: sum_p * problem.dx * problem.dx,
        mean_pressure: sum_p / n as f64,
        coarse: CoarseCost::default(),
    })
}
