"""Frictionless normal contact of an elastic rough surface with a rigid flat (BEM).

Conventions (all lengths in the surface's units, pressures in the units of ``E``):

* the flat first touches the highest point; the imposed approach ``Δ ≥ 0`` moves it down;
* displacement ``u = C p`` (positive into the body), ``C`` from Love's rectangle solution;
* gap ``g = max(h) − Δ − h + u`` with ``g ≥ 0``, ``p ≥ 0``, ``p·g = 0``;
* deformed surface ``s = h − u``; contact = ``p > 0``;
* contact modulus ``E* = E / (1 − ν²)``.

``boundary="free"``: the patch sits on an infinite half-space (``u → 0`` far away).
``boundary="periodic"``: the surface repeats and ``u`` has zero mean; full contact is reached
at ``Δ = max h − mean h`` and a larger approach is an error.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from . import _core
from .surfaces import Surface

if TYPE_CHECKING:
    from .flow import Flow
    from .percolation import Percolation

Boundary = Literal["free", "periodic"]
SolverName = Literal["lawson-hanson", "active-set", "polonsky-keer", "auto"]
SOLVERS = ("lawson-hanson", "active-set", "polonsky-keer", "auto")

#: Default KKT tolerance relative to the height range ``h_s``.
DEFAULT_TOL = 1e-11


def default_memory_limit() -> int:
    """Bytes leakpath may use for one solve: 70 % of physical memory."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        total = 8 << 30
    return int(0.7 * total)


def contact_modulus(E: float, nu: float) -> float:
    """``E* = E / (1 − ν²)``; validates ``E > 0`` and ``0 ≤ ν < 0.5``."""
    if not (np.isfinite(E) and E > 0):
        raise ValueError(f"E: Young's modulus must be a positive finite number, got {E!r}")
    if not (np.isfinite(nu) and 0.0 <= nu < 0.5):
        raise ValueError(f"nu: Poisson's ratio must be in [0, 0.5), got {nu!r}")
    return float(E) / (1.0 - float(nu) ** 2)


@dataclass(eq=False)
class ContactState:
    """The solved contact at one imposed approach.

    Fields are 2-D arrays on the surface grid; scalars are in the surface's length units and
    the pressure units of ``E``.
    """

    approach: float
    pressure: np.ndarray
    displacement: np.ndarray
    gap: np.ndarray
    heights: np.ndarray = field(repr=False)
    dx: float
    e_star: float
    boundary: str
    solver: str
    iterations: int
    kkt: float
    seconds: float

    @property
    def shape(self) -> tuple[int, int]:
        return self.pressure.shape  # type: ignore[return-value]

    @property
    def n_points(self) -> int:
        return int(self.pressure.size)

    @property
    def nominal_area(self) -> float:
        """``A0 = ny·nx·dx²``."""
        return self.n_points * self.dx**2

    @cached_property
    def contact(self) -> np.ndarray:
        """Contact mask ``p > 0``."""
        return self.pressure > 0

    @property
    def deformed(self) -> np.ndarray:
        """Deformed surface ``s = h − u``."""
        return self.heights - self.displacement

    @property
    def load(self) -> float:
        """Total load ``F = dx² Σ p``."""
        return float(self.pressure.sum() * self.dx**2)

    @property
    def mean_pressure(self) -> float:
        """``p̄ = F / A0``."""
        return float(self.pressure.mean())

    @property
    def contact_fraction(self) -> float:
        """``a = #(p > 0) / N``."""
        return float(np.count_nonzero(self.contact) / self.n_points)

    @property
    def contact_area(self) -> float:
        """``A = #(p > 0)·dx²``."""
        return float(np.count_nonzero(self.contact) * self.dx**2)

    @property
    def free_volume(self) -> float:
        """``V = dx² Σ g``."""
        return float(self.gap.sum() * self.dx**2)

    @property
    def mean_gap(self) -> float:
        """``ḡ = V / A0``."""
        return float(self.gap.mean())

    def percolation(self, axis: Any = 0, connectivity: int = 4) -> Percolation:
        """Percolation classes of the free region (see :func:`leakpath.percolation`)."""
        from .percolation import percolation

        key = (axis, connectivity)
        cache = self.__dict__.setdefault("_percolation_cache", {})
        if key not in cache:
            cache[key] = percolation(self, axis=axis, connectivity=connectivity)
        return cache[key]

    @property
    def percolating_volume(self) -> float:
        """``V_pg``: free volume of the clusters spanning along axis 0 (4-connectivity)."""
        return float(self.percolation().spanning_volume)

    @property
    def dead_end_volume(self) -> float:
        """Free volume of clusters touching the boundary without spanning (axis 0)."""
        return float(self.percolation().dead_end_volume)

    @property
    def trapped_volume(self) -> float:
        """Free volume of clusters touching no boundary."""
        return float(self.percolation().trapped_volume)

    def summary(self) -> dict[str, float | int | str]:
        """Scalars of this state, for tables."""
        return {
            "approach": self.approach,
            "contact_fraction": self.contact_fraction,
            "load": self.load,
            "mean_pressure": self.mean_pressure,
            "free_volume": self.free_volume,
            "mean_gap": self.mean_gap,
            "solver": self.solver,
            "iterations": self.iterations,
            "kkt": self.kkt,
            "seconds": self.seconds,
        }

    def flow(self, **kw: Any) -> Flow:
        """Leak rate: Reynolds flow through this gap (see :func:`leakpath.flow.flow`)."""
        from .flow import flow

        return flow(self, **kw)


