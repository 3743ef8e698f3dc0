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
//! 2. t = g + δ (G / G_old) t on F, 0 elsewhere (δ = 0 after a set change);
//!    no descent (Σ g t ≤ 0) or F empty: t = g on W = F ∪ {p = 0, g < 0} ∪ {p = H, g > 0}
//! 3. r = C t;  τ = Σ g t / Σ r t   (Σ r t ≤ 0, periodic constant mode: the ratio test)
//! 4. p ← clamp(p − τ t, 0, H)
//! 5. p = 0 and g < 0 → p = min(−τ g, H)   (the paper's I_ol);
//!    p = H and g > 0 → p = max(H − τ g, 0)  (its mirror at the cap: a plastic point unloads)
//!    either non-empty → δ = 0
//! ```
//!
//! A step whose pressures all follow the linear step updates the gap incrementally
//! (`g ← g − τ r`); up to [`pk::sparse_limit`] truncations, caps or entries `d` add `C d` by
//! direct summation with the influence table (the elastic solver's sparse correction); more
//! take a fresh product `u = C p`. Convergence is confirmed on a fresh product.
//!
//! The elastic solver's preconditioner and chord steps are not used here (their step rules
//! assume one bound). The coarse-to-fine start is kept: it only supplies a start pressure,
//! which is clamped into `[0, H]`, and the coarse levels are themselves capped solves.
//! Measured at 1025² (free, Δ = 0.3 h_s, H half the largest elastic pressure, 2 cores):
//! 109 iterations and 141 FFT products (184 without the sparse corrections), against 41 and
//! 45 for the elastic solve.
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
//! # Certificate
//!
//! [`super::kkt::kkt_certificate_capped`]: the violation of the three sign conditions and of
//! complementarity on the free set, relative to the same scale as the elastic solver.
//!
//! # Determinism
//!
//! Every reduction sums fixed chunks of [`CHUNK`] points, combined in chunk order.

use std::time::Instant;

use rayon::prelude::*;

use super::polonsky_keer::{self as pk, coarse, default_max_iter, CHUNK};
use super::problem::{CoarseCost, Control, Options, Problem, Solution, Solver};
use crate::alloc;
use crate::elastic::kernel::{love_displacement, Kernel};
use crate::elastic::operator::Operator;
use crate::error::{Error, Result};
use crate::grid::Boundary;

/// Relative accuracy of the mean pressure in load control (or the solve's `tol`, if larger).
pub const LOAD_RTOL: f64 = 1e-10;

/// Tolerance of the elastic solve that starts a cold load-controlled capped solve.
const ELASTIC_START_TOL: f64 = 1e-6;

/// Root-search solves allowed in load control.
const LOAD_MAX_SOLVES: usize = 200;

/// The finite hardness of `opts`, if any (`None` and `+∞` are the elastic problem).
pub fn finite_hardness(opts: &Options) -> Option<f64> {
    opts.hardness.filter(|h| h.is_finite())
}

/// `x > 0` and not NaN.
#[inline]
fn positive(x: f64) -> bool {
    x > 0.0
}

/// Partial reductions of one chunk.
#[derive(Clone, Copy, Debug)]
struct Red {
    n_c: usize,
    n_pl: usize,
    sum_p: f64,
    sum_pg: f64,
    gg: f64,
    viol: f64,
    bad: usize,
    gt: f64,
    rt: f64,
    n_ol: usize,
    n_ul: usize,
    n_nl: usize,
}

