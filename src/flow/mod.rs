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
//! touch both the inlet and the outlet row carry unknowns, and of those only the backbone:
//! a dead end, joined to the rest through one cell, takes that cell's pressure
//! ([`dead_ends`]). A cluster touching only the inlet
//! has `p = Δp` exactly, only the outlet `p = 0` exactly (no net flux either way); any other
//! cluster is not joined to a reservoir and has no pressure (NaN). So `Q = 0` exactly when no
//! cluster spans.
//!
//! # Solver
//!
//! The conductances are scaled by the largest open gap cubed so the system is dimensionless.
//! By default ([`Solver::Auto`]) a sparse Cholesky factor ([`direct`]) whenever its exact
//! size, known after the symbolic analysis, fits in memory and its predicted time is not
//! above the multigrid's ([`cost`]): exact to round-off however widely the conductances
//! spread, one factor for both right-hand sides. Otherwise conjugate gradients on the
//! spanning cells, preconditioned by classical (Ruge–Stüben) algebraic multigrid
//! ([`multigrid`]); from [`MULTIGRID_FROM`] unknowns the multigrid first. The flow along
//! axis 0 and its checks are in `axis0.rs`, the three solution paths and their answer
//! checks in `paths.rs`.
//! All loops run on rayon, reductions in fixed chunks: the same bits for any thread count.

pub mod assemble;
mod axis0;
pub mod cg;
mod compensated;
pub mod cost;
pub mod dead_ends;
pub mod direct;
mod extremes;
pub mod gth;
mod halves;
pub mod kept;
mod llt;
mod lower;
pub mod multigrid;
pub mod order;
mod paths;
mod substitution;
mod supernodal;
mod symbolic;
mod wide;

use rayon::prelude::*;

use crate::clusters::{self, Connectivity, Periodic};
use crate::error::{Error, Result};

use assemble::fine_stencil;
use multigrid::Multigrid;

use axis0::solve_axis0;
pub use extremes::free_gap_extremes;
use paths::{
    available_memory, cholesky_estimate, solve_direct, solve_gth, solve_multigrid, split_direct,
    trusted,
};
pub use paths::{CONSERVATION_MAX, FLUX_AGREEMENT};

/// Default relative residual `‖b − A x‖₂ / ‖b‖₂`.
pub const DEFAULT_TOL: f64 = 1e-12;

/// From this many unknowns `Auto` takes the multigrid without trying the factor: on the
/// near-threshold gaps of benchmarks/results/flow_amg.md it is there the faster and needs a
/// third of the memory (10.0 million unknowns at 4097²: 20.5 s and 2.6 GiB against the
/// factor's 54.2 s and 9.0 GiB), and its symbolic analysis alone takes seconds. Below,
/// either may be the faster, and `Auto` weighs them once the analysis is known
/// ([`cost`]).
pub const MULTIGRID_FROM: usize = 1 << 22;

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
    /// Cholesky when its factor fits in memory (the symbolic analysis skipped when even a
    /// lower bound of it does not) and is not predicted slower than the multigrid
    /// ([`cost`]), multigrid otherwise, and when the factor's answer fails its checks on
    /// more unknowns than the cancellation-free elimination takes. From [`MULTIGRID_FROM`]
    /// unknowns the multigrid first. Where the multigrid ran first (by size or by the
    /// prediction) and refuses the gap (a region joined through faces below its
    /// single-precision range), the factor when it fits.
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
    /// An analysis kept from the previous flows of a sequence (a sweep's levels), used by
    /// the factor when it fits and replaced when not ([`kept`]).
    pub analysis: Option<&'a kept::KeptAnalysis>,
    /// From this many unknowns [`Solver::Auto`] runs the multigrid first, and the factor
    /// only when the multigrid refuses and the factor fits (default [`MULTIGRID_FROM`]).
    pub multigrid_from: usize,
    /// Below [`Options::multigrid_from`], [`Solver::Auto`] takes the multigrid when the
    /// factor's predicted time exceeds this many seconds per unknown ([`cost`]; default
    /// [`cost::MULTIGRID_SECONDS_PER_UNKNOWN`]; 0 takes the multigrid whenever the factor
    /// fits too, the factor then answering where the multigrid refuses).
    pub multigrid_seconds_per_unknown: f64,
}

impl Default for Options<'_> {
    fn default() -> Self {
        Options {
            solver: Solver::Auto,
            tol: DEFAULT_TOL,
            max_iter: None,
            memory_limit: None,
            should_stop: None,
            analysis: None,
            multigrid_from: MULTIGRID_FROM,
            multigrid_seconds_per_unknown: cost::MULTIGRID_SECONDS_PER_UNKNOWN,
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
    let bad = crate::grid::first_cell(pr.gap, |k, &g| {
        !g.is_finite() || (g < 0.0 && !pr.contact.is_some_and(|m| m[k]))
    });
    if let Some(k) = bad {
        let g = pr.gap[k];
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
    let unit = solve_axis0(open_gap, ny, nx, pr.periodic, opts, given)?;

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

#[cfg(test)]
mod tests;
