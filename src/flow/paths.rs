//! The three solution paths of one system and their answer checks: the sparse Cholesky
//! factor ([`super::direct`]), its star–mesh fallback ([`super::gth`]) and conjugate gradients
//! with the multigrid preconditioner ([`super::multigrid`]).

use rayon::prelude::*;

use crate::alloc::{ZeroedAhead, ZeroedByIdle};

use super::*;

/// Largest net flux out of a cell, relative to the flow rate, of a returned solution.
pub const CONSERVATION_MAX: f64 = 1e-6;

/// Largest relative difference allowed between the inlet and the outlet flow rates.
pub const FLUX_AGREEMENT: f64 = 1e-9;

/// `Σ a_k b_k` over the solution's two right-hand sides, and the inlet/outlet test.
pub(super) fn rates_agree(q_in: f64, q_out: f64) -> bool {
    (q_in - q_out).abs() <= FLUX_AGREEMENT * q_out.abs()
}

/// A factored solve: `φ` and `ψ`, their exact residuals `b_in − A φ` and `b_out − A ψ`
/// (summed in double-double arithmetic), the low parts of `φ` and `ψ` when they are carried
/// in two doubles (empty otherwise), and what [`trusted`] reads of them ([`Checks`]).
pub(super) struct DirectAnswer {
    pub(super) x: Vec<f64>,
    pub(super) psi: Vec<f64>,
    r_x: Vec<f64>,
    r_psi: Vec<f64>,
    pub(super) lo: (Vec<f64>, Vec<f64>),
    checks: Checks,
}

impl DirectAnswer {
    /// The larger relative residual of `φ` and `ψ`.
    pub(super) fn residual(&self) -> f64 {
        self.checks.rel.0.max(self.checks.rel.1)
    }

    /// The two rates `Q_out = b_out · φ`, `Q_in = b_in · ψ` and their first-order errors
    /// relative to them, `|ψ · (b_in − A φ)| / Q_out` and `|φ · (b_out − A ψ)| / Q_in` (the
    /// errors infinite when a rate is not positive and finite).
    pub(super) fn rate_errors(&self) -> ((f64, f64), (f64, f64)) {
        (self.checks.rates, self.checks.errors)
    }

    /// Recomputes the checks after `x`, `psi`, their low parts or residuals changed.
    fn recheck(&mut self, b_in: &[f64], b_out: &[f64]) {
        self.checks = Checks::of(b_in, b_out, self);
    }
}

/// What the checks of a factored answer read, from one pass over its vectors
/// ([`Checks::of`]): the relative residuals `‖r‖₂ / ‖b‖₂` of `φ` and `ψ`, the rates and
/// their first-order errors ([`DirectAnswer::rate_errors`]), and whether every pressure is
/// in `[0, 1]` to round-off (the maximum principle).
#[derive(Clone, Copy, Default)]
struct Checks {
    rel: (f64, f64),
    rates: (f64, f64),
    errors: (f64, f64),
    in_range: bool,
}

/// One chunk's sums for [`Checks`]: each sum over `k` in index order.
#[derive(Clone, Copy, Default)]
struct Sums {
    /// `r_φ · r_φ`, `r_ψ · r_ψ`, `b_in · b_in`, `b_out · b_out`.
    norms: [f64; 4],
    /// `b_out · φ`, `b_out · φ_lo`, `b_in · ψ`, `b_in · ψ_lo`.
    rates: [f64; 4],
    /// `r_φ · ψ`, `r_φ · ψ_lo`, `r_ψ · φ`, `r_ψ · φ_lo`.
    errors: [f64; 4],
    in_range: bool,
}

