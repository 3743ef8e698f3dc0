"""Leak-rate columns of sweeps and paper runs: ``Q``, ``K`` and ``K* = K/K(Δ = 0)``.

Per level, the steady Reynolds flow through the gap (:func:`leakpath.flow`, docs/flow.md)
along the flow axis ``flow_axis`` (0 or 1), with ``η = 1`` and ``Δp = 1``:

=============  ==========================================================  ==========
column         definition                                                  unit
=============  ==========================================================  ==========
``Q``          flow rate at ``η = Δp = 1``: the conductance ``Q/Δp``·``η``  L³
``K``          permeability ``K = Q η L/(W Δp)`` (``g³/12`` for plates)     L³
``K_star``     ``K* = K/K(Δ = 0)``                                          1
=============  ==========================================================  ==========

``K(Δ = 0)`` is the permeability of the undeformed gap ``g = max h − h`` (the flat touching
the highest point, nothing in contact), computed once per surface with the same axis and
boundary (periodic wrap across the flow for ``boundary="periodic"``). ``Q = K = K* = 0``
exactly when no open cluster spans the flow axis; with the flow switched off (``flow=False``)
the three columns are NaN.

By default (``flow=None``) the columns are computed on grids of at most
:data:`FLOW_AUTO_MAX_POINTS` points (a sparse Cholesky solve per level: milliseconds at
129², a fraction of a second at 513²) and left out (NaN) above, where they are opt-in.

A sweep computes them with :class:`LevelFlows`: the flow of a level depends on that level's
gap alone, and its factorisation runs on one core, so with two or more solver threads the
flows run on a background thread (a one-thread pool of their own) while the next contact
solve runs. The numbers are the same bits as computing them in turn: the flow solver's
results do not depend on its thread count, and levels with identical gaps (the reference
and the ``Δ = 0`` row) are solved once. On grids of 2^20 cells and more the levels pass
the factor's ordering and symbolic analysis on (:class:`leakpath._core.FlowAnalysis`,
docs/flow.md) and their flows run in submission order.
"""

from __future__ import annotations

import hashlib
import math
import time
from collections import deque
from collections.abc import Hashable
from concurrent.futures import Future, ThreadPoolExecutor, wait
from typing import Any

import numpy as np

from . import _core, _validate
from ._flow import flow, kept_analysis
from .errors import InvalidArgumentError

__all__ = [
    "FLOW_AUTO_MAX_POINTS",
    "FLOW_COLUMNS",
    "FLOW_LEVEL_COLUMNS",
    "LevelFlows",
    "flow_axis_for",
    "flow_enabled",
    "flow_star",
]

#: ``flow=None`` computes the leak-rate columns on grids of at most this many points.
FLOW_AUTO_MAX_POINTS = 513 * 513

#: (name, type) of the leak-rate columns, in CSV order (types as in the sweep's table).
FLOW_COLUMNS: tuple[tuple[str, str], ...] = (("Q", "f"), ("K", "f"), ("K_star", "f"))
#: Columns a level computes itself (``K_star`` follows from the reference).
FLOW_LEVEL_COLUMNS: tuple[str, ...] = ("Q", "K")
#: Units of the columns, with ``L`` the length unit.
FLOW_UNITS = {"Q": "{L}^3", "K": "{L}^3", "K_star": "1"}
#: Descriptions for the JSON metadata.
FLOW_DESCRIPTIONS = {
    "Q": "flow rate along flow_axis at viscosity = pressure drop = 1 (Reynolds flow)",
    "K": "permeability K = Q eta L/(W dp) along flow_axis (g^3/12 for parallel plates)",
    "K_star": "K/K(Delta=0), the undeformed gap's permeability",
}


def flow_enabled(flow_option: Any, shape: tuple[int, int]) -> bool:
    """Whether a sweep computes the leak-rate columns: ``flow`` True/False, or ``None``
    (default) for grids of at most :data:`FLOW_AUTO_MAX_POINTS` points."""
    if flow_option is None:
        return int(shape[0]) * int(shape[1]) <= FLOW_AUTO_MAX_POINTS
    if isinstance(flow_option, (bool, np.bool_)):
        return bool(flow_option)
    raise InvalidArgumentError(
        f"flow: must be True, False or None (automatic by grid size), got {flow_option!r}",
        argument="flow",
    )


def flow_axis_for(flow_axis: Any, axis: Any) -> int:
    """The flow axis (0 or 1): ``flow_axis`` if given, else the sweep's percolation ``axis``
    when that is 0 or 1, else 0 (checks: :func:`leakpath._validate.flow_axis` and
    :func:`leakpath._validate.axis`)."""
    if flow_axis is None:
        canonical = _validate.axis(axis)
        return canonical if isinstance(canonical, int) else 0
    return _validate.flow_axis(flow_axis, "flow_axis")


