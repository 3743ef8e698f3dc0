//! PyO3 bindings: numpy in, numpy out, the GIL released around long work, every core error
//! mapped to a Python exception. No numerics live here.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{sync_channel, RecvTimeoutError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use numpy::{PyArray2, PyArrayMethods};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;

use crate::elastic::kernel as influence;
use crate::error::Error;

mod clusters;
mod contact;
mod elementary;
mod errors;
mod flow;
mod pools;

use errors::internal_error;
pub(crate) use errors::to_py;

/// Grids with fewer cells than this are solved on one thread. Their FFTs and factor updates
/// take tens of microseconds, about what handing a loop to the second thread costs (far more
/// when the cores are busy), so two threads would only slow them down. Results do not depend
/// on the thread count.
const ONE_THREAD_BELOW: usize = 64 * 64;

/// Runs a contact solve of a grid of `cells` cells on a rayon pool thread, so that its many
/// small parallel loops fork from inside the pool instead of each being injected from outside;
/// small grids on a kept one-thread pool (see [`ONE_THREAD_BELOW`]).
fn on_solver_pool<T: Send>(cells: usize, f: impl FnOnce() -> T + Send) -> T {
    static ONE_THREAD: std::sync::OnceLock<Option<rayon::ThreadPool>> = std::sync::OnceLock::new();
    if cells < ONE_THREAD_BELOW {
        let pool = ONE_THREAD.get_or_init(|| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .thread_name(|_| "leakpath-small-solve".into())
                .build()
                .ok()
        });
        if let Some(pool) = pool {
            return pool.install(f);
        }
    }
    rayon::scope(|_| f())
}

/// How often the calling thread runs Python's signal handlers while a worker computes.
const SIGNAL_POLL: Duration = Duration::from_millis(20);

/// Runs `work` on a worker thread with the GIL released, while the calling thread waits in
/// short timed waits and runs Python's signal handlers between them. CPython runs signal
/// handlers on the main thread only, so the work itself (on the worker and rayon's threads)
/// cannot see Ctrl-C; the waiting thread can. When a handler raises (KeyboardInterrupt for
/// Ctrl-C), `stop` is set — the solvers poll it — the worker is joined and the handler's
/// exception is raised. A panic in the work becomes a `RuntimeError`, never a crash.
fn interruptible<T: Send>(
    py: Python<'_>,
    work: impl FnOnce(&AtomicBool) -> T + Send,
) -> PyResult<T> {
    let stop = AtomicBool::new(false);
    let stop = &stop;
    py.detach(move || {
        std::thread::scope(|s| {
            let (done, finished) = sync_channel::<()>(1);
            let worker = std::thread::Builder::new()
                .name("leakpath-work".into())
                .spawn_scoped(s, move || {
                    let out = work(stop);
                    let _ = done.send(());
                    out
                })
                .map_err(|e| PyRuntimeError::new_err(format!("cannot start a thread: {e}")))?;
            let mut raised: Option<PyErr> = None;
            // A disconnected channel means the worker ended without sending: it panicked.
            while let Err(RecvTimeoutError::Timeout) = finished.recv_timeout(SIGNAL_POLL) {
                if raised.is_none() {
                    if let Err(e) = Python::attach(|py| py.check_signals()) {
                        stop.store(true, Ordering::Relaxed);
                        raised = Some(e);
                    }
                }
            }
            let joined = worker.join();
            if let Some(e) = raised {
                return Err(e);
            }
            joined.map_err(internal_error)
        })
    })
}

/// How long an interrupted computation that owns its data may take to notice the stop flag
/// before the caller stops waiting for it.
const STOP_GRACE: Duration = Duration::from_millis(200);

/// [`interruptible`] for work that owns its data: after a signal handler raised, the worker
/// gets [`STOP_GRACE`] to see `stop`; if it is inside one long step (a blocked Cholesky update
/// of a large contact block can take seconds) the caller raises anyway and the worker, left
/// to finish on its own, drops its result at its next poll of `stop`.
fn interruptible_owned<T: Send + 'static>(
    py: Python<'_>,
    work: impl FnOnce(&AtomicBool) -> T + Send + 'static,
) -> PyResult<T> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    let (done, finished) = sync_channel(1);
    let worker = std::thread::Builder::new()
        .name("leakpath-work".into())
        .spawn(move || {
            let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| work(&flag)));
            let _ = done.send(out);
        })
        .map_err(|e| PyRuntimeError::new_err(format!("cannot start a thread: {e}")))?;
    py.detach(move || {
        let mut raised: Option<(PyErr, Instant)> = None;
        loop {
            match finished.recv_timeout(SIGNAL_POLL) {
                Ok(out) => {
                    let _ = worker.join();
                    return match raised {
                        Some((e, _)) => Err(e),
                        None => out.map_err(internal_error),
                    };
                }
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(PyRuntimeError::new_err(
                        "internal error: a worker thread vanished",
                    ))
                }
                Err(RecvTimeoutError::Timeout) => match raised.take() {
                    None => {
                        if let Err(e) = Python::attach(|py| py.check_signals()) {
                            stop.store(true, Ordering::Relaxed);
                            raised = Some((e, Instant::now()));
                        }
                    }
                    // Detach the worker (dropping its handle): it stops at its next poll.
                    Some((e, at)) if at.elapsed() >= STOP_GRACE => return Err(e),
                    kept => raised = kept,
                },
            }
        }
    })
}

