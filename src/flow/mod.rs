//! Steady incompressible Reynolds flow through the gap of a solved contact: the leak rate.
//!
//! # Equation and discretisation
//!
//! On the free cells, `∇·(c ∇p) = 0` with the cell conductivity `c = g³/(12η)`; contact cells
//! are impermeable (`c = 0`). Cell-centred finite volumes on the surface grid (square cells
//! `dx × dx`): the flux through the face between edge neighbours 1 and 2 is
//!
//! ```text
//! q = c_f (p1 − p2),   c_f = 2 c1 c2 / (c1 + c2)   (0 when either cell is closed)
//! ```
//!
//! (volume per time; the face width `dx` and the centre distance `dx` cancel). Flow along
//! `axis`: the inlet reservoir at pressure `Δp` sits on the edge before the first row (or
//! column), the outlet at 0 on the edge after the last one, each half a cell from the
//! boundary cells' centres: boundary-face conductance `2c`. Side walls carry no flux, or wrap
//! when `periodic`. Parallel plates of gap `g` give exactly `Q = W g³ Δp / (12 η L)`,
//! `W = n_across·dx`, `L = n_along·dx`.
//!
//! # Unknowns
//!
//! A cell is *open* when it is free and its conductance is positive. Open cells are labelled
//! with 4-connectivity (the percolation classes' connectivity, same wrap). Only clusters that
//! touch both the inlet and the outlet row carry unknowns. A cluster touching only the inlet
//! has `p = Δp` exactly, only the outlet `p = 0` exactly (no net flux either way); any other
//! cluster is not joined to a reservoir and has no pressure (NaN). So `Q = 0` exactly when no
//! cluster spans.
//!
//! # Solver
//!
//! The conductances are scaled by the largest open gap cubed so the system is dimensionless.
//! By default ([`Solver::Auto`]) a sparse Cholesky factor ([`direct`]) whenever its exact
//! size, known after the symbolic analysis, fits in memory: exact to round-off however
//! widely the conductances spread, one factor for both right-hand sides. Otherwise conjugate
//! gradients on the spanning cells, preconditioned by aggregation multigrid ([`multigrid`]).
//! All loops run on rayon, reductions in fixed chunks: the same bits for any thread count.

pub mod assemble;
pub mod cg;
pub mod direct;
pub mod gth;
pub mod multigrid;

use rayon::prelude::*;

use crate::clusters::{self, Connectivity, Periodic};
use crate::error::{Error, Result};

use assemble::fine_stencil;
use multigrid::Multigrid;

/// Default relative residual `‖b − A x‖₂ / ‖b‖₂`.
pub const DEFAULT_TOL: f64 = 1e-12;

/// Default iteration cap. Gaps of contacts near the percolation threshold, whose
/// conductances `g³` span 15 orders of magnitude at the contact edges, take thousands.
pub const DEFAULT_MAX_ITER: usize = 20_000;

/// A Reynolds-flow problem on a row-major `ny × nx` gap field.
pub struct Problem<'a> {
    /// Gap `g ≥ 0` (length).
    pub gap: &'a [f64],
    /// Contact cells (`true` = closed). `None`: closed where `g ≤ 0`.
    pub contact: Option<&'a [bool]>,
    pub ny: usize,
    pub nx: usize,
    /// Grid spacing (length).
    pub dx: f64,
    /// Flow axis, 0 (along rows index i) or 1.
    pub axis: usize,
    /// Dynamic viscosity `η > 0`.
    pub viscosity: f64,
    /// `Δp = p_inlet − p_outlet`.
    pub pressure_drop: f64,
    /// Wrap across the flow (the axis other than `axis`).
    pub periodic: bool,
}

/// Which linear solver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Solver {
    /// Cholesky when its factor fits in memory, multigrid otherwise.
    Auto,
    /// Sparse Cholesky ([`direct`]), refined with double-double residuals.
    Cholesky,
    /// Conjugate gradients with the multigrid preconditioner ([`multigrid`]).
    Multigrid,
}

impl Solver {
    /// `"auto"`, `"cholesky"` or `"multigrid"`.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "auto" => Ok(Solver::Auto),
            "cholesky" => Ok(Solver::Cholesky),
            "multigrid" => Ok(Solver::Multigrid),
            _ => Err(Error::invalid(
                "solver",
                format!("must be 'auto', 'cholesky' or 'multigrid', got {s:?}"),
            )),
        }
    }
}

