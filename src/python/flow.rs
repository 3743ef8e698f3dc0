//! Bindings of the leak rate: steady Reynolds flow through the gap (core: flow/).

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use super::clusters::{Axis, Labelling};
use super::pools::{check_threads, pool_for, run_solve};
use super::{check_contact_shape, row_major, to_py};
use crate::clusters::Flow;
use crate::flow::kept::{KeptAnalysis, DEFAULT_MIN_CELLS};
use crate::flow::{self, Options, Problem};

/// The factor's ordering and symbolic analysis kept from one flow to the next
/// (`_core.pyi`; core: `flow::kept`).
#[pyclass(frozen, module = "leakpath._core", name = "FlowAnalysis")]
pub(super) struct FlowAnalysis {
    inner: KeptAnalysis,
}

#[pymethods]
impl FlowAnalysis {
    #[new]
    #[pyo3(signature = (min_cells=DEFAULT_MIN_CELLS))]
    fn new(min_cells: usize) -> Self {
        FlowAnalysis {
            inner: KeptAnalysis::new(min_cells),
        }
    }

    /// Flows that made a new analysis.
    #[getter]
    fn analyses(&self) -> usize {
        self.inner.made()
    }

    /// Flows that factored on the kept analysis.
    #[getter]
    fn reuses(&self) -> usize {
        self.inner.reused()
    }

    /// Unknowns of the kept analysis (0 without one).
    #[getter]
    fn unknowns(&self) -> usize {
        self.inner.unknowns()
    }

    /// Entries of a factor on the kept analysis (0 without one).
    #[getter]
    fn entries(&self) -> usize {
        self.inner.entries()
    }

    /// Drops the kept analysis.
    fn clear(&self) {
        self.inner.clear()
    }

    fn __repr__(&self) -> String {
        format!(
            "FlowAnalysis(unknowns={}, analyses={}, reuses={})",
            self.inner.unknowns(),
            self.inner.made(),
            self.inner.reused()
        )
    }
}

/// The flow through a gap (`_core.pyi`): fields as numpy arrays, integrals as floats.
#[pyclass(frozen, module = "leakpath._core", name = "FlowSolution")]
pub(super) struct FlowSolution {
    #[pyo3(get)]
    pressure: Py<PyArray2<f64>>,
    #[pyo3(get)]
    flux_axis0: Py<PyArray2<f64>>,
    #[pyo3(get)]
    flux_axis1: Py<PyArray2<f64>>,
    #[pyo3(get)]
    flow_rate: f64,
    #[pyo3(get)]
    inlet_flow_rate: f64,
    #[pyo3(get)]
    conductance: f64,
    #[pyo3(get)]
    permeability: f64,
    #[pyo3(get)]
    residual: f64,
    #[pyo3(get)]
    conservation: f64,
    #[pyo3(get)]
    iterations: usize,
    #[pyo3(get)]
    n_unknowns: usize,
    #[pyo3(get)]
    levels: usize,
    #[pyo3(get)]
    solver: &'static str,
    #[pyo3(get)]
    seconds: f64,
    /// Whether the solve labelled the open cells itself (false: a given labelling was used).
    #[pyo3(get)]
    labelled: bool,
}

#[pymethods]
impl FlowSolution {
    fn __repr__(&self) -> String {
        format!(
            "FlowSolution(flow_rate={:e}, permeability={:e}, solver={:?}, n_unknowns={})",
            self.flow_rate, self.permeability, self.solver, self.n_unknowns
        )
    }
}

