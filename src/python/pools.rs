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

/// Runs `f` on a pool of `threads` threads, or on rayon's global pool. The `KEPT` most
/// recently used pools are kept for later calls: starting threads per call would cost
/// more than labelling a small grid, and their per-thread buffers would be lost each
/// time. Older pools are dropped, which ends their threads, so calls with many different
/// counts do not pile up threads.
pub(crate) fn in_pool<T: Send>(
    threads: Option<usize>,
    f: impl FnOnce() -> T + Send,
) -> PyResult<T> {
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
                    .thread_name(|i| format!("leakpath-pool-{i}"))
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