/// Solver settings.
pub struct Options<'a> {
    /// Linear solver.
    pub solver: Solver,
    /// Relative residual to reach.
    pub tol: f64,
    /// Conjugate-gradient iterations allowed (default [`DEFAULT_MAX_ITER`]).
    pub max_iter: Option<usize>,
    /// Refuse up front with [`Error::TooLarge`] above this many bytes.
    pub memory_limit: Option<u64>,
    /// Polled once per iteration; `true` stops with [`Error::Interrupted`].
    pub should_stop: Option<&'a (dyn Fn() -> bool + Sync)>,
}

impl Default for Options<'_> {
    fn default() -> Self {
        Options {
            solver: Solver::Auto,
            tol: DEFAULT_TOL,
            max_iter: None,
            memory_limit: None,
            should_stop: None,
        }
    }
}

/// The flow field and its integrals, in the caller's orientation.
#[derive(Clone, Debug)]
pub struct Solution {
    /// Pressure (row-major `ny × nx`); NaN on closed cells and on clusters joined to no
    /// reservoir.
    pub pressure: Vec<f64>,
    /// Volume flux through the faces normal to axis 0, `(ny + 1) × nx`: face `[i, j]` lies
    /// before cell `(i, j)`; positive towards increasing `i`.
    pub flux_axis0: Vec<f64>,
    /// Volume flux through the faces normal to axis 1, `ny × (nx + 1)`: face `[i, j]` lies
    /// before cell `(i, j)`; positive towards increasing `j`. With wrap across axis 1,
    /// faces `[i, 0]` and `[i, nx]` are the same face.
    pub flux_axis1: Vec<f64>,
    /// Volume flow rate out through the outlet.
    pub flow_rate: f64,
    /// Volume flow rate in through the inlet.
    pub inlet_flow_rate: f64,
    /// `Q / Δp`, computed from the unit-pressure solution (defined for `Δp = 0` too).
    pub conductance: f64,
    /// `K = Q η L / (W Δp)` (length³), from the unit-pressure solution.
    pub permeability: f64,
    /// True relative residual of the linear system.
    pub residual: f64,
    /// Largest net flux out of a cell, relative to `Q` (0 when `Q = 0`).
    pub conservation: f64,
    pub iterations: usize,
    pub n_unknowns: usize,
    pub levels: usize,
    /// The linear solver that ran: `"cholesky"`, `"multigrid"`, or `"none"` (nothing
    /// spans).
    pub solver: &'static str,
}

/// Bytes a solve of `cells` cells needs beside its linear solver (inputs not counted).
pub fn memory_estimate(cells: usize) -> u64 {
    let c = cells as u64;
    // transposed inputs 9, labels 4, open mask 1, conductance 8, fine operator 33, two
    // right-hand sides 16, vectors φ, ψ and the refinement's and CG's r, δ, r, z, p, q 64,
    // outputs pressure + two fluxes 24.
    c * (9 + 4 + 1 + 8 + 33 + 16 + 64 + 24)
}

/// Bytes of a multigrid solve of `cells` cells of which `unknowns` carry unknowns.
pub fn multigrid_estimate(cells: usize, unknowns: usize) -> u64 {
    memory_estimate(cells) + multigrid::memory_estimate(unknowns)
}

/// Entries per unknown below which a sparse Cholesky factor of a contact gap's spanning
/// cells is not expected: about 25 at 1025², 65 at 4097² (10 million unknowns); the fill of
/// a nested 2-D order grows with the size.
fn factor_entries_lower_bound(unknowns: usize) -> u64 {
    let m = unknowns as u64;
    if m >= 8_000_000 {
        60 * m
    } else {
        20 * m
    }
}