/// Steady Reynolds flow through the gap; flow along `axis` (0 or 1), inlet at
/// `pressure_drop`, outlet at 0. `labels`: a [`Labelling`] of this gap's open cells made
/// with 4-connectivity and the flow's wrap, reused instead of labelling again. Returns a
/// [`FlowSolution`].
#[pyfunction]
#[pyo3(signature = (
    gap, dx, contact=None, axis=Axis(Flow::Axis0), viscosity=1.0, pressure_drop=1.0,
    periodic=false, tol=flow::DEFAULT_TOL, max_iter=None, memory_limit=None, solver="auto",
    threads=None, labels=None, analysis=None
))]
#[allow(clippy::too_many_arguments)]
pub(super) fn solve_reynolds_flow<'py>(
    py: Python<'py>,
    gap: PyReadonlyArray2<'py, f64>,
    dx: f64,
    contact: Option<PyReadonlyArray2<'py, bool>>,
    axis: Axis,
    viscosity: f64,
    pressure_drop: f64,
    periodic: bool,
    tol: f64,
    max_iter: Option<usize>,
    memory_limit: Option<u64>,
    solver: &str,
    threads: Option<i64>,
    labels: Option<PyRef<'py, Labelling>>,
    analysis: Option<PyRef<'py, FlowAnalysis>>,
) -> PyResult<FlowSolution> {
    let axis = match axis.0 {
        Flow::Axis0 => 0,
        Flow::Axis1 => 1,
        Flow::Either | Flow::Both => {
            return Err(PyValueError::new_err(
                "axis: the leak flows along one axis, 0 or 1",
            ))
        }
    };
    crate::flow::cg::mark("");
    let solver = flow::Solver::parse(solver).map_err(to_py)?;
    let pool = pool_for(check_threads(threads)?)?;
    let [ny, nx] = [gap.shape()[0], gap.shape()[1]];
    check_contact_shape(&gap, contact.as_ref())?;
    let g = row_major(&gap);
    let g: &[f64] = &g;
    let c = contact.as_ref().map(row_major);
    let c: Option<&[bool]> = c.as_deref();
    let problem = Problem {
        gap: g,
        contact: c,
        ny,
        nx,
        dx,
        axis,
        viscosity,
        pressure_drop,
        periodic,
    };
    if let Some(l) = &labels {
        if !l.for_flow(axis, periodic) {
            return Err(PyValueError::new_err(
                "labels: the flow needs a labelling with connectivity 4, no wrap along the \
                 flow axis and wrap across it exactly when periodic",
            ));
        }
        if l.labels(py).shape() != gap.shape() {
            return Err(PyValueError::new_err(format!(
                "labels: must have the gap's shape {:?}, got {:?}",
                gap.shape(),
                l.labels(py).shape()
            )));
        }
    }
    let lab = labels.as_ref().map(|l| l.labels(py).readonly());
    let lab_slice = match &lab {
        Some(a) => Some((a.as_slice()?, labels.as_ref().map_or(0, |l| l.n_clusters()))),
        None => None,
    };
    let kept: Option<&KeptAnalysis> = analysis.as_deref().map(|a| &a.inner);
    let start = std::time::Instant::now();
    let sol = py
        .detach(|| {
            let stop = || Python::attach(|py| py.check_signals().is_err());
            let opts = Options {
                solver,
                tol,
                max_iter,
                memory_limit,
                should_stop: Some(&stop),
                analysis: kept,
                ..Options::default()
            };
            run_solve(&pool, ny * nx, || {
                flow::solve_labelled(&problem, &opts, lab_slice)
            })
        })
        .map_err(to_py)?;
    let seconds = start.elapsed().as_secs_f64();
    crate::flow::cg::mark("wrapped in Python");
    Ok(FlowSolution {
        pressure: PyArray1::from_vec(py, sol.pressure)
            .reshape([ny, nx])?
            .unbind(),
        flux_axis0: PyArray1::from_vec(py, sol.flux_axis0)
            .reshape([ny + 1, nx])?
            .unbind(),
        flux_axis1: PyArray1::from_vec(py, sol.flux_axis1)
            .reshape([ny, nx + 1])?
            .unbind(),
        flow_rate: sol.flow_rate,
        inlet_flow_rate: sol.inlet_flow_rate,
        conductance: sol.conductance,
        permeability: sol.permeability,
        residual: sol.residual,
        conservation: sol.conservation,
        iterations: sol.iterations,
        n_unknowns: sol.n_unknowns,
        levels: sol.levels,
        solver: sol.solver,
        seconds,
        labelled: lab_slice.is_none(),
    })
}

/// `(min, max)` of `gap` over the cells off `contact` (every cell without a mask);
/// `(inf, -inf)` when none is free (core: `flow::free_gap_extremes`).
#[pyfunction]
#[pyo3(signature = (gap, contact=None))]
pub(super) fn free_gap_extremes<'py>(
    py: Python<'py>,
    gap: PyReadonlyArray2<'py, f64>,
    contact: Option<PyReadonlyArray2<'py, bool>>,
) -> PyResult<(f64, f64)> {
    check_contact_shape(&gap, contact.as_ref())?;
    let g = row_major(&gap);
    let c = contact.as_ref().map(row_major);
    let (g, c): (&[f64], Option<&[bool]>) = (&g, c.as_deref());
    Ok(py.detach(|| flow::free_gap_extremes(g, c)))
}
