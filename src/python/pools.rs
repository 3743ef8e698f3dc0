//! Thread pools of a given size for calls that ask for a thread count (`threads=`): the
//! labelling, and the flow solves a sweep runs beside its contact solves.

use std::sync::{Arc, Mutex};

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;

use super::to_py;
use crate::error::Error;

/// Most threads a call may ask for: four per available core. More only adds threads
/// that wait for a core; a count like 2⁴⁰ would try to start them all.
fn max_threads() -> usize {
    4 * std::thread::available_parallelism().map_or(1, |n| n.get())
}

pub(crate) fn check_threads(threads: Option<i64>) -> PyResult<Option<usize>> {
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

fn build(n: usize, name: &'static str) -> PyResult<Arc<rayon::ThreadPool>> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .thread_name(move |i| format!("leakpath-{name}-{i}"))
        .build()
        .map(Arc::new)
        .map_err(|e| PyRuntimeError::new_err(format!("cannot start {n} threads: {e}")))
}

/// The pool for `threads` threads (`None`: rayon's global pool, returned as `None`).
///
/// One thread: the calling thread's own pool, kept for its lifetime (so call this on the
/// Python thread, before the work moves to a worker thread). Two Python threads
/// that each ask for one thread (a sweep's contact solves and its flows on a background
/// thread) then run side by side instead of queueing on one shared worker.
///
/// More threads: the `KEPT` most recently used pools are shared and kept for later calls:
/// starting threads per call would cost more than labelling a small grid, and their
/// per-thread buffers would be lost each time. Older pools are dropped, which ends their
/// threads, so calls with many different counts do not pile up threads.
pub(crate) fn pool_for(threads: Option<usize>) -> PyResult<Option<Arc<rayon::ThreadPool>>> {
    const KEPT: usize = 2;
    static POOLS: Mutex<Vec<(usize, Arc<rayon::ThreadPool>)>> = Mutex::new(Vec::new());
    thread_local! {
        static OWN: std::cell::OnceCell<Arc<rayon::ThreadPool>> =
            const { std::cell::OnceCell::new() };
    }
    let Some(n) = threads else {
        return Ok(None);
    };
    if n == 1 {
        return OWN.with(|own| {
            if let Some(p) = own.get() {
                return Ok(Some(Arc::clone(p)));
            }
            let p = build(1, "own")?;
            let _ = own.set(Arc::clone(&p));
            Ok(Some(p))
        });
    }
    // A panic elsewhere cannot leave the list inconsistent: keep using it.
    let mut pools = POOLS.lock().unwrap_or_else(|e| e.into_inner());
    let entry = match pools.iter().position(|(k, _)| *k == n) {
        Some(i) => pools.remove(i),
        None => (n, build(n, "pool")?),
    };
    let pool = Arc::clone(&entry.1);
    pools.insert(0, entry);
    pools.truncate(KEPT);
    Ok(Some(pool))
}

/// Runs `f` on `pool`, or as called (rayon's global pool).
pub(crate) fn run_in<T: Send>(
    pool: &Option<Arc<rayon::ThreadPool>>,
    f: impl FnOnce() -> T + Send,
) -> T {
    match pool {
        Some(p) => p.install(f),
        None => f(),
    }
}

/// Runs a solve of `cells` cells on `pool`, or on the solver pool
/// ([`super::on_solver_pool`]) when none was asked for.
pub(crate) fn run_solve<T: Send>(
    pool: &Option<Arc<rayon::ThreadPool>>,
    cells: usize,
    f: impl FnOnce() -> T + Send,
) -> T {
    match pool {
        Some(p) => p.install(f),
        None => super::on_solver_pool(cells, f),
    }
}
