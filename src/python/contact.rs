//! Bindings of contact: a surface on an elastic half-space (kernel table, FFT operator and the
//! Lawson–Hanson factor kept across solves so a sweep can warm-start) and its single `solve`
//! (core: contact/, elastic/).

use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::pools::{check_threads, pool_for, run_solve};
use super::{check_positive, to_py};
use crate::alloc;
use crate::contact::multilevel::CoarseCost;
use crate::contact::{ContactProblem as Problem, Control, SolveOptions, Solver, Start};
use crate::error::Error;
use crate::grid::Boundary;

fn field<'py>(
    py: Python<'py>,
    v: Vec<f64>,
    ny: usize,
    nx: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    PyArray1::from_vec(py, v).reshape([ny, nx])
}

/// The coarse-to-fine start's cost as `coarse_*` entries of a result dict.
pub(super) fn set_coarse(d: &Bound<'_, PyDict>, c: &CoarseCost) -> PyResult<()> {
    d.set_item("coarse_levels", c.levels)?;
    d.set_item("coarse_iterations", c.iterations)?;
    d.set_item("coarse_applies", c.applies)?;
    d.set_item("coarse_preconditioner_applies", c.preconditioner_applies)?;
    d.set_item("coarse_applies_fine_equivalent", c.applies_fine_equivalent)?;
    d.set_item(
        "coarse_preconditioner_fine_equivalent",
        c.preconditioner_fine_equivalent,
    )
}

pub(super) fn boundary_from(name: &str) -> PyResult<Boundary> {
    match name {
        "free" => Ok(Boundary::Free),
        "periodic" => Ok(Boundary::Periodic),
        other => Err(to_py(Error::invalid(
            "boundary",
            format!("must be 'free' or 'periodic', got {other:?}"),
        ))),
    }
}

pub(super) fn heights_vec(h: &PyReadonlyArray2<'_, f64>) -> PyResult<(Vec<f64>, usize, usize)> {
    let a = h.as_array();
    let (ny, nx) = a.dim();
    if ny == 0 || nx == 0 {
        return Err(to_py(Error::invalid(
            "heights",
            "must have at least one point",
        )));
    }
    let mut v: Vec<f64> =
        alloc::try_with_capacity(ny * nx, "a copy of the heights").map_err(to_py)?;
    v.extend(a.iter().copied());
    if v.iter().any(|x| !x.is_finite()) {
        return Err(to_py(Error::invalid(
            "heights",
            "contains NaN or infinite values",
        )));
    }
    Ok((v, ny, nx))
}

/// An elastic rough surface against a rigid flat, ready to be solved at many approaches.
#[pyclass(name = "ContactProblem", module = "leakpath._core")]
pub(super) struct ContactProblem {
    /// Kernel, operator, heights, factor and last pressure (core: contact/problem.rs).
    pub(super) inner: Problem,
}

#[pymethods]
impl ContactProblem {
    #[new]
    #[pyo3(signature = (heights, dx, e_star, boundary="free", memory_limit=None))]
    fn new(
        py: Python<'_>,
        heights: PyReadonlyArray2<'_, f64>,
        dx: f64,
        e_star: f64,
        boundary: &str,
        memory_limit: Option<u64>,
    ) -> PyResult<Self> {
        check_positive("dx", dx)?;
        check_positive("e_star", e_star)?;
        let bc = boundary_from(boundary)?;
        let memory_limit = match memory_limit {
            Some(l) => l,
            None => super::default_memory_limit(py)?,
        };
        let [ny, nx] = [heights.shape()[0], heights.shape()[1]];
        // Refuse before copying anything.
        Problem::check_memory(ny, nx, bc, memory_limit).map_err(to_py)?;
        let (h, ny, nx) = heights_vec(&heights)?;
        // Building the kernel and the operator of a large grid takes seconds and cannot
        // stop half-way: the owned variant lets Ctrl-C return at once.
        let built = super::interruptible_owned(py, move |_| {
            Problem::try_new(h, ny, nx, dx, e_star, bc, memory_limit)
        })?;
        Ok(ContactProblem {
            inner: built.map_err(to_py)?,
        })
    }

    /// Number of points in the passive (contact) set kept from the last solve.
    #[getter]
    fn n_passive(&self) -> usize {
        self.inner.n_passive()
    }

