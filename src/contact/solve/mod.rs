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
mod tests;