impl Checks {
    /// The checks of `a` (its own `checks` not read) for the right-hand sides `b_in` and `b_out`:
    /// every vector read once, in fixed chunks of [`cg::CHUNK`] summed in chunk order (the
    /// same bits for any number of threads). The sums of a vector carried in two doubles
    /// add its high and low parts' sums, as two separate dot products would.
    fn of(b_in: &[f64], b_out: &[f64], a: &DirectAnswer) -> Checks {
        let n = b_in.len();
        let split = !a.lo.0.is_empty();
        let parts: Vec<Sums> = (0..n.div_ceil(cg::CHUNK))
            .into_par_iter()
            .map(|c| {
                let r = c * cg::CHUNK..n.min((c + 1) * cg::CHUNK);
                if split {
                    chunk_sums::<true>(b_in, b_out, a, r)
                } else {
                    chunk_sums::<false>(b_in, b_out, a, r)
                }
            })
            .collect();
        let mut t = Sums {
            in_range: true,
            ..Sums::default()
        };
        for p in &parts {
            for q in 0..4 {
                t.norms[q] += p.norms[q];
                t.rates[q] += p.rates[q];
                t.errors[q] += p.errors[q];
            }
            t.in_range &= p.in_range;
        }
        let relative = |rr: f64, bb: f64| {
            if bb == 0.0 {
                0.0
            } else {
                rr.sqrt() / bb.sqrt()
            }
        };
        let (q_out, q_in) = (t.rates[0] + t.rates[1], t.rates[2] + t.rates[3]);
        let errors = if q_out.is_finite() && q_in.is_finite() && q_out > 0.0 && q_in > 0.0 {
            (
                (t.errors[0] + t.errors[1]).abs() / q_out,
                (t.errors[2] + t.errors[3]).abs() / q_in,
            )
        } else {
            (f64::INFINITY, f64::INFINITY)
        };
        Checks {
            rel: (
                relative(t.norms[0], t.norms[2]),
                relative(t.norms[1], t.norms[3]),
            ),
            rates: (q_out, q_in),
            errors,
            in_range: t.in_range,
        }
    }
}

/// [`Sums`] over the entries `r` (`SPLIT`: `φ` and `ψ` carried in two doubles).
fn chunk_sums<const SPLIT: bool>(
    b_in: &[f64],
    b_out: &[f64],
    a: &DirectAnswer,
    r: std::ops::Range<usize>,
) -> Sums {
    let mut s = Sums {
        in_range: true,
        ..Sums::default()
    };
    let range = -1e-12..=1.0 + 1e-12;
    for k in r {
        let (x, p, rx, rp) = (a.x[k], a.psi[k], a.r_x[k], a.r_psi[k]);
        let (bi, bo) = (b_in[k], b_out[k]);
        s.norms[0] += rx * rx;
        s.norms[1] += rp * rp;
        s.norms[2] += bi * bi;
        s.norms[3] += bo * bo;
        s.rates[0] += bo * x;
        s.rates[2] += bi * p;
        s.errors[0] += rx * p;
        s.errors[2] += rp * x;
        let (xv, pv) = if SPLIT {
            let (xl, pl) = (a.lo.0[k], a.lo.1[k]);
            s.rates[1] += bo * xl;
            s.rates[3] += bi * pl;
            s.errors[1] += rx * pl;
            s.errors[3] += rp * xl;
            (x + xl, p + pl)
        } else {
            (x, p)
        };
        s.in_range &= range.contains(&xv) & range.contains(&pv);
    }
    s
}

/// `φ` (inlet at 1) and `ψ` (outlet at 1) from the factor, both columns in one pass, with
/// their exact residuals; [`split_direct`] refines them when they fail [`trusted`].
pub(super) fn solve_direct(
    f: &mut direct::Factor,
    st: &assemble::Stencil,
    b_in: &[f64],
    b_out: &[f64],
    spare: &mut ZeroedByIdle,
) -> DirectAnswer {
    let (mut x, mut psi) = (spare.take(), spare.take());
    let t0 = std::time::Instant::now();
    f.solve_pair(b_in, b_out, &mut x, &mut psi);
    if cg::profiling() {
        eprintln!("flow: two-column solve {:.3} s", cg::secs(t0));
    }
    let (mut r_x, mut r_psi) = (spare.take(), spare.take());
    st.residual_compensated(&x, b_in, &mut r_x);
    st.residual_compensated(&psi, b_out, &mut r_psi);
    let mut a = DirectAnswer {
        x,
        psi,
        r_x,
        r_psi,
        lo: (Vec::new(), Vec::new()),
        checks: Checks::default(),
    };
    a.recheck(b_in, b_out);
    a
}

/// Refinement steps at most of the low parts of a factored answer.
pub(super) const DIRECT_SPLIT: usize = 4;

