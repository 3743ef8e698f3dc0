//! One contact problem, one entry point: a rough surface on an elastic half-space that owns its
//! kernel, FFT operator and (for the exact solvers) dense Cholesky factor, solved by
//! [`ContactProblem::solve`] with any solver, any control and any start.
//!
//! The solve dispatches to the solvers of this folder unchanged (Polonsky–Keer with the kept
//! operator; Lawson–Hanson / block active set with the kept factor), so its numbers are the
//! solvers' own, bit for bit.

use std::sync::Arc;

use crate::alloc;
use crate::contact::lawson_hanson::{self as lh, Factor, LawsonHanson, Pivoting};
use crate::contact::multilevel::CoarseCost;
use crate::contact::polonsky_keer as pk;
use crate::elastic::kernel::Kernel;
use crate::elastic::memory;
use crate::elastic::operator::Operator;
use crate::error::{Error, Result};
use crate::grid::{check_shape, Boundary};

pub use crate::contact::polonsky_keer::Control;

/// `Solver::Auto` uses the exact block active set on grids of at most this many points and
/// Polonsky–Keer above. Measured from p = 0 at Δ = 0.3/0.6/1.0 h_s on an idle machine
/// (`benchmarks/auto_policy_bench.py` → `benchmarks/results/auto_policy.md`): on 17² the
/// active set is faster at every approach (0.2–0.4 ms); on 33²–65² it is faster at low
/// contact by at most 3 ms and 2–2.5× slower at half contact; from 129² on Polonsky–Keer is
/// faster at every approach, 45× at Δ = 0.6 h_s and hundreds of times at Δ = h_s (the factor
/// work grows like k³ in the contact points k, Polonsky–Keer like N log N per iteration). A
/// rule by grid size keeps one solver per grid, which warm-started sweeps need (pressure
/// fields versus contact sets); a per-solve contact-count model would save at most a few
/// milliseconds per solve on the small grids.
pub const AUTO_ACTIVE_SET_MAX_POINTS: usize = 32 * 32;

/// Which solver runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Solver {
    /// [`Solver::ActiveSet`] on grids of at most [`AUTO_ACTIVE_SET_MAX_POINTS`] points in
    /// displacement control, [`Solver::PolonskyKeer`] otherwise.
    Auto,
    /// Constrained conjugate gradients on the FFT operator (either control).
    PolonskyKeer,
    /// Lawson–Hanson with blocks of points entering at once (displacement control).
    ActiveSet,
    /// The paper's Lawson–Hanson, one point entering per iteration (displacement control).
    LawsonHanson,
}

impl Solver {
    /// The name used by the Python API.
    pub fn name(self) -> &'static str {
        match self {
            Solver::Auto => "auto",
            Solver::PolonskyKeer => "polonsky-keer",
            Solver::ActiveSet => "active-set",
            Solver::LawsonHanson => "lawson-hanson",
        }
    }

    /// Parse a Python-API name.
    pub fn from_name(name: &str) -> Result<Solver> {
        match name {
            "auto" => Ok(Solver::Auto),
            "polonsky-keer" => Ok(Solver::PolonskyKeer),
            "active-set" => Ok(Solver::ActiveSet),
            "lawson-hanson" => Ok(Solver::LawsonHanson),
            other => Err(Error::invalid(
                "solver",
                format!(
                    "must be 'auto', 'polonsky-keer', 'active-set' or 'lawson-hanson', got \
                     {other:?}"
                ),
            )),
        }
    }

    /// The solver that runs for `self` on a grid of `n_points` under `control` (the `auto`
    /// policy); an exact solver under load control is refused.
    pub fn resolve(self, n_points: usize, control: Control) -> Result<Solver> {
        match (self, control) {
            (Solver::Auto, Control::MeanPressure(_)) => Ok(Solver::PolonskyKeer),
            (Solver::Auto, Control::Approach(_)) => Ok(if n_points <= AUTO_ACTIVE_SET_MAX_POINTS {
                Solver::ActiveSet
            } else {
                Solver::PolonskyKeer
            }),
            (Solver::ActiveSet | Solver::LawsonHanson, Control::MeanPressure(_)) => {
                Err(Error::invalid(
                    "solver",
                    format!(
                        "{:?} imposes the approach only; use solver='auto' or 'polonsky-keer' \
                         with mean_pressure=",
                        self.name()
                    ),
                ))
            }
            (s, _) => Ok(s),
        }
    }
}

