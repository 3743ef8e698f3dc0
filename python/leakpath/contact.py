"""Frictionless normal contact of an elastic rough surface with a rigid flat (BEM).

Conventions (all lengths in the surface's units, pressures in the units of ``E``):

* the flat first touches the highest point; the imposed approach ``Δ ≥ 0`` moves it down;
* displacement ``u = C p`` (positive into the body), ``C`` from Love's rectangle solution;
* gap ``g = max(h) − Δ − h + u`` with ``g ≥ 0``, ``p ≥ 0``, ``p·g = 0``;
* deformed surface ``s = h − u``; contact = ``p > 0``;
* contact modulus ``E* = E / (1 − ν²)``.

``boundary="free"``: the patch sits on an infinite half-space (``u → 0`` far away).
Any approach ``Δ ≥ 0`` is allowed (about half a rough patch is in contact at ``Δ = h_s``).
``boundary="periodic"``: the surface repeats and ``u`` has zero mean; full contact is reached
at ``Δ = max h − mean h`` and a larger approach is an error. The conventions are written out
in ``docs/conventions.md``.

``hardness=H`` caps the contact pressure at ``p ≤ H`` (elastic–perfectly-plastic contact,
Polonsky–Keer only): points at ``p = H`` yield, and the interpenetration ``−g`` there is kept
as permanent plastic deformation (:attr:`ContactState.plastic_displacement`).
:meth:`ContactProblem.unloading` solves the elastic(-capped) contact of the permanently
deformed surface. See ``docs/plasticity.md``.
"""

from __future__ import annotations

import math
import sys
from typing import Any, Literal

import numpy as np

from . import _core, _validate
from ._contact_state import ContactState
from .errors import InvalidArgumentError
from .surfaces import Surface, check_slope

Boundary = Literal["free", "periodic"]
SolverName = Literal["lawson-hanson", "active-set", "polonsky-keer", "auto"]
SOLVERS = ("lawson-hanson", "active-set", "polonsky-keer", "auto")

#: Default KKT tolerance relative to the height range ``h_s``, for every solver. At this
#: tolerance the Polonsky–Keer contact set no longer changes: it equals the exact solvers'.
DEFAULT_TOL = 1e-12

#: ``solver="auto"`` uses the exact block active set on grids of at most this many points
#: (displacement control) and Polonsky–Keer above. The policy and the measurements behind it
#: live with the solvers in the Rust core (``src/contact/problem.rs``, ``Solver::resolve``).
AUTO_ACTIVE_SET_MAX_POINTS: int = _core.AUTO_ACTIVE_SET_MAX_POINTS


def default_memory_limit() -> int:
    """Bytes leakpath may use for one solve: what this process may still allocate (the least
    of the cgroup and ulimit headroom and the available memory) times a safety fraction; see
    :func:`leakpath._memory.memory_limit`."""
    from ._memory import memory_limit

    return memory_limit()


def contact_modulus(E: float, nu: float) -> float:
    """``E* = E / (1 − ν²)`` [pressure], for ``E > 0`` and ``−1 < ν ≤ 0.5``.

    ``ν = 0.5`` (incompressible, e.g. rubber) gives ``E* = 4E/3``; ``ν < 0`` (auxetic
    materials) is allowed down to the thermodynamic bound ``ν > −1``. ``E*`` must be a
    normal double (so the compliance ``∝ 1/E*`` does not overflow); otherwise ``E`` is
    refused.
    """
    e = _validate.positive("E", E, what="a positive finite Young's modulus")
    poisson = _validate.real(
        "nu", nu, low=-1.0, high=0.5, low_open=True, what="a Poisson's ratio in (-1, 0.5]"
    )
    e_star = e / (1.0 - poisson * poisson)
    if not (sys.float_info.min <= e_star < math.inf):
        raise InvalidArgumentError(
            f"E: {E!r} gives a contact modulus E* = E/(1 − ν²) = {e_star!r} outside the normal "
            "floating-point range (the compliance 1/E* would overflow, or E* itself); express "
            "E in another pressure unit"
        )
    return e_star