/// The factored answer `a` carried in two doubles, `φ = hi + lo` and `ψ = hi + lo`: the low
/// parts refined together with the factor against residuals of `hi + lo` summed exactly
/// ([`assemble::Stencil::residual_split`]) until [`trusted`], until a step halves neither
/// relative residual (the factor's error is then as large as the correction: a condition
/// number near `1/ε`), or [`DIRECT_SPLIT`] steps. Refinement in one double would stop at the
/// rounding of `φ` and `ψ`, which alone can leave a residual whose first-order rate error
/// `ψ · r` exceeds [`DIRECT_TRUST`] of a rate many decades below the conductances (the
/// 2049² contact gap of the benchmarks: 1.8e-12); the pair holds those digits.
pub(super) fn split_direct(
    f: &mut direct::Factor,
    st: &assemble::Stencil,
    b_in: &[f64],
    b_out: &[f64],
    mut a: DirectAnswer,
    trust: f64,
    spare: &mut ZeroedByIdle,
) -> DirectAnswer {
    a.lo = (spare.take(), spare.take());
    for step in 0..DIRECT_SPLIT {
        if cg::profiling() {
            eprintln!("flow: refinement step {} in two doubles", step + 1);
        }
        let before = a.checks.rel;
        f.correct_pair(&a.r_x, &a.r_psi, &mut a.lo.0, &mut a.lo.1);
        st.residual_split(&a.x, &a.lo.0, b_in, &mut a.r_x);
        st.residual_split(&a.psi, &a.lo.1, b_out, &mut a.r_psi);
        a.recheck(b_in, b_out);
        let after = a.checks.rel;
        let halved = after.0 <= 0.5 * before.0 || after.1 <= 0.5 * before.1;
        if trusted(&a, trust) || !halved {
            break;
        }
    }
    a
}

/// Largest first-order error of a flow rate, relative to the rate, at which the factor's
/// answer is kept, whatever the caller's `tol` ([`direct_trust`]).
pub(super) const DIRECT_TRUST: f64 = 1e-12;

/// The relative rate error at which a factored answer is kept for a caller's `tol`:
/// `max(tol, DIRECT_TRUST)`. A sweep, whose contact certificate leaves the rate uncertain
/// far above 1e-12, passes a larger `tol` and is spared the refinement in two doubles
/// (one more two-column solve and two exact residuals) that the default would need on
/// many contact gaps.
pub(super) fn direct_trust(tol: f64) -> f64 {
    tol.max(DIRECT_TRUST)
}

/// Whether the refined factor's `φ` (inlet at 1) and `ψ` (outlet at 1), with their low parts
/// when split, can be returned: both rates positive and finite, every pressure in `[0, 1]`
/// (the maximum principle) to round-off, the first-order errors of the rates from the exact
/// residuals, `ψ · (b_in − A φ)` and `φ · (b_out − A ψ)`, at most `trust` of them
/// ([`direct_trust`]),
/// and the rates agreeing to [`FLUX_AGREEMENT`]. The factor of the rounded matrix fails this
/// when a region is joined to the rest only through faces below `ε` of its own
/// (conductances spanning some sixteen decades or more).
pub(super) fn trusted(a: &DirectAnswer, trust: f64) -> bool {
    let c = &a.checks;
    let ((q_out, q_in), (e_out, e_in)) = (c.rates, c.errors);
    e_out.is_finite()
        && e_in.is_finite()
        && rates_agree(q_in, q_out)
        && c.in_range
        && e_out <= trust
        && e_in <= trust
}

/// `φ`, `ψ`, the larger relative residual, and the low parts of `φ` and `ψ`.
type GthOk = (Vec<f64>, Vec<f64>, f64, (Vec<f64>, Vec<f64>));

/// Refinement steps of the low part after the cancellation-free elimination.
pub(super) const REFINE_SPLIT: usize = 2;