/// Where a solve starts.
#[derive(Clone, Copy, Debug)]
pub enum Start<'a> {
    /// `p = 0` (the paper: "without warm starting").
    Cold,
    /// This problem's previous solve: Polonsky–Keer from its pressure, the exact solvers from
    /// the passive set of their factor. Cold when there was none.
    Previous,
    /// A pressure field (`ny × nx`): Polonsky–Keer from it, the exact solvers from its support
    /// `{p > 0}`.
    Pressure(&'a [f64]),
    /// A contact set (flat indices): the exact solvers from it; Polonsky–Keer cold.
    ContactSet(&'a [usize]),
}

/// Settings of a solve.
#[derive(Clone, Copy)]
pub struct SolveOptions<'a> {
    /// Stop when the KKT certificate (relative to `h_s`) is `≤ tol`.
    pub tol: f64,
    /// Iteration cap; `None` → the solver's default (Polonsky–Keer
    /// [`pk::default_max_iter`], Lawson–Hanson `50 N + 1000`).
    pub max_iter: Option<usize>,
    /// Polled between iterations; `true` → [`Error::Interrupted`].
    pub should_stop: Option<&'a (dyn Fn() -> bool + Sync)>,
    /// Hardness `H` (pressure cap `p ≤ H`, [`crate::contact::capped`]); `None` or `+∞`: elastic.
    /// Polonsky–Keer only ([`Solver::Auto`] resolves to it).
    pub hardness: Option<f64>,
}

impl Default for SolveOptions<'_> {
    fn default() -> Self {
        SolveOptions {
            tol: pk::DEFAULT_TOL,
            max_iter: None,
            should_stop: None,
            hardness: None,
        }
    }
}

/// A converged contact state, whichever solver produced it.
#[derive(Clone, Debug)]
pub struct ContactSolution {
    /// The solver that ran ([`Solver::Auto`] resolved).
    pub solver: Solver,
    /// Pressure `p ≥ 0`, row-major `ny × nx`.
    pub pressure: Vec<f64>,
    /// Displacement `u = C p`.
    pub displacement: Vec<f64>,
    /// Gap `g = u − (Δ − (max h − h))`, not clamped.
    pub gap: Vec<f64>,
    /// Approach `Δ` (imposed, or computed under load control).
    pub approach: f64,
    /// Solver iterations.
    pub iterations: usize,
    /// FFT operator applications (Polonsky–Keer; 0 for the exact solvers).
    pub applies: usize,
    /// Preconditioner applications (Polonsky–Keer; 0 for the exact solvers).
    pub preconditioner_applies: usize,
    /// The coarse-to-fine start's cost (Polonsky–Keer from a cold start; zero otherwise).
    pub coarse: CoarseCost,
    /// KKT certificate relative to `h_s` ([`crate::contact::kkt`]).
    pub kkt: f64,
    /// Number of points with `p > 0`.
    pub contact_points: usize,
    /// Number of points at the hardness (`p = H`; 0 without one).
    pub plastic_points: usize,
}

/// A rough surface on an elastic half-space, solved at as many approaches or loads as needed.
/// The kernel, operator and heights are shared (`Arc`) so a solve can run on a worker thread
/// that owns a handle ([`ContactProblem::detach`]).
pub struct ContactProblem {
    kernel: Arc<Kernel>,
    op: Arc<Operator>,
    h: Arc<Vec<f64>>,
    dx: f64,
    e_star: f64,
    /// `None` after a solve that did not hand it back: the next exact solve starts a new one.
    factor: Option<Factor>,
    /// Pressure of the previous solve (the `Start::Previous` of Polonsky–Keer).
    last_pressure: Option<Arc<Vec<f64>>>,
    memory_limit: u64,
}