impl Red {
    const ZERO: Red = Red {
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

    fn merge(self, o: &Red) -> Red {
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
    fn observe(&mut self, p: f64, g: f64, cap: f64) {
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
    fn certificate(&self) -> f64 {
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
fn reduce(n: usize, f: impl Fn(usize, usize) -> Red + Sync) -> Red {
    let parts: Vec<Red> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| f(c * CHUNK, ((c + 1) * CHUNK).min(n)))
        .collect();
    parts.iter().fold(Red::ZERO, |a, b| a.merge(b))
}

/// `(max h, max h − min h)`.
fn height_range(h: &[f64]) -> (f64, f64) {
    let (mx, mn) = h
        .par_chunks(CHUNK)
        .map(|c| {
            c.iter()
                .fold((f64::NEG_INFINITY, f64::INFINITY), |(a, b), &v| {
                    (a.max(v), b.min(v))
                })
        })
        .collect::<Vec<_>>()
        .into_iter()
        .fold((f64::NEG_INFINITY, f64::INFINITY), |(a, b), (c, d)| {
            (a.max(c), b.min(d))
        });
    (mx, mx - mn)
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
    solve_level(problem, control, opts, initial, pk::MAX_COARSE_LEVELS)
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

/// The capped solve with at most `levels` coarse levels (operator built here).
fn solve_level(
    problem: &Problem,
    control: Control,
    opts: &Options,
    initial: Option<&[f64]>,
    levels: usize,
) -> Result<Solution> {
    let (ny, nx) = (problem.ny, problem.nx);
    match problem.boundary {
        Boundary::Free => {
            let kernel = Kernel::try_new(ny, nx, problem.dx, problem.e_star)?;
            let op = Operator::try_free(&kernel)?;
            solve_with_operator(
                &op,
                Some(&kernel.table),
                problem,
                control,
                opts,
                initial,
                levels,
            )
        }
        Boundary::Periodic => {
            let op = Operator::try_periodic(ny, nx, problem.dx, problem.e_star)?;
            solve_with_operator(&op, None, problem, control, opts, initial, levels)
        }
    }
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
    let (hmax, hs) = height_range(problem.heights);
    let c00 = love_displacement(0.0, 0.0, problem.dx, problem.e_star);
    let start_of = |control: Control| -> Result<(Option<Vec<f64>>, CoarseCost)> {
        if let Some(p0) = initial {
            return Ok((Some(p0.to_vec()), CoarseCost::default()));
        }
        if levels > 0 && coarse::applies_to(problem.ny, problem.nx, opts, initial) {
            // The coarse levels are capped solves too; only their pressure is used.
            let level = |p: &Problem, c: Control, o: &Options, below: usize| {
                solve_level(p, c, o, None, below)
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
            let mut sol = run(op, table, problem, hmax, hs, c00, delta, cap, opts, p0)?;
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
            let mut side = 0i32;
            for _ in 0..LOAD_MAX_SOLVES {
                let mut sol = run(op, table, problem, hmax, hs, c00, d, cap, opts, warm.take())?;
                total.0 += sol.iterations;
                total.1 += sol.fft_products;
                let m = sol.mean_pressure;
                if (m - target).abs() <= rtol * target {
                    sol.iterations = total.0;
                    sol.fft_products = total.1;
                    sol.coarse = std::mem::take(&mut cost);
                    return Ok(sol);
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
                residual: f64::NAN,
                what: "Polonsky–Keer with hardness (load control root search)".into(),
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
        kkt: red.certificate() / scale,
        contact_points: n,
        plastic_points: n,
        load: cap * n as f64 * problem.dx * problem.dx,
        mean_pressure: cap,
        coarse: CoarseCost::default(),
    }
}

/// The certificate's scale: `max(h_s, |Δ|)`, or `H · C_00` for a flat surface at `Δ = 0`.
fn scale(hs: f64, delta: f64, cap: f64, c00: f64) -> f64 {
    let s = hs.max(delta.abs());
    if s > 0.0 {
        s
    } else {
        (cap * c00).max(f64::MIN_POSITIVE)
    }
}

/// The capped iteration at the approach `delta` from `p0` (clamped into `[0, H]`).
#[allow(clippy::too_many_arguments)]
fn run(
    op: &Operator,
    table: Option<&[f64]>,
    problem: &Problem,
    hmax: f64,
    hs: f64,
    c00: f64,
    delta: f64,
    cap: f64,
    opts: &Options,
    p0: Option<Vec<f64>>,
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
        // Step 2.
        let n_free = state.n_c - state.n_pl;
        let mut steepest = n_free == 0;
        let mut gt = 0.0;
        if !steepest {
            let beta = if cg && g_old > 0.0 {
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
        // Steps 4–5, with the incremental gap.
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
                            pn = (-tau * gi).min(cap);
                            a.n_ol += 1;
                        } else if pn == cap && gi > 0.0 {
                            pn = (cap - tau * gi).max(0.0);
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
        cg = up.n_ol + up.n_ul == 0;
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
        preconditioner_products: 0,
        chord_steps: 0,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::kkt::kkt_certificate_capped;
    use crate::contact::polonsky_keer as pk;
    use crate::elastic::operator::dense_apply;

    fn rough(ny: usize, nx: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        let mut h = vec![0.0; ny * nx];
        for k in 1..5 {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let ph = (s >> 11) as f64 / (1u64 << 53) as f64 * std::f64::consts::TAU;
            for i in 0..ny {
                for j in 0..nx {
                    let x = (i as f64 / ny as f64 + j as f64 / nx as f64 * 0.7) * k as f64;
                    h[i * nx + j] += (std::f64::consts::TAU * x + ph).sin() / k as f64;
                }
            }
        }
        h
    }

    fn opts(hardness: f64) -> Options<'static> {
        Options {
            hardness: Some(hardness),
            ..Options::default()
        }
    }

    /// Projected Gauss–Seidel on the dense matrix: the box QP solved point by point, an
    /// independent oracle for small grids.
    fn dense_box_qp(c: &[f64], b: &[f64], cap: f64) -> Vec<f64> {
        let n = b.len();
        let mut p = vec![0.0; n];
        for _ in 0..200_000 {
            let mut change = 0.0f64;
            for i in 0..n {
                let mut s = b[i];
                for j in 0..n {
                    if j != i {
                        s -= c[i * n + j] * p[j];
                    }
                }
                let v = (s / c[i * n + i]).clamp(0.0, cap);
                change = change.max((v - p[i]).abs());
                p[i] = v;
            }
            if change < 1e-15 * cap {
                break;
            }
        }
        p
    }

    #[test]
    fn capped_matches_projected_gauss_seidel() {
        let (ny, nx) = (8, 9);
        let h = rough(ny, nx, 3);
        for boundary in [Boundary::Free, Boundary::Periodic] {
            let problem = Problem {
                heights: &h,
                ny,
                nx,
                dx: 0.1,
                e_star: 1.0,
                boundary,
            };
            let kernel = match boundary {
                Boundary::Free => Kernel::new(ny, nx, 0.1, 1.0),
                Boundary::Periodic => {
                    let op = Operator::periodic(ny, nx, 0.1, 1.0);
                    let mut e0 = vec![0.0; ny * nx];
                    e0[0] = 1.0;
                    let mut col = vec![0.0; ny * nx];
                    op.apply(&e0, &mut col);
                    Kernel::from_table(ny, nx, 0.1, 1.0, col)
                }
            };
            let n = ny * nx;
            let mut c = vec![0.0; n * n];
            for j in 0..n {
                let mut e = vec![0.0; n];
                e[j] = 1.0;
                let col = dense_apply(&kernel, &e);
                for i in 0..n {
                    c[i * n + j] = col[i];
                }
            }
            let hmax = h.iter().cloned().fold(f64::MIN, f64::max);
            let delta = 0.8;
            let b: Vec<f64> = h.iter().map(|&hi| delta - (hmax - hi)).collect();
            let cap = 0.05;
            let want = dense_box_qp(&c, &b, cap);
            let got = solve(&problem, Control::Approach(delta), &opts(cap), None).unwrap();
            let err = got
                .pressure
                .iter()
                .zip(&want)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(err < 1e-9 * cap, "{boundary:?}: {err}");
            assert!(got.plastic_points > 0);
            assert!(got.pressure.iter().all(|&v| (0.0..=cap).contains(&v)));
            let k = kkt_certificate_capped(&got.pressure, &got.gap, cap, 1.0);
            assert!(k <= 1e-10, "{k}");
        }
    }

    #[test]
    fn load_control_meets_the_load_and_the_approach_solution() {
        let (ny, nx) = (12, 10);
        let h = rough(ny, nx, 5);
        for boundary in [Boundary::Free, Boundary::Periodic] {
            let problem = Problem {
                heights: &h,
                ny,
                nx,
                dx: 0.1,
                e_star: 1.0,
                boundary,
            };
            let cap = 0.08;
            let load = solve(&problem, Control::MeanPressure(0.02), &opts(cap), None).unwrap();
            assert!((load.mean_pressure - 0.02).abs() <= 1e-9 * 0.02);
            assert!(load.plastic_points > 0);
            let disp = solve(&problem, Control::Approach(load.approach), &opts(cap), None).unwrap();
            let err = load
                .pressure
                .iter()
                .zip(&disp.pressure)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(err < 1e-7 * cap, "{err}");
        }
    }

    #[test]
    fn full_plastic_and_refusals() {
        let (ny, nx) = (6, 7);
        let h = rough(ny, nx, 1);
        let problem = Problem {
            heights: &h,
            ny,
            nx,
            dx: 0.1,
            e_star: 1.0,
            boundary: Boundary::Free,
        };
        let s = solve(&problem, Control::MeanPressure(0.3), &opts(0.3), None).unwrap();
        assert!(s.pressure.iter().all(|&v| v == 0.3));
        assert!(s.gap.iter().all(|&g| g <= 1e-12));
        assert_eq!(s.plastic_points, ny * nx);
        let e = solve(&problem, Control::MeanPressure(0.31), &opts(0.3), None).unwrap_err();
        assert!(e.to_string().contains("hardness"), "{e}");
        for bad in [0.0, -1.0, f64::NAN] {
            let e = solve(&problem, Control::Approach(0.5), &opts(bad), None).unwrap_err();
            assert!(e.to_string().starts_with("hardness"), "{e}");
        }
    }

    #[test]
    fn infinite_hardness_is_the_elastic_solve_bit_for_bit() {
        let (ny, nx) = (70, 66);
        let h = rough(ny, nx, 7);
        let problem = Problem {
            heights: &h,
            ny,
            nx,
            dx: 0.1,
            e_star: 1.0,
            boundary: Boundary::Free,
        };
        let a = pk::solve(&problem, Control::Approach(0.7), &Options::default(), None).unwrap();
        let b = pk::solve(&problem, Control::Approach(0.7), &opts(f64::INFINITY), None).unwrap();
        assert_eq!(a.pressure, b.pressure);
        assert_eq!(a.iterations, b.iterations);
        // A cap above every elastic pressure gives the elastic contact set.
        let pmax = a.pressure.iter().cloned().fold(0.0, f64::max);
        let c = solve(&problem, Control::Approach(0.7), &opts(2.0 * pmax), None).unwrap();
        assert_eq!(c.plastic_points, 0);
        let err = a
            .pressure
            .iter()
            .zip(&c.pressure)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        assert!(err < 1e-8 * pmax, "{err}");
    }
}