def _as_surface(surface: Surface | np.ndarray, dx: float | None) -> Surface:
    if isinstance(surface, Surface):
        return surface
    h = np.asarray(surface)
    if h.ndim != 2:
        raise ValueError(f"heights: expected a 2-D array, got {h.ndim} dimension(s)")
    if dx is None:
        raise ValueError("dx: give the grid spacing when passing a bare height array")
    return Surface(np.asarray(h, dtype=np.float64), float(dx))


class ContactProblem:
    """A rough surface on an elastic half-space, solved at as many approaches as needed.

    Keeps the influence kernel, the FFT operator and the Lawson–Hanson Cholesky factor between
    solves, so a sweep over increasing approaches can warm-start from the previous level.
    """

    def __init__(
        self,
        surface: Surface | np.ndarray,
        *,
        E: float = 1.0,
        nu: float = 0.0,
        boundary: Boundary = "free",
        dx: float | None = None,
        memory_limit: int | None = None,
    ) -> None:
        self.surface = _as_surface(surface, dx)
        if boundary not in ("free", "periodic"):
            raise ValueError(f"boundary: must be 'free' or 'periodic', got {boundary!r}")
        self.boundary = boundary
        self.e_star = contact_modulus(E, nu)
        self.memory_limit = int(memory_limit or default_memory_limit())
        h = np.ascontiguousarray(self.surface.heights, dtype=np.float64)
        self._h = h
        self.h_max = float(h.max())
        self.h_range = float(h.max() - h.min())
        self._core = _core.ContactProblem(
            h, self.surface.dx, self.e_star, boundary, self.memory_limit
        )
        self._last: ContactState | None = None

    @property
    def max_approach(self) -> float:
        """Largest allowed approach: ``h_s`` (free) or ``max h − mean h`` (periodic)."""
        if self.boundary == "periodic":
            return self.h_max - float(self._h.mean())
        return self.h_range

    def _check_approach(self, approach: float) -> float:
        try:
            a = float(approach)
        except (TypeError, ValueError):
            raise ValueError(f"approach: must be a number, got {approach!r}") from None
        if not np.isfinite(a) or a < 0:
            raise ValueError(f"approach: must be a finite number ≥ 0, got {approach!r}")
        limit = self.max_approach
        if a > limit * (1 + 1e-12) + 1e-300:
            what = (
                "full contact (max h − mean h)"
                if self.boundary == "periodic"
                else "h_s = max h − min h"
            )
            raise ValueError(
                f"approach: {a:.6g} exceeds {what} = {limit:.6g}; "
                "nothing more can be pressed into contact"
            )
        return min(a, limit)

    def solve(
        self,
        approach: float,
        *,
        solver: SolverName = "lawson-hanson",
        warm_start: bool | ContactState | np.ndarray | None = None,
        tol: float | None = None,
        max_iter: int | None = None,
    ) -> ContactState:
        """Solve the contact at imposed approach ``Δ`` (see the module docstring).

        ``solver``: ``"lawson-hanson"`` (the paper: one point enters the contact set per
        iteration), ``"active-set"`` (Lawson–Hanson with blocks of points entering at once:
        the same unique minimiser, far fewer factor updates), ``"polonsky-keer"``
        (matrix-free conjugate gradients), ``"auto"``: Polonsky–Keer to find the contact set,
        then an exact Lawson–Hanson finish from that set when its Cholesky factor fits in
        half the memory limit (the result's ``solver`` reads
        ``"polonsky-keer+active-set"``), else the Polonsky–Keer answer alone. With
        ``warm_start=True`` it continues from the previous solve's factor instead.

        ``warm_start``: ``None``/``False`` start from ``p = 0`` (the paper); ``True`` from the
        contact set of this problem's previous solve; a :class:`ContactState` or a boolean
        contact mask from that set.
        """
        a = self._check_approach(approach)
        if solver not in SOLVERS:
            raise ValueError(f"solver: must be one of {', '.join(SOLVERS)}; got {solver!r}")
        tol = DEFAULT_TOL if tol is None else float(tol)
        if not (np.isfinite(tol) and tol > 0):
            raise ValueError(f"tol: must be a positive number, got {tol!r}")
        if solver == "auto":
            return self._solve_auto(a, warm_start, tol, max_iter)
        if solver == "polonsky-keer":
            return self._solve_pk(a, warm_start, tol, max_iter)
        start, contact_set = self._start(warm_start)
        out = self._core.solve_lawson_hanson(
            a,
            start=start,
            contact_set=contact_set,
            tol=tol,
            max_iter=max_iter,
            block=(solver == "active-set"),
        )
        state = self._state(out, solver)
        self._last = state
        return state

    def _solve_auto(
        self, a: float, warm_start: Any, tol: float, max_iter: int | None
    ) -> ContactState:
        if warm_start is True and self._last is not None and self._core.n_passive > 0:
            return self.solve(a, solver="active-set", warm_start=True, tol=tol, max_iter=max_iter)
        if a == 0.0:
            return self.solve(a, solver="active-set", tol=tol, max_iter=max_iter)
        rough = self._solve_pk(a, warm_start, max(tol, 1e-9), max_iter)
        k = int(np.count_nonzero(rough.contact))
        full = k == rough.n_points
        # Worst case of the growing factor: 1.5 × k rows, squared, 8 bytes each.
        factor_bytes = 8 * (1.5 * k) ** 2
        if full or factor_bytes > 0.5 * self.memory_limit:
            return rough
        exact = self.solve(
            a, solver="active-set", warm_start=rough.contact, tol=tol, max_iter=max_iter
        )
        exact.solver = "polonsky-keer+active-set"
        exact.iterations += rough.iterations
        exact.seconds += rough.seconds
        return exact

    def _start(self, warm_start: Any) -> tuple[str, np.ndarray | None]:
        if warm_start is None or warm_start is False:
            return "cold", None
        if warm_start is True:
            return "previous", None
        mask = warm_start.contact if isinstance(warm_start, ContactState) else warm_start
        mask = np.asarray(mask)
        if mask.shape != self._h.shape or mask.dtype != bool:
            raise ValueError(
                "warm_start: expected True/False, a ContactState or a boolean contact mask of "
                f"shape {self._h.shape}"
            )
        return "set", np.flatnonzero(mask).astype(np.int64)

    def _solve_pk(self, a: float, warm_start: Any, tol: float, max_iter: int | None):
        if not hasattr(_core, "solve_polonsky_keer"):  # pragma: no cover
            raise ValueError("solver: polonsky-keer is not available in this build")
        init = None
        if warm_start is True and self._last is not None:
            init = self._last.pressure
        elif isinstance(warm_start, ContactState):
            init = warm_start.pressure
        out = _core.solve_polonsky_keer(
            self._h,
            self.surface.dx,
            self.e_star,
            self.boundary,
            approach=a,
            tol=tol,
            max_iter=max_iter,
            initial_pressure=init,
            memory_limit=self.memory_limit,
        )
        state = self._state(out, "polonsky-keer")
        self._last = state
        return state

    def _state(self, out: dict[str, Any], solver: str) -> ContactState:
        return ContactState(
            approach=float(out["approach"]),
            pressure=out["pressure"],
            displacement=out["displacement"],
            gap=out["gap"],
            heights=self._h,
            dx=self.surface.dx,
            e_star=self.e_star,
            boundary=self.boundary,
            solver=solver,
            iterations=int(out["iterations"]),
            kkt=float(out["kkt"]),
            seconds=float(out["seconds"]),
        )


def solve(
    surface: Surface | np.ndarray,
    approach: float,
    *,
    E: float = 1.0,
    nu: float = 0.0,
    boundary: Boundary = "free",
    solver: SolverName = "lawson-hanson",
    warm_start: bool | ContactState | np.ndarray | None = None,
    tol: float | None = None,
    max_iter: int | None = None,
    dx: float | None = None,
    memory_limit: int | None = None,
) -> ContactState:
    """Solve the contact of ``surface`` with a rigid flat at imposed approach ``approach``.

    See :class:`ContactProblem` and :meth:`ContactProblem.solve`. ``warm_start=True`` has no
    previous solve to start from here; pass a :class:`ContactState` or a contact mask.
    """
    problem = ContactProblem(
        surface, E=E, nu=nu, boundary=boundary, dx=dx, memory_limit=memory_limit
    )
    return problem.solve(
        approach,
        solver=solver,
        warm_start=None if warm_start is True else warm_start,
        tol=tol,
        max_iter=max_iter,
    )