impl ContactProblem {
    /// `Error::TooLarge` when the problem of an `ny × nx` grid does not fit `memory_limit`
    /// ([`memory::contact_problem`]); checked before anything is copied.
    pub fn check_memory(ny: usize, nx: usize, boundary: Boundary, memory_limit: u64) -> Result<()> {
        let need = memory::contact_problem(ny, nx, boundary);
        if need > memory_limit {
            return Err(Error::TooLarge {
                bytes: need,
                limit: memory_limit,
                what: format!(
                    "the contact problem of a {ny} × {nx} grid (kernel table, FFT operator \
                     and solution fields)"
                ),
            });
        }
        Ok(())
    }

    /// Build the kernel and operator of row-major `ny × nx` heights (finite), grid spacing
    /// `dx` and contact modulus `e_star` (both > 0).
    pub fn try_new(
        heights: Vec<f64>,
        ny: usize,
        nx: usize,
        dx: f64,
        e_star: f64,
        boundary: Boundary,
        memory_limit: u64,
    ) -> Result<Self> {
        check_shape(ny, nx)?;
        if heights.len() != ny * nx {
            return Err(Error::invalid(
                "heights",
                format!("{} values for a {ny} × {nx} grid", heights.len()),
            ));
        }
        Self::check_memory(ny, nx, boundary, memory_limit)?;
        let (kernel, op) = match boundary {
            Boundary::Free => {
                let kernel = Kernel::try_new(ny, nx, dx, e_star)?;
                let op = Operator::try_free(&kernel)?;
                (kernel, op)
            }
            Boundary::Periodic => {
                // The periodic C_PP blocks come from the circulant's first column.
                let op = Operator::try_periodic(ny, nx, dx, e_star)?;
                let mut unit: Vec<f64> = alloc::try_zeroed(ny * nx, "a unit load")?;
                unit[0] = 1.0;
                let mut column: Vec<f64> = alloc::try_zeroed(ny * nx, "the periodic kernel table")?;
                op.apply(&unit, &mut column);
                (Kernel::from_table(ny, nx, dx, e_star, column), op)
            }
        };
        let factor = Factor::try_new(ny * nx, memory_limit)?;
        Ok(ContactProblem {
            kernel: Arc::new(kernel),
            op: Arc::new(op),
            h: Arc::new(heights),
            dx,
            e_star,
            factor: Some(factor),
            last_pressure: None,
            memory_limit,
        })
    }

    pub fn ny(&self) -> usize {
        self.op.ny
    }

    pub fn nx(&self) -> usize {
        self.op.nx
    }

    pub fn boundary(&self) -> Boundary {
        self.op.boundary
    }

    pub fn kernel(&self) -> &Kernel {
        &self.kernel
    }

    /// The kernel table `C e_0`, shared (the stand-alone Polonsky–Keer binding reuses it as
    /// the influence table of its sparse corrections).
    pub fn shared_kernel(&self) -> &Arc<Kernel> {
        &self.kernel
    }

    /// The FFT operator, shared (the stand-alone Polonsky–Keer binding reuses it).
    pub fn operator(&self) -> &Arc<Operator> {
        &self.op
    }

    /// Number of points in the passive (contact) set kept from the last exact solve.
    pub fn n_passive(&self) -> usize {
        self.factor.as_ref().map_or(0, Factor::len)
    }

    /// A handle sharing the kernel, operator and heights that takes the factor and the last
    /// pressure, so a solve can run on a thread that owns it; [`ContactProblem::attach`] hands
    /// them back. When the handle is lost (an interrupted solve), the next exact solve starts
    /// a new factor.
    pub fn detach(&mut self) -> ContactProblem {
        ContactProblem {
            kernel: Arc::clone(&self.kernel),
            op: Arc::clone(&self.op),
            h: Arc::clone(&self.h),
            dx: self.dx,
            e_star: self.e_star,
            factor: self.factor.take(),
            last_pressure: self.last_pressure.clone(),
            memory_limit: self.memory_limit,
        }
    }

