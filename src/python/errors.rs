//! Core errors to Python exceptions: each `Error` becomes its `leakpath.errors` class with its
//! structured fields; a Rust panic becomes a Python `RuntimeError`, never an abort.

use std::any::Any;

use pyo3::exceptions::{PyKeyboardInterrupt, PyRuntimeError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::error::Error;

/// Maps a core error to the matching `leakpath.errors` exception, with its structured fields
/// (`argument`; `estimate`, `limit`, `what`; `solver`, `iterations`, `residual`).
pub(crate) fn to_py(err: Error) -> PyErr {
    if matches!(err, Error::Interrupted) {
        return PyKeyboardInterrupt::new_err("interrupted");
    }
    Python::attach(|py| typed_error(py, &err).unwrap_or_else(|e| e))
}

fn typed_error(py: Python<'_>, err: &Error) -> PyResult<PyErr> {
    let kwargs = PyDict::new(py);
    let class = match err {
        Error::InvalidArgument { name, .. } => {
            kwargs.set_item("argument", *name)?;
            "InvalidArgumentError"
        }
        Error::TooLarge { bytes, limit, what } => {
            kwargs.set_item("estimate", *bytes)?;
            kwargs.set_item("limit", *limit)?;
            kwargs.set_item("what", what.as_str())?;
            "ProblemTooLargeError"
        }
        Error::NotConverged {
            iterations,
            residual,
            what,
        } => {
            kwargs.set_item("solver", what.as_str())?;
            kwargs.set_item("iterations", *iterations)?;
            kwargs.set_item("residual", *residual)?;
            "NotConvergedError"
        }
        Error::Interrupted => return Ok(PyKeyboardInterrupt::new_err("interrupted")),
    };
    let errors = py.import("leakpath.errors")?;
    let value = errors
        .getattr(class)?
        .call((err.to_string(),), Some(&kwargs))?;
    Ok(PyErr::from_value(value))
}

/// The `RuntimeError` for a panic in the core (a bug: no input should cause one).
pub(super) fn internal_error(panic: Box<dyn Any + Send>) -> PyErr {
    let msg = panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_default();
    PyRuntimeError::new_err(format!("internal error in leakpath's core: {msg}"))
}
