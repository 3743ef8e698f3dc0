//! Bindings of contact: a surface on an elastic half-space (kernel table, FFT operator and the
//! Lawson–Hanson factor kept across solves so a sweep can warm-start) and its single `solve`
//! (core: contact/, elastic/).

use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use super::pools::{check_threads, pool_for, run_solve};
use super::{check_positive, to_py};
use crate::alloc;
use crate::contact::{
    CoarseCost, ContactProblem as Problem, Control, Options, Solution, Solver, Start,
};
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

/// What the coarse levels of a cold Polonsky–Keer start cost (core: `contact::CoarseCost`).
#[pyclass(frozen, name = "CoarseCost", module = "leakpath._core")]
pub(super) struct PyCoarseCost {
    #[pyo3(get)]
    levels: usize,
    #[pyo3(get)]
    iterations: usize,
    #[pyo3(get)]
    fft_products: usize,
    #[pyo3(get)]
    preconditioner_products: usize,
    #[pyo3(get)]
    fft_products_fine_equivalent: f64,
    #[pyo3(get)]
    preconditioner_products_fine_equivalent: f64,
}

impl From<CoarseCost> for PyCoarseCost {
    fn from(c: CoarseCost) -> Self {
        PyCoarseCost {
            levels: c.levels,
            iterations: c.iterations,
            fft_products: c.fft_products,
            preconditioner_products: c.preconditioner_products,
            fft_products_fine_equivalent: c.fft_products_fine_equivalent,
            preconditioner_products_fine_equivalent: c.preconditioner_products_fine_equivalent,
        }
    }
}

/// A solved contact state as the core returns it (core: `contact::Solution`), its fields
/// under the core's names; the grids are `(ny, nx)` numpy arrays.
#[pyclass(frozen, name = "ContactSolution", module = "leakpath._core")]
pub(super) struct PySolution {
    #[pyo3(get)]
    solver: &'static str,
    #[pyo3(get)]
    pressure: Py<PyArray2<f64>>,
    #[pyo3(get)]
    displacement: Py<PyArray2<f64>>,
    #[pyo3(get)]
    gap: Py<PyArray2<f64>>,
    #[pyo3(get)]
    approach: f64,
    #[pyo3(get)]
    iterations: usize,
    #[pyo3(get)]
    fft_products: usize,
    #[pyo3(get)]
    single_products: usize,
    #[pyo3(get)]
    preconditioner_products: usize,
    #[pyo3(get)]
    chord_steps: usize,
    #[pyo3(get)]
    kkt: f64,
    #[pyo3(get)]
    contact_points: usize,
    #[pyo3(get)]
    plastic_points: usize,
    #[pyo3(get)]
    load: f64,
    #[pyo3(get)]
    mean_pressure: f64,
    #[pyo3(get)]
    coarse: Py<PyCoarseCost>,
    /// Wall time of the solve [s].
    #[pyo3(get)]
    seconds: f64,
}

impl PySolution {
    fn new(py: Python<'_>, s: Solution, ny: usize, nx: usize, seconds: f64) -> PyResult<Self> {
        Ok(PySolution {
            solver: s.solver.name(),
            pressure: field(py, s.pressure, ny, nx)?.unbind(),
            displacement: field(py, s.displacement, ny, nx)?.unbind(),
            gap: field(py, s.gap, ny, nx)?.unbind(),
            approach: s.approach,
            iterations: s.iterations,
            fft_products: s.fft_products,
            single_products: s.single_products,
            preconditioner_products: s.preconditioner_products,
            chord_steps: s.chord_steps,
            kkt: s.kkt,
            contact_points: s.contact_points,
            plastic_points: s.plastic_points,
            load: s.load,
            mean_pressure: s.mean_pressure,
            coarse: Py::new(py, PyCoarseCost::from(s.coarse))?,
            seconds,
        })
    }
}

#[pymethods]
impl PySolution {
    fn __repr__(&self) -> String {
        format!(
            "ContactSolution(solver={:?}, approach={:.6e}, contact_points={}, iterations={}, \
             kkt={:.1e}, seconds={:.3})",
            self.solver,
            self.approach,
            self.contact_points,
            self.iterations,
            self.kkt,
            self.seconds
        )
    }
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
    /// Kernel, operator, heights, factor and last pressure (core: contact/solve.rs).
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

    /// Solve at `approach` or at `mean_pressure` (exactly one) with `solver` ("auto",
    /// "polonsky-keer", "active-set", "lawson-hanson"). `start`: "cold" (p = 0), "previous"
    /// (this problem's last solve), "pressure" with `initial_pressure` or "set" with
    /// `contact_set` (flat indices). `precondition`, `coarse_start`, `chord_steps`, `rescaled_steps` tune
    /// Polonsky–Keer (see `contact::Options`), as does `single_precision_above` (the
    /// certificate above which all its FFT products are made in f32, below which only the
    /// increments `C t`, `C d`; 0: f64 throughout); the
    /// answer is the same minimiser. `hardness`:
    /// cap the pressure at `p ≤ H` (`contact::capped`; `None` or `inf`: elastic).
    #[pyo3(signature = (
        approach=None, mean_pressure=None, solver="auto", start="cold",
        initial_pressure=None, contact_set=None, tol=1e-12, max_iter=None, threads=None,
        precondition=true, coarse_start=true, chord_steps=true, rescaled_steps=true, hardness=None,
        single_precision_above=crate::contact::problem::DEFAULT_SINGLE_PRECISION_ABOVE
    ))]
    #[allow(clippy::too_many_arguments)]
    fn solve(
        &mut self,
        py: Python<'_>,
        approach: Option<f64>,
        mean_pressure: Option<f64>,
        solver: &str,
        start: &str,
        initial_pressure: Option<PyReadonlyArray2<'_, f64>>,
        contact_set: Option<PyReadonlyArray1<'_, i64>>,
        tol: f64,
        max_iter: Option<usize>,
        threads: Option<i64>,
        precondition: bool,
        coarse_start: bool,
        chord_steps: bool,
        rescaled_steps: bool,
        hardness: Option<f64>,
        single_precision_above: f64,
    ) -> PyResult<PySolution> {
        let pool = pool_for(check_threads(threads)?)?;
        if single_precision_above.is_nan() || single_precision_above < 0.0 {
            return Err(to_py(Error::invalid(
                "single_precision_above",
                format!(
                    "{single_precision_above} must be a certificate level ≥ 0 (0: f64 throughout)"
                ),
            )));
        }
        if let Some(h) = hardness {
            crate::contact::polonsky_keer::check_hardness(h).map_err(to_py)?;
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
            let opts = Options {
                tol,
                max_iter,
                should_stop: Some(&should_stop),
                precondition,
                coarse_start,
                chord_steps,
                rescaled_steps,
                hardness,
                single_precision_above,
                ..Options::default()
            };
            let result = run_solve(&pool, n, || work.solve(control, solver, start, &opts));
            (result, work)
        })?;
        self.inner.attach(work);
        let sol = result.map_err(to_py)?;
        let seconds = t0.elapsed().as_secs_f64();
        PySolution::new(py, sol, ny, nx, seconds)
    }
}
