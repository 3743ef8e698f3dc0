//! Polonsky–Keer with a hardness cap: elastic–perfectly-plastic contact (`0 ≤ p ≤ H`).
//!
//! # Problem
//!
//! With the notation of [`super::polonsky_keer`] (`g = max h − Δ − h + C p`), find
//!
//! ```text
//! 0 ≤ p ≤ H,   p = 0 ⇒ g ≥ 0,   0 < p < H ⇒ g = 0,   p = H ⇒ g ≤ 0,
//! ```
//!
//! i.e. minimise `f(p) = ½ pᵀCp − bᵀp` over the box `0 ≤ p ≤ H` (the bound-constrained
//! quadratic programme of the Kato / Almqvist perfectly-plastic model). Points at `p = H` are
//! *plastic*: their gap may be negative, and `−g` there is the plastic interpenetration that the
//! caller records as permanent deformation of the surface.
//!
//! # Iteration (displacement control)
//!
//! Polonsky–Keer with two bounds. `F = {0 < p < H}` is the free set.
//!
//! ```text
//! 1. g = max h − Δ − h + u;  G = Σ_F g²
//! 2. t = g + δ (G / G_old) t on F, 0 elsewhere (δ = 0 after a large set change, step 5);
//!    no descent (Σ g t ≤ 0) or F empty: t = g on W = F ∪ {p = 0, g < 0} ∪ {p = H, g > 0}
//! 3. r = C t;  τ = Σ g t / Σ r t   (Σ r t ≤ 0, periodic constant mode: the ratio test)
//! 4. p ← clamp(p − τ t, 0, H)
//! 5. p = 0 and g < 0 → p = min(−τ g, H)   (the paper's I_ol);
//!    p = H and g > 0 → p = max(H − τ g, 0)  (its mirror at the cap: a plastic point unloads)
//!    either holding more than 1 % of the free set → δ = 0 (the paper: any entry; see
//!    `docs/conventions.md`, "Conjugacy through boundary flips")
//! ```
//!
//! A step whose pressures all follow the linear step updates the gap incrementally
//! (`g ← g − τ r`); up to [`pk::sparse_limit`] truncations, caps or entries `d` add `C d` by
//! direct summation with the influence table (the elastic solver's sparse correction); more
//! take a fresh product `u = C p`. Convergence is confirmed on a fresh product.
//!
//! # Preconditioning
//!
//! With [`Options::precondition`] (the default) a conjugate step uses the elastic solver's
//! preconditioner (see [`super::polonsky_keer`], "Preconditioning") restricted to the free set:
//!
//! ```text
//! z = M (g on F) on F,   G = Σ_F g z,   t = z + δ (G / G_old) t on F
//! ```
//!
//! `M = E*|q|/2` by FFT on the zero-padded `ny × nx` grid ([`Operator::inverse_compliance`],
//! rows without a free point skip their FFTs). Its restriction to `F` is SPD, so the step is
//! a descent step with the same exact line search, projection onto `[0, H]` and entry and
//! release sets. A preconditioned `τ` is dimensionless, so the pressure moves of step 5 use
//! `τ / C_00` in place of `τ` (`p = min(−τ g / C_00, H)`, `p = max(H − τ g / C_00, 0)`: the
//! change that closes the gap of that point alone). `β` continues only a sequence of the same
//! kind. The step stays plain where the elastic solver's does: a steepest-descent step (empty
//! free set, or no descent), more than [`pk::PRECONDITION_MAX_FRACTION`] of the points free,
//! and, for the rest of the solve, once the certificate grows past `10³×` its best value.
//! A preconditioned solve whose certificate reaches no new best value in
//! 100 iterations (`PRECONDITION_STALL`) is started over from its start pressure with plain
//! steps (seen once, on a periodic 128² surface with half its points at the hardness, where
//! plain steps continuing from the stalled state cycle as well).
//! Each preconditioned iteration costs one FFT pair on the unpadded grid. The answer is the
//! same minimiser (identical contact and plastic sets in the tests).
//!
//! The chord steps of the elastic solver are not used (their chord is built from the
//! one-bound projection). The coarse-to-fine start is kept: it only supplies a start
//! pressure, which is clamped into `[0, H]`, and the coarse levels are themselves capped
//! solves. Measured at 1025² (free, Δ = 0.3 h_s, H half the largest elastic pressure,
//! 2 shared cores, medians of 3): plain steps 109 iterations, 141 FFT products, 5.6 s;
//! preconditioned 48 iterations, 62 FFT products (+ 48 preconditioner pairs), 3.1 s; the
//! elastic solve takes 41 iterations and 45 products. At 257²: 56 / 65 plain, 33 / 40
//! preconditioned.
//!
//! # Load control
//!
//! The total load `P(Δ) = Σ p(Δ)` of the capped displacement-controlled solution is continuous
//! and non-decreasing in `Δ`, linear between changes of the contact and plastic sets. The
//! imposed mean pressure `p̄ ≤ H` is met by a bracketing root search on `Δ` (Illinois
//! regula falsi, each solve warm-started from the previous pressure) until
//! `|Σp/N − p̄| ≤ max(LOAD_RTOL, tol) · p̄`. A cold solve starts from the elastic solution at
//! the load (a loose elastic solve), whose clamped pressure and approach begin the search. `p̄ = H` has the closed-form answer `p ≡ H`
//! everywhere, with the smallest approach that makes every gap `≤ 0`.
//!
//! A solve's load is known only as well as its KKT tolerance allows (a few `tol` relative):
//! near the root a warm-started solve may meet that tolerance at once, without an iteration,
//! so its load does not follow the change of `Δ` and the bracket would collapse on a `Δ`
//! whose load is still off. When a solve takes no iteration and misses the load by at most
//! [`LOAD_UNRESOLVED`] times its tolerance, the inner tolerance is tightened 100× (down to [`LOAD_INNER_TOL_MIN`]) and the bracket is searched
//! afresh from there. (Without this, `tol = 1e-8` failed on 13 of 72 small capped
//! load-controlled problems, 65²–129², and on a 513² one.)
//!
//! # Certificate
//!
//! [`super::kkt::kkt_certificate_capped`]: the violation of the three sign conditions and of
//! complementarity on the free set, relative to the same scale as the elastic solver.
//!
//! # Determinism
//!
//! Every reduction sums fixed chunks of [`pk::CHUNK`] points, combined in chunk order.