/// `φ` and `ψ` by the cancellation-free elimination ([`gth`]): both from right-hand sides
/// `≥ 0`, so each rate is a sum of positive terms accurate to a few `n ε` however widely the
/// conductances spread; the rates must still agree to [`FLUX_AGREEMENT`]. Returns the larger
/// relative residual of the two solves.
pub(super) fn solve_gth(
    st: &assemble::Stencil,
    b_in: &[f64],
    b_out: &[f64],
    room: Option<u64>,
) -> Result<GthOk> {
    let elim = match gth::Elimination::new(st, room) {
        Ok(e) => e,
        Err(Error::TooLarge { bytes, limit, what }) => {
            return Err(Error::NotConverged {
                iterations: 0,
                residual: f64::NAN,
                what: format!(
                    "reynolds-flow sparse Cholesky: the factor's answer fails its checks (the \
                     gap's conductances g³ span too many decades for it) and {what} is too \
                     large here ({bytes} bytes for {limit} allowed, at most {} unknowns); \
                     close the cells of negligible gap (e.g. set gaps below 1e-5 of the \
                     largest to 0) or use a smaller grid",
                    gth::MAX_UNKNOWNS
                ),
            })
        }
        Err(e) => return Err(e),
    };
    let n = b_in.len();
    let (mut x, mut psi) = (vec![0.0; n], vec![0.0; n]);
    elim.solve(b_in, &mut x);
    elim.solve(b_out, &mut psi);
    let (q_out, q_in) = (cg::dot(b_out, &x), cg::dot(b_in, &psi));
    // Two refinement steps on the low part, residuals of `hi + lo` summed exactly: a pressure
    // field whose cells balance to ~ε² of their conductances, not ε.
    let rel = |r: &[f64], b: &[f64]| cg::dot(r, r).sqrt() / cg::dot(b, b).sqrt();
    let refine = |hi: &[f64], b: &[f64]| {
        let (mut lo, mut r, mut d) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        for _ in 0..REFINE_SPLIT {
            st.residual_split(hi, &lo, b, &mut r);
            elim.solve(&r, &mut d);
            lo.iter_mut().zip(&d).for_each(|(l, v)| *l += v);
        }
        st.residual_split(hi, &lo, b, &mut r);
        let res = rel(&r, b);
        (lo, res)
    };
    let (xlo, rx) = refine(&x, b_in);
    let (psilo, rpsi) = refine(&psi, b_out);
    let residual = rx.max(rpsi);
    if !(q_out.is_finite() && q_out > 0.0 && rates_agree(q_in, q_out)) {
        return Err(Error::NotConverged {
            iterations: 0,
            residual,
            what: format!(
                "reynolds-flow elimination (inlet rate {q_in:e} and outlet rate {q_out:e} \
                 differ)"
            ),
        });
    }
    Ok((x, psi, residual, (xlo, psilo)))
}

/// `Σ (1 − x_k) r_k`: to first order the error of the rate `w · x` of a solution `x` with
/// residual `r`, since `w · (x* − x) = ψ* · r` with the adjoint `ψ* = A⁻¹ w = 1 − x*`.
/// With `r = b_in` it is the inlet rate of `x`.
pub(super) fn rate_error(x: &[f64], r: &[f64]) -> f64 {
    let parts: Vec<f64> = x
        .par_chunks(cg::CHUNK)
        .zip(r.par_chunks(cg::CHUNK))
        .map(|(xc, rc)| xc.iter().zip(rc).map(|(u, v)| (1.0 - u) * v).sum::<f64>())
        .collect();
    parts.iter().sum()
}

/// φ and ψ on the unknowns (not scattered to the grid: [`super::axis0`] reads them through
/// the unknowns' index), the residual and the iterations.
type MultigridOk = (Vec<f64>, Vec<f64>, f64, usize);

