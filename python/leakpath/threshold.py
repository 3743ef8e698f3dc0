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
) -> PercolationThreshold:
    """Approach ``Δ_c`` and contact fraction at which the free region stops percolating.

    Bisection on the approach between ``0`` (nothing in contact: the free region spans) and
    the largest approach (``h_s`` free, ``max h − mean h`` periodic), to ``atol`` in approach
    (default ``1e-4·h_s``). Each solve warm-starts from the contact set of the nearest
    percolating level below. The result assumes the spanning property changes once along
    the sweep, as it does when the contact set grows with the approach.
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
    _validate.axis(axis)
    _validate.connectivity(connectivity)
    prob = ContactProblem(surface, E=E, nu=nu, boundary=boundary)

    def spans(state: ContactState) -> bool:
        return bool(state.percolation(axis=axis, connectivity=connectivity).percolates)

    lo_state = prob.solve(0.0, solver=solver)
    solves = 1
    if not spans(lo_state):
        # Even the undeformed free region does not span (e.g. a wall of maxima).
        frac = lo_state.contact_fraction
        return PercolationThreshold(0.0, frac, 0.0, lo_state, lo_state, 1, axis)
    hi = prob.max_approach
    hi_state = prob.solve(hi, solver=solver)
    solves += 1
    if spans(hi_state):
        return PercolationThreshold(
            float("nan"), float("nan"), float("nan"), hi_state, None, solves, axis
        )
    lo = 0.0
    while hi - lo > tol and solves < max_solves:
        mid = 0.5 * (lo + hi)
        st = prob.solve(mid, solver=solver, warm_start=lo_state if lo > 0 else None)
        solves += 1
        if spans(st):
            lo, lo_state = mid, st
        else:
            hi, hi_state = mid, st
    return PercolationThreshold(
        approach=hi,
        contact_fraction=hi_state.contact_fraction,
        approach_dimensionless=hi / hs if hs > 0 else float("nan"),
        below=lo_state,
        above=hi_state,
        solves=solves,
        axis=axis,
    )