def check_hardness(hardness: Any) -> float | None:
    """``hardness`` as a positive float [pressure], or ``None`` for none (``None`` or
    ``inf``); anything else raises :class:`~leakpath.errors.InvalidArgumentError` naming it."""
    if hardness is None:
        return None
    if isinstance(hardness, (bool, np.bool_)) or not isinstance(
        hardness, (int, float, np.integer, np.floating)
    ):
        raise InvalidArgumentError(
            f"hardness: expected a positive number [pressure, E's unit] or None, got "
            f"{type(hardness).__name__} {_validate.describe(hardness, 40)}",
            argument="hardness",
        )
    h = float(hardness)
    if h == math.inf:
        return None
    if not (h > 0 and math.isfinite(h)):
        raise InvalidArgumentError(
            f"hardness: must be a positive number (or None / inf for elastic contact), got "
            f"{hardness!r}",
            argument="hardness",
        )
    return h


def _describe_start(value: Any) -> str:
    """A short description of a rejected ``warm_start``: its type and value."""
    return f"{type(value).__name__} {_validate.describe(value, 40)}"


def _as_surface(surface: Surface | np.ndarray, dx: float | None) -> Surface:
    if isinstance(surface, Surface):
        if dx is not None and _validate.spacing("dx", dx) != surface.dx:
            raise InvalidArgumentError(
                f"dx: {dx!r} conflicts with the surface's own dx = {surface.dx!r}; omit dx, or "
                "build Surface(surface.heights, dx) to rescale"
            )
        return surface
    if dx is None:
        raise InvalidArgumentError("dx: give the grid spacing when passing a bare height array")
    return Surface(surface, dx)  # copies and validates heights and dx