mod iteration;

use iteration::{positive, reduce, run, scale, Red};

use super::polonsky_keer::{self as pk, coarse};
use super::problem::{CoarseCost, Control, Options, Problem, Solution, Solver};
use crate::elastic::kernel::love_displacement;
use crate::elastic::operator::Operator;
use crate::error::{Error, Result};

/// Relative accuracy of the mean pressure in load control (or the solve's `tol`, if larger).
pub const LOAD_RTOL: f64 = 1e-10;

/// Tolerance of the elastic solve that starts a cold load-controlled capped solve.
const ELASTIC_START_TOL: f64 = 1e-6;

/// A preconditioned capped solve whose certificate grows past this multiple of its best value
/// so far continues with plain steps (the elastic solver's safeguard).
const PRECONDITION_SAFEGUARD: f64 = 1e3;

/// A preconditioned capped solve whose certificate has not reached a new best value for this
/// many iterations is started over with plain steps (seen on a periodic 128² surface pressed
/// to half its points at the hardness, where the preconditioned steps, and plain steps
/// continuing from their state, cycle).
const PRECONDITION_STALL: usize = 100;

/// Root-search solves allowed in load control.
const LOAD_MAX_SOLVES: usize = 200;

/// Tightest KKT tolerance the root search gives its inner solves when the requested one
/// cannot resolve the load (relative to `h_s`, a few hundred ulps of the gaps).
const LOAD_INNER_TOL_MIN: f64 = 1e-13;

/// A solve that takes no iteration and misses the load by at most this many times its KKT
/// tolerance (relative) did not resolve the load: its tolerance is tightened. (A larger miss
/// with no iteration is an exact start far from the root, e.g. no contact: the search goes on.)
const LOAD_UNRESOLVED: f64 = 1e3;

