//! PyO3 bindings: numpy in, numpy out, the GIL released around long work, every core error
//! mapped to a Python exception. No numerics live here.

use std::any::Any;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{sync_channel, RecvTimeoutError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use numpy::{PyArray2, PyArrayMethods};
use pyo3::exceptions::{PyKeyboardInterrupt, PyRuntimeError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::error::Error;
use crate::influence;

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

/// The `RuntimeError` for a panic in the core (a bug: no input should cause one).
fn internal_error(panic: Box<dyn Any + Send>) -> PyErr {
    let msg = panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_default();
    PyRuntimeError::new_err(format!("internal error in leakpath's core: {msg}"))
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

// ---- clusters ----
// Connected components of the free region and their percolation classes (core: clusters.rs).
// Kept in a private module so that its imports cannot clash with the rest of this file.
mod clusters_py {
    use std::sync::{Arc, Mutex};

    use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
    use pyo3::exceptions::PyRuntimeError;
    use pyo3::prelude::*;
    use pyo3::types::PyDict;

    use super::{row_major, to_py};
    use crate::clusters::{self, Connectivity, ContactMask, Flow, FreeMask, Periodic, PositiveGap};
    use crate::error::Error;

    /// Most threads a call may ask for: four per available core. More only adds threads
    /// that wait for a core; a count like 2⁴⁰ would try to start them all.
    fn max_threads() -> usize {
        4 * std::thread::available_parallelism().map_or(1, |n| n.get())
    }

    fn check_threads(threads: Option<i64>) -> PyResult<Option<usize>> {
        let max = max_threads();
        match threads {
            None => Ok(None),
            Some(t) if t >= 1 && t as u64 <= max as u64 => Ok(Some(t as usize)),
            Some(t) if t >= 1 => Err(to_py(Error::invalid(
                "threads",
                format!(
                    "{t} is more than {max} (four per available core); pass at most {max}, or \
                     None for all cores"
                ),
            ))),
            Some(t) => Err(to_py(Error::invalid(
                "threads",
                format!("must be at least 1 (or None for all cores), got {t}"),
            ))),
        }
    }

    /// Runs `f` on a pool of `threads` threads, or on rayon's global pool. The `KEPT` most
    /// recently used pools are kept for later calls: starting threads per call would cost
    /// more than labelling a small grid, and their per-thread buffers would be lost each
    /// time. Older pools are dropped, which ends their threads, so calls with many different
    /// counts do not pile up threads.
    fn in_pool<T: Send>(threads: Option<usize>, f: impl FnOnce() -> T + Send) -> PyResult<T> {
        const KEPT: usize = 2;
        static POOLS: Mutex<Vec<(usize, Arc<rayon::ThreadPool>)>> = Mutex::new(Vec::new());
        let Some(n) = threads else {
            return Ok(f());
        };
        let pool = {
            // A panic elsewhere cannot leave the list inconsistent: keep using it.
            let mut pools = POOLS.lock().unwrap_or_else(|e| e.into_inner());
            let entry = match pools.iter().position(|(k, _)| *k == n) {
                Some(i) => pools.remove(i),
                None => {
                    let p = rayon::ThreadPoolBuilder::new()
                        .num_threads(n)
                        .thread_name(|i| format!("leakpath-clusters-{i}"))
                        .build()
                        .map_err(|e| {
                            PyRuntimeError::new_err(format!("cannot start {n} threads: {e}"))
                        })?;
                    (n, Arc::new(p))
                }
            };
            let pool = Arc::clone(&entry.1);
            pools.insert(0, entry);
            pools.truncate(KEPT);
            pool
        };
        Ok(pool.install(f))
    }

    /// A zeroed `uint32` array from `numpy.zeros`: numpy backs large arrays with huge pages
    /// (saving thousands of first-touch page faults, see `clusters::label_into`), and a
    /// failed allocation raises `MemoryError` instead of panicking.
    fn zeros_u32(py: Python<'_>, ny: usize, nx: usize) -> PyResult<Bound<'_, PyArray2<u32>>> {
        let arr = py
            .import("numpy")?
            .call_method1("zeros", ((ny, nx), "uint32"))
            .map_err(|e| {
                if e.is_instance_of::<pyo3::exceptions::PyMemoryError>(py) {
                    let what = format!("the cluster labels of a {ny} × {nx} grid");
                    let bytes = (ny as u64).saturating_mul(nx as u64).saturating_mul(4);
                    to_py(crate::alloc::refused(bytes, &what))
                } else {
                    e
                }
            })?;
        Ok(arr.cast_into::<PyArray2<u32>>()?)
    }

    fn periodic(axis0: bool, axis1: bool) -> Periodic {
        Periodic { axis0, axis1 }
    }

    /// Labels the connected components of a free mask (True = free). Returns (labels, K):
    /// labels uint32 of the mask's shape, 0 off the free region, 1..=K in raster order of
    /// each cluster's first cell; the same for any thread count.
    #[pyfunction]
    #[pyo3(signature = (free, connectivity=4, periodic_axis0=false, periodic_axis1=false, threads=None))]
    pub(super) fn label_clusters<'py>(
        py: Python<'py>,
        free: PyReadonlyArray2<'py, bool>,
        connectivity: i64,
        periodic_axis0: bool,
        periodic_axis1: bool,
        threads: Option<i64>,
    ) -> PyResult<(Bound<'py, PyArray2<u32>>, usize)> {
        let conn = Connectivity::from_neighbours(connectivity).map_err(to_py)?;
        let threads = check_threads(threads)?;
        let [ny, nx] = [free.shape()[0], free.shape()[1]];
        clusters::check_grid("free", ny, nx).map_err(to_py)?;
        let cells = row_major(&free);
        let cells: &[bool] = &cells;
        let per = periodic(periodic_axis0, periodic_axis1);
        let labels = zeros_u32(py, ny, nx)?;
        let n = {
            let mut rw = labels.readwrite();
            let out = rw.as_slice_mut()?;
            super::interruptible(py, |_| {
                in_pool(threads, || {
                    clusters::label_into(&FreeMask(cells), ny, nx, conn, per, out)
                })
            })??
            .map_err(to_py)?
        };
        Ok((labels, n))
    }

    /// Labels the free region and classifies its clusters for flow along `flow`. Free cells
    /// are `~contact` when a contact mask is given, else `gap > 0`. Returns a dict (see
    /// `_core.pyi`).
    #[pyfunction]
    #[pyo3(signature = (
        gap, dx, contact=None, connectivity=4, periodic_axis0=false, periodic_axis1=false,
        flow="0", threads=None
    ))]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn classify_clusters<'py>(
        py: Python<'py>,
        gap: PyReadonlyArray2<'py, f64>,
        dx: f64,
        contact: Option<PyReadonlyArray2<'py, bool>>,
        connectivity: i64,
        periodic_axis0: bool,
        periodic_axis1: bool,
        flow: &str,
        threads: Option<i64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let conn = Connectivity::from_neighbours(connectivity).map_err(to_py)?;
        let flow = Flow::parse(flow).map_err(to_py)?;
        let per = periodic(periodic_axis0, periodic_axis1);
        flow.check_periodic(per).map_err(to_py)?;
        let threads = check_threads(threads)?;
        let [ny, nx] = [gap.shape()[0], gap.shape()[1]];
        clusters::check_grid("gap", ny, nx).map_err(to_py)?;
        if let Some(c) = &contact {
            if c.shape() != gap.shape() {
                return Err(to_py(Error::invalid(
                    "contact",
                    format!(
                        "must have the shape of gap {:?}, got {:?}",
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
        let labels = zeros_u32(py, ny, nx)?;
        let (cl, class) = {
            let mut rw = labels.readwrite();
            let out = rw.as_slice_mut()?;
            super::interruptible(py, |_| {
                in_pool(threads, || {
                    let cl = match c {
                        Some(c) => {
                            clusters::analyze_into(&ContactMask(c), g, ny, nx, dx, conn, per, out)?
                        }
                        None => {
                            clusters::analyze_into(&PositiveGap(g), g, ny, nx, dx, conn, per, out)?
                        }
                    };
                    let class = clusters::classify(&cl, flow)?;
                    Ok::<_, Error>((cl, class))
                })
            })??
            .map_err(to_py)?
        };
        let d = PyDict::new(py);
        d.set_item("labels", labels)?;
        d.set_item("n_clusters", cl.n_clusters)?;
        d.set_item("areas", PyArray1::from_vec(py, cl.areas))?;
        d.set_item("volumes", PyArray1::from_vec(py, cl.volumes))?;
        d.set_item("touches", PyArray1::from_vec(py, cl.touches))?;
        d.set_item("classes", PyArray1::from_vec(py, class.classes))?;
        d.set_item("spanning_volume", class.spanning_volume)?;
        d.set_item("dead_end_volume", class.dead_end_volume)?;
        d.set_item("trapped_volume", class.trapped_volume)?;
        d.set_item("free_volume", class.free_volume)?;
        d.set_item("spanning_area", class.spanning_area)?;
        d.set_item("dead_end_area", class.dead_end_area)?;
        d.set_item("trapped_area", class.trapped_area)?;
        d.set_item("free_area", class.free_area)?;
        d.set_item("n_spanning", class.n_spanning)?;
        d.set_item("n_dead_end", class.n_dead_end)?;
        d.set_item("n_trapped", class.n_trapped)?;
        Ok(d)
    }
}
// ---- end clusters ----

// ---- contact problem ----
// A surface on an elastic half-space: kernel table, FFT operator and the Lawson–Hanson factor,
// kept across solves so a sweep can warm-start (core: influence.rs, operator.rs, nnls.rs).
mod contact_py {
    use std::sync::Arc;

    use numpy::{
        PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
        PyUntypedArrayMethods,
    };
    use pyo3::prelude::*;
    use pyo3::types::PyDict;

    use super::{check_positive, to_py};
    use crate::alloc;
    use crate::error::Error;
    use crate::influence::Kernel;
    use crate::nnls::{Factor, LawsonHanson, Options, Pivoting, Start};
    use crate::operator::{Boundary, Operator};

    fn field<'py>(
        py: Python<'py>,
        v: Vec<f64>,
        ny: usize,
        nx: usize,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        PyArray1::from_vec(py, v).reshape([ny, nx])
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
        kernel: Arc<Kernel>,
        /// Shared with the Polonsky–Keer binding, which reuses it across solves.
        pub(super) op: Arc<Operator>,
        h: Arc<Vec<f64>>,
        /// `None` while a solve runs, and after an interrupted one (whose worker may still
        /// hold it): the next solve then starts a fresh factor.
        factor: Option<Factor>,
        memory_limit: u64,
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
            // Kernel table, heights, the solvers' fields (p, u, g, b, …) and the FFT operator
            // with the transient peak of building it.
            let need = Operator::memory_estimate(ny, nx, bc)
                .saturating_add((ny as u64).saturating_mul(nx as u64).saturating_mul(64));
            if need > memory_limit {
                return Err(to_py(Error::TooLarge {
                    bytes: need,
                    limit: memory_limit,
                    what: format!(
                        "the contact problem of a {ny} × {nx} grid (kernel table, FFT operator \
                         and solution fields)"
                    ),
                }));
            }
            let (h, ny, nx) = heights_vec(&heights)?;
            // Building the kernel and the operator of a large grid takes seconds and cannot
            // stop half-way: the owned variant lets Ctrl-C return at once.
            let built = super::interruptible_owned(py, move |_| -> Result<_, Error> {
                Ok(match bc {
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
                        let mut column: Vec<f64> =
                            alloc::try_zeroed(ny * nx, "the periodic kernel table")?;
                        op.apply(&unit, &mut column);
                        (Kernel::from_table(ny, nx, dx, e_star, column), op)
                    }
                })
            })?;
            let (kernel, op) = built.map_err(to_py)?;
            let n = h.len();
            Ok(ContactProblem {
                kernel: Arc::new(kernel),
                op: Arc::new(op),
                h: Arc::new(h),
                factor: Some(Factor::try_new(n, memory_limit).map_err(to_py)?),
                memory_limit,
            })
        }

        /// Number of points in the passive (contact) set kept from the last solve.
        #[getter]
        fn n_passive(&self) -> usize {
            self.factor.as_ref().map_or(0, Factor::len)
        }

        /// u = C p by FFT (shape (ny, nx)).
        fn apply<'py>(
            &self,
            py: Python<'py>,
            pressure: PyReadonlyArray2<'_, f64>,
        ) -> PyResult<Bound<'py, PyArray2<f64>>> {
            let a = pressure.as_array();
            if a.dim() != (self.op.ny, self.op.nx) {
                return Err(to_py(Error::invalid(
                    "pressure",
                    "shape differs from the surface",
                )));
            }
            let p: Vec<f64> = a.iter().copied().collect();
            let mut u = vec![0.0; p.len()];
            py.detach(|| self.op.apply(&p, &mut u));
            field(py, u, self.op.ny, self.op.nx)
        }

        /// The dense block C_PP (k × k) for flat indices (Love or periodic coefficients).
        fn block<'py>(
            &self,
            py: Python<'py>,
            indices: PyReadonlyArray1<'_, i64>,
        ) -> PyResult<Bound<'py, PyArray2<f64>>> {
            let n = self.h.len() as i64;
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
            let b = py.detach(|| self.kernel.block(&idx)).map_err(to_py)?;
            // Column-major and symmetric: the same numbers read row-major.
            PyArray1::from_vec(py, b).reshape([k, k])
        }

        /// Lawson–Hanson solve at `approach`. `start`: "cold" (p = 0, the paper), "previous"
        /// (the passive set of the last solve) or "set" with `contact_set` (flat indices).
        #[pyo3(signature = (approach, start="cold", contact_set=None, tol=1e-11, max_iter=None, block=false))]
        #[allow(clippy::too_many_arguments)]
        fn solve_lawson_hanson<'py>(
            &mut self,
            py: Python<'py>,
            approach: f64,
            start: &str,
            contact_set: Option<PyReadonlyArray1<'_, i64>>,
            tol: f64,
            max_iter: Option<usize>,
            block: bool,
        ) -> PyResult<Bound<'py, PyDict>> {
            if !(approach.is_finite() && approach >= 0.0) {
                return Err(to_py(Error::invalid(
                    "approach",
                    format!("must be ≥ 0, got {approach}"),
                )));
            }
            check_positive("tol", tol)?;
            let n = self.h.len();
            let set: Option<Vec<usize>> = match (start, contact_set) {
                ("set", Some(s)) => Some(
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
                ("set", None) => {
                    return Err(to_py(Error::invalid(
                        "warm_start",
                        "start='set' needs contact_set",
                    )))
                }
                ("cold" | "previous", _) => None,
                (other, _) => {
                    return Err(to_py(Error::invalid(
                        "start",
                        format!("must be 'cold', 'previous' or 'set', got {other:?}"),
                    )))
                }
            };
            let opts = Options {
                tol,
                max_iter: max_iter.unwrap_or(50 * n + 1000),
                pivoting: if block {
                    Pivoting::Block
                } else {
                    Pivoting::Single
                },
                memory_limit: 0,
            };
            let start_kind = start.to_string();
            let t0 = std::time::Instant::now();
            let (ny, nx) = (self.op.ny, self.op.nx);
            let mut factor = match self.factor.take() {
                Some(f) => f,
                None => Factor::try_new(n, self.memory_limit).map_err(to_py)?,
            };
            let (kernel, op, h) = (
                Arc::clone(&self.kernel),
                Arc::clone(&self.op),
                Arc::clone(&self.h),
            );
            let (result, factor) = super::interruptible_owned(py, move |stop| {
                let should_stop = super::stop_flag(stop);
                let start = match (start_kind.as_str(), &set) {
                    ("previous", _) => Start::Previous,
                    (_, Some(s)) => Start::Set(s),
                    _ => Start::Cold,
                };
                let mut lh = LawsonHanson::new(&kernel, &op, &h, &mut factor);
                let result = super::on_solver_pool(ny * nx, || {
                    lh.solve(approach, start, &opts, &should_stop)
                });
                (result, factor)
            })?;
            self.factor = Some(factor);
            let sol = result.map_err(to_py)?;
            let seconds = t0.elapsed().as_secs_f64();
            let d = PyDict::new(py);
            d.set_item("pressure", field(py, sol.pressure, ny, nx)?)?;
            d.set_item("displacement", field(py, sol.displacement, ny, nx)?)?;
            d.set_item("gap", field(py, sol.gap, ny, nx)?)?;
            d.set_item("approach", sol.approach)?;
            d.set_item("iterations", sol.iterations)?;
            d.set_item("kkt", sol.kkt)?;
            d.set_item("n_contact", sol.n_contact)?;
            d.set_item("seconds", seconds)?;
            Ok(d)
        }
    }
}
// ---- end contact problem ----

