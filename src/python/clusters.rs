//! Bindings of the connected components of the free region and their percolation classes
//! (core: clusters/).

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::pools::{check_threads, pool_for, run_in};
use super::{row_major, to_py};
use crate::clusters::{self, Connectivity, ContactMask, Flow, FreeMask, Periodic, PositiveGap};
use crate::error::Error;

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
    // Resolved here, on the calling thread: a one-thread pool is that thread's own.
    let pool = pool_for(check_threads(threads)?)?;
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
            run_in(&pool, || {
                clusters::label_into(&FreeMask(cells), ny, nx, conn, per, out)
            })
        })?
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
    // Resolved here, on the calling thread: a one-thread pool is that thread's own.
    let pool = pool_for(check_threads(threads)?)?;
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
            run_in(&pool, || {
                let cl = match c {
                    Some(c) => {
                        clusters::analyze_into(&ContactMask(c), g, ny, nx, dx, conn, per, out)?
                    }
                    None => clusters::analyze_into(&PositiveGap(g), g, ny, nx, dx, conn, per, out)?,
                };
                let class = clusters::classify(&cl, flow)?;
                Ok::<_, Error>((cl, class))
            })
        })?
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