/// The finite hardness of `opts`, if any (`None` and `+∞` are the elastic problem).
pub fn finite_hardness(opts: &Options) -> Option<f64> {
    opts.hardness.filter(|h| h.is_finite())
}

/// The capped solve on a new operator built for `problem` (as [`pk::solve`]); `opts.hardness`
/// must be finite.
pub fn solve(
    problem: &Problem,
    control: Control,
    opts: &Options,
    initial: Option<&[f64]>,
) -> Result<Solution> {
    check(problem, control, opts, initial)?;
    pk::check_memory(problem, opts)?;
    solve_level(problem, control, opts, initial, pk::MAX_COARSE_LEVELS, None)
}

/// The capped solve on the caller's operator and influence table (as
/// [`pk::solve_with_kernel`]); `opts.hardness` must be finite.
pub fn solve_with_kernel(
    op: &Operator,
    table: Option<&[f64]>,
    problem: &Problem,
    control: Control,
    opts: &Options,
    initial: Option<&[f64]>,
) -> Result<Solution> {
    check(problem, control, opts, initial)?;
    pk::check_operator(op, table, problem)?;
    solve_with_operator(
        op,
        table,
        problem,
        control,
        opts,
        initial,
        pk::MAX_COARSE_LEVELS,
    )
}

/// The inputs of [`pk`] and a finite hardness.
fn check(
    problem: &Problem,
    control: Control,
    opts: &Options,
    initial: Option<&[f64]>,
) -> Result<()> {
    pk::validate(problem, control, opts, initial)?;
    if finite_hardness(opts).is_none() {
        return Err(Error::invalid(
            "hardness",
            "a capped solve needs a finite hardness (the elastic problem is pk::solve's)",
        ));
    }
    Ok(())
}

/// The capped solve with at most `levels` coarse levels (operator built here; a free level's
/// Love table from `finer`, the table of the grid it coarsens, when there is one).
fn solve_level(
    problem: &Problem,
    control: Control,
    opts: &Options,
    initial: Option<&[f64]>,
    levels: usize,
    finer: Option<(&[f64], usize)>,
) -> Result<Solution> {
    let kernel = pk::coarsened_kernel(problem, finer)?;
    let (op, kernel) = pk::operator_with(problem, kernel)?;
    let table = kernel.as_ref().map(|k| k.table.as_slice());
    solve_with_operator(&op, table, problem, control, opts, initial, levels)
}

