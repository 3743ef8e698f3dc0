"""The percolation threshold: the approach at which the free region stops spanning."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from . import _validate
from .contact import Boundary, ContactProblem, ContactState, SolverName
from .errors import InvalidArgumentError
from .surfaces import Surface


@dataclass(frozen=True, eq=False)
class PercolationThreshold:
    """Result of :func:`percolation_threshold`.

    ``approach`` is the smallest imposed approach (within ``atol``) at which no free cluster
    joins the two sides along ``axis``; ``contact_fraction`` is the contact fraction there.
    ``below`` is the last solved state that still percolates, ``above`` the first that does
    not (``None`` when the free region still spans at the largest approach: then
    ``approach`` and ``contact_fraction`` are NaN).
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
        above = "None" if self.above is None else f"{self.above.approach:.6g}"
        return (
            f"PercolationThreshold(approach={self.approach:.6g}, "
            f"contact_fraction={self.contact_fraction:.4g}, "
            f"approach/h_s={self.approach_dimensionless:.4g}, axis={self.axis!r}, "
            f"found={self.found}, solves={self.solves}, "
            f"bracket=[{self.below.approach:.6g}, {above}])"
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
    max_solves: int = 60,
    warm_start: bool = True,
) -> PercolationThreshold:
    """Approach ``Δ_c`` and contact fraction at which the free region stops percolating.

    Bisection on the approach, to ``atol`` in approach (default ``1e-4·h_s``). The bracket
    starts at ``[0, Δ_max]``: ``Δ = 0`` (nothing in contact: the free region spans) and
    ``Δ_max = max h − mean h`` (periodic: full contact) or ``h_s`` (free). A free patch may
    still percolate at ``h_s`` (about half of it is in contact there): the upper end is then
    doubled until the free region stops spanning (at most ``2^10·h_s``).

    ``warm_start`` (default): each solve starts from the nearest solved state below it (the
    contact grows with the approach, so that state's pressure is a close, feasible start);
    ``False`` solves each one from ``p = 0``. The result assumes the spanning property
    changes once along the approach, as it does when the contact set grows with it.
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
    tol = 1e-4 * hs if atol is None else _validate.positive("atol", atol)
    max_solves = _validate.integer("max_solves", max_solves, low=2, high=100_000)
    warm_start = _validate.flag("warm_start", warm_start)
    _validate.axis(axis)
    _validate.connectivity(connectivity)
    prob = ContactProblem(surface, E=E, nu=nu, boundary=boundary)

    def spans(state: ContactState) -> bool:
        return bool(state.percolation(axis=axis, connectivity=connectivity).percolates)

    def solve(approach: float, below: ContactState | None) -> ContactState:
        start = below if (warm_start and below is not None and below.approach > 0) else None
        return prob.solve(approach, solver=solver, warm_start=start)

    lo_state = solve(0.0, None)
    solves = 1
    if not spans(lo_state):
        # Even the undeformed free region does not span (e.g. a wall of maxima).
        frac = lo_state.contact_fraction
        return PercolationThreshold(0.0, frac, 0.0, lo_state, lo_state, 1, axis)
    lo = 0.0
    hi = prob.max_approach
    hi_state: ContactState | None = None
    if boundary == "periodic":
        # Full contact: no free cell, so nothing spans; no need to solve there (near full
        # contact is the slowest state to solve). Solved at the end only if still needed.
        pass
    else:
        hi_state = solve(hi, lo_state)
        solves += 1
    doublings = 0
    while hi_state is not None and spans(hi_state):
        if boundary != "free" or doublings >= _MAX_DOUBLINGS or solves >= max_solves:
            return PercolationThreshold(
                float("nan"), float("nan"), float("nan"), hi_state, None, solves, axis
            )
        lo, lo_state = hi, hi_state
        hi *= 2.0
        hi_state = solve(hi, lo_state)
        solves += 1
        doublings += 1
    while hi - lo > tol and solves < max_solves:
        mid = 0.5 * (lo + hi)
        st = solve(mid, lo_state)
        solves += 1
        if spans(st):
            lo, lo_state = mid, st
        else:
            hi, hi_state = mid, st
    if hi_state is None:
        hi_state = solve(hi, lo_state)
        solves += 1
    return PercolationThreshold(
        approach=hi,
        contact_fraction=hi_state.contact_fraction,
        approach_dimensionless=hi / hs,
        below=lo_state,
        above=hi_state,
        solves=solves,
        axis=axis,
    )


#: Doublings of the free-boundary bracket past ``h_s`` before the search gives up.
_MAX_DOUBLINGS = 10