/// `φ` and `ψ` by multigrid-preconditioned CG with iterative refinement ([`cg::refined`]),
/// each until its relative residual is `≤ tol` and its flow rate is accurate to `tol`
/// (estimated from the exact residual by [`rate_error`]); then the inlet and outlet rates
/// must agree to [`FLUX_AGREEMENT`]. The inner `Err` is the failure to report (or to
/// recover from with the direct solver). `b_in`: the inlet's vector on the unknowns
/// ([`Multigrid::gather_row`]), `b_out` the outlet's non-zero entries
/// ([`Multigrid::row_entries`]); each is held dense only while it is a right-hand side (as
/// the other solve's rate weight it has only its row's entries). `ahead`: the solve's
/// vectors, made ahead ([`multigrid_vectors`]).
pub(super) fn solve_multigrid(
    mg: &Multigrid,
    b_in: Vec<f64>,
    b_out: Vec<(u32, f64)>,
    opts: &Options<'_>,
    max_iter: usize,
    mut ahead: ZeroedAhead,
) -> Result<std::result::Result<MultigridOk, Error>> {
    // Everything runs on the unknowns (the spanning cells), not the grid's cells.
    let qtol = opts.tol;
    let n = b_in.len();
    let out_rows = Sparse(b_out);
    // The rate's first-order error at most `tol` of it, and the pressure change a Jacobi step
    // would make, `max |r_k| / d_k`, at most `tol` (a dead end behind a narrow face has a
    // small residual for a large pressure error).
    fn accurate<'a>(
        mg: &'a Multigrid,
        w: &'a Sparse,
        qtol: f64,
    ) -> impl Fn(&[f64], &[f64]) -> f64 + 'a {
        move |x: &[f64], r: &[f64]| {
            let jacobi = r
                .par_chunks(cg::CHUNK)
                .enumerate()
                .map(|(blk, rc)| {
                    rc.iter().enumerate().fold(0.0, |m: f64, (t, rv)| {
                        m.max(rv.abs() / mg.diagonal(blk * cg::CHUNK + t))
                    })
                })
                .reduce(|| 0.0, f64::max);
            let rate = rate_error(x, r).abs() / (qtol * w.dot(x).abs());
            rate.max(jacobi / qtol)
        }
    }
    let mut work = cg::Work::new(&mut ahead, n);
    let mut correction = Correction::new(mg, opts.should_stop, &mut ahead);
    let mut correct = |r: &mut [f64], r_norm: f64, d: &mut [f64], rtol: f64, max_iter: usize| {
        correction.correct(r, r_norm, d, rtol, max_iter)
    };
    let mut x = ahead.take(n);
    // φ carried as two doubles: `1 − φ` then keeps its digits where φ is near 1.
    let mut lo = ahead.take(n);
    debug_assert_eq!(
        ahead.left(),
        0,
        "every vector made ahead is one of the solve's"
    );
    drop(ahead);
    let exact = |x: &[&[f64]], b: &[f64], r: &mut [f64]| mg.residual_exact(x, b, r);
    let a = cg::refined(
        &exact,
        &mut correct,
        &accurate(mg, &out_rows, qtol),
        &b_in,
        &mut x,
        Some(&mut lo),
        false,
        opts.tol,
        max_iter,
        &mut work,
    )?;
    let failed = |o: &cg::Outcome, what: &str| Error::NotConverged {
        iterations: o.iterations,
        residual: o.residual,
        what: format!("reynolds-flow multigrid CG ({what})"),
    };
    if !a.converged {
        return Ok(Err(failed(&a, "pressure")));
    }
    // ψ from 1 − φ with φ's low part, so that only ψ's own rounding and what φ's residual
    // leaves of the inlet rate are to find. (ψ carried as two doubles too, from the exact
    // complement, took more CG iterations on the 4097² gap: 11 against 7.)
    // In `lo`'s place (one vector less at the peak).
    let mut psi = lo;
    psi.par_iter_mut()
        .zip(x.par_iter())
        .for_each(|(l, &v)| *l = (1.0 - v) - *l);
    let in_rows = Sparse::of(&b_in);
    drop(b_in);
    let b_out = out_rows.dense(n);
    let b = cg::refined(
        &exact,
        &mut correct,
        &accurate(mg, &in_rows, qtol),
        &b_out,
        &mut psi,
        None,
        true,
        opts.tol,
        max_iter,
        &mut work,
    )?;
    let total = cg::Outcome {
        iterations: a.iterations + b.iterations,
        residual: a.residual.max(b.residual),
        converged: b.converged,
    };
    if !b.converged {
        return Ok(Err(failed(&total, "reversed pressure")));
    }
    let (q_out, q_in) = (out_rows.dot(&x), in_rows.dot(&psi));
    if !rates_agree(q_in, q_out) {
        return Ok(Err(failed(
            &total,
            &format!("inlet rate {q_in:e} and outlet rate {q_out:e} differ"),
        )));
    }
    drop(work);
    drop(correction);
    Ok(Ok((x, psi, total.residual, total.iterations)))
}

/// The lengths of the vectors [`solve_multigrid`] takes for `n` unknowns and `m` on `S`
/// (for [`Multigrid::new_ahead`]): φ and its low part and the refinement's residual and
/// correction on the unknowns, CG's three and the reduced right-hand side and solution
/// on `S`.
pub(super) fn multigrid_vectors(n: usize, m: usize) -> Vec<usize> {
    [[n; 4].as_slice(), &[m; 5]].concat()
}

