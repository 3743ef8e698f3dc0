//! PyO3 bindings: numpy in, numpy out, the GIL released around long work, every core error
//! mapped to a Python exception. No numerics live here.

use numpy::{PyArray2, PyArrayMethods};
use pyo3::exceptions::{PyKeyboardInterrupt, PyMemoryError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;

use crate::error::Error;
use crate::influence;

pub(crate) fn to_py(err: Error) -> PyErr {
    match err {
        Error::InvalidArgument { .. } => PyValueError::new_err(err.to_string()),
        Error::TooLarge { .. } => PyMemoryError::new_err(err.to_string()),
        Error::NotConverged { .. } => PyRuntimeError::new_err(err.to_string()),
        Error::Interrupted => PyKeyboardInterrupt::new_err("interrupted"),
    }
}

fn check_positive(name: &'static str, v: f64) -> PyResult<()> {
    if !(v.is_finite() && v > 0.0) {
        return Err(to_py(Error::invalid(
            name,
            format!("must be a positive finite number, got {v}"),
        )));
    }
    Ok(())
}

/// Love kernel table K[|di|, |dj|] (shape (ny, nx)) for element size dx and contact modulus E*.
#[pyfunction]
#[pyo3(signature = (ny, nx, dx, e_star))]
fn kernel_table<'py>(
    py: Python<'py>,
    ny: usize,
    nx: usize,
    dx: f64,
    e_star: f64,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    if ny == 0 || nx == 0 {
        return Err(to_py(Error::invalid("shape", "ny and nx must be at least 1")));
    }
    check_positive("dx", dx)?;
    check_positive("e_star", e_star)?;
    let table = py.detach(|| influence::kernel_table(ny, nx, dx, e_star));
    let arr = numpy::PyArray1::from_vec(py, table);
    arr.reshape([ny, nx])
}

#[pymodule]
#[pyo3(name = "_core")]
fn core_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(kernel_table, m)?)?;
    Ok(())
}