#: Tolerance of each level's flow (:func:`leakpath.flow`'s ``tol``): the factored answer is
#: kept when each rate's first-order error, from the exact residuals, is at most this
#: fraction of the rate (docs/flow.md, "Accuracy"), and the multigrid iterates to it. The
#: level's contact certificate (``leakpath._sweep.SOLVE_TOL``) leaves the rate uncertain
#: by more: certificates of 1e-10 and 1e-9 give rates up to 4.5e-8 apart. The single
#: flow's default, 1e-12, refines the factor's answer in two doubles on many contact gaps
#: (2049², RMD D = 2.2: rate errors 2.4e-12 at Δ = 0.5 h_s, 5.8e-10 at Δ = h_s), one more
#: two-column solve and two exact residuals, 1.2–1.6 s of a 9–10 s flow.
FLOW_TOL = 1e-9

#: Grids of at least this many cells pass the factor's analysis from level to level
#: (:class:`leakpath._core.FlowAnalysis`'s default ``min_cells``).
ANALYSIS_MIN_CELLS = 1 << 20

#: Flows queued or running at most before :meth:`LevelFlows.submit` computes one itself:
#: bounds the states held when flows are slower than contact solves.
MAX_PENDING = 3


def _state_digest(state: Any) -> bytes:
    """Digest of what a state's flow depends on within one sweep: its gap and contact mask."""
    h = hashlib.blake2b(digest_size=16)
    h.update(np.ascontiguousarray(state.gap, dtype=np.float64).tobytes())
    h.update(np.packbits(np.asarray(state.contact, dtype=bool)).tobytes())
    return h.digest()


def _timed_columns(
    state: Any,
    flow_axis: int,
    threads: int | None,
    analysis: _core.FlowAnalysis | None = None,
) -> tuple[dict[str, float], float]:
    """``({"Q": …, "K": …}, seconds)`` of :func:`leakpath.flow` on ``state`` along
    ``flow_axis`` with ``η = Δp = 1`` to :data:`FLOW_TOL`, on the factor analysis kept in
    ``analysis`` when it fits (docs/flow.md)."""
    t0 = time.perf_counter()
    with kept_analysis(analysis):
        f = flow(state, axis=flow_axis, threads=threads, tol=FLOW_TOL)
    cols = {"Q": float(f.flow_rate), "K": float(f.permeability)}
    return cols, time.perf_counter() - t0


