"""Percolation of the free region between the surfaces: its clusters and their classes.

Definitions (``docs/conventions.md``):

* A cell is *free* when it is not in contact (``p = 0``). Two free cells belong to the same
  *cluster* when a chain of neighbouring free cells joins them: edge neighbours with
  ``connectivity=4`` (the default; fluid does not pass through a corner), edge and corner
  neighbours with ``connectivity=8``.
* For flow along ``axis`` 0 (or 1), a cluster is *spanning* (percolating) when it touches both
  the first and the last row (column); ``"either"`` spans along axis 0 or 1, ``"both"`` along
  both. A cluster is *dead-end* when it touches some boundary of the grid but does not span,
  and *trapped* when it touches no boundary.
* With periodic wrap across the other axis (a periodic surface: ``boundary="periodic"``), the
  first and last index along that axis are neighbours, and that axis has no boundary; only
  the inlet and outlet edges of the flow axis count as boundary then.
* Volumes are ``Σ g·dx²`` over a cluster's cells (length³, the surface's units); areas are cell
  counts (multiply by ``dx²`` for length²). The free volume splits exactly into the classes::

      V = V_pg + V_dead + V_trapped

  each a compensated sum over clusters, so the identity holds to a few ulps. ``V`` sums the
  free cells only: the contact state's ``dx² Σ g`` less the gaps left on contact cells
  (zero for an exact solve).
* Given a plain gap array and no contact mask, the cells with ``g > 0`` are free. With a
  contact mask (a contact state's ``p > 0``), a cell is free when it is not in contact *and*
  ``g > 0``: the one definition of an *open* cell that :func:`leakpath.flow` uses too, so
  the flow leaks exactly when the free region percolates.

The labelling runs in Rust on all cores (``threads`` to limit it); labels are numbered
``1..K`` in raster order of each cluster's first cell, identical for any thread count.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import _core, _validate
from .errors import InvalidArgumentError

__all__ = [
    "CLASS_NAMES",
    "CONTACT",
    "DEAD_END",
    "SPANNING",
    "TRAPPED",
    "Percolation",
    "label",
    "percolation",
]

#: Class codes used by :attr:`Percolation.classes` and :meth:`Percolation.class_map`.
CONTACT, SPANNING, DEAD_END, TRAPPED = 0, 1, 2, 3
#: Names of the class codes 0–3.
CLASS_NAMES: tuple[str, ...] = ("contact", "spanning", "dead-end", "trapped")


@dataclass(frozen=True, eq=False)
class Percolation:
    """Clusters of the free region and their percolation classes for one flow direction.

    Per-cluster arrays have one entry per cluster; cluster ``k`` (label ``k``) is entry
    ``k − 1``.

    Attributes:
        labels: ``uint32`` array of the grid's shape: 0 on contact cells, ``1..n_clusters``
            on free cells, numbered in raster order of each cluster's first cell.
        n_clusters: number of clusters ``K``.
        areas: cells per cluster (``uint64``; × ``dx²`` for length²).
        volumes: ``Σ g·dx²`` per cluster (length³).
        classes: class code per cluster (``uint8``): ``SPANNING`` 1, ``DEAD_END`` 2,
            ``TRAPPED`` 3.
        spanning_volume: ``V_pg``, volume of the spanning clusters (length³).
        dead_end_volume: ``V_dead``, volume of the dead-end clusters.
        trapped_volume: ``V_trapped``, volume of the trapped clusters.
        free_volume: ``V = V_pg + V_dead + V_trapped``, ``Σ g·dx²`` over all free cells.
        spanning_area, dead_end_area, trapped_area, free_area: cell counts of the same sets.
        n_spanning, n_dead_end, n_trapped: number of clusters of each class.
        axis: flow direction: 0, 1, ``"either"`` or ``"both"``.
        connectivity: 4 or 8.
        periodic: whether the grid wrapped across the axis other than the flow axis.
        dx: grid spacing (length).
    """

    labels: np.ndarray = field(repr=False)
    n_clusters: int
    areas: np.ndarray = field(repr=False)
    volumes: np.ndarray = field(repr=False)
    classes: np.ndarray = field(repr=False)
    spanning_volume: float
    dead_end_volume: float
    trapped_volume: float
    free_volume: float
    spanning_area: int
    dead_end_area: int
    trapped_area: int
    free_area: int
    n_spanning: int
    n_dead_end: int
    n_trapped: int
    axis: int | str
    connectivity: int
    periodic: bool
    dx: float

    @property
    def percolates(self) -> bool:
        """True when at least one cluster spans the grid along the flow direction."""
        return self.n_spanning > 0

    def __repr__(self) -> str:
        ny, nx = self.shape
        return (
            f"Percolation({ny}x{nx} grid, axis={self.axis!r}, "
            f"connectivity={self.connectivity}, percolates={self.percolates}, "
            f"clusters={self.n_clusters} (spanning {self.n_spanning}, dead-end "
            f"{self.n_dead_end}, trapped {self.n_trapped}), V_pg={self.spanning_volume:.4g}, "
            f"V_dead={self.dead_end_volume:.4g}, V_trapped={self.trapped_volume:.4g}, "
            f"V={self.free_volume:.4g})"
        )

    @property
    def shape(self) -> tuple[int, int]:
        return self.labels.shape  # type: ignore[return-value]

    def class_map(self) -> np.ndarray:
        """Class of every cell (``int8``, the grid's shape): 0 contact, 1 spanning,
        2 dead-end, 3 trapped — for plotting (names in :data:`CLASS_NAMES`)."""
        lut = np.empty(self.n_clusters + 1, dtype=np.int8)
        lut[0] = CONTACT
        lut[1:] = self.classes
        return lut[self.labels]

    def class_volumes(self) -> dict[str, float]:
        """``{"spanning": V_pg, "dead-end": V_dead, "trapped": V_trapped}`` (length³)."""
        return {
            "spanning": self.spanning_volume,
            "dead-end": self.dead_end_volume,
            "trapped": self.trapped_volume,
        }


def _flow(axis: Any) -> tuple[str, int | str]:
    """Rust flow name and the canonical axis for ``axis``."""
    canonical = _validate.axis(axis)
    return str(canonical), canonical


def _is_state(obj: Any) -> bool:
    return all(hasattr(obj, name) for name in ("gap", "contact", "dx"))


def percolation(
    state_or_gap: Any,
    *,
    axis: int | str = 0,
    connectivity: int = 4,
    periodic: bool | None = None,
    dx: float | None = None,
    contact: np.ndarray | None = None,
    threads: int | None = None,
) -> Percolation:
    """Clusters of the free region and their percolation classes (module docstring).

    Args:
        state_or_gap: a solved contact state (anything with the attributes ``gap``,
            ``contact`` (mask ``p > 0``), ``dx`` and ``boundary``, like
            :class:`leakpath.contact.ContactState`), or a 2-D array of gaps ``g`` (length).
            For an array, free cells are ``~contact`` when ``contact`` is given, else
            ``g > 0``.
        axis: flow direction: 0 (default), 1, ``"either"`` or ``"both"``.
        connectivity: 4 (default) or 8.
        periodic: wrap across the axis that is not the flow axis. ``None`` (default): wrap
            when the state's ``boundary`` is ``"periodic"`` and ``axis`` is 0 or 1. For
            ``"either"`` and ``"both"`` every edge is an inlet or outlet, so there is no
            wrap: the periodic cell is analysed as one patch (``periodic=True`` is an error
            there). A plain array has no boundary condition: ``None`` means no wrap.
        dx: grid spacing (length); required for a gap array, taken from a state.
        contact: contact mask (bool, the gap's shape) for a gap array.
        threads: number of threads (default: all cores). Results do not depend on it.

    Returns:
        :class:`Percolation`.

    Raises:
        ValueError: naming the argument — a non-2-D or empty gap, NaN or infinite gaps, a
            contact mask of another shape or not boolean, a bad ``axis``, ``connectivity``,
            ``periodic``, ``dx`` or ``threads``.
    """
    flow, axis_used = _flow(axis)
    conn = _validate.connectivity(connectivity)
    threads = _validate.threads(threads)

    boundary = None
    if _is_state(state_or_gap):
        state = state_or_gap
        if dx is not None:
            raise InvalidArgumentError(
                "dx: taken from the contact state; pass a gap array to set it"
            )
        if contact is not None:
            raise InvalidArgumentError(
                "contact: taken from the contact state (p > 0); pass a gap array to set it"
            )
        gap_in, contact, dx = state.gap, state.contact, state.dx
        boundary = getattr(state, "boundary", None)
    else:
        gap_in = state_or_gap
        if dx is None:
            raise InvalidArgumentError(
                "dx: the grid spacing is required when a gap array is given"
            )

    # NaN and infinite gaps are refused by the core, with the same message.
    gap = _validate.real_array("gap", gap_in, finite=False, copy=False)
    if gap.size == 0:
        raise InvalidArgumentError(f"gap: must have at least one cell, got shape {gap.shape}")

    if contact is not None:
        contact = np.asarray(contact)
        if contact.dtype != np.bool_:
            raise InvalidArgumentError(
                f"contact: must be a boolean mask (e.g. pressure > 0), got dtype {contact.dtype}"
            )
        if contact.shape != gap.shape:
            raise InvalidArgumentError(
                f"contact: must have the gap's shape {gap.shape}, got {contact.shape}"
            )
        # One definition of an open cell for the percolation and the flow
        # (docs/conventions.md): not in contact and g > 0. A free cell whose gap an iterative
        # solve left at or below 0 within its tolerance conducts nothing, so it is closed.
        contact = contact | ~(gap > 0)

    dx_f = _validate.spacing("dx", dx)

    if periodic is None:
        wrap = boundary == "periodic" and flow in ("0", "1")
    else:
        wrap = _validate.flag("periodic", periodic)
        if wrap and flow not in ("0", "1"):
            raise InvalidArgumentError(
                f"periodic: wrap is across the flow axis, so it needs axis 0 or 1, "
                f"not {axis_used!r} (every edge is an inlet or outlet there)"
            )

    res = _core.classify_clusters(
        gap,
        dx_f,
        contact=contact,
        connectivity=conn,
        # A periodic surface wraps across the flow: axis 1 for flow along axis 0, and back.
        periodic_axis0=wrap and flow == "1",
        periodic_axis1=wrap and flow == "0",
        flow=flow,
        threads=None if threads is None else int(threads),
    )
    return Percolation(
        labels=res["labels"],
        n_clusters=int(res["n_clusters"]),
        areas=res["areas"],
        volumes=res["volumes"],
        classes=res["classes"],
        spanning_volume=float(res["spanning_volume"]),
        dead_end_volume=float(res["dead_end_volume"]),
        trapped_volume=float(res["trapped_volume"]),
        free_volume=float(res["free_volume"]),
        spanning_area=int(res["spanning_area"]),
        dead_end_area=int(res["dead_end_area"]),
        trapped_area=int(res["trapped_area"]),
        free_area=int(res["free_area"]),
        n_spanning=int(res["n_spanning"]),
        n_dead_end=int(res["n_dead_end"]),
        n_trapped=int(res["n_trapped"]),
        axis=axis_used,
        connectivity=conn,
        periodic=wrap,
        dx=dx_f,
    )


def label(
    free: Any,
    *,
    connectivity: int = 4,
    periodic: tuple[bool, bool] = (False, False),
    threads: int | None = None,
) -> tuple[np.ndarray, int]:
    """Connected components of a boolean mask (``True`` = free): the labelling behind
    :func:`percolation`, for any mask.

    Args:
        free: (ny, nx) boolean mask.
        connectivity: 4 (edge neighbours, default) or 8 (edges and corners).
        periodic: ``(wrap rows, wrap columns)``: whether the first and last row (column)
            are neighbours.
        threads: worker threads (default: all cores); the labels do not depend on it.

    Returns:
        ``(labels, K)``: ``uint32`` labels of the mask's shape, 0 off the mask and ``1..K`` on
        it, numbered in raster order of each cluster's first cell (as
        ``scipy.ndimage.label`` numbers them).

    Raises:
        leakpath.errors.InvalidArgumentError: a mask that is not 2-D boolean, a bad
            ``connectivity``, ``periodic`` or ``threads``.
    """
    mask = np.asarray(free)
    if mask.dtype != np.bool_ or mask.ndim != 2:
        raise InvalidArgumentError(
            f"free: must be a 2-D boolean mask, got dtype {mask.dtype} with {mask.ndim} "
            "dimensions; pass e.g. gap > 0",
            argument="free",
        )
    conn = _validate.connectivity(connectivity)
    if not (isinstance(periodic, tuple) and len(periodic) == 2):
        raise InvalidArgumentError(
            f"periodic: must be a pair of booleans (rows, columns), got {periodic!r}",
            argument="periodic",
        )
    wrap0 = _validate.flag("periodic", periodic[0])
    wrap1 = _validate.flag("periodic", periodic[1])
    threads = _validate.threads(threads)
    labels, k = _core.label_clusters(
        np.ascontiguousarray(mask),
        connectivity=conn,
        periodic_axis0=wrap0,
        periodic_axis1=wrap1,
        threads=threads,
    )
    return labels, int(k)