fn validate(pr: &Problem<'_>, opts: &Options<'_>) -> Result<()> {
    let n = pr.ny.saturating_mul(pr.nx);
    if pr.ny == 0 || pr.nx == 0 {
        return Err(Error::invalid("gap", "must have at least one cell"));
    }
    clusters::check_grid("gap", pr.ny, pr.nx)?;
    if pr.gap.len() != n {
        return Err(Error::invalid(
            "gap",
            format!(
                "has {} values, expected {} × {}",
                pr.gap.len(),
                pr.ny,
                pr.nx
            ),
        ));
    }
    if let Some(c) = pr.contact {
        if c.len() != n {
            return Err(Error::invalid("contact", "must have the gap's shape"));
        }
    }
    if !(pr.dx.is_finite() && pr.dx > 0.0) {
        return Err(Error::invalid(
            "dx",
            format!("must be a positive finite grid spacing, got {}", pr.dx),
        ));
    }
    if pr.axis > 1 {
        return Err(Error::invalid(
            "axis",
            format!("must be 0 or 1, got {}", pr.axis),
        ));
    }
    if !(pr.viscosity.is_finite() && pr.viscosity > 0.0) {
        return Err(Error::invalid(
            "viscosity",
            format!("must be a positive finite number, got {}", pr.viscosity),
        ));
    }
    if !pr.pressure_drop.is_finite() {
        return Err(Error::invalid(
            "pressure_drop",
            format!("must be a finite number, got {}", pr.pressure_drop),
        ));
    }
    if !(opts.tol.is_finite() && opts.tol > 0.0 && opts.tol < 1.0) {
        return Err(Error::invalid(
            "tol",
            format!("must be in (0, 1), got {}", opts.tol),
        ));
    }
    let bad = pr.gap.par_iter().enumerate().find_first(|&(k, &g)| {
        g.is_nan() || g.is_infinite() || (g < 0.0 && !pr.contact.is_some_and(|c| c[k]))
    });
    if let Some((k, &g)) = bad {
        let (i, j) = (k / pr.nx, k % pr.nx);
        let what = if g.is_nan() || g.is_infinite() {
            "is not finite"
        } else {
            "is negative on a free cell"
        };
        return Err(Error::invalid(
            "gap",
            format!("the value {g} at ({i}, {j}) {what}; gaps must be finite and ≥ 0 off contact"),
        ));
    }
    Ok(())
}

#[inline(always)]
fn closed(pr: &Problem<'_>, k: usize) -> bool {
    !clusters::is_open(pr.gap[k], pr.contact.is_some_and(|c| c[k]))
}

fn transpose<T: Copy + Send + Sync>(a: &[T], ny: usize, nx: usize) -> Vec<T> {
    // out is nx × ny.
    let mut out = Vec::with_capacity(a.len());
    // SAFETY-free: build row by row in parallel.
    let rows: Vec<Vec<T>> = (0..nx)
        .into_par_iter()
        .map(|j| (0..ny).map(|i| a[i * nx + j]).collect())
        .collect();
    for r in rows {
        out.extend_from_slice(&r);
    }
    out
}

/// Solves the Reynolds flow (module docs).
pub fn solve(pr: &Problem<'_>, opts: &Options<'_>) -> Result<Solution> {
    solve_labelled(pr, opts, None)
}