/// The refinement's inner solve on the multigrid: `A δ = r` reduced to the Schur complement
/// `S` of the red unknowns (`S δ_B = s`, [`Multigrid::reduce`]), solved there by CG
/// preconditioned with one multigrid cycle on `S`, with `S` applied from its stored faces
/// where they are faithful ([`Multigrid::inner_reduced_product`]), then `δ_R` from `δ_B`
/// ([`Multigrid::extend`]). The same Krylov method as CG on
/// `A` with the block preconditioner `L⁻ᵀ diag(D_R⁻¹, M_S) L⁻¹` (docs/flow.md), without
/// the red half in its vectors and products. Without a reduction (the finest level is the
/// coarsest), CG on `A` with the dense factor.
struct Correction<'a> {
    mg: &'a Multigrid,
    should_stop: Option<&'a (dyn Fn() -> bool + Sync)>,
    inner: cg::Inner,
    /// Right-hand side (then residual) and solution on `S`.
    s: Vec<f64>,
    xs: Vec<f64>,
}

impl<'a> Correction<'a> {
    fn new(
        mg: &'a Multigrid,
        should_stop: Option<&'a (dyn Fn() -> bool + Sync)>,
        ahead: &mut ZeroedAhead,
    ) -> Self {
        let m = mg.reduced_len().unwrap_or(mg.n_unknowns());
        let own = if mg.reduced_len().is_some() { m } else { 0 };
        Correction {
            mg,
            should_stop,
            inner: cg::Inner::new(ahead, m),
            s: ahead.take(own),
            xs: ahead.take(own),
        }
    }

    /// `d ≈ A⁻¹ r` to a relative residual `rtol` (`r` is overwritten without a
    /// reduction); `r_norm` is `‖r‖₂`.
    fn correct(
        &mut self,
        r: &mut [f64],
        r_norm: f64,
        d: &mut [f64],
        rtol: f64,
        max_iter: usize,
    ) -> Result<cg::Outcome> {
        let mg = self.mg;
        if mg.reduced_len().is_none() {
            return cg::pcg(
                &mut |v, y| mg.operator(v, y),
                &mut |r, z| mg.precondition(r, z),
                r,
                r_norm,
                d,
                rtol,
                max_iter,
                self.should_stop,
                &mut self.inner,
            );
        }
        mg.reduce(r, &mut self.s);
        // The fine residual after the correction is `(0, s − S δ_B)`: CG on `S` stops where
        // that is `rtol` of the fine `r`, as CG on `A` would.
        let (rn, sn) = (r_norm, cg::dot(&self.s, &self.s).sqrt());
        let tol = if sn > 0.0 { rtol * rn / sn } else { rtol };
        let outcome = cg::pcg(
            &mut |v, y| mg.inner_reduced_product(v, y),
            &mut |s, z| mg.cycle(s, z),
            &mut self.s,
            sn,
            &mut self.xs,
            tol,
            max_iter,
            self.should_stop,
            &mut self.inner,
        )?;
        mg.extend(r, &self.xs, d);
        Ok(outcome)
    }
}

/// The non-zero entries `(unknown, value)` of a reservoir's vector (its row's cells only),
/// in index order.
struct Sparse(Vec<(u32, f64)>);

impl Sparse {
    fn of(v: &[f64]) -> Self {
        Sparse(
            v.par_iter()
                .enumerate()
                .filter(|e| *e.1 != 0.0)
                .map(|(i, &w)| (i as u32, w))
                .collect(),
        )
    }

    /// `w · x`, summed in index order.
    fn dot(&self, x: &[f64]) -> f64 {
        self.0.iter().map(|&(i, w)| w * x[i as usize]).sum()
    }

    /// The dense vector of `n` entries.
    fn dense(&self, n: usize) -> Vec<f64> {
        let mut v = vec![0.0; n];
        for &(i, w) in &self.0 {
            v[i as usize] = w;
        }
        v
    }
}

/// Bytes of a sparse Cholesky factor of `cells` unknowns (AMD on a 2-D grid: a few tens of
/// entries, value and row index, per unknown).
pub(super) fn cholesky_estimate(cells: usize) -> u64 {
    40 * 16 * cells as u64
}

/// `MemAvailable` of `/proc/meminfo` (Linux), in bytes.
pub(super) fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}
