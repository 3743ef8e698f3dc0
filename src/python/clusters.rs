//! Bindings of the connected components of the free region and their percolation classes
//! (core: clusters/).

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{IntoPyDict, PyInt, PyString};

use super::pools::{check_threads, pool_for, run_in};
use super::{check_contact_shape, row_major, to_py};
use crate::clusters::{self, Clusters, Connectivity, Flow, FreeMask, OpenCells, Periodic};
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

/// A flow direction as it crosses from Python: the integer 0 or 1, or the string
/// `"either"` or `"both"` (leakpath's canonical axis values). The flow solver takes 0 or 1.
#[derive(Clone, Copy, Debug)]
pub(super) struct Axis(pub Flow);

impl<'a, 'py> FromPyObject<'a, 'py> for Axis {
    type Error = PyErr;

    fn extract(obj: Borrowed<'a, 'py, PyAny>) -> PyResult<Self> {
        if obj.is_instance_of::<PyInt>() && !obj.is_instance_of::<pyo3::types::PyBool>() {
            match obj.extract::<i64>() {
                Ok(0) => return Ok(Axis(Flow::Axis0)),
                Ok(1) => return Ok(Axis(Flow::Axis1)),
                _ => {}
            }
        } else if obj.is_instance_of::<PyString>() {
            match obj.extract::<String>()?.as_str() {
                "either" => return Ok(Axis(Flow::Either)),
                "both" => return Ok(Axis(Flow::Both)),
                _ => {}
            }
        }
        Err(PyValueError::new_err(format!(
            "axis: must be 0, 1, 'either' or 'both', got {}",
            obj.repr()?
        )))
    }
}

impl Axis {
    /// The Python value of this axis: 0, 1, "either" or "both".
    pub(super) fn to_object<'py>(self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(match self.0 {
            Flow::Axis0 => 0i64.into_pyobject(py)?.into_any(),
            Flow::Axis1 => 1i64.into_pyobject(py)?.into_any(),
            Flow::Either => "either".into_pyobject(py)?.into_any(),
            Flow::Both => "both".into_pyobject(py)?.into_any(),
        })
    }
}

/// Marks a numpy array read-only (results are shared between the objects that hold them).
fn read_only(arr: &Bound<'_, PyAny>) -> PyResult<()> {
    let kwargs = [("write", false)].into_py_dict(arr.py())?;
    arr.call_method("setflags", (), Some(&kwargs))?;
    Ok(())
}

/// The open cells of one gap labelled once: labels and per-cluster sums (`_core.pyi`).
#[pyclass(frozen, module = "leakpath._core", name = "Labelling")]
pub(super) struct Labelling {
    /// `uint32` labels, 0 on closed cells, `1..=K` in raster order (read-only).
    #[pyo3(get)]
    labels: Py<PyArray2<u32>>,
    #[pyo3(get)]
    n_clusters: usize,
    /// Cells per cluster (`uint64`), entry `k − 1` for label `k`.
    #[pyo3(get)]
    areas: Py<PyArray1<u64>>,
    /// `dx² Σ g` per cluster (`float64`).
    #[pyo3(get)]
    volumes: Py<PyArray1<f64>>,
    /// Touch flags per cluster: 1 first row, 2 last row, 4 first column, 8 last column.
    #[pyo3(get)]
    touches: Py<PyArray1<u8>>,
    #[pyo3(get)]
    connectivity: i64,
    #[pyo3(get)]
    periodic_axis0: bool,
    #[pyo3(get)]
    periodic_axis1: bool,
    #[pyo3(get)]
    dx: f64,
    /// The same sums, kept for [`classify`].
    clusters: Clusters,
}

impl Labelling {
    /// Whether the labels were made with the flow's connectivity (4) and wrap (across
    /// `axis` when `periodic`, never along it).
    pub(super) fn for_flow(&self, axis: usize, periodic: bool) -> bool {
        let (along, across) = if axis == 0 {
            (self.periodic_axis0, self.periodic_axis1)
        } else {
            (self.periodic_axis1, self.periodic_axis0)
        };
        self.connectivity == 4 && !along && across == periodic
    }

    pub(super) fn labels<'py>(&self, py: Python<'py>) -> &Bound<'py, PyArray2<u32>> {
        self.labels.bind(py)
    }

    pub(super) fn n_clusters(&self) -> usize {
        self.n_clusters
    }
}

#[pymethods]
impl Labelling {
    fn __repr__(&self, py: Python<'_>) -> String {
        let shape = self.labels.bind(py).shape().to_vec();
        format!(
            "Labelling({}x{} grid, clusters={}, connectivity={}, periodic=({}, {}))",
            shape[0],
            shape[1],
            self.n_clusters,
            self.connectivity,
            self.periodic_axis0,
            self.periodic_axis1
        )
    }
}