class LevelFlows:
    """The leak-rate columns of a sweep's levels, computed beside its contact solves.

    :meth:`submit` hands over a solved level, with optional other work on it (the sweep's
    percolation and moments) to run first in the same job; :meth:`finished` returns the
    levels whose job is done, in submission order; :meth:`finish` the rest, helping with the
    ones not started; :meth:`close` stops (cancels what has not started). Each result is
    ``(key, work's result, {"Q": …, "K": …}, seconds)`` (NaN columns when not ``enabled``),
    ``seconds`` the flow's wall time. ``background=None``: on a background thread when the
    solvers have two or more threads (:func:`leakpath._core.solver_threads`), else in
    :meth:`submit`. A job on the background thread passes ``threads=1`` to its work and
    flow; one run here passes ``None`` (all solver threads).

    The flows share one :class:`leakpath._core.FlowAnalysis`: a level whose unknowns are
    among an earlier level's is factored on that level's ordering and symbolic analysis
    (grids of 2^20 cells and more, docs/flow.md). Which analysis a level uses depends on the
    levels solved before it, so on those grids the flows run strictly in submission order
    (none is taken over by :meth:`submit` or :meth:`finish`): the same bits with one thread
    or two.
    """

    def __init__(self, flow_axis: int, enabled: bool, background: bool | None = None) -> None:
        self.flow_axis = flow_axis
        self.enabled = enabled
        if background is None:
            background = enabled and _core.solver_threads() >= 2
        #: Whether the jobs run on a background thread.
        self.background = bool(background)
        self._pool = ThreadPoolExecutor(1, "leakpath-flow") if background else None
        self._queue: deque[tuple[Hashable, Future[Any], bytes | None]] = deque()
        self._jobs: dict[Future[Any], tuple[Any, Any, bool]] = {}  # inputs of queued jobs
        self._seen: set[bytes] = set()  # digests of the states whose flow a job computes
        self._cols: dict[bytes, dict[str, float]] = {}  # their columns, once taken
        #: The factor analysis the flows pass on from level to level.
        self.analysis = _core.FlowAnalysis(ANALYSIS_MIN_CELLS) if enabled else None
        self._in_order = False  # a grid on which the flows share the analysis was seen

    def _job(
        self, state: Any, work: Any, solve: bool, threads: int | None
    ) -> tuple[Any, dict[str, float] | None, float]:
        out = None if work is None else work(threads)
        if not self.enabled:
            return out, {"Q": math.nan, "K": math.nan}, 0.0
        if not solve:  # an identical state's flow: its columns are filled in when taken
            return out, None, 0.0
        cols, seconds = _timed_columns(state, self.flow_axis, threads, self.analysis)
        return out, cols, seconds

    def _here(self, state: Any, work: Any, solve: bool) -> Future[Any]:
        """A job run on this thread (on all solver threads), as a done future."""
        fut: Future[Any] = Future()
        try:
            fut.set_result(self._job(state, work, solve, None))
        except BaseException as exc:  # re-raised where the result is taken
            fut.set_exception(exc)
        return fut

    def submit(self, key: Hashable, state: Any, work: Any = None) -> None:
        """Queue the job of ``state`` under ``key``: ``work(threads)`` if given, then the
        flow (once per distinct gap and contact mask)."""
        digest = _state_digest(state) if self.enabled else None
        if self.enabled and np.size(state.gap) >= ANALYSIS_MIN_CELLS:
            self._in_order = True
        solve = digest is not None and digest not in self._seen
        if solve:
            self._seen.add(digest)  # type: ignore[arg-type]
        if self._pool is None:
            fut = self._here(state, work, solve)
        else:
            fut = self._pool.submit(self._job, state, work, solve, 1)
            self._jobs[fut] = (state, work, solve)
        self._queue.append((key, fut, digest))
        if sum(not f.done() for _, f, _ in self._queue) > MAX_PENDING and not self._help_one():
            wait([next(f for _, f, _ in self._queue if not f.done())])

    def _help_one(self) -> bool:
        """Run the newest job not yet started here (the pool's thread takes the oldest);
        False when every job has started, or when the jobs run in order (class docs)."""
        if self._in_order:
            return False
        for i in range(len(self._queue) - 1, -1, -1):
            key, fut, digest = self._queue[i]
            if fut.cancel():
                self._queue[i] = (key, self._here(*self._jobs.pop(fut)), digest)
                return True
        return False

    def _take(self) -> tuple[Hashable, Any, dict[str, float], float]:
        key, fut, digest = self._queue.popleft()
        self._jobs.pop(fut, None)
        out, cols, seconds = fut.result()
        if cols is None:
            cols = self._cols[digest]  # type: ignore[index]
        elif digest is not None:
            self._cols[digest] = cols
        return key, out, dict(cols), seconds

    def finished(self) -> list[tuple[Hashable, Any, dict[str, float], float]]:
        """The results done so far, oldest first, up to the first one not done."""
        out = []
        while self._queue and self._queue[0][1].done():
            out.append(self._take())
        return out

    def finish(self) -> list[tuple[Hashable, Any, dict[str, float], float]]:
        """All remaining results, oldest first."""
        while self._help_one():
            pass
        return [self._take() for _ in range(len(self._queue))]

    def close(self) -> None:
        """Cancel what has not started and wait for a job in progress."""
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
        self._queue.clear()
        self._jobs.clear()
        if self.analysis is not None:
            self.analysis.clear()


def flow_star(row: dict[str, Any], k_ref: float) -> float:
    """``K* = K/K(Δ = 0)`` (NaN when either is NaN or the reference is 0)."""
    k = row["K"]
    if not (math.isfinite(k) and math.isfinite(k_ref)) or k_ref == 0:
        return math.nan
    return k / k_ref


# ---------------------------------------------------------------------------- command line
def _level_list(text: str) -> list[int]:
    import argparse

    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated row indices such as 10,19, got {text!r}"
        ) from None
    if not values or min(values) < 0:
        raise argparse.ArgumentTypeError(f"expected row indices ≥ 0, got {text!r}")
    return values


def add_flow_arguments(p: Any) -> None:
    """``--flow/--no-flow``, ``--flow-axis`` and ``--flux-maps`` of ``leakpath sweep`` and
    ``leakpath paper``."""
    import argparse

    p.add_argument(
        "--flow",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="leak-rate columns Q, K, K* and their figures (default: on up to 513 x 513 "
        "points, off above)",
    )
    p.add_argument(
        "--flow-axis",
        type=int,
        choices=(0, 1),
        default=None,
        help="direction of the leak (default: --axis when it is 0 or 1, else 0)",
    )
    p.add_argument(
        "--flux-maps",
        type=_level_list,
        default=None,
        metavar="K1,K2,...",
        help="rows whose flux magnitude to map (default: the last leaking row)",
    )


def sweep_flow_options(args: Any) -> dict[str, Any]:
    """``flow``/``flow_axis`` keyword arguments of :func:`leakpath.sweep` from the CLI."""
    return {"flow": getattr(args, "flow", None), "flow_axis": getattr(args, "flow_axis", None)}