/// [`solve`] with the open cells already labelled (row-major, the caller's orientation):
/// `labels` from [`clusters::label`] of the open cells ([`clusters::is_open`]) with
/// 4-connectivity, no wrap along the flow axis and wrap across it when `pr.periodic`, and
/// the number of clusters. The solve then does not label again. Labels whose non-zero
/// cells are not exactly the open cells are refused (`labels`).
pub fn solve_labelled(
    pr: &Problem<'_>,
    opts: &Options<'_>,
    labels: Option<(&[u32], usize)>,
) -> Result<Solution> {
    validate(pr, opts)?;
    if let Some((l, k)) = labels {
        if l.len() != pr.ny * pr.nx || l.par_iter().any(|&v| v as usize > k) {
            return Err(Error::invalid(
                "labels",
                format!("must be 0..={k} on the gap's {} × {} grid", pr.ny, pr.nx),
            ));
        }
    }
    let cells = pr.ny * pr.nx;
    if let Some(limit) = opts.memory_limit {
        // Before the labelling only the cells are known: the rest of the solve, and the
        // factor's rough estimate when it is asked for. The multigrid's hierarchy is checked
        // once the unknowns are counted, the factor exactly after its symbolic analysis.
        let factor = match opts.solver {
            Solver::Cholesky => cholesky_estimate(cells),
            _ => 0,
        };
        let need = memory_estimate(cells) + factor;
        if need > limit {
            return Err(Error::TooLarge {
                bytes: need,
                limit,
                what: format!("Reynolds flow on {} × {}", pr.ny, pr.nx),
            });
        }
    }
    // Work in the orientation where the flow runs along axis 0.
    let (ny, nx) = if pr.axis == 0 {
        (pr.ny, pr.nx)
    } else {
        (pr.nx, pr.ny)
    };
    let open_gap: Vec<f64> = (0..cells)
        .into_par_iter()
        .map(|k| if closed(pr, k) { 0.0 } else { pr.gap[k] })
        .collect();
    let open_gap = if pr.axis == 0 {
        open_gap
    } else {
        transpose(&open_gap, pr.ny, pr.nx)
    };
    let given = labels.map(|(l, k)| {
        let l = if pr.axis == 0 {
            l.to_vec()
        } else {
            transpose(l, pr.ny, pr.nx)
        };
        (l, k)
    });
    let unit = solve_axis0(&open_gap, ny, nx, pr.periodic, opts, given)?;
    drop(open_gap);

    // Dimensional scale: c = ĉ g_ref³ / (12 η), p = Δp φ, each factor kept as mantissa and
    // exponent so that the result is finite whenever it is representable (g_ref³ alone
    // overflows from g_ref ≈ 5.6e102, 1/η from η ≈ 5.6e-309).
    let g3 = Scale::of(unit.gref).pow3();
    let cscale = g3.div(Scale::of(12.0)).div(Scale::of(pr.viscosity));
    let dp = pr.pressure_drop;
    let qscale = cscale.mul(Scale::of(dp.abs()));
    let sign = if dp < 0.0 { -1.0 } else { 1.0 };
    let (n_along, n_across) = (ny as f64, nx as f64);
    let kscale = g3.div(Scale::of(12.0 * n_across)).mul(Scale::of(n_along));
    if unit.n_unknowns > 0 {
        check_range(pr, unit.gref, "flow rate", dp != 0.0, qscale, unit.q_out)?;
        check_range(pr, unit.gref, "flow rate", dp != 0.0, qscale, unit.q_in)?;
        check_range(pr, unit.gref, "conductance", true, cscale, unit.q_out)?;
        check_range(pr, unit.gref, "permeability", true, kscale, unit.q_out)?;
    }
    let mut pressure = unit.phi;
    pressure.par_iter_mut().for_each(|v| *v *= dp);
    let mut fa = unit.flux_along;
    let mut fb = unit.flux_across;
    let flux = |v: &mut f64| {
        *v = if dp == 0.0 {
            0.0
        } else {
            sign * qscale.apply(*v)
        }
    };
    fa.par_iter_mut().for_each(flux);
    fb.par_iter_mut().for_each(flux);
    let (pressure, flux_axis0, flux_axis1) = if pr.axis == 0 {
        (pressure, fa, fb)
    } else {
        // Transposed problem (ny = pr.nx): fb is pr.nx × (pr.ny + 1), fa (pr.nx + 1) × pr.ny.
        (
            transpose(&pressure, ny, nx),
            transpose(&fb, ny, nx + 1),
            transpose(&fa, ny + 1, nx),
        )
    };
    Ok(Solution {
        pressure,
        flux_axis0,
        flux_axis1,
        flow_rate: if dp == 0.0 {
            0.0
        } else {
            sign * qscale.apply(unit.q_out)
        },
        inlet_flow_rate: if dp == 0.0 {
            0.0
        } else {
            sign * qscale.apply(unit.q_in)
        },
        conductance: cscale.apply(unit.q_out),
        permeability: kscale.apply(unit.q_out),
        residual: unit.residual,
        conservation: unit.conservation,
        iterations: unit.iterations,
        n_unknowns: unit.n_unknowns,
        levels: unit.levels,
        solver: unit.solver,
    })
}

/// A positive factor `m 2^e` (`m` in `[½, 1)`), so that products of factors that would over-
/// or underflow on their own are exact to a few roundings whenever the result is
/// representable.
#[derive(Clone, Copy, Debug)]
struct Scale {
    m: f64,
    e: i32,
}

impl Scale {
    /// `v > 0` finite (0 gives the zero factor).
    fn of(v: f64) -> Scale {
        if v == 0.0 || !v.is_finite() {
            return Scale { m: v, e: 0 };
        }
        // Subnormals: scale into the normal range first.
        let (v, adj) = if v.abs() < f64::MIN_POSITIVE {
            (v * 2f64.powi(64), -64)
        } else {
            (v, 0)
        };
        let bits = v.to_bits();
        let e = ((bits >> 52) & 0x7ff) as i32 - 1022;
        let m = f64::from_bits((bits & !(0x7ffu64 << 52)) | (1022u64 << 52));
        Scale { m, e: e + adj }
    }

    fn norm(self) -> Scale {
        let s = Scale::of(self.m);
        Scale {
            m: s.m,
            e: s.e + self.e,
        }
    }

    fn mul(self, o: Scale) -> Scale {
        Scale {
            m: self.m * o.m,
            e: self.e + o.e,
        }
        .norm()
    }

    fn div(self, o: Scale) -> Scale {
        Scale {
            m: self.m / o.m,
            e: self.e - o.e,
        }
        .norm()
    }

    fn pow3(self) -> Scale {
        self.mul(self).mul(self)
    }