class ContactProblem:
    """A rough surface on an elastic half-space, solved at as many approaches as needed.

    Keeps the influence kernel, the FFT operator and the Lawson–Hanson Cholesky factor between
    solves, so a sweep over increasing approaches can warm-start from the previous level.

    ``hardness``: the hardness ``H`` [pressure, the unit of ``E``] of the surface: every solve
    caps the pressure at ``p ≤ H`` (elastic–perfectly-plastic contact, Polonsky–Keer; ``None``
    or ``inf``: elastic). See ``docs/plasticity.md``.
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
        hardness: float | None = None,
    ) -> None:
        self.surface = _as_surface(surface, dx)
        check_slope(self.surface, stacklevel=2)  # the small-slope model's range
        self.boundary = _validate.boundary(boundary)
        self.e_star = contact_modulus(E, nu)
        self.hardness = check_hardness(hardness)
        #: Plastic displacement of the surface this problem solves relative to the original
        #: one (an unloading problem, :meth:`unloading`), and the height of the original's
        #: highest point above this surface's (the approach offset): approaches stay referenced
        #: to the original surface's highest point.
        self._plastic_base: np.ndarray | None = None
        self._original: np.ndarray | None = None
        self._approach_offset = 0.0
        _validate.contact_scales(self.e_star, self.surface.dx, self.surface.height_range)
        limit = _validate.memory_limit(memory_limit)
        self.memory_limit = default_memory_limit() if limit is None else limit
        h = np.ascontiguousarray(self.surface.heights, dtype=np.float64)
        self._h = h
        self.h_max = float(h.max())
        self.h_range = float(h.max() - h.min())
        self._core = _core.ContactProblem(
            h, self.surface.dx, self.e_star, boundary, self.memory_limit
        )
        self._last: ContactState | None = None

    def __repr__(self) -> str:
        ny, nx = self.surface.shape
        return (
            f"ContactProblem({ny}x{nx} surface, dx={self.surface.dx:.6g}, "
            f"E*={self.e_star:.6g}, boundary={self.boundary!r}, "
            + ("" if self.hardness is None else f"hardness={self.hardness:.6g}, ")
            + f"h_s={self.h_range:.6g}, max_approach={self.max_approach:.6g})"
        )

    def unloading(self, state: ContactState) -> ContactProblem:
        """The contact problem of ``state``'s permanently deformed surface ``h − w_p``, for
        unloading (and reloading) after plastic deformation.

        Same ``E*``, boundary, ``dx`` and hardness. Approaches (given and reported) stay
        referenced to the highest point of the *original* surface: the flat sits at
        ``max h − Δ``. Its states carry the permanent ``w_p`` of ``state`` (plus any new
        yield), their ``heights`` are the original ones, so ``gap``, ``deformed`` and the
        percolation and flow of the free volume are those of the deformed interface.
        """
        if not isinstance(state, ContactState):
            raise InvalidArgumentError(
                f"state: expected a ContactState, got {type(state).__name__}", argument="state"
            )
        original = self._original if self._original is not None else self._h
        if state.pressure.shape != original.shape or state.dx != self.surface.dx:
            raise InvalidArgumentError(
                "state: not a state of this problem's surface (shape or dx differ)",
                argument="state",
            )
        return self._unloading_from(np.array(state.plastic_displacement, dtype=np.float64))

    def _unloading_from(self, w: np.ndarray) -> ContactProblem:
        """:meth:`unloading` from a plastic displacement field ``w ≥ 0`` of the original
        surface."""
        original = self._original if self._original is not None else self._h
        deformed = original - w
        out = ContactProblem(
            Surface(deformed, self.surface.dx),
            E=self.e_star,
            nu=0.0,
            boundary=self.boundary,  # type: ignore[arg-type]
            memory_limit=self.memory_limit,
            hardness=self.hardness,
        )
        out._plastic_base = w
        out._original = original
        out._approach_offset = float(original.max()) - out.h_max
        return out

    @property
    def max_approach(self) -> float:
        """The approach of a full sweep: ``h_s`` (free; larger approaches are allowed too) or
        ``max h − mean h`` (periodic: full contact, the largest allowed)."""
        if self.boundary == "periodic":
            return self.h_max - float(self._h.mean())
        return self.h_range

    def _check_approach(self, approach: float) -> float:
        # A free-boundary patch keeps gaining contact past h_s (about half of it is in
        # contact at Δ = h_s), and a capped problem is well posed at any approach (periodic:
        # past full contact the pressure rises to the hardness everywhere).
        periodic_elastic = self.boundary == "periodic" and self.hardness is None
        full = self.max_approach if periodic_elastic else None
        return _validate.approach(approach, full_contact=full)

    def solve(
        self,
        approach: float | None = None,
        *,
        mean_pressure: float | None = None,
        solver: SolverName = "auto",
        warm_start: bool | ContactState | np.ndarray | None = None,
        tol: float | None = None,
        max_iter: int | None = None,
        threads: int | None = None,
    ) -> ContactState:
        """Solve the contact at an imposed approach ``Δ`` or an imposed mean pressure ``p̄``.

        Give exactly one of ``approach`` (displacement control, ``Δ ≥ 0`` [length]) and
        ``mean_pressure`` (load control, ``p̄ = F/A0 > 0`` [pressure]; the approach is then an
        output, the state's ``approach``).

        ``solver`` (every one returns the same unique minimiser, checked by the KKT
        certificate ``kkt ≤ tol``, default :data:`DEFAULT_TOL` relative to ``h_s``, or past
        the height range to ``max(h_s, Δ)`` and under a mean pressure to ``max(h_s, |Δ|,
        p̄·C_00)``, where round-off is relative to them; ``docs/conventions.md``):

        * ``"auto"`` (default): Polonsky–Keer, matrix-free and preconditioned, on grids of more
          than :data:`AUTO_ACTIVE_SET_MAX_POINTS` points; the exact block active set on smaller
          ones (displacement control), where its dense factor is cheaper. The state's
          ``solver`` names the one that ran.
        * ``"polonsky-keer"``: constrained conjugate gradients with the FFT operator.
        * ``"active-set"``: Lawson–Hanson with blocks of points entering at once (exact to
          round-off; dense Cholesky of the contact block, so O(k³) in the contact points k).
        * ``"lawson-hanson"``: the paper's algorithm, one point enters per iteration.

        ``warm_start``: ``None``/``False`` start cold (``p = 0``, the paper); ``True`` from
        this problem's previous solve; a :class:`ContactState` from that state (Polonsky–Keer
        starts from its pressure, the exact solvers from its contact set); a float pressure
        field of the surface's shape likewise; a boolean contact mask (exact solvers: from
        that set; Polonsky–Keer: cold). A pressure field must be finite and ``≥ 0``; under an
        imposed approach at most :attr:`WARM_START_MARGIN` times the largest pressure a
        solution can have (:meth:`_pressure_bound`); under a mean pressure it is rescaled to
        the load. Anything else is refused naming ``warm_start``.

        ``threads``: threads of the solve (default ``None``: all cores, or
        ``RAYON_NUM_THREADS``); the result does not depend on it.

        With the problem's ``hardness`` the pressure is capped at ``p ≤ H``
        (``docs/plasticity.md``): ``"auto"`` runs Polonsky–Keer, the exact solvers are refused
        (naming ``solver``), and ``mean_pressure`` must be ``≤ H``.
        """
        _validate.choice("solver", solver, SOLVERS)
        if self.hardness is not None and solver in ("active-set", "lawson-hanson"):
            raise InvalidArgumentError(
                f"solver: {solver!r} cannot cap the pressure at a hardness; use solver='auto' "
                "or 'polonsky-keer' with hardness=",
                argument="solver",
            )
        threads = _validate.threads(threads)
        tol = DEFAULT_TOL if tol is None else _validate.positive("tol", tol)
        max_iter = _validate.optional_integer("max_iter", max_iter, low=1)
        if (approach is None) == (mean_pressure is None):
            raise InvalidArgumentError(
                "approach: give exactly one of approach= (displacement control) and "
                "mean_pressure= (load control)",
                argument="approach",
            )
        if mean_pressure is not None:
            pbar = _validate.mean_pressure(mean_pressure)
            _validate.load_scales(pbar, self.e_star, self.surface.dx)
            if self.hardness is not None and pbar > self.hardness:
                raise InvalidArgumentError(
                    f"mean_pressure: {pbar:.6g} exceeds the hardness {self.hardness:.6g}; a "
                    "perfectly plastic surface carries at most p̄ = hardness (every point "
                    "yielding); give mean_pressure ≤ hardness",
                    argument="mean_pressure",
                )
            if solver in ("active-set", "lawson-hanson"):
                raise InvalidArgumentError(
                    f"solver: {solver!r} imposes the approach only; use solver='auto' or "
                    "'polonsky-keer' with mean_pressure=",
                    argument="solver",
                )
            start = self._check_warm_start(warm_start, None, pbar)
            return self._solve(None, pbar, solver, start, tol, max_iter, threads)
        a = self._check_approach(approach)
        lift = 0.0
        if self._approach_offset:
            # The approach is referenced to the original surface's highest point; a flat
            # above the deformed surface's highest point touches nothing (p = 0) and stands
            # `lift` above it.
            lift = max(self._approach_offset - a, 0.0)
            a = max(a - self._approach_offset, 0.0)
        start = self._check_warm_start(warm_start, a, None)
        return self._solve(a, None, solver, start, tol, max_iter, threads, lift)

    #: A pressure start whose largest value exceeds this multiple of the largest pressure a
    #: solution can have (:meth:`_pressure_bound`) is refused: it says nothing about the
    #: solution, and from 1e300 the first product ``C p`` overflows.
    WARM_START_MARGIN = 1e6

    def _pressure_bound(self, approach: float) -> float:
        """``max(h_s, Δ) / C_00`` [pressure]: the largest pressure of any solution at
        approach ``Δ`` (free boundary: at a contact point ``C_00 p_i ≤ (C p)_i = Δ − (max h −
        h_i) ≤ Δ``, every ``C_ij > 0``; periodic: the same order), with ``C_00 = 4 dx
        ln(1 + √2)/(π E*)`` the displacement of a unit pressure at its own cell."""
        c00 = 4.0 * self.surface.dx * math.log1p(math.sqrt(2.0)) / (math.pi * self.e_star)
        return max(self.h_range, approach) / c00

    def _check_warm_start(
        self, warm_start: Any, approach: float | None, mean_pressure: float | None
    ) -> Any:
        """``warm_start`` in the form :meth:`_start` takes (``None``, a bool, a boolean mask or
        a float pressure field), or :class:`~leakpath.errors.InvalidArgumentError` naming it.

        A pressure field (given, or a state's) must have the surface's shape and be finite
        and ``≥ 0``. Displacement control: its largest value must not exceed
        :attr:`WARM_START_MARGIN` times :meth:`_pressure_bound`. Load control rescales it to
        the load ``p̄ N``, so only that rescaling must stay finite.
        """
        shape = self._h.shape
        if warm_start is None or isinstance(warm_start, (bool, np.bool_)):
            return None if warm_start is None else bool(warm_start)
        what = (
            f"True/False, a ContactState of this surface, a boolean contact mask or a float "
            f"pressure field (≥ 0) of shape {shape}"
        )
        if isinstance(warm_start, ContactState):
            value, source = warm_start.pressure, "the state's pressure"
        else:
            value, source = warm_start, "the pressure field"
        try:
            arr = np.asarray(value)
        except (TypeError, ValueError):  # ragged nested lists
            arr = None
        if arr is None or (arr.dtype.kind not in "bfiu"):
            raise InvalidArgumentError(
                f"warm_start: expected {what}; got {_describe_start(warm_start)}",
                argument="warm_start",
            )
        if arr.shape != shape:
            raise InvalidArgumentError(
                f"warm_start: {source} has shape {arr.shape}, the surface is {shape}; pass a "
                "start of this surface",
                argument="warm_start",
            )
        if arr.dtype.kind == "b":
            if isinstance(warm_start, ContactState):
                raise InvalidArgumentError(
                    f"warm_start: the state's pressure is boolean; expected {what}",
                    argument="warm_start",
                )
            return np.ascontiguousarray(arr)
        p = np.ascontiguousarray(arr, dtype=np.float64)
        if not np.isfinite(p).all():
            raise InvalidArgumentError(
                f"warm_start: {source} contains NaN or infinite values; pass a finite start "
                "or None",
                argument="warm_start",
            )
        p_min, p_max = float(p.min()), float(p.max())
        if p_min < 0:
            raise InvalidArgumentError(
                f"warm_start: {source} has negative values (min {p_min:.3g}); contact "
                "pressures are ≥ 0: clip it (np.maximum(p, 0)) or pass None",
                argument="warm_start",
            )
        if mean_pressure is not None:
            with np.errstate(over="ignore", divide="ignore"):
                total = float(np.sum(p))
                factor = mean_pressure * p.size / total if total > 0 else 1.0
            if not (math.isfinite(total) and math.isfinite(factor) and factor > 0):
                raise InvalidArgumentError(
                    f"warm_start: {source} sums to {total:.3g}, which cannot be rescaled to "
                    f"the load p̄·N = {mean_pressure * p.size:.3g}; pass a start of the "
                    "order of the mean pressure, or None",
                    argument="warm_start",
                )
        elif approach is not None:
            bound = self._pressure_bound(approach)
            if p_max > self.WARM_START_MARGIN * bound:
                raise InvalidArgumentError(
                    f"warm_start: {source} reaches {p_max:.3g}, more than "
                    f"{self.WARM_START_MARGIN:g} times the largest pressure a solution at "
                    f"approach {approach:.6g} can have (max(h_s, Δ)/C_00 = {bound:.3g}, "
                    "C_00 = 4 dx ln(1+√2)/(π E*)); pass a start of this problem (e.g. a "
                    "previous state of it) or None",
                    argument="warm_start",
                )
        return p

    def _start(self, warm_start: Any) -> dict[str, Any]:
        """The core's start: Polonsky–Keer starts from a pressure field, the exact solvers
        from its support (the core takes ``p > 0``) or from a contact mask."""
        if warm_start is None or warm_start is False:
            return {"start": "cold"}
        if warm_start is True:
            return {"start": "previous"}
        if isinstance(warm_start, ContactState):
            return {"start": "pressure", "initial_pressure": warm_start.pressure}
        arr = np.asarray(warm_start)
        if arr.dtype == bool:
            return {"start": "set", "contact_set": np.flatnonzero(arr).astype(np.int64)}
        return {"start": "pressure", "initial_pressure": np.ascontiguousarray(arr, np.float64)}

    def _solve(
        self,
        a: float | None,
        mean_pressure: float | None,
        solver: str,
        warm_start: Any,
        tol: float,
        max_iter: int | None,
        threads: int | None = None,
        lift: float = 0.0,
    ) -> ContactState:
        out = self._core.solve(
            approach=a,
            mean_pressure=mean_pressure,
            solver=solver,
            tol=tol,
            max_iter=max_iter,
            threads=threads,
            hardness=self.hardness,
            **self._start(warm_start),
        )
        state = self._state(out, lift)
        self._last = state
        return state

    def _state(self, out: _core.ContactSolution, lift: float = 0.0) -> ContactState:
        # ``lift``: the unloading problem's flat reference sits ``lift`` below the deformed
        # surface's top (see :meth:`unloading`); the state reports gaps and approaches of
        # the original surface.
        gap = out.gap + lift if lift > 0 else out.gap
        plastic = None
        if self.hardness is not None:
            # Points at the hardness have flowed: their interpenetration −g is permanent, and
            # the flattened surface touches the flat there (gap 0).
            yielded = out.pressure >= self.hardness
            new = np.where(yielded, np.maximum(-gap, 0.0), 0.0)
            gap = np.where(yielded, np.maximum(gap, 0.0), gap)
            plastic = new if self._plastic_base is None else self._plastic_base + new
        elif self._plastic_base is not None:
            plastic = self._plastic_base
        return ContactState(
            approach=out.approach - lift + self._approach_offset,
            pressure=out.pressure,
            displacement=out.displacement,
            gap=gap,
            hardness=self.hardness,
            plastic_displacement_field=plastic,
            heights=self._h if self._original is None else self._original,
            dx=self.surface.dx,
            e_star=self.e_star,
            boundary=self.boundary,
            solver=out.solver,
            iterations=out.iterations,
            kkt=out.kkt,
            seconds=out.seconds,
            fft_products=out.fft_products,
            preconditioner_products=out.preconditioner_products,
            coarse_fft_products=out.coarse.fft_products_fine_equivalent,
            unit=self.surface.unit,
        )


def solve(
    surface: Surface | np.ndarray,
    approach: float | None = None,
    *,
    mean_pressure: float | None = None,
    E: float = 1.0,
    nu: float = 0.0,
    boundary: Boundary = "free",
    solver: SolverName = "auto",
    warm_start: bool | ContactState | np.ndarray | None = None,
    tol: float | None = None,
    max_iter: int | None = None,
    dx: float | None = None,
    memory_limit: int | None = None,
    hardness: float | None = None,
) -> ContactState:
    """Solve the contact of ``surface`` with a rigid flat at an imposed approach, or at an
    imposed ``mean_pressure`` (load control); ``hardness`` caps the pressure at ``p ≤ H``
    (elastic–perfectly-plastic, ``docs/plasticity.md``).

    See :class:`ContactProblem` and :meth:`ContactProblem.solve`. ``warm_start=True`` has no
    previous solve to start from here; pass a :class:`ContactState` or a contact mask.
    """
    problem = ContactProblem(
        surface,
        E=E,
        nu=nu,
        boundary=boundary,
        dx=dx,
        memory_limit=memory_limit,
        hardness=hardness,
    )
    return problem.solve(
        approach,
        mean_pressure=mean_pressure,
        solver=solver,
        warm_start=None if warm_start is True else warm_start,
        tol=tol,
        max_iter=max_iter,
    )