// ---- polonsky-keer ----
// Polonsky–Keer constrained conjugate gradients on the FFT operator (core: pk.rs).
mod pk_py {
    use std::time::Instant;

    use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
    use pyo3::prelude::*;
    use pyo3::types::PyDict;

    use super::{row_major, to_py};
    use crate::alloc;
    use crate::error::Error;
    use crate::operator::Boundary;
    use crate::pk::{self, Control, Options, Problem};

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
        operator_of=None, coarse_start=true
    ))]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn solve_polonsky_keer<'py>(
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
        operator_of: Option<PyRef<'py, super::contact_py::ContactProblem>>,
        coarse_start: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let op = operator_of.as_ref().map(|cp| std::sync::Arc::clone(&cp.op));
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
            None => super::default_memory_limit(py)?,
        };
        // Refuse before copying anything (the estimate includes the copy of the heights).
        let need = pk::memory_estimate(ny, nx, boundary);
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
        let outcome = super::interruptible_owned(py, move |stop| {
            let problem = Problem {
                heights: &h,
                ny,
                nx,
                dx,
                e_star,
                boundary,
            };
            // Ctrl-C: the solver polls this flag between iterations (see `interruptible`).
            let should_stop = super::stop_flag(stop);
            let opts = Options {
                tol,
                max_iter,
                initial_pressure: p0.as_deref(),
                memory_limit: Some(memory_limit),
                should_stop: Some(&should_stop),
                precondition,
                coarse_start,
            };
            super::on_solver_pool(ny * nx, || match &op {
                // The operator of a kept ContactProblem: no kernel or FFT set-up per solve.
                Some(op) => pk::solve_with_operator(op, &problem, control, &opts),
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
        let c = sol.coarse;
        d.set_item("coarse_levels", c.levels)?;
        d.set_item("coarse_iterations", c.iterations)?;
        d.set_item("coarse_applies", c.applies)?;
        d.set_item("coarse_preconditioner_applies", c.preconditioner_applies)?;
        d.set_item("coarse_applies_fine_equivalent", c.applies_fine_equivalent)?;
        d.set_item(
            "coarse_preconditioner_fine_equivalent",
            c.preconditioner_fine_equivalent,
        )?;
        d.set_item("kkt", sol.kkt)?;
        d.set_item("load", sol.load)?;
        d.set_item("mean_pressure", sol.mean_pressure)?;
        d.set_item("contact_points", sol.contact_points)?;
        d.set_item("seconds", seconds)?;
        Ok(d)
    }
}
// ---- end polonsky-keer ----

// ---- reynolds flow ----
// Leak rate: steady Reynolds flow through the gap (core: flow/).
mod flow_py {

    use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
    use pyo3::prelude::*;
    use pyo3::types::PyDict;

    use super::{row_major, to_py};
    use crate::error::Error;
    use crate::flow::{self, Options, Problem};

    /// Steady Reynolds flow through the gap; flow along `axis`, inlet at `pressure_drop`,
    /// outlet at 0. Returns a dict (see `_core.pyi`).
    #[pyfunction]
    #[pyo3(signature = (
        gap, dx, contact=None, axis=0, viscosity=1.0, pressure_drop=1.0, periodic=false,
        tol=flow::DEFAULT_TOL, max_iter=None, memory_limit=None, solver="auto"
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
    ) -> PyResult<Bound<'py, PyDict>> {
        let solver = flow::Solver::parse(solver).map_err(to_py)?;
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
                super::on_solver_pool(ny * nx, || flow::solve(&problem, &opts))
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
        d.set_item("residual", sol.residual)?;
        d.set_item("conservation", sol.conservation)?;
        d.set_item("iterations", sol.iterations)?;
        d.set_item("n_unknowns", sol.n_unknowns)?;
        d.set_item("levels", sol.levels)?;
        d.set_item("seconds", seconds)?;
        Ok(d)
    }
}
// ---- end reynolds flow ----

#[pymodule]
#[pyo3(name = "_core")]
fn core_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(kernel_table, m)?)?;
    m.add_class::<contact_py::ContactProblem>()?;
    m.add_function(wrap_pyfunction!(clusters_py::label_clusters, m)?)?;
    m.add_function(wrap_pyfunction!(clusters_py::classify_clusters, m)?)?;
    m.add_function(wrap_pyfunction!(pk_py::solve_polonsky_keer, m)?)?;
    m.add_function(wrap_pyfunction!(flow_py::solve_reynolds_flow, m)?)?;
    Ok(())
}