/// The capped solve on the caller's operator (checked by the caller), with its influence
/// table `C e_0` when at hand (built by one product on first use otherwise).
#[allow(clippy::too_many_arguments)]
fn solve_with_operator(
    op: &Operator,
    table: Option<&[f64]>,
    problem: &Problem,
    control: Control,
    opts: &Options,
    initial: Option<&[f64]>,
    levels: usize,
) -> Result<Solution> {
    let cap = finite_hardness(opts).expect("a capped solve needs a finite hardness");
    let (hmax, hmin, _) = pk::height_stats(problem.heights);
    let hs = hmax - hmin;
    let c00 = love_displacement(0.0, 0.0, problem.dx, problem.e_star);
    // One preconditioner for every solve at this level (load control runs several).
    let pre = if opts.precondition {
        Some(Operator::inverse_compliance(
            problem.ny,
            problem.nx,
            problem.dx,
            problem.e_star,
        )?)
    } else {
        None
    };
    let pre = pre.as_ref();
    let start_of = |control: Control| -> Result<(Option<Vec<f64>>, CoarseCost)> {
        if let Some(p0) = initial {
            return Ok((Some(p0.to_vec()), CoarseCost::default()));
        }
        if levels > 0 && coarse::applies_to(problem.ny, problem.nx, opts, initial) {
            // The coarse levels are capped solves too; only their pressure is used.
            let love = pk::finer_table(problem, table);
            let level = |p: &Problem, c: Control, o: &Options, below: usize| {
                solve_level(p, c, o, None, below, love)
            };
            if let Some((p, cost)) = coarse::start(problem, control, opts, levels, level)? {
                return Ok((Some(p), cost));
            }
        }
        Ok((None, CoarseCost::default()))
    };
    match control {
        Control::Approach(delta) => {
            let (p0, cost) = start_of(control)?;
            let mut sol = run(op, table, problem, hmax, hs, c00, delta, cap, opts, pre, p0)?;
            sol.coarse = cost;
            Ok(sol)
        }
        Control::MeanPressure(pbar) => {
            if pbar >= cap {
                return Ok(full_plastic(op, problem, hmax, hs, c00, cap));
            }
            let target = pbar;
            let rtol = LOAD_RTOL.max(opts.tol);
            // Bracket: Δ = 0 carries no load (p = 0 is its solution).
            let (mut lo_d, mut lo_m) = (0.0f64, 0.0f64);
            let mut hi: Option<(f64, f64)> = None;
            let mut d = if hs > 0.0 { 0.5 * hs } else { pbar * c00 };
            let mut applies0 = 0;
            let mut cost = CoarseCost::default();
            // A cold start begins from the elastic solution at the load (a loose elastic
            // solve): its pressure, clamped, is the first start.
            let elastic = if initial.is_none() {
                let eo = Options {
                    hardness: None,
                    tol: ELASTIC_START_TOL.max(opts.tol),
                    ..*opts
                };
                match pk::solve_with_kernel(op, table, problem, control, &eo, None) {
                    Ok(sol) => {
                        applies0 += sol.fft_products;
                        cost = sol.coarse;
                        Some(sol.pressure)
                    }
                    Err(Error::Interrupted) => return Err(Error::Interrupted),
                    Err(_) => None,
                }
            } else {
                None
            };
            let p_start = initial.or(elastic.as_deref());
            if let Some(p0) = p_start {
                // A start pressure also gives the approach: the mean over its free set of
                // `max h − h + C p` (the elastic solver's load-control formula).
                if let Some(e) = approach_of(op, problem, hmax, p0, pbar, cap) {
                    d = e;
                }
                applies0 += 1;
            }
            let mut warm = match p_start {
                Some(p0) => Some(p0.to_vec()),
                None => {
                    let (w, c) = start_of(Control::Approach(d))?;
                    cost = c;
                    w
                }
            };
            drop(elastic);
            let mut total = (0usize, applies0);
            let mut pre_total = 0usize;
            let mut side = 0i32;
            // The inner solves' tolerance: tightened when it cannot resolve the load (below).
            let mut inner = *opts;
            let mut load_error = f64::NAN;
            for _ in 0..LOAD_MAX_SOLVES {
                let mut sol = run(
                    op,
                    table,
                    problem,
                    hmax,
                    hs,
                    c00,
                    d,
                    cap,
                    &inner,
                    pre,
                    warm.take(),
                )?;
                total.0 += sol.iterations;
                total.1 += sol.fft_products;
                pre_total += sol.preconditioner_products;
                let m = sol.mean_pressure;
                load_error = (m - target).abs() / target;
                if load_error <= rtol {
                    sol.iterations = total.0;
                    sol.fft_products = total.1;
                    sol.preconditioner_products = pre_total;
                    sol.coarse = std::mem::take(&mut cost);
                    return Ok(sol);
                }
                if sol.iterations == 0 && load_error <= LOAD_UNRESOLVED * inner.tol {
                    // The start already met the KKT tolerance at this Δ, so the solve could
                    // not follow the change of Δ: the load is known only to what that
                    // tolerance allows (a few `tol` relative), and the bracket would collapse
                    // on a Δ whose load is off. Solve tighter and bracket afresh from here.
                    if inner.tol <= LOAD_INNER_TOL_MIN {
                        break;
                    }
                    inner.tol = (inner.tol * 1e-2).max(LOAD_INNER_TOL_MIN);
                    (lo_d, lo_m, hi, side) = (0.0, 0.0, None, 0);
                    warm = Some(sol.pressure);
                    continue;
                }
                if m < target {
                    lo_d = d;
                    lo_m = m;
                    if side == -1 {
                        if let Some(h) = hi.as_mut() {
                            // Illinois: halve the retained end's excess.
                            h.1 = target + 0.5 * (h.1 - target);
                        }
                    }
                    side = -1;
                } else {
                    if side == 1 {
                        lo_m = target - 0.5 * (target - lo_m);
                    }
                    hi = Some((d, m));
                    side = 1;
                }
                d = match hi {
                    // The load grows at least linearly with Δ from P(0) = 0 (the contact
                    // spreads), so the line through the origin overshoots the root: a
                    // bracket in one step, at most 4× further.
                    None if m > 0.0 => (d * target / m).min(4.0 * d),
                    None => 2.0 * d.max(f64::MIN_POSITIVE),
                    Some((hd, hm)) => {
                        let next = lo_d + (target - lo_m) * (hd - lo_d) / (hm - lo_m);
                        if next.is_finite() && next > lo_d && next < hd {
                            next
                        } else {
                            0.5 * (lo_d + hd)
                        }
                    }
                };
                warm = Some(sol.pressure);
            }
            Err(Error::NotConverged {
                iterations: total.0,
                residual: load_error,
                what: "Polonsky–Keer with hardness (load control root search; residual: \
                       relative load error)"
                    .into(),
            })
        }
    }
}