    /// u = C p by FFT (shape (ny, nx)).
    fn apply<'py>(
        &self,
        py: Python<'py>,
        pressure: PyReadonlyArray2<'_, f64>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let op = self.inner.operator();
        let a = pressure.as_array();
        if a.dim() != (op.ny, op.nx) {
            return Err(to_py(Error::invalid(
                "pressure",
                "shape differs from the surface",
            )));
        }
        let p: Vec<f64> = a.iter().copied().collect();
        let mut u = vec![0.0; p.len()];
        py.detach(|| op.apply(&p, &mut u));
        field(py, u, op.ny, op.nx)
    }

    /// The dense block C_PP (k × k) for flat indices (Love or periodic coefficients).
    fn block<'py>(
        &self,
        py: Python<'py>,
        indices: PyReadonlyArray1<'_, i64>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let n = (self.inner.ny() * self.inner.nx()) as i64;
        let idx: Vec<usize> = indices
            .as_array()
            .iter()
            .map(|&i| {
                if (0..n).contains(&i) {
                    Ok(i as usize)
                } else {
                    Err(to_py(Error::invalid(
                        "indices",
                        format!("{i} is outside the grid"),
                    )))
                }
            })
            .collect::<PyResult<_>>()?;
        let k = idx.len();
        let kernel = self.inner.kernel();
        let b = py.detach(|| kernel.block(&idx)).map_err(to_py)?;
        // Column-major and symmetric: the same numbers read row-major.
        PyArray1::from_vec(py, b).reshape([k, k])
    }

    /// The solver that `solver` runs on this grid under the given control (the `auto`
    /// policy).
    #[pyo3(signature = (solver="auto", load_control=false, hardness=None))]
    fn resolve_solver(
        &self,
        solver: &str,
        load_control: bool,
        hardness: Option<f64>,
    ) -> PyResult<&'static str> {
        if let Some(h) = hardness {
            crate::contact::capped::check_hardness(h).map_err(to_py)?;
            if h.is_finite() {
                return match Solver::from_name(solver).map_err(to_py)? {
                    Solver::Auto | Solver::PolonskyKeer => Ok(Solver::PolonskyKeer.name()),
                    other => Err(to_py(Error::invalid(
                        "solver",
                        format!(
                            "{:?} cannot cap the pressure at a hardness; use solver='auto' or \
                             'polonsky-keer' with hardness=",
                            other.name()
                        ),
                    ))),
                };
            }
        }
        let control = if load_control {
            Control::MeanPressure(1.0)
        } else {
            Control::Approach(0.0)
        };
        let n = self.inner.ny() * self.inner.nx();
        Ok(Solver::from_name(solver)
            .and_then(|s| s.resolve(n, control))
            .map_err(to_py)?
            .name())
    }

    /// Solve at `approach` or at `mean_pressure` (exactly one) with `solver` ("auto",
    /// "polonsky-keer", "active-set", "lawson-hanson"). `start`: "cold" (p = 0), "previous"
    /// (this problem's last solve), "pressure" with `initial_pressure` or "set" with
    /// `contact_set` (flat indices).
    #[pyo3(signature = (
        approach=None, mean_pressure=None, solver="auto", start="cold",
        initial_pressure=None, contact_set=None, tol=1e-12, max_iter=None, threads=None,
        hardness=None
    ))]
    #[allow(clippy::too_many_arguments)]
    fn solve<'py>(
        &mut self,
        py: Python<'py>,
        approach: Option<f64>,
        mean_pressure: Option<f64>,
        solver: &str,
        start: &str,
        initial_pressure: Option<PyReadonlyArray2<'_, f64>>,
        contact_set: Option<PyReadonlyArray1<'_, i64>>,
        tol: f64,
        max_iter: Option<usize>,
        threads: Option<i64>,
        hardness: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let pool = pool_for(check_threads(threads)?)?;
        if let Some(h) = hardness {
            crate::contact::capped::check_hardness(h).map_err(to_py)?;
        }
        let control = match (approach, mean_pressure) {
            (Some(d), None) => Control::Approach(d),
            (None, Some(m)) => Control::MeanPressure(m),
            _ => {
                return Err(to_py(Error::invalid(
                    "approach",
                    "give exactly one of approach= (displacement control) and \
                     mean_pressure= (load control)",
                )))
            }
        };
        let solver = Solver::from_name(solver).map_err(to_py)?;
        check_positive("tol", tol)?;
        let (ny, nx) = (self.inner.ny(), self.inner.nx());
        let n = ny * nx;
        enum Owned {
            Cold,
            Previous,
            Pressure(Vec<f64>),
            Set(Vec<usize>),
        }
        let owned = match (start, initial_pressure, contact_set) {
            ("cold", _, _) => Owned::Cold,
            ("previous", _, _) => Owned::Previous,
            ("pressure", Some(p), _) => {
                if p.shape() != [ny, nx] {
                    return Err(to_py(Error::invalid(
                        "initial_pressure",
                        format!("must have the shape of the heights ({ny}, {nx})"),
                    )));
                }
                let src = super::row_major(&p);
                let mut v =
                    alloc::try_with_capacity(n, "a copy of the initial pressure").map_err(to_py)?;
                v.extend_from_slice(&src);
                Owned::Pressure(v)
            }
            ("set", _, Some(s)) => Owned::Set(
                s.as_array()
                    .iter()
                    .map(|&i| {
                        if (0..n as i64).contains(&i) {
                            Ok(i as usize)
                        } else {
                            Err(to_py(Error::invalid(
                                "warm_start",
                                "contact set index outside the grid",
                            )))
                        }
                    })
                    .collect::<PyResult<_>>()?,
            ),
            ("pressure", None, _) => {
                return Err(to_py(Error::invalid(
                    "warm_start",
                    "start='pressure' needs initial_pressure",
                )))
            }
            ("set", _, None) => {
                return Err(to_py(Error::invalid(
                    "warm_start",
                    "start='set' needs contact_set",
                )))
            }
            (other, _, _) => {
                return Err(to_py(Error::invalid(
                    "start",
                    format!("must be 'cold', 'previous', 'pressure' or 'set', got {other:?}"),
                )))
            }
        };
        let t0 = std::time::Instant::now();
        let mut work = self.inner.detach();
        let (result, work) = super::interruptible_owned(py, move |stop| {
            let should_stop = super::stop_flag(stop);
            let start = match &owned {
                Owned::Cold => Start::Cold,
                Owned::Previous => Start::Previous,
                Owned::Pressure(p) => Start::Pressure(p),
                Owned::Set(s) => Start::ContactSet(s),
            };
            let opts = SolveOptions {
                tol,
                max_iter,
                should_stop: Some(&should_stop),
                hardness,
            };
            let result = run_solve(&pool, n, || work.solve(control, solver, start, &opts));
            (result, work)
        })?;
        self.inner.attach(work);
        let sol = result.map_err(to_py)?;
        let seconds = t0.elapsed().as_secs_f64();
        let d = PyDict::new(py);
        d.set_item("solver", sol.solver.name())?;
        d.set_item("pressure", field(py, sol.pressure, ny, nx)?)?;
        d.set_item("displacement", field(py, sol.displacement, ny, nx)?)?;
        d.set_item("gap", field(py, sol.gap, ny, nx)?)?;
        d.set_item("approach", sol.approach)?;
        d.set_item("iterations", sol.iterations)?;
        d.set_item("applies", sol.applies)?;
        d.set_item("preconditioner_applies", sol.preconditioner_applies)?;
        set_coarse(&d, &sol.coarse)?;
        d.set_item("kkt", sol.kkt)?;
        d.set_item("contact_points", sol.contact_points)?;
        d.set_item("plastic_points", sol.plastic_points)?;
        d.set_item("seconds", seconds)?;
        Ok(d)
    }
}