    /// Take back the solver state of a handle from [`ContactProblem::detach`].
    pub fn attach(&mut self, handle: ContactProblem) {
        self.factor = handle.factor;
        self.last_pressure = handle.last_pressure;
    }

    /// Solve under `control` with `solver` from `start`. The one entry point of every solver.
    pub fn solve(
        &mut self,
        control: Control,
        solver: Solver,
        start: Start<'_>,
        opts: &SolveOptions<'_>,
    ) -> Result<ContactSolution> {
        let (ny, nx) = (self.op.ny, self.op.nx);
        let n = ny * nx;
        let capped = opts.hardness.is_some_and(|h| h.is_finite());
        let solver = if capped {
            match solver {
                Solver::Auto | Solver::PolonskyKeer => Solver::PolonskyKeer,
                other => {
                    return Err(Error::invalid(
                        "solver",
                        format!(
                            "{:?} cannot cap the pressure at a hardness; use solver='auto' or \
                             'polonsky-keer' with hardness=",
                            other.name()
                        ),
                    ))
                }
            }
        } else {
            solver.resolve(n, control)?
        };
        match start {
            Start::Pressure(p) if p.len() != n => {
                return Err(Error::invalid(
                    "initial_pressure",
                    format!("{} values for a {ny} × {nx} grid", p.len()),
                ))
            }
            Start::ContactSet(s) if s.iter().any(|&i| i >= n) => {
                return Err(Error::invalid(
                    "warm_start",
                    "contact set index outside the grid",
                ))
            }
            _ => {}
        }
        let sol = match solver {
            Solver::PolonskyKeer => self.solve_pk(control, start, opts)?,
            _ => {
                let Control::Approach(approach) = control else {
                    unreachable!("resolve refuses load control for the exact solvers")
                };
                self.solve_exact(approach, solver == Solver::ActiveSet, start, opts)?
            }
        };
        let mut last: Vec<f64> = alloc::try_with_capacity(n, "the kept pressure field")?;
        last.extend_from_slice(&sol.pressure);
        self.last_pressure = Some(Arc::new(last));
        Ok(sol)
    }

    fn solve_pk(
        &mut self,
        control: Control,
        start: Start<'_>,
        opts: &SolveOptions<'_>,
    ) -> Result<ContactSolution> {
        let (ny, nx, boundary) = (self.op.ny, self.op.nx, self.op.boundary);
        let need = memory::polonsky_keer(ny, nx, boundary);
        if need > self.memory_limit {
            let kind = match boundary {
                Boundary::Free => "free",
                Boundary::Periodic => "periodic",
            };
            return Err(Error::TooLarge {
                bytes: need,
                limit: self.memory_limit,
                what: format!("Polonsky–Keer on a {ny} × {nx} {kind} grid"),
            });
        }
        let last = self.last_pressure.clone();
        let initial_pressure = match start {
            Start::Cold | Start::ContactSet(_) => None,
            Start::Previous => last.as_deref().map(|v| v.as_slice()),
            Start::Pressure(p) => Some(p),
        };
        let problem = pk::Problem {
            heights: &self.h,
            ny,
            nx,
            dx: self.dx,
            e_star: self.e_star,
            boundary,
        };
        let pk_opts = pk::Options {
            tol: opts.tol,
            max_iter: opts.max_iter,
            initial_pressure,
            memory_limit: Some(self.memory_limit),
            should_stop: opts.should_stop,
            precondition: true,
            coarse_start: true,
            chord_steps: true,
            hardness: opts.hardness,
        };
        let s = pk::solve_with_kernel(
            &self.op,
            Some(&self.kernel.table),
            &problem,
            control,
            &pk_opts,
        )?;
        Ok(ContactSolution {
            solver: Solver::PolonskyKeer,
            pressure: s.pressure,
            displacement: s.displacement,
            gap: s.gap,
            approach: s.approach,
            iterations: s.iterations,
            applies: s.applies,
            preconditioner_applies: s.preconditioner_applies,
            coarse: s.coarse,
            kkt: s.kkt,
            contact_points: s.contact_points,
            plastic_points: s.plastic_points,
        })
    }

