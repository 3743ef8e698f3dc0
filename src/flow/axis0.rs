//! The flow along axis 0 on the open cells: unknowns on the spanning clusters, the
//! dimensionless system, the solve by the chosen path, and the flow rate with its checks.

use rayon::prelude::*;

use crate::alloc::ZeroedByIdle;

use super::*;

/// The dimensionless solution for flow along axis 0 with `φ = 1` at the inlet, 0 at the outlet,
/// cell conductances `(g / g_ref)³`.
pub(super) struct UnitSolution {
    pub(super) gref: f64,
    pub(super) phi: Vec<f64>,
    pub(super) flux_along: Vec<f64>,
    pub(super) flux_across: Vec<f64>,
    pub(super) q_out: f64,
    pub(super) q_in: f64,
    pub(super) residual: f64,
    pub(super) conservation: f64,
    pub(super) iterations: usize,
    pub(super) n_unknowns: usize,
    pub(super) levels: usize,
    pub(super) solver: &'static str,
}

/// Whether `Auto` takes the multigrid without trying the factor: from `from` unknowns
/// ([`Options::multigrid_from`]), or when even the factor's lower bound does not fit in
/// `room` bytes (its symbolic analysis, itself costly on large grids, is then skipped).
pub(super) fn auto_skips_factor(n_unknowns: usize, from: usize, room: Option<u64>) -> bool {
    n_unknowns >= from || room.is_some_and(|r| 16 * factor_entries_lower_bound(n_unknowns) > r)
}

/// The class of a dead-end cell of a spanning cluster (beside 1 inlet only, 2 outlet only,
/// 3 spanning).
const DEAD_END: u8 = 4;

/// φ or ψ read by grid cell: stored by cell (the factored paths), or by unknown with each
/// cell's unknown (the multigrid's answer, not scattered to a cell-sized vector first).
struct ByCell<'a> {
    v: Vec<f64>,
    /// Each cell's unknown; empty when `v` is by cell.
    index: &'a [u32],
}

impl<'a> ByCell<'a> {
    fn new(v: Vec<f64>, index: &'a [u32]) -> Self {
        ByCell { v, index }
    }

    /// The value at cell `k`, which has an unknown when `v` is by unknown.
    #[inline(always)]
    fn at(&self, k: usize) -> f64 {
        if self.index.is_empty() {
            self.v[k]
        } else {
            self.v[self.index[k] as usize]
        }
    }
}