/// Polonsky–Keer constrained conjugate gradients on the FFT operator (core: contact/polonsky_keer.rs); a stand-alone call on heights.
pub(crate) mod pk_py {
    use std::time::Instant;

    use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
    use pyo3::prelude::*;
    use pyo3::types::PyDict;

    use crate::alloc;
    use crate::contact::polonsky_keer::{self as pk, Control, Options, Problem};
    use crate::elastic::memory;
    use crate::error::Error;
    use crate::grid::Boundary;
    use crate::python::{row_major, to_py};

    fn invalid(name: &'static str, msg: String) -> PyErr {
        to_py(Error::invalid(name, msg))
    }

    /// Frictionless normal contact of an elastic rough surface against a rigid flat by
    /// Polonsky–Keer conjugate gradients. Exactly one of `approach` / `mean_pressure`.
    /// Returns a dict: pressure, displacement, gap (2-D), approach, iterations, applies, kkt,
    /// load, mean_pressure, contact_points, seconds.
    #[pyfunction]
    #[pyo3(signature = (
        heights, dx, e_star, boundary="free", approach=None, mean_pressure=None, tol=None,
        max_iter=None, initial_pressure=None, memory_limit=None, precondition=true,
        operator_of=None, coarse_start=true, chord_steps=true, hardness=None
    ))]
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn solve_polonsky_keer<'py>(
        py: Python<'py>,
        heights: PyReadonlyArray2<'py, f64>,
        dx: f64,
        e_star: f64,
        boundary: &str,
        approach: Option<f64>,
        mean_pressure: Option<f64>,
        tol: Option<f64>,
        max_iter: Option<usize>,
        initial_pressure: Option<PyReadonlyArray2<'py, f64>>,
        memory_limit: Option<u64>,
        precondition: bool,
        operator_of: Option<PyRef<'py, super::ContactProblem>>,
        coarse_start: bool,
        chord_steps: bool,
        hardness: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let op = operator_of.as_ref().map(|cp| {
            (
                std::sync::Arc::clone(cp.inner.operator()),
                std::sync::Arc::clone(cp.inner.shared_kernel()),
            )
        });
        let [ny, nx] = [heights.shape()[0], heights.shape()[1]];
        let control = match (approach, mean_pressure) {
            (Some(d), None) => Control::Approach(d),
            (None, Some(m)) => Control::MeanPressure(m),
            _ => {
                return Err(invalid(
                    "approach",
                    "give exactly one of approach= (displacement control) and mean_pressure= \
                     (load control)"
                        .into(),
                ))
            }
        };
        let boundary = match boundary {
            "free" => Boundary::Free,
            "periodic" => Boundary::Periodic,
            other => {
                return Err(invalid(
                    "boundary",
                    format!("must be 'free' or 'periodic', got {other:?}"),
                ))
            }
        };
        if let Some(p0) = &initial_pressure {
            let s = p0.shape();
            if s != [ny, nx] {
                return Err(invalid(
                    "initial_pressure",
                    format!(
                        "must have the shape of the heights ({ny}, {nx}), got ({}, {})",
                        s[0], s[1]
                    ),
                ));
            }
        }
        let tol = tol.unwrap_or(pk::DEFAULT_TOL);
        let memory_limit = match memory_limit {
            Some(l) => l,
            None => crate::python::default_memory_limit(py)?,
        };
        // Refuse before copying anything (the estimate includes the copy of the heights).
        let need = memory::polonsky_keer(ny, nx, boundary);
        if need > memory_limit {
            let kind = match boundary {
                Boundary::Free => "free",
                Boundary::Periodic => "periodic",
            };
            return Err(to_py(Error::TooLarge {
                bytes: need,
                limit: memory_limit,
                what: format!("Polonsky–Keer on a {ny} × {nx} {kind} grid"),
            }));
        }
        // The solve owns its inputs, so that Ctrl-C can return while the operator of a large
        // grid is still being built (see `interruptible_owned`).
        let owned = |a: &PyReadonlyArray2<'_, f64>, what: &str| -> PyResult<Vec<f64>> {
            let src = row_major(a);
            let mut v = alloc::try_with_capacity(src.len(), what).map_err(to_py)?;
            v.extend_from_slice(&src);
            Ok(v)
        };
        let h = owned(&heights, "a copy of the heights")?;
        let p0 = match &initial_pressure {
            Some(a) => Some(owned(a, "a copy of the initial pressure")?),
            None => None,
        };
        let start = Instant::now();
        let outcome = crate::python::interruptible_owned(py, move |stop| {
            let problem = Problem {
                heights: &h,
                ny,
                nx,
                dx,
                e_star,
                boundary,
            };
            // Ctrl-C: the solver polls this flag between iterations (see `interruptible`).
            let should_stop = crate::python::stop_flag(stop);
            let opts = Options {
                tol,
                max_iter,
                initial_pressure: p0.as_deref(),
                memory_limit: Some(memory_limit),
                should_stop: Some(&should_stop),
                precondition,
                coarse_start,
                chord_steps,
                hardness,
            };
            crate::python::on_solver_pool(ny * nx, || match &op {
                // The operator of a kept ContactProblem: no kernel or FFT set-up per solve.
                // Its kernel table is the influence table of the sparse corrections.
                Some((op, kernel)) => {
                    pk::solve_with_kernel(op, Some(&kernel.table), &problem, control, &opts)
                }
                None => pk::solve(&problem, control, &opts),
            })
        })?;
        let seconds = start.elapsed().as_secs_f64();
        let sol = outcome.map_err(to_py)?;
        let d = PyDict::new(py);
        d.set_item(
            "pressure",
            PyArray1::from_vec(py, sol.pressure).reshape([ny, nx])?,
        )?;
        d.set_item(
            "displacement",
            PyArray1::from_vec(py, sol.displacement).reshape([ny, nx])?,
        )?;
        d.set_item("gap", PyArray1::from_vec(py, sol.gap).reshape([ny, nx])?)?;
        d.set_item("approach", sol.approach)?;
        d.set_item("iterations", sol.iterations)?;
        d.set_item("applies", sol.applies)?;
        d.set_item("preconditioner_applies", sol.preconditioner_applies)?;
        d.set_item("chord_steps", sol.chord_steps)?;
        super::set_coarse(&d, &sol.coarse)?;
        d.set_item("kkt", sol.kkt)?;
        d.set_item("load", sol.load)?;
        d.set_item("mean_pressure", sol.mean_pressure)?;
        d.set_item("contact_points", sol.contact_points)?;
        d.set_item("plastic_points", sol.plastic_points)?;
        d.set_item("seconds", seconds)?;
        Ok(d)
    }
}
