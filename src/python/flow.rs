//! Bindings of the leak rate: steady Reynolds flow through the gap (core: flow/).

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::pools::{check_threads, pool_for, run_solve};
use super::{row_major, to_py};
use crate::error::Error;
use crate::flow::{self, Options, Problem};

/// Steady Reynolds flow through the gap; flow along `axis`, inlet at `pressure_drop`,
/// outlet at 0. Returns a dict (see `_core.pyi`).
#[pyfunction]
#[pyo3(signature = (
    gap, dx, contact=None, axis=0, viscosity=1.0, pressure_drop=1.0, periodic=false,
    tol=flow::DEFAULT_TOL, max_iter=None, memory_limit=None, solver="auto", threads=None
))]
#[allow(clippy::too_many_arguments)]
pub(super) fn solve_reynolds_flow<'py>(
    py: Python<'py>,
    gap: PyReadonlyArray2<'py, f64>,
    dx: f64,
    contact: Option<PyReadonlyArray2<'py, bool>>,
    axis: usize,
    viscosity: f64,
    pressure_drop: f64,
    periodic: bool,
    tol: f64,
    max_iter: Option<usize>,
    memory_limit: Option<u64>,
    solver: &str,
    threads: Option<i64>,
) -> PyResult<Bound<'py, PyDict>> {
    let solver = flow::Solver::parse(solver).map_err(to_py)?;
    let pool = pool_for(check_threads(threads)?)?;
    let [ny, nx] = [gap.shape()[0], gap.shape()[1]];
    if let Some(c) = &contact {
        if c.shape() != gap.shape() {
            return Err(to_py(Error::invalid(
                "contact",
                format!(
                    "must have the shape of gap {:?}, got {:?}; pass the contact mask of \
                     this gap",
                    gap.shape(),
                    c.shape()
                ),
            )));
        }
    }
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
            };
            run_solve(&pool, ny * nx, || flow::solve(&problem, &opts))
        })
        .map_err(to_py)?;
    let seconds = start.elapsed().as_secs_f64();
    let d = PyDict::new(py);
    d.set_item(
        "pressure",
        PyArray1::from_vec(py, sol.pressure).reshape([ny, nx])?,
    )?;
    d.set_item(
        "flux_axis0",
        PyArray1::from_vec(py, sol.flux_axis0).reshape([ny + 1, nx])?,
    )?;
    d.set_item(
        "flux_axis1",
        PyArray1::from_vec(py, sol.flux_axis1).reshape([ny, nx + 1])?,
    )?;
    d.set_item("flow_rate", sol.flow_rate)?;
    d.set_item("inlet_flow_rate", sol.inlet_flow_rate)?;
    d.set_item("conductance", sol.conductance)?;
    d.set_item("permeability", sol.permeability)?;
    d.set_item("residual", sol.residual)?;
    d.set_item("conservation", sol.conservation)?;
    d.set_item("iterations", sol.iterations)?;
    d.set_item("n_unknowns", sol.n_unknowns)?;
    d.set_item("levels", sol.levels)?;
    d.set_item("solver", sol.solver)?;
    d.set_item("seconds", seconds)?;
    Ok(d)
}