    fn solve_exact(
        &mut self,
        approach: f64,
        block: bool,
        start: Start<'_>,
        opts: &SolveOptions<'_>,
    ) -> Result<ContactSolution> {
        if !(opts.tol.is_finite() && opts.tol > 0.0) {
            return Err(Error::invalid(
                "tol",
                format!("must be a finite number > 0, got {}", opts.tol),
            ));
        }
        let n = self.h.len();
        let support: Vec<usize>;
        let start = match start {
            Start::Cold => lh::Start::Cold,
            Start::Previous => lh::Start::Previous,
            Start::ContactSet(s) => lh::Start::Set(s),
            Start::Pressure(p) => {
                support = (0..n).filter(|&i| p[i] > 0.0).collect();
                lh::Start::Set(&support)
            }
        };
        let lh_opts = lh::Options {
            tol: opts.tol,
            max_iter: opts.max_iter.unwrap_or(50 * n + 1000),
            pivoting: if block {
                Pivoting::Block
            } else {
                Pivoting::Single
            },
            memory_limit: 0,
        };
        let mut factor = match self.factor.take() {
            Some(f) => f,
            None => Factor::try_new(n, self.memory_limit)?,
        };
        let never = || false;
        let should_stop: &(dyn Fn() -> bool + Sync) = match opts.should_stop {
            Some(f) => f,
            None => &never,
        };
        let result = LawsonHanson::new(&self.kernel, &self.op, &self.h, &mut factor).solve(
            approach,
            start,
            &lh_opts,
            should_stop,
        );
        self.factor = Some(factor);
        let s = result?;
        Ok(ContactSolution {
            solver: if block {
                Solver::ActiveSet
            } else {
                Solver::LawsonHanson
            },
            pressure: s.pressure,
            displacement: s.displacement,
            gap: s.gap,
            approach: s.approach,
            iterations: s.iterations,
            applies: 0,
            preconditioner_applies: 0,
            coarse: CoarseCost::default(),
            kkt: s.kkt,
            contact_points: s.contact_points,
            plastic_points: 0,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth bumpy surface (no randomness needed: several incommensurate waves).
    fn surface(ny: usize, nx: usize) -> Vec<f64> {
        (0..ny * nx)
            .map(|k| {
                let (i, j) = ((k / nx) as f64, (k % nx) as f64);
                (0.7 * i).sin() * (0.45 * j).cos() + 0.3 * (1.3 * i + 0.9 * j).sin()
            })
            .collect()
    }

    const LIMIT: u64 = 1 << 30;

    fn problem(h: &[f64], ny: usize, nx: usize, boundary: Boundary) -> ContactProblem {
        ContactProblem::try_new(h.to_vec(), ny, nx, 0.5, 2.0, boundary, LIMIT).unwrap()
    }

    fn same_bits(a: &[f64], b: &[f64]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
    }

    fn pk_direct(
        h: &[f64],
        ny: usize,
        nx: usize,
        boundary: Boundary,
        control: Control,
        initial_pressure: Option<&[f64]>,
    ) -> pk::Solution {
        let problem = pk::Problem {
            heights: h,
            ny,
            nx,
            dx: 0.5,
            e_star: 2.0,
            boundary,
        };
        let opts = pk::Options {
            initial_pressure,
            memory_limit: Some(LIMIT),
            ..Default::default()
        };
        match boundary {
            // A free solve keeps the Love table it builds its operator from.
            Boundary::Free => pk::solve(&problem, control, &opts).unwrap(),
            // A ContactProblem hands its periodic kernel table (the product C e_0) to the
            // solver, which otherwise builds it on first use.
            Boundary::Periodic => {
                let (op, column) = periodic_column(ny, nx);
                pk::solve_with_kernel(&op, Some(&column), &problem, control, &opts).unwrap()
            }
        }
    }

    /// The periodic operator of the tests and its column `C e_0` (the kernel table).
    fn periodic_column(ny: usize, nx: usize) -> (Operator, Vec<f64>) {
        let op = Operator::try_periodic(ny, nx, 0.5, 2.0).unwrap();
        let mut unit = vec![0.0; ny * nx];
        unit[0] = 1.0;
        let mut column = vec![0.0; ny * nx];
        op.apply(&unit, &mut column);
        (op, column)
    }

    #[allow(clippy::too_many_arguments)]
    fn lh_direct(
        h: &[f64],
        ny: usize,
        nx: usize,
        boundary: Boundary,
        approach: f64,
        block: bool,
        factor: &mut Factor,
        start: lh::Start<'_>,
    ) -> lh::Solution {
        let (kernel, op) = match boundary {
            Boundary::Free => {
                let kernel = Kernel::try_new(ny, nx, 0.5, 2.0).unwrap();
                let op = Operator::try_free(&kernel).unwrap();
                (kernel, op)
            }
            Boundary::Periodic => {
                let (op, column) = periodic_column(ny, nx);
                (Kernel::from_table(ny, nx, 0.5, 2.0, column), op)
            }
        };
        let n = ny * nx;
        let opts = lh::Options {
            tol: pk::DEFAULT_TOL,
            max_iter: 50 * n + 1000,
            pivoting: if block {
                Pivoting::Block
            } else {
                Pivoting::Single
            },
            memory_limit: 0,
        };
        LawsonHanson::new(&kernel, &op, h, factor)
            .solve(approach, start, &opts, &|| false)
            .unwrap()
    }

    #[test]
    fn solve_equals_each_solver_called_directly() {
        let (ny, nx) = (12, 10);
        let h = surface(ny, nx);
        for boundary in [Boundary::Free, Boundary::Periodic] {
            let mut cp = problem(&h, ny, nx, boundary);
            let opts = SolveOptions::default();
            for control in [Control::Approach(0.6), Control::MeanPressure(0.05)] {
                let got = cp
                    .solve(control, Solver::PolonskyKeer, Start::Cold, &opts)
                    .unwrap();
                let want = pk_direct(&h, ny, nx, boundary, control, None);
                assert_eq!(got.solver, Solver::PolonskyKeer);
                assert!(
                    same_bits(&got.pressure, &want.pressure),
                    "{boundary:?} {control:?}"
                );
                assert!(same_bits(&got.gap, &want.gap));
                assert!(same_bits(&got.displacement, &want.displacement));
                assert_eq!(got.kkt.to_bits(), want.kkt.to_bits());
                assert_eq!(got.approach.to_bits(), want.approach.to_bits());
                assert_eq!(
                    (got.iterations, got.applies, got.contact_points),
                    (want.iterations, want.applies, want.contact_points)
                );
            }
            for (solver, block) in [(Solver::ActiveSet, true), (Solver::LawsonHanson, false)] {
                let got = cp
                    .solve(Control::Approach(0.6), solver, Start::Cold, &opts)
                    .unwrap();
                let mut factor = Factor::new(ny * nx, LIMIT);
                let want = lh_direct(
                    &h,
                    ny,
                    nx,
                    boundary,
                    0.6,
                    block,
                    &mut factor,
                    lh::Start::Cold,
                );
                assert_eq!(got.solver, solver);
                assert!(
                    same_bits(&got.pressure, &want.pressure),
                    "{boundary:?} {solver:?}"
                );
                assert!(same_bits(&got.gap, &want.gap));
                assert_eq!(got.kkt.to_bits(), want.kkt.to_bits());
                assert_eq!(got.iterations, want.iterations);
                assert_eq!(got.contact_points, want.contact_points);
                // Both certify the same minimiser as Polonsky–Keer.
                assert!(got.kkt <= pk::DEFAULT_TOL);
            }
        }
    }

    #[test]
    fn warm_starts_are_the_solvers_own() {
        let (ny, nx) = (12, 10);
        let h = surface(ny, nx);
        let opts = SolveOptions::default();
        let mut cp = problem(&h, ny, nx, Boundary::Free);
        // Polonsky–Keer from the previous pressure, and from a given field.
        let first = cp
            .solve(
                Control::Approach(0.4),
                Solver::PolonskyKeer,
                Start::Cold,
                &opts,
            )
            .unwrap();
        let got = cp
            .solve(
                Control::Approach(0.7),
                Solver::PolonskyKeer,
                Start::Previous,
                &opts,
            )
            .unwrap();
        let want = pk_direct(
            &h,
            ny,
            nx,
            Boundary::Free,
            Control::Approach(0.7),
            Some(&first.pressure),
        );
        assert!(same_bits(&got.pressure, &want.pressure));
        assert_eq!(got.iterations, want.iterations);
        let got = cp
            .solve(
                Control::Approach(0.7),
                Solver::PolonskyKeer,
                Start::Pressure(&first.pressure),
                &opts,
            )
            .unwrap();
        assert!(same_bits(&got.pressure, &want.pressure));
        // The exact solver from the support of a pressure field = from that contact set, and
        // from its own previous set = the direct solver keeping its factor.
        let set: Vec<usize> = (0..ny * nx).filter(|&i| first.pressure[i] > 0.0).collect();
        let mut cp = problem(&h, ny, nx, Boundary::Free);
        let got = cp
            .solve(
                Control::Approach(0.7),
                Solver::ActiveSet,
                Start::Pressure(&first.pressure),
                &opts,
            )
            .unwrap();
        let mut factor = Factor::new(ny * nx, LIMIT);
        let want = lh_direct(
            &h,
            ny,
            nx,
            Boundary::Free,
            0.7,
            true,
            &mut factor,
            lh::Start::Set(&set),
        );
        assert!(same_bits(&got.pressure, &want.pressure));
        assert_eq!(got.iterations, want.iterations);
        let got = cp
            .solve(
                Control::Approach(0.9),
                Solver::ActiveSet,
                Start::Previous,
                &opts,
            )
            .unwrap();
        let want = lh_direct(
            &h,
            ny,
            nx,
            Boundary::Free,
            0.9,
            true,
            &mut factor,
            lh::Start::Previous,
        );
        assert!(same_bits(&got.pressure, &want.pressure));
        assert_eq!(got.iterations, want.iterations);
        let got = cp
            .solve(
                Control::Approach(0.9),
                Solver::ActiveSet,
                Start::ContactSet(&set),
                &opts,
            )
            .unwrap();
        let mut factor = Factor::new(ny * nx, LIMIT);
        let want = lh_direct(
            &h,
            ny,
            nx,
            Boundary::Free,
            0.9,
            true,
            &mut factor,
            lh::Start::Set(&set),
        );
        assert!(same_bits(&got.pressure, &want.pressure));
    }

    #[test]
    fn auto_policy_by_grid_size_and_control() {
        let a = Control::Approach(0.1);
        let m = Control::MeanPressure(0.1);
        assert_eq!(Solver::Auto.resolve(32 * 32, a).unwrap(), Solver::ActiveSet);
        assert_eq!(
            Solver::Auto.resolve(32 * 32 + 1, a).unwrap(),
            Solver::PolonskyKeer
        );
        assert_eq!(Solver::Auto.resolve(16, m).unwrap(), Solver::PolonskyKeer);
        assert!(Solver::ActiveSet.resolve(16, m).is_err());
        assert!(Solver::LawsonHanson.resolve(16, m).is_err());
        assert_eq!(
            Solver::LawsonHanson.resolve(1 << 20, a).unwrap(),
            Solver::LawsonHanson
        );
        // Auto on a small grid runs the active set: the same numbers as asking for it.
        let (ny, nx) = (12, 10);
        let h = surface(ny, nx);
        let opts = SolveOptions::default();
        let auto = problem(&h, ny, nx, Boundary::Free)
            .solve(a, Solver::Auto, Start::Cold, &opts)
            .unwrap();
        let exact = problem(&h, ny, nx, Boundary::Free)
            .solve(a, Solver::ActiveSet, Start::Cold, &opts)
            .unwrap();
        assert_eq!(auto.solver, Solver::ActiveSet);
        assert!(same_bits(&auto.pressure, &exact.pressure));
        for name in ["auto", "polonsky-keer", "active-set", "lawson-hanson"] {
            assert_eq!(Solver::from_name(name).unwrap().name(), name);
        }
        assert!(Solver::from_name("cg").is_err());
    }
}