/// `g`: the open gap (0 on closed cells), row-major `ny × nx`, taken over as the cells'
/// conductances' buffer.
pub(super) fn solve_axis0(
    g: Vec<f64>,
    ny: usize,
    nx: usize,
    periodic: bool,
    opts: &Options<'_>,
    given: Option<(Vec<u32>, usize)>,
) -> Result<UnitSolution> {
    let n = ny * nx;
    let t_start = std::time::Instant::now();
    cg::mark("arguments to the unit solve");
    let gref = g.par_iter().cloned().reduce(|| 0.0, f64::max);
    // The conductances `(g / g_ref)³` in the gap's own buffer.
    let mut c = g;
    if gref > 0.0 {
        c.par_iter_mut().for_each(|v| {
            let t = *v / gref;
            *v = t * t * t;
        });
    } else {
        c.iter_mut().for_each(|v| *v = 0.0);
    }
    let open: Vec<bool> = c.par_iter().map(|&v| v > 0.0).collect();
    let per = Periodic {
        axis0: false,
        axis1: periodic,
    };
    let (labels, k) = match given {
        Some((labels, k)) => {
            if labels
                .par_iter()
                .zip(open.par_iter())
                .any(|(&l, &o)| (l != 0) != o)
            {
                return Err(Error::invalid(
                    "labels",
                    "do not label exactly the open cells of this gap (free and g > 0)",
                ));
            }
            (labels, k)
        }
        None => clusters::label(&open, ny, nx, Connectivity::Four, per)?,
    };
    drop(open);
    cg::mark("open cells and labels");
    // Touch flags per cluster: 1 inlet row, 2 outlet row.
    let mut touch = vec![0u8; k + 1];
    for j in 0..nx {
        touch[labels[j] as usize] |= 1;
        touch[labels[(ny - 1) * nx + j] as usize] |= 2;
    }
    touch[0] = 0;
    // Only spanning clusters keep their conductance.
    c.par_iter_mut()
        .zip(labels.par_iter())
        .for_each(|(cv, &l)| {
            if touch[l as usize] != 3 {
                *cv = 0.0;
            }
        });
    // Each cell's reservoirs (the touch flags of its cluster), in place of its label.
    let mut class: Vec<u8> = labels.par_iter().map(|&l| touch[l as usize]).collect();
    drop(labels);
    // The dead ends of the spanning clusters carry no flow and sit at their anchors'
    // pressures (`dead_ends`): no unknowns there, their conductances closed.
    // The search is sequential: the stencil of the spanning clusters is built beside it, on
    // the other core, and the dead ends' cells are closed in it after.
    let t_dead = std::time::Instant::now();
    let (dead, (mut fine, mut rhs)) = if n <= dead_ends::MAX_CELLS && touch.contains(&3) {
        let spanning: Vec<bool> = class.par_iter().map(|&t| t == 3).collect();
        rayon::join(
            || dead_ends::anchors(&spanning, ny, nx, periodic),
            || fine_stencil(&c, ny, nx, periodic),
        )
    } else {
        (Vec::new(), fine_stencil(&c, ny, nx, periodic))
    };
    for &(k, _) in &dead {
        class[k as usize] = DEAD_END;
        c[k as usize] = 0.0;
        // The inlet's right-hand side is `2 c` on the first row, 0 elsewhere.
        rhs[k as usize] = 0.0;
    }
    if !dead.is_empty() {
        fine.close_cells(dead.iter().map(|&(k, _)| k as usize));
    }
    let n_unknowns = class.par_iter().filter(|&&t| t == 3).count();
    cg::mark("dead ends and stencil");
    if cg::profiling() {
        eprintln!(
            "flow: dead ends and stencil {:.3} s ({} cells, {} unknowns)",
            cg::secs(t_dead),
            dead.len(),
            n_unknowns
        );
    }

    // The outlet reservoir's share of the diagonal: `Q_out = b_out · φ`, and `ψ = 1 − φ` (the
    // flow reversed) solves `A ψ = b_out` with `Q_in = b_in · ψ`.
    let mut b_out: Vec<f64> = (0..n)
        .into_par_iter()
        .map(|k| if k >= (ny - 1) * nx { 2.0 * c[k] } else { 0.0 })
        .collect();
    // Of the conductances only the inlet and outlet rows are read from here on (the
    // reservoir fluxes).
    let (c_in, c_out) = (c[..nx].to_vec(), c[(ny - 1) * nx..].to_vec());
    drop(c);
    let max_iter = opts.max_iter.unwrap_or(DEFAULT_MAX_ITER);
    cg::mark("right-hand sides");
    let prof = cg::profiling();
    if prof {
        eprintln!(
            "flow: open gaps, labels, stencil {:.3} s",
            cg::secs(t_start)
        );
    }
    let mut iterations = 0;
    let mut levels = 0;
    // Room for the factor: what the limits leave beside the rest of the solve.
    let factor_room = {
        let base = multigrid_estimate(n, n_unknowns);
        let room = |l: u64| l.saturating_sub(base);
        match (opts.memory_limit, available_memory()) {
            (Some(l), Some(a)) => Some(room(l).min(room(a))),
            (Some(l), None) => Some(room(l)),
            (None, Some(a)) => Some(room(a)),
            (None, None) => None,
        }
    };
    let hopeless = opts.solver == Solver::Auto
        && auto_skips_factor(n_unknowns, opts.multigrid_from, factor_room);
    // `lo`: the parts of φ and ψ below the last digit of `x` and `psi` (the elimination's
    // refinement; empty otherwise).
    let mut lo = (Vec::new(), Vec::new());
    let direct_answer = if n_unknowns == 0 || opts.solver == Solver::Multigrid || hopeless {
        Direct::Unavailable
    } else {
        factored(
            &fine,
            [&rhs, &b_out],
            n_unknowns,
            opts,
            factor_room,
            true,
            &mut lo,
        )?
    };
    // `Auto` took the multigrid as the faster, the factor fitting: it is there if the
    // multigrid refuses the gap.
    let declined = matches!(direct_answer, Direct::Slower);
    // `index`: each cell's unknown when `x` and `psi` are by unknown (the multigrid's), else
    // empty (by cell).
    let (st, x, psi, index, residual, solver) = if n_unknowns == 0 {
        (fine, vec![0.0; n], vec![0.0; n], Vec::new(), 0.0, "none")
    } else if let Direct::Answer((x, psi, residual)) = direct_answer {
        (fine, x, psi, Vec::new(), residual, "cholesky")
    } else {
        let need = multigrid_estimate(n, n_unknowns);
        if let Some(limit) = opts.memory_limit {
            if need > limit {
                return Err(Error::TooLarge {
                    bytes: need,
                    limit,
                    what: format!(
                        "Reynolds flow on {ny} × {nx} by multigrid ({n_unknowns} unknowns)"
                    ),
                });
            }
        }
        // `rhs` is 0 off the inlet row and `b_out` off the outlet row (above): only those
        // rows are kept through the setup, not two cell-sized vectors.
        let (in_row, out_row) = (rhs[..nx].to_vec(), b_out[(ny - 1) * nx..].to_vec());
        (rhs, b_out) = (Vec::new(), Vec::new());
        let (mg, ahead) = Multigrid::new_ahead(fine, paths::multigrid_vectors);
        levels = mg.n_levels();
        // The reservoirs' vectors on the unknowns.
        let (b_in, b_o) = (
            mg.gather_row(&in_row, 0),
            mg.row_entries(&out_row, (ny - 1) * nx),
        );
        // `Auto` ran the multigrid first by size alone or as the predicted faster: when it
        // refuses the gap, the factor if its lower bound fits.
        let fallback = opts.solver == Solver::Auto
            && (declined
                || n_unknowns >= opts.multigrid_from
                    && !auto_skips_factor(n_unknowns, usize::MAX, factor_room));
        match solve_multigrid(&mg, b_in, b_o, opts, max_iter, ahead)? {
            Ok((x, psi, residual, it)) => {
                iterations = it;
                let (fine, index) = mg.into_fine_and_index();
                (fine, x, psi, index, residual, "multigrid")
            }
            Err(refusal @ Error::NotConverged { .. }) if fallback => {
                levels = 0;
                let (fine, _) = mg.into_fine_and_index();
                let mut rhs = vec![0.0; n];
                rhs[..nx].copy_from_slice(&in_row);
                let mut b_out = vec![0.0; n];
                b_out[(ny - 1) * nx..].copy_from_slice(&out_row);
                match factored(
                    &fine,
                    [&rhs, &b_out],
                    n_unknowns,
                    opts,
                    factor_room,
                    false,
                    &mut lo,
                ) {
                    Ok(Direct::Answer((x, psi, residual))) => {
                        (fine, x, psi, Vec::new(), residual, "cholesky")
                    }
                    // The factor did not fit or its answer failed its checks: the
                    // multigrid's refusal says why the gap is out of reach.
                    Ok(Direct::Slower | Direct::Unavailable)
                    | Err(Error::TooLarge { .. } | Error::NotConverged { .. }) => {
                        return Err(refusal)
                    }
                    Err(e) => return Err(e),
                }
            }
            Err(e) => return Err(e),
        }
    };
    let (x, psi) = (ByCell::new(x, &index), ByCell::new(psi, &index));
    drop((rhs, b_out));
    let t_post = std::time::Instant::now();
    cg::mark("to the pressures");
    let st = &st;
    // Pressures: solution on spanning cells, reservoir pressure on one-sided clusters.
    let anchored = |k: usize| {
        let at = dead.binary_search_by_key(&(k as u32), |&(c, _)| c);
        match at.map(|i| dead[i].1) {
            Ok(dead_ends::INLET) => 1.0,
            Ok(dead_ends::OUTLET) => 0.0,
            Ok(a) => x.at(a as usize),
            Err(_) => f64::NAN,
        }
    };
    let phi: Vec<f64> = (0..n)
        .into_par_iter()
        .map(|k| match class[k] {
            3 => x.at(k),
            1 => 1.0,
            2 => 0.0,
            DEAD_END => anchored(k),
            _ => f64::NAN,
        })
        .collect();
    drop(dead);
    drop(class);
    // A face flux `c_f (φ1 − φ2)` loses the digits of `φ` near 1 (all of the inlet side near
    // the percolation threshold, where the flow is many decades below the conductances):
    // there the same flux is `c_f (ψ2 − ψ1)` with `ψ = 1 − φ` solved for directly.
    // With the low parts, a difference of two close pressures keeps the digits below the
    // last one of `x` (the difference of the high parts is exact).
    let (xlo, psilo) = (&lo.0, &lo.1);
    let split = !xlo.is_empty();
    let face = |cf: f64, k: usize, l: usize| -> f64 {
        if cf <= 0.0 {
            return 0.0;
        }
        let (xk, xl) = (x.at(k), x.at(l));
        if xk + xl <= 1.0 {
            if split {
                cf * ((xk - xl) + (xlo[k] - xlo[l]))
            } else {
                cf * (xk - xl)
            }
        } else if split {
            cf * ((psi.at(l) - psi.at(k)) + (psilo[l] - psilo[k]))
        } else {
            cf * (psi.at(l) - psi.at(k))
        }
    };
    let at = |v: &ByCell, low: &[f64], k: usize| {
        if split {
            v.at(k) + low[k]
        } else {
            v.at(k)
        }
    };
    // Fluxes along: (ny + 1) × nx.
    let mut fa = vec![0.0; (ny + 1) * nx];
    fa.par_chunks_mut(nx).enumerate().for_each(|(i, row)| {
        for j in 0..nx {
            row[j] = if i == 0 {
                let cf = 2.0 * c_in[j];
                if cf > 0.0 {
                    cf * at(&psi, psilo, j)
                } else {
                    0.0
                }
            } else if i == ny {
                let k = (ny - 1) * nx + j;
                let cf = 2.0 * c_out[j];
                if cf > 0.0 {
                    cf * at(&x, xlo, k)
                } else {
                    0.0
                }
            } else {
                let k = (i - 1) * nx + j;
                face(st.s[k], k, k + nx)
            };
        }
    });
    let mut fb = vec![0.0; ny * (nx + 1)];
    fb.par_chunks_mut(nx + 1).enumerate().for_each(|(i, row)| {
        let base = i * nx;
        for (j, v) in row.iter_mut().enumerate().take(nx).skip(1) {
            *v = face(st.e[base + j - 1], base + j - 1, base + j);
        }
        if periodic && nx > 1 {
            let w = face(st.e[base + nx - 1], base + nx - 1, base);
            row[0] = w;
            row[nx] = w;
        }
    });
    drop((x, psi));
    drop(index);
    drop(lo);
    let q_in: f64 = fa[..nx].iter().sum();
    let q_out: f64 = fa[ny * nx..].iter().sum();
    // Net flux out of every cell.
    let worst = (0..ny)
        .into_par_iter()
        .map(|i| {
            let mut m: f64 = 0.0;
            for j in 0..nx {
                let out = fa[(i + 1) * nx + j] - fa[i * nx + j] + fb[i * (nx + 1) + j + 1]
                    - fb[i * (nx + 1) + j];
                m = m.max(out.abs());
            }
            m
        })
        .reduce(|| 0.0, f64::max);
    let conservation = if q_out != 0.0 {
        worst / q_out.abs()
    } else {
        0.0
    };
    cg::mark("pressures, fluxes, conservation");
    if prof {
        eprintln!(
            "flow: pressures, fluxes, conservation {:.3} s",
            cg::secs(t_post)
        );
    }
    if conservation > CONSERVATION_MAX || !conservation.is_finite() {
        return Err(Error::NotConverged {
            iterations,
            residual,
            what: format!(
                "reynolds-flow {solver} (the flow rate {q_out:e} is resolved but the net flux \
                 of a cell reaches {conservation:.1e} of it: the flow passes necks whose g³ is \
                 below ~1e-21 of the wide regions between them, too many decades for the \
                 face fluxes to balance in double precision; close the cells of negligible \
                 gap (set gaps below e.g. 1e-6 of the largest to 0))"
            ),
        });
    }
    Ok(UnitSolution {
        gref,
        phi,
        flux_along: fa,
        flux_across: fb,
        q_out,
        q_in,
        residual,
        conservation,
        iterations,
        n_unknowns,
        levels,
        solver,
    })
}