    /// `v m 2^e`, rounded once more at most where it leaves the normal range.
    fn apply(self, v: f64) -> f64 {
        let mut x = v * self.m;
        let mut e = self.e;
        while e > 1000 && x.is_finite() && x != 0.0 {
            x *= 2f64.powi(1000);
            e -= 1000;
        }
        while e < -1000 && x.is_finite() && x != 0.0 {
            x *= 2f64.powi(-1000);
            e += 1000;
        }
        if x == 0.0 || !x.is_finite() {
            return x;
        }
        x * 2f64.powi(e)
    }

    fn log10(self) -> f64 {
        self.m.log10() + self.e as f64 * std::f64::consts::LOG10_2
    }
}

/// Refuses a reported quantity `unit · scale` that is not a normal double (it would be
/// returned as ∞, or as 0 or a subnormal with digits lost, while the flow spans), naming the
/// argument that pushes it furthest out of range.
fn check_range(
    pr: &Problem<'_>,
    gref: f64,
    what: &str,
    applies: bool,
    scale: Scale,
    unit: f64,
) -> Result<()> {
    if !applies || unit == 0.0 {
        return Ok(());
    }
    let v = scale.apply(unit.abs());
    if v.is_finite() && v >= f64::MIN_POSITIVE {
        return Ok(());
    }
    let log = scale.log10() + unit.abs().log10();
    let over = log > 0.0;
    // Each argument's share of log10 of the result.
    let mut parts: Vec<(&'static str, f64)> = vec![("gap", 3.0 * gref.log10())];
    if what != "permeability" {
        parts.push(("viscosity", -pr.viscosity.log10()));
    }
    if what == "flow rate" {
        parts.push(("pressure_drop", pr.pressure_drop.abs().log10()));
    }
    let pick = |a: &&(&'static str, f64), b: &&(&'static str, f64)| a.1.total_cmp(&b.1);
    let name = if over {
        parts.iter().max_by(pick)
    } else {
        parts.iter().min_by(pick)
    }
    .map(|p| p.0)
    .unwrap_or("gap");
    Err(Error::invalid(
        name,
        format!(
            "the {what} would be about 1e{log:.0}, {} the range of a double (normal numbers \
             2.2e-308 to 1.8e308): it scales with g³/η (and Δp), here largest gap {gref:e}, \
             viscosity {:e}, pressure drop {:e}; express lengths, pressures and viscosity in \
             units that bring it into range",
            if over { "above" } else { "below" },
            pr.viscosity,
            pr.pressure_drop
        ),
    ))
}

/// The dimensionless solution for flow along axis 0 with `φ = 1` at the inlet, 0 at the outlet,
/// cell conductances `(g / g_ref)³`.
struct UnitSolution {
    gref: f64,
    phi: Vec<f64>,
    flux_along: Vec<f64>,
    flux_across: Vec<f64>,
    q_out: f64,
    q_in: f64,
    residual: f64,
    conservation: f64,
    iterations: usize,
    n_unknowns: usize,
    levels: usize,
    solver: &'static str,
}

fn solve_axis0(
    g: &[f64],
    ny: usize,
    nx: usize,
    periodic: bool,
    opts: &Options<'_>,
    given: Option<(Vec<u32>, usize)>,
) -> Result<UnitSolution> {
    let n = ny * nx;
    let gref = g.par_iter().cloned().reduce(|| 0.0, f64::max);
    let mut c: Vec<f64> = if gref > 0.0 {
        g.par_iter()
            .map(|&v| {
                let t = v / gref;
                t * t * t
            })
            .collect()
    } else {
        vec![0.0; n]
    };
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
    let n_unknowns = labels
        .par_iter()
        .filter(|&&l| touch[l as usize] == 3)
        .count();

    let (fine, rhs) = fine_stencil(&c, ny, nx, periodic);
    // The outlet reservoir's share of the diagonal: `Q_out = b_out · φ`, and `ψ = 1 − φ` (the
    // flow reversed) solves `A ψ = b_out` with `Q_in = b_in · ψ`.
    let b_out: Vec<f64> = (0..n)
        .into_par_iter()
        .map(|k| if k >= (ny - 1) * nx { 2.0 * c[k] } else { 0.0 })
        .collect();
    let max_iter = opts.max_iter.unwrap_or(DEFAULT_MAX_ITER);
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
    // `Some(Ok)`: a factor; `Some(Err)`: the factor broke down (a non-positive pivot of the
    // rounded matrix); `None`: no factor (multigrid, or too large for `Auto`).
    // `Auto` skips the symbolic analysis (itself costly on large grids) when even the
    // factor's lower bound does not fit.
    let hopeless = opts.solver == Solver::Auto
        && factor_room.is_some_and(|r| 16 * factor_entries_lower_bound(n_unknowns) > r);
    let factor = if n_unknowns == 0 || opts.solver == Solver::Multigrid || hopeless {
        None
    } else {
        match direct::Factor::new(&fine, factor_room) {
            Ok(f) => Some(Ok(f)),
            Err(Error::TooLarge { .. }) if opts.solver == Solver::Auto => None,
            Err(e @ Error::NotConverged { .. }) => Some(Err(e)),
            Err(e) => return Err(e),
        }
    };
    // `lo`: the parts of φ and ψ below the last digit of `x` and `psi` (the elimination's
    // refinement; empty otherwise).
    let mut lo = (Vec::new(), Vec::new());
    // The factor's answer when it passes its checks; else the cancellation-free elimination,
    // or with `Auto` beyond the elimination's size the multigrid (`None`).
    let direct_answer = match factor {
        None => None,
        Some(f) => {
            let trusted = f.ok().and_then(|mut f| {
                let (x, psi, residual) = solve_direct(&mut f, &fine, &rhs, &b_out);
                trusted(&fine, &rhs, &b_out, &x, &psi).then_some((x, psi, residual))
            });
            match trusted {
                Some(t) => Some(t),
                None if opts.solver == Solver::Auto && n_unknowns > gth::MAX_UNKNOWNS => None,
                None => {
                    let (x, psi, residual, split) = solve_gth(&fine, &rhs, &b_out, factor_room)?;
                    lo = split;
                    Some((x, psi, residual))
                }
            }
        }
    };
    let (st, x, psi, residual, solver) = if n_unknowns == 0 {
        (fine, vec![0.0; n], vec![0.0; n], 0.0, "none")
    } else if let Some((x, psi, residual)) = direct_answer {
        (fine, x, psi, residual, "cholesky")
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
        let mg = Multigrid::new(fine);
        levels = mg.n_levels();
        let (x, psi, residual, it) = solve_multigrid(&mg, &rhs, &b_out, opts, max_iter)??;
        iterations = it;
        (mg.into_fine(), x, psi, residual, "multigrid")
    };
    drop(rhs);
    let st = &st;
    // Pressures: solution on spanning cells, reservoir pressure on one-sided clusters.
    let phi: Vec<f64> = (0..n)
        .into_par_iter()
        .map(|k| match touch[labels[k] as usize] {
            3 => x[k],
            1 => 1.0,
            2 => 0.0,
            _ => f64::NAN,
        })
        .collect();
    drop(labels);
    // A face flux `c_f (φ1 − φ2)` loses the digits of `φ` near 1 (all of the inlet side near
    // the percolation threshold, where the flow is many decades below the conductances):
    // there the same flux is `c_f (ψ2 − ψ1)` with `ψ = 1 − φ` solved for directly.
    // With the low parts, a difference of two close pressures keeps the digits below the
    // last one of `x` (the difference of the high parts is exact).
    let (xlo, psilo) = (&lo.0, &lo.1);
    let split = !xlo.is_empty();
    let face = |cf: f64, k: usize, l: usize| -> f64 {
        if cf <= 0.0 {
            0.0
        } else if x[k] + x[l] <= 1.0 {
            if split {
                cf * ((x[k] - x[l]) + (xlo[k] - xlo[l]))
            } else {
                cf * (x[k] - x[l])
            }
        } else if split {
            cf * ((psi[l] - psi[k]) + (psilo[l] - psilo[k]))
        } else {
            cf * (psi[l] - psi[k])
        }
    };
    let at = |v: &[f64], low: &[f64], k: usize| if split { v[k] + low[k] } else { v[k] };
    // Fluxes along: (ny + 1) × nx.
    let mut fa = vec![0.0; (ny + 1) * nx];
    fa.par_chunks_mut(nx).enumerate().for_each(|(i, row)| {
        for j in 0..nx {
            row[j] = if i == 0 {
                let cf = 2.0 * c[j];
                if cf > 0.0 {
                    cf * at(&psi, psilo, j)
                } else {
                    0.0
                }
            } else if i == ny {
                let k = (ny - 1) * nx + j;
                let cf = 2.0 * c[k];
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
    drop(x);
    drop(psi);
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

/// Largest net flux out of a cell, relative to the flow rate, of a returned solution.
pub const CONSERVATION_MAX: f64 = 1e-6;

/// Largest relative difference allowed between the inlet and the outlet flow rates.
pub const FLUX_AGREEMENT: f64 = 1e-9;

/// `Σ a_k b_k` over the solution's two right-hand sides, and the inlet/outlet test.
fn rates_agree(q_in: f64, q_out: f64) -> bool {
    (q_in - q_out).abs() <= FLUX_AGREEMENT * q_out.abs()
}

/// `φ` from the factor, and `ψ = 1 − φ`: taken from `φ` when the inlet rate
/// `Σ b_in (1 − φ)` keeps its digits (the cancellation bound `4 ε Σ b_in` is below `10⁻¹³` of
/// it) and agrees with the outlet rate `b_out · φ` to [`DIRECT_AGREEMENT`]; else solved for
/// with the same factor (the flow many decades below the conductances, near the percolation
/// threshold). The larger relative residual of the solves.
fn solve_direct(
    f: &mut direct::Factor,
    st: &assemble::Stencil,
    b_in: &[f64],
    b_out: &[f64],
) -> (Vec<f64>, Vec<f64>, f64) {
    let n = b_in.len();
    let mut x = vec![0.0; n];
    let mut residual = f.solve(st, b_in, &mut x);
    let q_out = cg::dot(b_out, &x);
    let q_in = rate_error(&x, b_in);
    let scale = cg::sum(b_in);
    let kept = 4.0 * f64::EPSILON * scale <= 1e-13 * q_in.abs()
        && (q_in - q_out).abs() <= DIRECT_AGREEMENT * q_out.abs();
    let psi = if kept {
        x.par_iter()
            .zip(st.active.par_iter())
            .map(|(&v, &on)| if on { 1.0 - v } else { 0.0 })
            .collect()
    } else {
        let mut psi = vec![0.0; n];
        residual = residual.max(f.solve(st, b_out, &mut psi));
        psi
    };
    (x, psi, residual)
}

/// Inlet and outlet rates of a factored solve that agree to this need no reversed solve.
const DIRECT_AGREEMENT: f64 = 1e-12;

/// Largest first-order error of a flow rate, relative to the rate, at which the factor's
/// answer is kept.
const DIRECT_TRUST: f64 = 1e-12;

/// Whether the refined factor's `φ` (inlet at 1) and `ψ` (outlet at 1) can be returned: both
/// rates positive and finite, every pressure in `[0, 1]` (the maximum principle) to
/// round-off, the first-order errors of the rates from the exact residuals,
/// `ψ · (b_in − A φ)` and `φ · (b_out − A ψ)`, at most [`DIRECT_TRUST`] of them, and the
/// rates agreeing to [`FLUX_AGREEMENT`]. The factor of the rounded matrix fails this when a
/// region is joined to the rest only through faces below `ε` of its own (conductances
/// spanning some sixteen decades or more).
fn trusted(st: &assemble::Stencil, b_in: &[f64], b_out: &[f64], x: &[f64], psi: &[f64]) -> bool {
    let (q_out, q_in) = (cg::dot(b_out, x), cg::dot(b_in, psi));
    if !(q_out.is_finite() && q_in.is_finite() && q_out > 0.0 && q_in > 0.0) {
        return false;
    }
    if !rates_agree(q_in, q_out) {
        return false;
    }
    let in_range = |v: &[f64]| v.par_iter().all(|&t| (-1e-12..=1.0 + 1e-12).contains(&t));
    if !(in_range(x) && in_range(psi)) {
        return false;
    }
    let mut r = vec![0.0; x.len()];
    st.residual_compensated(x, b_in, &mut r);
    if cg::dot(psi, &r).abs() > DIRECT_TRUST * q_out {
        return false;
    }
    st.residual_compensated(psi, b_out, &mut r);
    cg::dot(x, &r).abs() <= DIRECT_TRUST * q_in
}

/// `φ`, `ψ`, the larger relative residual, and the low parts of `φ` and `ψ`.
type GthOk = (Vec<f64>, Vec<f64>, f64, (Vec<f64>, Vec<f64>));

/// Refinement steps of the low part after the cancellation-free elimination.
const REFINE_SPLIT: usize = 2;

/// `φ` and `ψ` by the cancellation-free elimination ([`gth`]): both from right-hand sides
/// `≥ 0`, so each rate is a sum of positive terms accurate to a few `n ε` however widely the
/// conductances spread; the rates must still agree to [`FLUX_AGREEMENT`]. Returns the larger
/// relative residual of the two solves.
fn solve_gth(
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
fn rate_error(x: &[f64], r: &[f64]) -> f64 {
    let parts: Vec<f64> = x
        .par_chunks(cg::CHUNK)
        .zip(r.par_chunks(cg::CHUNK))
        .map(|(xc, rc)| xc.iter().zip(rc).map(|(u, v)| (1.0 - u) * v).sum::<f64>())
        .collect();
    parts.iter().sum()
}

/// `φ` and `ψ` by multigrid-preconditioned CG with iterative refinement ([`cg::refined`]),
/// each until its relative residual is `≤ tol` and its flow rate is accurate to `tol`
/// (estimated from the exact residual by [`rate_error`]); then the inlet and outlet rates must agree to [`FLUX_AGREEMENT`]. The
/// inner `Err` is the failure to report (or to recover from with the direct solver).
type MultigridOk = (Vec<f64>, Vec<f64>, f64, usize);
fn solve_multigrid(
    mg: &Multigrid,
    b_in: &[f64],
    b_out: &[f64],
    opts: &Options<'_>,
    max_iter: usize,
) -> Result<std::result::Result<MultigridOk, Error>> {
    let n = b_in.len();
    let st = mg.fine();
    let qtol = opts.tol;
    let apply = |v: &[f64], out: &mut [f64]| st.apply(v, out);
    let mut pre = |r: &[f64], z: &mut [f64]| mg.apply(r, z);
    // The rate's first-order error at most `tol` of it, and the pressure change a Jacobi step
    // would make, `max |r_k| / d_k`, at most `tol` (a dead end behind a narrow face has a
    // small residual for a large pressure error).
    fn accurate<'a>(
        st: &'a assemble::Stencil,
        w: &'a [f64],
        qtol: f64,
    ) -> impl Fn(&[f64], &[f64]) -> f64 + 'a {
        move |x: &[f64], r: &[f64]| {
            let jacobi = r
                .par_chunks(cg::CHUNK)
                .zip(st.d.par_chunks(cg::CHUNK))
                .map(|(rc, dc)| {
                    rc.iter()
                        .zip(dc)
                        .fold(0.0, |m: f64, (rv, dv)| m.max(rv.abs() / dv))
                })
                .reduce(|| 0.0, f64::max);
            let rate = rate_error(x, r).abs() / (qtol * cg::dot(w, x).abs());
            rate.max(jacobi / qtol)
        }
    }
    let mut x = vec![0.0; n];
    let exact = |x: &[f64], b: &[f64], r: &mut [f64]| st.residual_compensated(x, b, r);
    let a = cg::refined(
        &apply,
        &exact,
        &mut pre,
        &accurate(st, b_out, qtol),
        b_in,
        &mut x,
        opts.tol,
        max_iter,
        opts.should_stop,
    )?;
    let failed = |o: &cg::Outcome, what: &str| Error::NotConverged {
        iterations: o.iterations,
        residual: o.residual,
        what: format!("reynolds-flow multigrid CG ({what})"),
    };
    if !a.converged {
        return Ok(Err(failed(&a, "pressure")));
    }
    // ψ from 1 − φ: only the digits that φ cannot hold near 1 are left to find.
    let mut psi: Vec<f64> = x
        .par_iter()
        .zip(st.active.par_iter())
        .map(|(&v, &on)| if on { 1.0 - v } else { 0.0 })
        .collect();
    let b = cg::refined(
        &apply,
        &exact,
        &mut pre,
        &accurate(st, b_in, qtol),
        b_out,
        &mut psi,
        opts.tol,
        max_iter,
        opts.should_stop,
    )?;
    let total = cg::Outcome {
        iterations: a.iterations + b.iterations,
        residual: a.residual.max(b.residual),
        converged: b.converged,
    };
    if !b.converged {
        return Ok(Err(failed(&total, "reversed pressure")));
    }
    let (q_out, q_in) = (cg::dot(b_out, &x), cg::dot(b_in, &psi));
    if !rates_agree(q_in, q_out) {
        return Ok(Err(failed(
            &total,
            &format!("inlet rate {q_in:e} and outlet rate {q_out:e} differ"),
        )));
    }
    Ok(Ok((x, psi, total.residual, total.iterations)))
}

/// Bytes of a sparse Cholesky factor of `cells` unknowns (AMD on a 2-D grid: a few tens of
/// entries, value and row index, per unknown).
fn cholesky_estimate(cells: usize) -> u64 {
    40 * 16 * cells as u64
}

/// `MemAvailable` of `/proc/meminfo` (Linux), in bytes.
fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

#[cfg(test)]
mod tests;
