//! Bindings of the elementwise elementary functions (core: elementary.rs).

use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;

use super::to_py;
use crate::elementary::{apply, Elementary};
use crate::error::Error;

/// `function` (`"power"` with `exponent`, `"exp"`, `"log"`, `"log10"`, `"cbrt"`) of every
/// value of a contiguous float64 vector, each by one scalar function whatever the CPU
/// (`crate::elementary`): the same bits on every CPU.
#[pyfunction]
#[pyo3(signature = (values, function, exponent=None))]
pub(super) fn elementary<'py>(
    py: Python<'py>,
    values: PyReadonlyArray1<'py, f64>,
    function: &str,
    exponent: Option<f64>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let f = match (function, exponent) {
        ("power", Some(y)) => Elementary::Power(y),
        ("exp", None) => Elementary::Exp,
        ("log", None) => Elementary::Ln,
        ("log10", None) => Elementary::Log10,
        ("cbrt", None) => Elementary::Cbrt,
        _ => {
            return Err(to_py(Error::invalid(
                "function",
                format!(
                    "must be 'power' with an exponent, or 'exp', 'log', 'log10' or 'cbrt' \
                     without one; got {function:?} with exponent {exponent:?}"
                ),
            )))
        }
    };
    let mut v = values.as_slice()?.to_vec();
    py.detach(|| apply(&mut v, f));
    Ok(PyArray1::from_vec(py, v))
}