/// Labels the open cells (`clusters::is_open`: not in contact and `g > 0`; without a contact
/// mask, `g > 0`) of a gap field once, with per-cluster cells, volumes `dx² Σ g` and touch
/// flags. Returns a [`Labelling`].
#[pyfunction]
#[pyo3(signature = (
    gap, dx, contact=None, connectivity=4, periodic_axis0=false, periodic_axis1=false,
    threads=None
))]
#[allow(clippy::too_many_arguments)]
pub(super) fn label_open<'py>(
    py: Python<'py>,
    gap: PyReadonlyArray2<'py, f64>,
    dx: f64,
    contact: Option<PyReadonlyArray2<'py, bool>>,
    connectivity: i64,
    periodic_axis0: bool,
    periodic_axis1: bool,
    threads: Option<i64>,
) -> PyResult<Labelling> {
    let conn = Connectivity::from_neighbours(connectivity).map_err(to_py)?;
    let per = periodic(periodic_axis0, periodic_axis1);
    // Resolved here, on the calling thread: a one-thread pool is that thread's own.
    let pool = pool_for(check_threads(threads)?)?;
    let [ny, nx] = [gap.shape()[0], gap.shape()[1]];
    clusters::check_grid("gap", ny, nx).map_err(to_py)?;
    check_contact_shape(&gap, contact.as_ref())?;
    let g = row_major(&gap);
    let g: &[f64] = &g;
    let c = contact.as_ref().map(row_major);
    let c: Option<&[bool]> = c.as_deref();
    let labels = zeros_u32(py, ny, nx)?;
    let cl = {
        let mut rw = labels.readwrite();
        let out = rw.as_slice_mut()?;
        super::interruptible(py, |_| {
            run_in(&pool, || {
                let open = OpenCells { gap: g, contact: c };
                clusters::analyze_into(&open, g, ny, nx, dx, conn, per, out)
            })
        })?
        .map_err(to_py)?
    };
    read_only(labels.as_any())?;
    let areas = PyArray1::from_slice(py, &cl.areas);
    let volumes = PyArray1::from_slice(py, &cl.volumes);
    let touches = PyArray1::from_slice(py, &cl.touches);
    for a in [areas.as_any(), volumes.as_any(), touches.as_any()] {
        read_only(a)?;
    }
    Ok(Labelling {
        labels: labels.unbind(),
        n_clusters: cl.n_clusters,
        areas: areas.unbind(),
        volumes: volumes.unbind(),
        touches: touches.unbind(),
        connectivity,
        periodic_axis0,
        periodic_axis1,
        dx,
        clusters: cl,
    })
}

/// Percolation classes of a labelling's clusters for one flow direction and the class totals
/// (`_core.pyi`).
#[pyclass(frozen, module = "leakpath._core", name = "Classification")]
pub(super) struct Classification {
    axis: Axis,
    /// Class per cluster (`uint8`): 1 spanning, 2 dead-end, 3 trapped (read-only).
    #[pyo3(get)]
    classes: Py<PyArray1<u8>>,
    #[pyo3(get)]
    spanning_volume: f64,
    #[pyo3(get)]
    dead_end_volume: f64,
    #[pyo3(get)]
    trapped_volume: f64,
    #[pyo3(get)]
    free_volume: f64,
    #[pyo3(get)]
    spanning_cells: u64,
    #[pyo3(get)]
    dead_end_cells: u64,
    #[pyo3(get)]
    trapped_cells: u64,
    #[pyo3(get)]
    free_cells: u64,
    #[pyo3(get)]
    n_spanning: usize,
    #[pyo3(get)]
    n_dead_end: usize,
    #[pyo3(get)]
    n_trapped: usize,
}

#[pymethods]
impl Classification {
    /// The flow direction: 0, 1, "either" or "both".
    #[getter]
    fn axis<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.axis.to_object(py)
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        Ok(format!(
            "Classification(axis={}, spanning={}, dead_end={}, trapped={})",
            self.axis.to_object(py)?.repr()?,
            self.n_spanning,
            self.n_dead_end,
            self.n_trapped
        ))
    }
}

/// Classifies the clusters of `labelling` for flow along each of `axes` (0, 1, "either" or
/// "both"): no labelling, only per-cluster work; one [`Classification`] per axis, in order.
/// Wrap along a flow axis is refused.
#[pyfunction]
#[pyo3(signature = (labelling, axes, threads=None))]
pub(super) fn classify<'py>(
    py: Python<'py>,
    labelling: PyRef<'py, Labelling>,
    axes: Vec<Axis>,
    threads: Option<i64>,
) -> PyResult<Vec<Classification>> {
    let pool = pool_for(check_threads(threads)?)?;
    let cl = &labelling.clusters;
    let classes = py
        .detach(|| {
            run_in(&pool, || {
                axes.iter()
                    .map(|a| clusters::classify(cl, a.0))
                    .collect::<Result<Vec<_>, Error>>()
            })
        })
        .map_err(to_py)?;
    let mut out = Vec::with_capacity(axes.len());
    for (axis, class) in axes.into_iter().zip(classes) {
        let codes = PyArray1::from_vec(py, class.classes);
        read_only(codes.as_any())?;
        out.push(Classification {
            axis,
            classes: codes.unbind(),
            spanning_volume: class.spanning_volume,
            dead_end_volume: class.dead_end_volume,
            trapped_volume: class.trapped_volume,
            free_volume: class.free_volume,
            spanning_cells: class.spanning_area,
            dead_end_cells: class.dead_end_area,
            trapped_cells: class.trapped_area,
            free_cells: class.free_area,
            n_spanning: class.n_spanning,
            n_dead_end: class.n_dead_end,
            n_trapped: class.n_trapped,
        });
    }
    Ok(out)
}
