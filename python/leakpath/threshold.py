"""The percolation threshold: the approach at which the free region stops spanning."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import _validate
from .contact import DEFAULT_TOL, Boundary, ContactProblem, ContactState, SolverName
from .errors import InvalidArgumentError
from .surfaces import Surface

#: Default bisection tolerance on the approach, relative to the height range ``h_s``.
DEFAULT_ATOL_REL = 1e-4

#: The contact solves of a threshold search default to a KKT tolerance of this fraction of
#: ``atol/h_s`` (at most :data:`MAX_SOLVE_TOL`, at least ``contact.DEFAULT_TOL``): a gap error
#: a hundred times smaller than the approach resolution.
SOLVE_TOL_PER_ATOL = 1e-2

#: Loosest default KKT tolerance of a threshold search's contact solves (relative to h_s).
MAX_SOLVE_TOL = 1e-6


@dataclass(frozen=True, eq=False)
class PercolationThreshold:
    """Result of :func:`percolation_threshold`.

    ``approach`` is the smallest imposed approach (within ``atol``) at which no free cluster
    joins the two sides along ``axis``; ``contact_fraction`` is the contact fraction there.
    ``below`` is the last solved state that still percolates, ``above`` the first that does
    not (``None`` when the free region still spans at the largest approach: then
    ``approach`` and ``contact_fraction`` are NaN). ``solves`` counts the contact solves
    this search ran (states shared with an earlier axis of :func:`percolation_thresholds`
    are not counted again).
    """

    approach: float
    contact_fraction: float
    approach_dimensionless: float
    below: ContactState
    above: ContactState | None
    solves: int
    axis: Any

    @property
    def found(self) -> bool:
        return self.above is not None

    def __repr__(self) -> str:
        # The two bracketing states are grids: name their approaches only.
        u = getattr(self.below, "unit", None) or "length"
        above = "None" if self.above is None else f"{self.above.approach:.6g}"
        return (
            f"PercolationThreshold(approach={self.approach:.6g} {u}, "
            f"contact_fraction={self.contact_fraction:.4g}, "
            f"approach/h_s={self.approach_dimensionless:.4g}, axis={self.axis!r}, "
            f"found={self.found}, solves={self.solves}, "
            f"bracket=[{self.below.approach:.6g}, {above}] {u})"
        )


def percolation_threshold(
    surface: Surface,
    *,
    axis: Any = 0,
    connectivity: int = 4,
    solver: SolverName = "auto",
    boundary: Boundary = "free",
    E: float = 1.0,
    nu: float = 0.0,
    atol: float | None = None,
    tol: float | None = None,
    max_solves: int = 60,
    warm_start: bool = True,
) -> PercolationThreshold:
    """Approach ``Δ_c`` and contact fraction at which the free region stops percolating.

    Bisection on the approach, to ``atol`` in approach (default ``1e-4·h_s``). The bracket
    starts at ``[0, Δ_max]``: ``Δ = 0`` (nothing in contact: the free region spans) and
    ``Δ_max = max h − mean h`` (periodic: full contact) or ``h_s`` (free). A free patch may
    still percolate at ``h_s`` (about half of it is in contact there): the upper end is then
    doubled until the free region stops spanning (at most ``2^10·h_s``).

    ``tol``: KKT tolerance of each contact solve, relative to ``h_s``
    (:meth:`ContactProblem.solve`). Default ``10⁻²·atol/h_s``, clipped to
    ``[1e-12, 1e-6]`` (``1e-6`` with the default ``atol``): every gap is then known to a
    hundredth of the approach resolution, while a solve to ``1e-12`` would take about twice
    the iterations without moving the bracket.

    ``warm_start`` (default): each solve starts from the pressure interpolated linearly in
    the approach between the two states bracketing it, ``p₀ = (1 − t)·p_lo + t·p_hi`` with
    ``t = (Δ − Δ_lo)/(Δ_hi − Δ_lo)`` (feasible, ``p₀ ≥ 0``, and close: the pressure grows
    smoothly with the approach); while no state above has been solved, from the linear
    extrapolation of the two solved states nearest below, ``max(p_lo + t·(p_lo − p_prev),
    0)`` with ``t = (Δ − Δ_lo)/(Δ_lo − Δ_prev)`` (from the state below while it is the only
    one); ``False`` solves each one from ``p = 0``. The result assumes the spanning
    property changes once along the approach, as it does when the contact set grows with it.
    """
    found = percolation_thresholds(
        surface,
        axes=(_validate.axis(axis),),
        connectivity=connectivity,
        solver=solver,
        boundary=boundary,
        E=E,
        nu=nu,
        atol=atol,
        tol=tol,
        max_solves=max_solves,
        warm_start=warm_start,
    )
    return found[0]


def percolation_thresholds(
    surface: Surface,
    *,
    axes: Sequence[Any] = (0, 1),
    connectivity: int = 4,
    solver: SolverName = "auto",
    boundary: Boundary = "free",
    E: float = 1.0,
    nu: float = 0.0,
    atol: float | None = None,
    tol: float | None = None,
    max_solves: int = 60,
    warm_start: bool = True,
) -> list[PercolationThreshold]:
    """:func:`percolation_threshold` along each of ``axes`` (default both, 0 and 1), sharing
    one :class:`ContactProblem` and every solved state.

    The axes are searched in order; each later search starts from the tightest bracket the
    states solved so far give for its axis, so it solves only the levels between them.
    Each result equals what :func:`percolation_threshold` returns for its axis up to the
    states its search started from (the same ``atol``; the bracket may differ within it).
    ``max_solves`` applies to each axis.
    """
    if not isinstance(surface, Surface):
        raise InvalidArgumentError(
            f"surface: expected a leakpath Surface, got {type(surface).__name__}"
        )
    hs = surface.height_range
    if not hs > 0:
        raise InvalidArgumentError(
            "surface: flat (h_s = max h − min h = 0): every point touches at once, so there "
            "is no percolation threshold to find"
        )
    if isinstance(axes, (str, bytes)) or not isinstance(axes, Sequence) or not axes:
        raise InvalidArgumentError(
            f"axes: expected a non-empty sequence of axes (0, 1, 'either', 'both'), got "
            f"{axes!r}",
            argument="axes",
        )
    canon = [_validate.axis(a, "axes") for a in axes]
    tol_a = DEFAULT_ATOL_REL * hs if atol is None else _validate.positive("atol", atol)
    if tol is None:
        solve_tol = min(max(SOLVE_TOL_PER_ATOL * tol_a / hs, DEFAULT_TOL), MAX_SOLVE_TOL)
    else:
        solve_tol = _validate.positive("tol", tol)
    max_solves = _validate.integer("max_solves", max_solves, low=2, high=100_000)
    warm_start = _validate.flag("warm_start", warm_start)
    _validate.connectivity(connectivity)
    _validate.choice("solver", solver, ("auto", "polonsky-keer", "active-set", "lawson-hanson"))
    prob = ContactProblem(surface, E=E, nu=nu, boundary=boundary)
    search = _Search(prob, solver, solve_tol, warm_start)
    return [
        search.threshold(
            lambda st, a=a: bool(st.percolation(axis=a, connectivity=connectivity).percolates),
            a,
            tol_a,
            max_solves,
        )
        for a in canon
    ]


class _Search:
    """Solved states of one problem by approach, and the bisection on a spanning verdict."""

    def __init__(self, prob: ContactProblem, solver: str, tol: float, warm: bool) -> None:
        self.prob = prob
        self.solver = solver
        self.tol = tol
        self.warm = warm
        self.states: dict[float, ContactState] = {}
        self.hs = prob.h_range

    def solve(
        self, approach: float, below: ContactState | None, above: ContactState | None
    ) -> ContactState:
        if approach in self.states:
            return self.states[approach]
        start: Any = None
        if self.warm and below is not None and below.approach > 0:
            start = below
            if above is not None and above.approach > below.approach:
                t = (approach - below.approach) / (above.approach - below.approach)
                start = (1.0 - t) * below.pressure + t * above.pressure
            else:
                # Nothing solved above: extrapolate linearly from the two solved states
                # nearest below, clipped at p = 0.
                prev = [a for a in self.states if 0.0 < a < below.approach]
                if prev:
                    p_prev = self.states[max(prev)]
                    t = (approach - below.approach) / (below.approach - p_prev.approach)
                    start = np.maximum(
                        below.pressure + t * (below.pressure - p_prev.pressure), 0.0
                    )
        st = self.prob.solve(approach, solver=self.solver, warm_start=start, tol=self.tol)
        self.states[approach] = st
        return st

    def threshold(
        self, spans: Callable[[ContactState], bool], axis: Any, atol: float, max_solves: int
    ) -> PercolationThreshold:
        prob = self.prob
        n0 = len(self.states)

        def solves() -> int:
            return len(self.states) - n0

        lo_state = self.solve(0.0, None, None)
        if not spans(lo_state):
            # Even the undeformed free region does not span (e.g. a wall of maxima).
            frac = lo_state.contact_fraction
            return PercolationThreshold(0.0, frac, 0.0, lo_state, lo_state, solves(), axis)
        # The tightest bracket the states solved so far (for another axis) give: the last
        # spanning one and the first non-spanning one above it.
        known = sorted(self.states)
        lo = max(a for a in known if spans(self.states[a]))
        lo_state = self.states[lo]
        blocked = [a for a in known if a > lo and not spans(self.states[a])]
        hi_state: ContactState | None = None
        doublings = 0
        if blocked:
            hi = blocked[0]
            hi_state = self.states[hi]
        else:
            hi = prob.max_approach
            if prob.boundary != "periodic":
                while hi <= lo:
                    hi *= 2.0
                    doublings += 1
                hi_state = self.solve(hi, lo_state, None)
            # Periodic: full contact has no free cell, so nothing spans; no need to solve
            # there (near full contact is the slowest state to solve). Solved at the end
            # only if still needed.
        while hi_state is not None and spans(hi_state):
            if (
                prob.boundary != "free"
                or doublings >= _MAX_DOUBLINGS
                or solves() >= max_solves
            ):
                return PercolationThreshold(
                    float("nan"), float("nan"), float("nan"), hi_state, None, solves(), axis
                )
            lo, lo_state = hi, hi_state
            hi *= 2.0
            hi_state = self.solve(hi, lo_state, None)
            doublings += 1
        while hi - lo > atol and solves() < max_solves:
            mid = 0.5 * (lo + hi)
            st = self.solve(mid, lo_state, hi_state)
            if spans(st):
                lo, lo_state = mid, st
            else:
                hi, hi_state = mid, st
        if hi_state is None:
            hi_state = self.solve(hi, lo_state, None)
        return PercolationThreshold(
            approach=hi,
            contact_fraction=hi_state.contact_fraction,
            approach_dimensionless=hi / self.hs,
            below=lo_state,
            above=hi_state,
            solves=solves(),
            axis=axis,
        )


#: Doublings of the free-boundary bracket past ``h_s`` before the search gives up.
_MAX_DOUBLINGS = 10

__all__ = ["PercolationThreshold", "percolation_threshold", "percolation_thresholds"]