/// The solvers' `should_stop`: set by [`interruptible`] when a signal handler raised.
fn stop_flag(stop: &AtomicBool) -> impl Fn() -> bool + Sync + '_ {
    move || stop.load(Ordering::Relaxed)
}

/// The default memory limit in bytes: `leakpath._memory.memory_limit()`, the one definition
/// of what this process may still allocate (cgroup, ulimits, available memory).
fn default_memory_limit(py: Python<'_>) -> PyResult<u64> {
    py.import("leakpath._memory")?
        .call_method0("memory_limit")?
        .extract()
}

/// `contact` (when given) has the shape of `gap`, else `InvalidArgumentError` naming
/// `contact`.
fn check_contact_shape(
    gap: &numpy::PyReadonlyArray2<'_, f64>,
    contact: Option<&numpy::PyReadonlyArray2<'_, bool>>,
) -> PyResult<()> {
    use numpy::PyUntypedArrayMethods;
    match contact {
        Some(c) if c.shape() != gap.shape() => Err(to_py(Error::invalid(
            "contact",
            format!(
                "must have the shape of gap {:?}, got {:?}; pass the contact mask of this gap",
                gap.shape(),
                c.shape()
            ),
        ))),
        _ => Ok(()),
    }
}

/// Row-major values of a 2-D array, copied only when it is not C-contiguous (`as_slice` alone
/// also accepts Fortran-contiguous arrays, whose memory order is column-major).
fn row_major<'a, T: numpy::Element + Copy>(
    a: &'a numpy::PyReadonlyArray2<'_, T>,
) -> std::borrow::Cow<'a, [T]> {
    use numpy::PyUntypedArrayMethods;
    match a.as_slice() {
        Ok(s) if a.is_c_contiguous() => std::borrow::Cow::Borrowed(s),
        _ => std::borrow::Cow::Owned(a.as_array().iter().copied().collect()),
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
/// Refused with `ProblemTooLargeError` when its ny·nx·8 bytes exceed `memory_limit` (default:
/// `leakpath._memory.memory_limit()`).
#[pyfunction]
#[pyo3(signature = (ny, nx, dx, e_star, memory_limit=None))]
fn kernel_table<'py>(
    py: Python<'py>,
    ny: usize,
    nx: usize,
    dx: f64,
    e_star: f64,
    memory_limit: Option<u64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    if ny == 0 || nx == 0 {
        return Err(to_py(Error::invalid(
            "shape",
            "ny and nx must be at least 1",
        )));
    }
    check_positive("dx", dx)?;
    check_positive("e_star", e_star)?;
    let what = format!("the {ny} × {nx} kernel table");
    let cells = crate::alloc::checked_cells(ny, nx, &what).map_err(to_py)?;
    let bytes = crate::alloc::bytes_of::<f64>(cells, &what).map_err(to_py)?;
    let limit = match memory_limit {
        Some(l) => l,
        None => default_memory_limit(py)?,
    };
    if bytes > limit {
        return Err(to_py(Error::TooLarge { bytes, limit, what }));
    }
    let table = interruptible_owned(py, move |_| influence::try_kernel_table(ny, nx, dx, e_star))?
        .map_err(to_py)?;
    let arr = numpy::PyArray1::from_vec(py, table);
    arr.reshape([ny, nx])
}

/// Threads of the pool the solvers run on (rayon's global pool: all cores, or
/// `RAYON_NUM_THREADS`).
#[pyfunction]
fn solver_threads() -> usize {
    rayon::current_num_threads()
}

/// Bytes of the packing scratch faer's dense products allocate once per thread on this CPU.
#[pyfunction]
fn dense_scratch_bytes() -> u64 {
    crate::dense_scratch::bytes_per_thread()
}

#[pymodule]
#[pyo3(name = "_core")]
fn core_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(kernel_table, m)?)?;
    m.add_function(wrap_pyfunction!(elementary::elementary, m)?)?;
    m.add_class::<contact::ContactProblem>()?;
    m.add_class::<contact::PySolution>()?;
    m.add_class::<contact::PyCoarseCost>()?;
    m.add(
        "AUTO_ACTIVE_SET_MAX_POINTS",
        crate::contact::AUTO_ACTIVE_SET_MAX_POINTS,
    )?;
    m.add_function(wrap_pyfunction!(clusters::label_clusters, m)?)?;
    m.add_function(wrap_pyfunction!(clusters::label_open, m)?)?;
    m.add_function(wrap_pyfunction!(clusters::classify, m)?)?;
    m.add_class::<clusters::Labelling>()?;
    m.add_class::<clusters::Classification>()?;
    m.add_class::<flow::FlowSolution>()?;
    m.add_class::<flow::FlowAnalysis>()?;
    m.add_function(wrap_pyfunction!(flow::solve_reynolds_flow, m)?)?;
    m.add_function(wrap_pyfunction!(flow::free_gap_extremes, m)?)?;
    m.add_function(wrap_pyfunction!(solver_threads, m)?)?;
    m.add_function(wrap_pyfunction!(dense_scratch_bytes, m)?)?;
    Ok(())
}
