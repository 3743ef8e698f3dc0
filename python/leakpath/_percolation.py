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
* Volumes are ``Σ g·dx²`` over a cluster's cells (length³, the surface's unit cubed); areas
  are ``cells·dx²`` (length²), and the cell counts are kept under names ending in
  ``cells``/``cell_counts``. The free volume splits exactly into the classes::

      V = V_pg + V_dead + V_trapped

  each a compensated sum over clusters, so the identity holds to a few ulps. ``V`` sums the
  free cells only: the contact state's ``dx² Σ g`` less the gaps left on contact cells
  (zero for an exact solve).
* A cell is *open* when it is not in contact *and* ``g > 0`` (no contact mask: ``g > 0``).
  The rule is written once, in the core (``clusters::is_open``), and the percolation and
  :func:`leakpath.flow` both use it, so the flow leaks exactly when the free region
  percolates. The open cells of a contact state are labelled once (:func:`state_labelling`)
  and that labelling serves every axis, the class volumes and the flow.

The labelling runs in Rust on all cores (``threads`` to limit it); labels are numbered
``1..K`` in raster order of each cluster's first cell, identical for any thread count.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import _core, _validate
from .errors import InvalidArgumentError

__all__ = [
    "CLASS_NAMES",
    "state_labelling",
    "CONTACT",
    "DEAD_END",
    "SPANNING",
    "TRAPPED",
    "Percolation",
    "label",
    "percolation",
    "percolations",
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
        cell_counts: cells per cluster (``uint64``); :attr:`areas` gives them in length².
        volumes: ``Σ g·dx²`` per cluster (length³).
        classes: class code per cluster (``uint8``): ``SPANNING`` 1, ``DEAD_END`` 2,
            ``TRAPPED`` 3.
        spanning_volume: ``V_pg``, volume of the spanning clusters (length³).
        dead_end_volume: ``V_dead``, volume of the dead-end clusters.
        trapped_volume: ``V_trapped``, volume of the trapped clusters.
        free_volume: ``V = V_pg + V_dead + V_trapped``, ``Σ g·dx²`` over all free cells.
        spanning_cells, dead_end_cells, trapped_cells, free_cells: cell counts of the same
            sets.
        spanning_area, dead_end_area, trapped_area, free_area: their areas, the count ×
            ``dx²`` (length², the surface's unit squared).
        n_spanning, n_dead_end, n_trapped: number of clusters of each class.
        axis: flow direction: 0, 1, ``"either"`` or ``"both"``.
        connectivity: 4 or 8.
        periodic: whether the grid wrapped across the axis other than the flow axis.
        dx: grid spacing (length).
        unit: name of the length unit (a contact state's :attr:`leakpath.Surface.unit`;
            ``None`` for a gap array, printed as "length").
    """

    labels: np.ndarray = field(repr=False)
    n_clusters: int
    cell_counts: np.ndarray = field(repr=False)
    volumes: np.ndarray = field(repr=False)
    classes: np.ndarray = field(repr=False)
    spanning_volume: float
    dead_end_volume: float
    trapped_volume: float
    free_volume: float
    spanning_cells: int
    dead_end_cells: int
    trapped_cells: int
    free_cells: int
    spanning_area: float
    dead_end_area: float
    trapped_area: float
    free_area: float
    n_spanning: int
    n_dead_end: int
    n_trapped: int
    axis: int | str
    connectivity: int
    periodic: bool
    dx: float
    unit: str | None = field(default=None, repr=False)

    @property
    def percolates(self) -> bool:
        """True when at least one cluster spans the grid along the flow direction."""
        return self.n_spanning > 0

    def __repr__(self) -> str:
        ny, nx = self.shape
        v = f" {self.unit or 'length'}^3"
        return (
            f"Percolation({ny}x{nx} grid, axis={self.axis!r}, "
            f"connectivity={self.connectivity}, percolates={self.percolates}, "
            f"clusters={self.n_clusters} (spanning {self.n_spanning}, dead-end "
            f"{self.n_dead_end}, trapped {self.n_trapped}), "
            f"V_pg={self.spanning_volume:.4g}{v}, V_dead={self.dead_end_volume:.4g}{v}, "
            f"V_trapped={self.trapped_volume:.4g}{v}, V={self.free_volume:.4g}{v})"
        )

    @property
    def shape(self) -> tuple[int, int]:
        return self.labels.shape  # type: ignore[return-value]

    @property
    def areas(self) -> np.ndarray:
        """Area of each cluster, ``cells × dx²`` (length²)."""
        return self.cell_counts * (self.dx * self.dx)

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


def _label_open(
    gap: np.ndarray,
    dx: float,
    contact: np.ndarray | None,
    connectivity: int,
    wrap: tuple[bool, bool],
    threads: int | None,
) -> Any:
    """The one labelling of the open cells (``not contact and g > 0``, the rule written once
    in the core, ``clusters::is_open``): labels and per-cluster cells, volumes and touch
    flags (:class:`leakpath._core.Labelling`). Every percolation class, volume and flow of a
    gap reuses it."""
    return _core.label_open(
        gap,
        dx,
        contact=contact,
        connectivity=connectivity,
        periodic_axis0=wrap[0],
        periodic_axis1=wrap[1],
        threads=threads,
    )


def _wrap_for(axis: int | str, periodic: bool) -> tuple[bool, bool]:
    """``(wrap rows, wrap columns)`` for flow along ``axis``: a periodic surface wraps across
    the flow (columns for axis 0, rows for axis 1); ``"either"``/``"both"`` never wrap."""
    if not periodic or axis not in (0, 1):
        return (False, False)
    return (axis == 1, axis == 0)


def state_labelling(
    state: Any, *, connectivity: int = 4, wrap: tuple[bool, bool], threads: int | None = None
) -> Any:
    """The labelling of a contact state's open cells, made once per ``(connectivity, wrap)``
    and kept on the state: its percolation classes for every axis, its volumes and its flow
    all read the same labels (a free boundary has a single labelling per state)."""
    key = (connectivity, bool(wrap[0]), bool(wrap[1]))
    cache = state.__dict__.setdefault("_labelling_cache", {})
    if key not in cache:
        gap = _validate.real_array("gap", state.gap, finite=False, copy=False)
        contact = np.asarray(state.contact)
        if contact.dtype != np.bool_:
            raise InvalidArgumentError(
                f"contact: must be a boolean mask (e.g. pressure > 0), got dtype {contact.dtype}"
            )
        contact = np.ascontiguousarray(contact)
        cache[key] = _label_open(
            gap, _validate.spacing("dx", state.dx), contact, connectivity, key[1:], threads
        )
    return cache[key]


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
            For an array, open cells are ``~contact & (g > 0)`` when ``contact`` is given,
            else ``g > 0``.
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
        :class:`Percolation`. For a contact state, the labelling of its open cells is made
        once and kept on the state (:func:`state_labelling`): further axes, the flow and
        the volumes reuse it.

    Raises:
        ValueError: naming the argument — a non-2-D or empty gap, NaN or infinite gaps, a
            contact mask of another shape or not boolean, a bad ``axis``, ``connectivity``,
            ``periodic``, ``dx`` or ``threads``.
    """
    axis_used = _validate.axis(axis)
    conn = _validate.connectivity(connectivity)
    threads = _validate.threads(threads)

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
        if periodic is None:
            wrap_on = getattr(state, "boundary", None) == "periodic" and axis_used in (0, 1)
        else:
            wrap_on = _check_wrap(periodic, axis_used)
        dx_f = _validate.spacing("dx", state.dx)
        lab = state_labelling(
            state, connectivity=conn, wrap=_wrap_for(axis_used, wrap_on), threads=threads
        )
        return _classified(
            lab, axis_used, conn, wrap_on, dx_f, threads, getattr(state, "unit", None)
        )

    gap_in = state_or_gap
    if dx is None:
        raise InvalidArgumentError("dx: the grid spacing is required when a gap array is given")
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
        contact = np.ascontiguousarray(contact)
    dx_f = _validate.spacing("dx", dx)
    wrap_on = False if periodic is None else _check_wrap(periodic, axis_used)
    lab = _label_open(gap, dx_f, contact, conn, _wrap_for(axis_used, wrap_on), threads)
    return _classified(lab, axis_used, conn, wrap_on, dx_f, threads)


def _check_wrap(periodic: Any, axis: int | str) -> bool:
    wrap = _validate.flag("periodic", periodic)
    if wrap and axis not in (0, 1):
        raise InvalidArgumentError(
            f"periodic: wrap is across the flow axis, so it needs axis 0 or 1, "
            f"not {axis!r} (every edge is an inlet or outlet there)"
        )
    return wrap


def percolations(
    state: Any,
    axes: Sequence[int | str],
    *,
    connectivity: int = 4,
    threads: int | None = None,
) -> list[Percolation]:
    """:func:`percolation` of a contact state along each of ``axes`` (the state's wrap, as
    with ``periodic=None``), from its one labelling per wrap (:func:`state_labelling`) and
    one classification call per labelling: what a sweep level tabulates."""
    canon = [_validate.axis(a, "axes") for a in axes]
    conn = _validate.connectivity(connectivity)
    threads = _validate.threads(threads)
    dx_f = _validate.spacing("dx", state.dx)
    periodic = getattr(state, "boundary", None) == "periodic"
    groups: dict[tuple[bool, bool], list[int | str]] = {}
    for a in dict.fromkeys(canon):  # distinct axes, in order
        groups.setdefault(_wrap_for(a, periodic), []).append(a)
    found: dict[int | str, Percolation] = {}
    for wrap, group in groups.items():
        lab = state_labelling(state, connectivity=conn, wrap=wrap, threads=threads)
        for a, res in zip(group, _core.classify(lab, group, threads=threads), strict=True):
            found[a] = _percolation_of(
                lab, res, a, conn, any(wrap), dx_f, getattr(state, "unit", None)
            )
    return [found[a] for a in canon]


def _classified(
    lab: Any,
    axis: int | str,
    conn: int,
    wrap: bool,
    dx: float,
    threads: int | None,
    unit: str | None = None,
) -> Percolation:
    """:class:`Percolation` of a labelling for ``axis`` (per-cluster work only)."""
    (res,) = _core.classify(lab, [axis], threads=threads)
    return _percolation_of(lab, res, axis, conn, wrap, dx, unit)


def _percolation_of(
    lab: Any,
    res: Any,
    axis: int | str,
    conn: int,
    wrap: bool,
    dx: float,
    unit: str | None = None,
) -> Percolation:
    """:class:`Percolation` from a labelling and its classification for ``axis``."""
    cell = dx * dx
    return Percolation(
        labels=lab.labels,
        n_clusters=int(lab.n_clusters),
        cell_counts=lab.areas,
        volumes=lab.volumes,
        classes=res.classes,
        spanning_volume=float(res.spanning_volume),
        dead_end_volume=float(res.dead_end_volume),
        trapped_volume=float(res.trapped_volume),
        free_volume=float(res.free_volume),
        spanning_cells=int(res.spanning_cells),
        dead_end_cells=int(res.dead_end_cells),
        trapped_cells=int(res.trapped_cells),
        free_cells=int(res.free_cells),
        spanning_area=int(res.spanning_cells) * cell,
        dead_end_area=int(res.dead_end_cells) * cell,
        trapped_area=int(res.trapped_cells) * cell,
        free_area=int(res.free_cells) * cell,
        n_spanning=int(res.n_spanning),
        n_dead_end=int(res.n_dead_end),
        n_trapped=int(res.n_trapped),
        axis=axis,
        connectivity=conn,
        periodic=wrap,
        dx=dx,
        unit=unit,
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