/// The approach a start pressure `p0` (rescaled to the mean `pbar`, clamped into `[0, H]`)
/// implies: `Δ = mean_{0<p<H} (max h − h + C p)` (over `p > 0` when no point is free), or
/// `None` when it has no contact or the value is not a positive number.
fn approach_of(
    op: &Operator,
    problem: &Problem,
    hmax: f64,
    p0: &[f64],
    pbar: f64,
    cap: f64,
) -> Option<f64> {
    let n = p0.len();
    let sum: f64 = p0.iter().map(|&v| v.max(0.0)).sum();
    if !positive(sum) {
        return None;
    }
    let s = pbar * n as f64 / sum;
    let p: Vec<f64> = p0.iter().map(|&v| (v.max(0.0) * s).min(cap)).collect();
    let mut u = vec![0.0; n];
    op.apply(&p, &mut u);
    let h = problem.heights;
    let (mut free, mut nf, mut all, mut na) = (0.0, 0usize, 0.0, 0usize);
    for i in 0..n {
        if p[i] > 0.0 {
            let v = hmax - h[i] + u[i];
            all += v;
            na += 1;
            if p[i] < cap {
                free += v;
                nf += 1;
            }
        }
    }
    let d = if nf > 0 {
        free / nf as f64
    } else if na > 0 {
        all / na as f64
    } else {
        return None;
    };
    (d.is_finite() && d > 0.0).then_some(d)
}

/// `p ≡ H`: the mean pressure equals the hardness.
fn full_plastic(
    op: &Operator,
    problem: &Problem,
    hmax: f64,
    hs: f64,
    c00: f64,
    cap: f64,
) -> Solution {
    let n = problem.ny * problem.nx;
    let h = problem.heights;
    let p = vec![cap; n];
    let mut u = vec![0.0; n];
    op.apply(&p, &mut u);
    // The smallest approach that leaves no gap open: Δ = max (max h − h + u).
    let delta = u
        .iter()
        .zip(h)
        .map(|(&ui, &hi)| hmax - hi + ui)
        .fold(f64::NEG_INFINITY, f64::max);
    let g: Vec<f64> = u
        .iter()
        .zip(h)
        .map(|(&ui, &hi)| hmax - delta - hi + ui)
        .collect();
    let red = reduce(n, |lo, hi| {
        let mut a = Red::ZERO;
        for i in lo..hi {
            a.observe(p[i], g[i], cap);
        }
        a
    });
    let scale = scale(hs, delta, cap, c00);
    Solution {
        solver: Solver::PolonskyKeer,
        pressure: p,
        displacement: u,
        gap: g,
        approach: delta,
        iterations: 0,
        fft_products: 1,
        preconditioner_products: 0,
        chord_steps: 0,
        single_products: 0,
        kkt: red.certificate() / scale,
        contact_points: n,
        plastic_points: n,
        load: cap * n as f64 * problem.dx * problem.dx,
        mean_pressure: cap,
        coarse: CoarseCost::default(),
    }
}

#[cfg(test)]
mod tests;
