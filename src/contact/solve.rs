//! One contact problem, one entry point: a rough surface on an elastic half-space that owns its
//! kernel, FFT operator and (for the exact solvers) dense Cholesky factor, solved by
//! [`ContactProblem::solve`] with any solver, any control and any start.
//!
//! The solve dispatches to the solvers of this folder unchanged (Polonsky–Keer with the kept
//! operator; Lawson–Hanson / block active set with the kept factor), so its numbers are the
//! solvers' own, bit for bit.

use std::sync::Arc;

use crate::alloc;
use crate::contact::capped;
use crate::contact::factor::Factor;
use crate::contact::lawson_hanson::{self as lh, LawsonHanson, Pivoting};
use crate::contact::polonsky_keer as pk;
use crate::contact::problem::{Control, Options, Problem, Solution, Solver, Start};
use crate::elastic::kernel::Kernel;
use crate::elastic::memory;
use crate::elastic::operator::Operator;
use crate::error::{Error, Result};
use crate::grid::{check_shape, Boundary};

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
        opts: &Options<'_>,
    ) -> Result<Solution> {
        let (ny, nx) = (self.op.ny, self.op.nx);
        let n = ny * nx;
        let solver = solver.resolve(n, control, opts.hardness)?;
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
        opts: &Options<'_>,
    ) -> Result<Solution> {
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
        let problem = Problem {
            heights: &self.h,
            ny,
            nx,
            dx: self.dx,
            e_star: self.e_star,
            boundary,
        };
        let pk_opts = Options {
            memory_limit: Some(self.memory_limit),
            ..*opts
        };
        if pk_opts.hardness.is_some_and(f64::is_finite) {
            capped::solve_with_kernel(
                &self.op,
                Some(&self.kernel.table),
                &problem,
                control,
                &pk_opts,
                initial_pressure,
            )
        } else {
            pk::solve_with_kernel(
                &self.op,
                Some(&self.kernel.table),
                &problem,
                control,
                &pk_opts,
                initial_pressure,
            )
        }
    }

    fn solve_exact(
        &mut self,
        approach: f64,
        block: bool,
        start: Start<'_>,
        opts: &Options<'_>,
    ) -> Result<Solution> {
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
        result
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
    ) -> Solution {
        let problem = Problem {
            heights: h,
            ny,
            nx,
            dx: 0.5,
            e_star: 2.0,
            boundary,
        };
        let opts = Options {
            memory_limit: Some(LIMIT),
            ..Default::default()
        };
        match boundary {
            // A free solve keeps the Love table it builds its operator from.
            Boundary::Free => pk::solve(&problem, control, &opts, initial_pressure).unwrap(),
            // A ContactProblem hands its periodic kernel table (the product C e_0) to the
            // solver, which otherwise builds it on first use.
            Boundary::Periodic => {
                let (op, column) = periodic_column(ny, nx);
                pk::solve_with_kernel(
                    &op,
                    Some(&column),
                    &problem,
                    control,
                    &opts,
                    initial_pressure,
                )
                .unwrap()
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
    ) -> Solution {
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
            let opts = Options::default();
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
                    (got.iterations, got.fft_products, got.contact_points),
                    (want.iterations, want.fft_products, want.contact_points)
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
        let opts = Options::default();
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
        assert_eq!(
            Solver::Auto.resolve(32 * 32, a, None).unwrap(),
            Solver::ActiveSet
        );
        assert_eq!(
            Solver::Auto.resolve(32 * 32 + 1, a, None).unwrap(),
            Solver::PolonskyKeer
        );
        assert_eq!(
            Solver::Auto.resolve(16, m, None).unwrap(),
            Solver::PolonskyKeer
        );
        assert!(Solver::ActiveSet.resolve(16, m, None).is_err());
        assert!(Solver::LawsonHanson.resolve(16, m, None).is_err());
        assert_eq!(
            Solver::LawsonHanson.resolve(1 << 20, a, None).unwrap(),
            Solver::LawsonHanson
        );
        // Auto on a small grid runs the active set: the same numbers as asking for it.
        let (ny, nx) = (12, 10);
        let h = surface(ny, nx);
        let opts = Options::default();
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