/// `φ`, `ψ` (by cell) and the relative residual of a factored answer.
type Factored = (Vec<f64>, Vec<f64>, f64);

/// What [`factored`] gives `Auto`.
enum Direct {
    /// The factored answer.
    Answer(Factored),
    /// The multigrid is predicted the faster ([`cost::prefers_multigrid`]): no factor.
    Slower,
    /// No answer: the factor does not fit, or its answer failed its checks on more unknowns
    /// than the elimination takes.
    Unavailable,
}

/// The factored answer `(φ, ψ, residual)` on the cells of `fine` (by cell), its low parts in
/// `lo` when it was refined in two doubles or eliminated without cancellation: the factor's
/// answer when it passes its checks, else the cancellation-free elimination. For `Auto`,
/// [`Direct::Unavailable`] when the factor does not fit or its answer fails on more
/// unknowns than the elimination takes (the caller then runs, or reports, the multigrid),
/// and with `weigh` [`Direct::Slower`] when the analysis predicts the multigrid faster.
fn factored(
    fine: &assemble::Stencil,
    [rhs, b_out]: [&[f64]; 2],
    n_unknowns: usize,
    opts: &Options<'_>,
    factor_room: Option<u64>,
    weigh: bool,
    lo: &mut (Vec<f64>, Vec<f64>),
) -> Result<Direct> {
    let n = fine.ny * fine.nx;
    let prof = cg::profiling();
    let kept = opts.analysis.filter(|k| k.applies(n));
    let prior = kept.and_then(|k| k.get());
    // The solves' vectors (φ, ψ, their residuals and low parts), zeroed where a core
    // waits in the factor.
    let mut spare = ZeroedByIdle::new(6, n);
    // A kept analysis carries the fill of an earlier level's larger set of unknowns: when
    // that does not fit, this level's own (smaller) analysis may.
    let slower = |an: &direct::Analysis| {
        let (flops, entries) = (an.critical_flops(), an.entries());
        let rate = opts.multigrid_seconds_per_unknown;
        let slower = cost::prefers_multigrid(flops, n_unknowns, rate);
        if prof {
            eprintln!(
                "flow: auto predicts the factor {:.3} s ({:.3e} critical flops, {entries} \
                 entries), the multigrid {:.3} s ({n_unknowns} unknowns): {}",
                cost::factor_seconds(flops),
                flops,
                cost::multigrid_seconds(n_unknowns, rate),
                if slower { "multigrid" } else { "factor" }
            );
        }
        slower
    };
    let declines = (weigh && opts.solver == Solver::Auto)
        .then_some(&slower as &dyn Fn(&direct::Analysis) -> bool);
    let make =
        |prior| direct::Factor::new_reusing(fine, factor_room, prior, Some(&spare), declines);
    let made = match make(prior.as_ref()) {
        Err(Error::TooLarge { .. }) if prior.is_some() => make(None),
        made => made,
    };
    // `Ok`: a factor; `Err`: the factor broke down (a non-positive pivot of the rounded
    // matrix).
    let factor = match made {
        Ok(Some(f)) => {
            if let Some(k) = kept {
                k.keep(f.analysis(), f.reused());
            }
            Ok(f)
        }
        Ok(None) => return Ok(Direct::Slower),
        Err(Error::TooLarge { .. }) if opts.solver == Solver::Auto => {
            return Ok(Direct::Unavailable)
        }
        Err(e @ Error::NotConverged { .. }) => Err(e),
        Err(e) => return Err(e),
    };
    let trust = paths::direct_trust(opts.tol);
    let trusted = factor.ok().and_then(|mut f| {
        let t0 = std::time::Instant::now();
        cg::mark("factor");
        let a = solve_direct(&mut f, fine, rhs, b_out, &mut spare);
        cg::mark("first solve, residuals, checks");
        let t_solve = cg::secs(t0);
        let t0 = std::time::Instant::now();
        let ok = trusted(&a, trust);
        if prof {
            let (_, (e_out, e_in)) = a.rate_errors();
            eprintln!(
                "flow: solve and residuals {t_solve:.3} s, checks {:.3} s ({}; rate \
                 errors {e_out:.1e}, {e_in:.1e}, kept at {trust:.0e})",
                cg::secs(t0),
                if ok { "trusted" } else { "refining" }
            );
        }
        if ok {
            return Some(a);
        }
        let t0 = std::time::Instant::now();
        let a = split_direct(&mut f, fine, rhs, b_out, a, trust, &mut spare);
        cg::mark("refinement");
        let ok = trusted(&a, trust);
        if prof {
            let (_, (e_out, e_in)) = a.rate_errors();
            eprintln!(
                "flow: refinement in two doubles and checks {:.3} s ({}; rate errors \
                 {e_out:.1e}, {e_in:.1e})",
                cg::secs(t0),
                if ok { "trusted" } else { "refused" }
            );
        }
        ok.then_some(a)
    });
    Ok(match trusted {
        Some(a) => {
            let residual = a.residual();
            *lo = a.lo;
            Direct::Answer((a.x, a.psi, residual))
        }
        None if opts.solver == Solver::Auto && n_unknowns > gth::MAX_UNKNOWNS => {
            Direct::Unavailable
        }
        None => {
            let (x, psi, residual, split) = solve_gth(fine, rhs, b_out, factor_room)?;
            *lo = split;
            Direct::Answer((x, psi, residual))
        }
    })
}
