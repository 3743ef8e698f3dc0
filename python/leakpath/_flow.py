"""Leak rate: steady incompressible Reynolds flow through the gap of a contact.

Conventions (docs/flow.md):

* ``∇·(g³/(12η) ∇p) = 0`` on the free cells; contact cells are impermeable.
* Cell-centred finite volumes on the surface grid: cell conductivity ``c = g³/(12η)``, face
  conductance the harmonic mean ``2c₁c₂/(c₁ + c₂)`` (0 across contact), flux through a face
  ``q = c_face (p₁ − p₂)`` (volume per time; the face width ``dx`` and the centre distance
  ``dx`` cancel).
* Flow along ``axis``: inlet reservoir at ``pressure_drop`` before the first index, outlet at
  0 after the last one, each half a cell from the boundary cells' centres (face conductance
  ``2c``). Side walls carry no flux, or wrap when ``periodic``.
* Free cells with a negative gap within ``ROUND_OFF`` (1e-9) of the largest free gap are
  contact (a contact solve's round-off; docs/flow.md "Supported range of gaps").
* Unknowns on the clusters (4-connectivity, as :func:`leakpath.percolation`) that join inlet
  and outlet; clusters touching only the inlet sit at ``Δp``, only the outlet at 0, others
  have no pressure (NaN). ``Q = 0`` exactly when nothing spans.
* Parallel plates of gap ``g``: ``Q = W g³ Δp / (12 η L)``, ``W`` the width across the flow,
  ``L`` the length along it.

Ideal gas (``gas=True``, isothermal, docs/flow.md): the mass flux ``ρ q`` with
``ρ = p/(R_s T)`` is ``−g³/(24 η R_s T) ∇(p²)``, so ``φ = p²`` obeys the same equation and the
same conductance ``C`` gives ``ṁ = C (p_in² − p_out²)/(2 R_s T)``; the pressure is
``p = √φ``.

Derived quantities: conductance ``Q/Δp``; permeability ``K = Q η L / (W Δp)`` (length²·length:
the gap permeability with η taken out, ``g³/12`` for plates, so ``Q/W = (K/η) Δp/L``);
hydraulic aperture ``(12 K)^{1/3}`` (``g`` for plates).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import _core, _elementary, _validate
from ._memory import memory_limit as default_memory_limit
from .errors import InvalidArgumentError

__all__ = ["DEFAULT_TOL", "Flow", "flow"]

#: Open gaps below this fraction of the largest open gap are raised to it, so that every open
#: cell's conductance ``(g/g_max)³`` and every face's harmonic mean (a product of two of
#: them) is a positive double: otherwise an open cell whose gap is below ~1e-54 g_max would
#: conduct nothing while :func:`leakpath.percolation` counts it open. Such a neck passes
#: ~1e-150 of the flow of the largest gap: no gap a contact solve returns is that small.
GAP_FLOOR = 1e-50

#: Negative gaps off contact down to this fraction of the largest free gap are a contact
#: solve's round-off (it leaves ``|g|`` up to ~2e-12 of the largest gap on its contact cells,
#: of either sign) and count as contact, as :func:`leakpath.percolation` counts them; more
#: negative ones are refused.
ROUND_OFF = 1e-9

#: Default relative residual ``‖b − Ax‖₂/‖b‖₂`` (also the aimed inlet/outlet agreement).
DEFAULT_TOL = 1e-12


@dataclass(frozen=True, eq=False)
class Flow:
    """The flow through the gap for one pressure drop along one axis.

    Attributes:
        flow_rate: volume flow rate ``Q`` through the outlet (length³/time).
        inlet_flow_rate: volume flow rate through the inlet (equals ``Q`` to round-off).
        conductance: ``Q/Δp`` (computed from the solution at unit ``Δp``; defined for
            ``Δp = 0`` too).
        permeability: ``K = conductance·η·L/W`` (length³ per unit length of width; ``g³/12``
            for parallel plates of gap ``g``), independent of ``η`` and ``Δp``.
        hydraulic_aperture: ``(12 K)^{1/3}`` (length): the gap of the parallel plates with
            the same conductance.
        pressure: pressure field (the gap's shape); NaN on contact cells, on closed cells
            (``g = 0``) and on clusters joined to neither reservoir (trapped ones included).
        flux_axis0: volume flux through the faces normal to axis 0, shape ``(ny + 1, nx)``:
            face ``[i, j]`` lies before cell ``(i, j)``; positive towards increasing ``i``.
        flux_axis1: the same normal to axis 1, shape ``(ny, nx + 1)``; with wrap across axis
            1, faces ``[:, 0]`` and ``[:, nx]`` are the same face.
        residual: final relative residual ``‖b − Ax‖₂/‖b‖₂`` of the linear system.
        conservation: largest net volume flux out of a cell relative to ``Q`` (0 if ``Q = 0``).
        iterations: conjugate-gradient iterations (0 for the Cholesky solve).
        solver: the linear solver that ran: ``"cholesky"``, ``"multigrid"``, or ``"none"``
            when nothing spans.
        n_unknowns: cells carrying an unknown pressure: those of the spanning clusters'
            backbone (the dead ends, which meet the flow at one cell only, take that
            cell's pressure; docs/flow.md, "Dead ends").
        axis, viscosity, pressure_drop, periodic, dx: the inputs.
        seconds: wall time of the solve.
        gas: True for the isothermal ideal gas (``gas=True``); then ``mass_flow_rate`` is
            ``ṁ = C (p_in² − p_out²)/(2 R_s T)`` (mass/time), ``flow_rate`` and
            ``inlet_flow_rate`` are volume flow rates at the outlet density
            (``ṁ R_s T/p_out``; inf for ``p_out = 0``), ``pressure`` is the absolute pressure
            ``√φ``, the fluxes are mass fluxes, and ``pressure_drop`` is ``p_in − p_out``.
            NaN for a liquid.
        inlet_pressure, outlet_pressure, gas_constant, temperature: the gas inputs (NaN for
            a liquid).
        unit: name of the length unit of the gap and ``dx`` (the contact state's surface
            unit; ``None`` for a bare gap array, printed as ``length``). Times are in the
            units ``η`` and ``Δp`` imply (seconds for Pa·s and Pa), printed as ``t``.
    """

    flow_rate: float
    inlet_flow_rate: float
    conductance: float
    permeability: float
    hydraulic_aperture: float
    pressure: np.ndarray = field(repr=False)
    flux_axis0: np.ndarray = field(repr=False)
    flux_axis1: np.ndarray = field(repr=False)
    residual: float
    conservation: float
    iterations: int
    n_unknowns: int
    solver: str
    axis: int
    viscosity: float
    pressure_drop: float
    periodic: bool
    dx: float
    seconds: float
    gas: bool = False
    mass_flow_rate: float = float("nan")
    inlet_pressure: float = float("nan")
    outlet_pressure: float = float("nan")
    gas_constant: float = float("nan")
    temperature: float = float("nan")
    unit: str | None = field(default=None, repr=False)

    @property
    def percolates(self) -> bool:
        """True when fluid crosses from inlet to outlet (``Q ≠ 0`` at ``Δp ≠ 0``)."""
        return self.n_unknowns > 0

    def __repr__(self) -> str:
        ny, nx = self.pressure.shape
        u = self.unit or "length"
        # t and p: the time and pressure units that the viscosity and pressure drop imply.
        return (
            f"Flow(Q={self.flow_rate:.6g} {u}^3/t, conductance={self.conductance:.6g} "
            f"{u}^3/(t·p), K={self.permeability:.6g} {u}^3, "
            f"aperture={self.hydraulic_aperture:.6g} {u}, "
            f"axis={self.axis}, grid={ny}x{nx}, unknowns={self.n_unknowns}, "
            f"iterations={self.iterations}, residual={self.residual:.1e}; "
            f"t, p: time and pressure units of viscosity and pressure_drop)"
        )


def _number(name: str, value: Any, *, positive: bool = False) -> float:
    """A finite real number (``> 0`` with ``positive``); ints beyond the float range, bools
    and strings are refused naming ``name``."""
    if positive:
        return _validate.positive(name, value, hint="pass a float")
    return _validate.real(name, value, hint="pass a float")


def _prepare_gaps(gap: np.ndarray, contact: np.ndarray | None) -> np.ndarray:
    """The gap with free negative gaps within ``ROUND_OFF·g_max`` set to 0 (contact) and open
    gaps (``g > 0`` off contact) raised to ``GAP_FLOOR·g_max`` (a new array only if any
    changes); a free gap below ``−ROUND_OFF·g_max`` is refused.

    The free cells' extremes come from one parallel pass of the core
    (:func:`leakpath._core.free_gap_extremes`): numpy's reductions with ``where=`` masks took
    1.5 ms at 513² and 0.2 s at 4097², and a gathered copy of the free gaps faults in fresh
    memory (0.35 s on a first call at 4097²)."""
    # min and max propagate NaN and ±inf: refused by the core with its message.
    if not (np.isfinite(gap.min()) and np.isfinite(gap.max())):
        return gap
    gmin, gmax = _core.free_gap_extremes(gap, contact)
    gmax = max(gmax, 0.0)
    floor = gmax * GAP_FLOOR
    if gmin < -ROUND_OFF * gmax:
        bad = gap < -ROUND_OFF * gmax
        if contact is not None:
            bad &= ~contact
        i, j = np.argwhere(bad)[0]
        raise InvalidArgumentError(
            f"gap: the value {gap[i, j]!r} at ({i}, {j}) is negative on a free cell (beyond "
            f"the round-off band {ROUND_OFF:g} × the largest free gap {gmax!r}); gaps must be "
            "≥ 0 off contact: pass the contact mask, or clip the gap at 0",
            argument="gap",
        )
    # Free gaps below the floor (negative, zero or tiny): only then is a mask needed.
    if gmin >= floor:
        return gap
    low = gap < floor
    if contact is not None:
        low &= ~contact
    negative = low & (gap < 0)
    tiny = low & (gap > 0)
    if not (negative.any() or tiny.any()):
        return gap
    return np.ascontiguousarray(np.where(negative, 0.0, np.where(tiny, floor, gap)))


def _scaled(nums: tuple[float, ...], dens: tuple[float, ...] = ()) -> tuple[float, int]:
    """``Π nums / Π dens`` as mantissa and exponent (``m 2^e``): no intermediate over- or
    underflows, so the product is right whenever it is representable."""
    m, e = 1.0, 0
    for v, sign in [(v, 1) for v in nums] + [(v, -1) for v in dens]:
        fm, fe = math.frexp(v)
        if fm == 0.0:
            return 0.0, 0
        m = m * fm if sign > 0 else m / fm
        e += sign * fe
        m, de = math.frexp(m)
        e += de
    return m, e


def _value(m: float, e: int) -> float:
    """``m 2^e`` as a float (±inf when it overflows)."""
    try:
        return math.ldexp(m, e)
    except OverflowError:
        return math.copysign(math.inf, m)


def _approx(scaled: tuple[float, int]) -> str:
    """``m 2^e`` written as a power of ten (it may not fit a double)."""
    m, e = scaled
    if m == 0.0:
        return "0"
    return f"1e{math.log10(abs(m)) + e * math.log10(2.0):.0f}"


def _representable(name: str, what: str, scaled: tuple[float, int], formula: str) -> float:
    """The value ``m 2^e`` of ``scaled``, refused naming ``name`` when it is not zero and not a
    normal double (∞, or 0 or a subnormal with its digits lost)."""
    v = _value(*scaled)
    if scaled[0] != 0.0 and not (_validate._FLOAT_MIN <= abs(v) < math.inf):
        side = "above" if abs(v) == math.inf else "below"
        raise InvalidArgumentError(
            f"{name}: the {what} {formula} is {side} the range of a double (normal numbers "
            "2.2e-308 to 1.8e308); express the pressures (and lengths) in units that bring "
            "it into range",
            argument=name,
        )
    return v


def _is_state(obj: Any) -> bool:
    return all(hasattr(obj, name) for name in ("gap", "contact", "dx"))


#: The factor analysis that :func:`flow` passes to the solver in this context (private:
#: :func:`kept_analysis`).
_KEPT_ANALYSIS: ContextVar[_core.FlowAnalysis | None] = ContextVar(
    "leakpath_kept_flow_analysis", default=None
)


@contextmanager
def kept_analysis(analysis: _core.FlowAnalysis | None) -> Iterator[None]:
    """Within the block (this thread and context), :func:`flow` factors on the ordering and
    symbolic analysis kept in ``analysis`` when it fits and keeps a new one when not
    (:class:`leakpath._core.FlowAnalysis`; used by :class:`leakpath.leakage.LevelFlows`)."""
    token = _KEPT_ANALYSIS.set(analysis)
    try:
        yield
    finally:
        _KEPT_ANALYSIS.reset(token)


def flow(
    state_or_gap: Any,
    *,
    axis: int = 0,
    viscosity: float = 1.0,
    pressure_drop: float | None = None,
    dx: float | None = None,
    periodic: bool | None = None,
    contact: np.ndarray | None = None,
    tol: float = DEFAULT_TOL,
    max_iter: int | None = None,
    memory_limit: int | None = None,
    solver: str = "auto",
    gas: bool = False,
    inlet_pressure: float | None = None,
    outlet_pressure: float | None = None,
    gas_constant: float | None = None,
    temperature: float | None = None,
    threads: int | None = None,
) -> Flow:
    """Steady Reynolds flow through the gap (module docstring; docs/flow.md).

    Args:
        state_or_gap: a solved :class:`leakpath.ContactState` (its ``gap``, ``contact``
            (``p > 0``), ``dx`` and ``boundary`` are used) or a 2-D array of gaps (length).
        axis: flow direction, 0 (default) or 1.
        viscosity: dynamic viscosity ``η > 0``.
        pressure_drop: ``Δp = p_inlet − p_outlet`` (finite; negative reverses the flow;
            default 1). Not used with ``gas=True``.
        dx: grid spacing; required for a gap array, taken from a state.
        periodic: wrap across the flow; ``None``: the state's ``boundary == "periodic"``
            (no wrap for a gap array).
        contact: contact mask for a gap array (bool, the gap's shape); default ``gap ≤ 0``.
        tol: accuracy of the flow rate (default 1e-12): multigrid iterates until the
            relative residual ``‖b − Ax‖₂/‖b‖₂`` and the rate's first-order error are below
            it; Cholesky keeps its answer when the rate's first-order error is at most
            ``max(tol, 1e-12)`` of the rate.
        max_iter: conjugate-gradient iterations allowed (default 20000).
        memory_limit: bytes allowed, a positive integer (default: what this process may
            still allocate, :func:`leakpath._memory.memory_limit`).
        solver: ``"cholesky"`` (sparse Cholesky; the answer's residuals are summed in
            double-double arithmetic and it is kept when each rate's first-order error
            ``ψ·(b_in − Aφ)``, ``φ·(b_out − Aψ)`` is at most ``max(tol, 1e-12)`` of the
            rate, else refined
            with the factor as two doubles per pressure, else solved by a cancellation-free
            elimination up to 2^20 unknowns), ``"multigrid"`` (conjugate gradients
            preconditioned by classical algebraic multigrid, refined on exact residuals
            until the residual, the rate's error and the Jacobi pressure change are below
            ``tol``; memory linear in the grid), or ``"auto"`` (default: the multigrid from
            2^22 unknowns (4097²-class gaps, where it is the faster); below, Cholesky
            whenever its factor, whose exact size and work are known after the symbolic
            analysis, fits in ``memory_limit`` and the available memory and is not predicted
            slower than the multigrid (more than 19 000 multiply-adds per unknown: large
            open regions), skipping the analysis when even a lower bound of the factor
            (320 bytes per unknown) does not fit; multigrid otherwise, and when the factor's
            answer fails its checks on more than 2^20 unknowns; where the multigrid ran
            first and refuses the gap, Cholesky when it fits; docs/flow.md).
        gas: isothermal ideal gas instead of an incompressible liquid (module docstring);
            needs ``inlet_pressure`` and ``outlet_pressure`` (absolute, ``≥ 0``),
            ``gas_constant`` ``R_s`` (specific, e.g. 287.05 J/(kg K) for air) and
            ``temperature`` ``T`` (absolute, > 0). ``viscosity`` is the gas's.
        threads: threads of the solve (default ``None``: all cores). ``1`` runs it on one
            core beside other work, as sweeps do. Results do not depend on it.

    Raises:
        InvalidArgumentError: naming the argument (NaN or infinite gaps, negative gaps off
            contact beyond ``ROUND_OFF·g_max``, wrong shapes, ``η ≤ 0``, non-finite ``Δp``,
            numbers beyond the float range, bools or strings given as numbers, a bad
            ``axis``; a flow rate, conductance, permeability or gas mass flow that is not a
            normal double, naming ``gap``, ``viscosity``, ``pressure_drop``,
            ``inlet_pressure`` or ``outlet_pressure``).
        NotConvergedError: ``max_iter`` reached, or an answer that fails its checks (rates
            disagreeing, or a cell's net flux above 1e-6 of ``Q``: necks whose ``g³`` is
            below ~1e-21 of the wide cells between them).
        ProblemTooLargeError: the solve would need more than ``memory_limit`` bytes.
    """
    axis = _validate.flow_axis(axis)
    eta = _number("viscosity", viscosity, positive=True)
    if not isinstance(gas, (bool, np.bool_)):
        raise InvalidArgumentError(f"gas: must be True or False, got {gas!r}", argument="gas")
    gas_inputs = {
        "inlet_pressure": inlet_pressure,
        "outlet_pressure": outlet_pressure,
        "gas_constant": gas_constant,
        "temperature": temperature,
    }
    if gas:
        if pressure_drop is not None:
            raise InvalidArgumentError(
                "pressure_drop: not used for a gas; give inlet_pressure and outlet_pressure "
                "(absolute)",
                argument="pressure_drop",
            )
        for name, value in gas_inputs.items():
            if value is None:
                raise InvalidArgumentError(
                    f"{name}: required with gas=True; pass {name}=", argument=name
                )
        p_in = _number("inlet_pressure", inlet_pressure)
        p_out = _number("outlet_pressure", outlet_pressure)
        for name, v in (("inlet_pressure", p_in), ("outlet_pressure", p_out)):
            if v < 0:
                raise InvalidArgumentError(
                    f"{name}: an absolute pressure must be ≥ 0, got {v!r}", argument=name
                )
        r_s = _number("gas_constant", gas_constant, positive=True)
        temp = _number("temperature", temperature, positive=True)
        # φ = p² obeys the liquid's equation: solve it at unit Δφ and scale by
        # p_in² − p_out² = (p_in − p_out)(p_in + p_out) afterwards (never formed: it
        # over- or underflows long before the mass flow does).
        dp = 1.0
    else:
        for name, value in gas_inputs.items():
            if value is not None:
                raise InvalidArgumentError(
                    f"{name}: only used with gas=True", argument=name
                )
        dp = _number("pressure_drop", 1.0 if pressure_drop is None else pressure_drop)
    tol_f = _number("tol", tol, positive=True)
    if tol_f >= 1:
        raise InvalidArgumentError(f"tol: must be in (0, 1), got {tol!r}", argument="tol")
    max_iter = _validate.optional_integer(
        "max_iter", max_iter, low=1, what="a positive integer or None"
    )
    limit = _validate.memory_limit(memory_limit)

    boundary = None
    state = None
    if _is_state(state_or_gap):
        state = state_or_gap
        if dx is not None:
            raise InvalidArgumentError(
                "dx: taken from the contact state; pass a gap array to set it", argument="dx"
            )
        if contact is not None:
            raise InvalidArgumentError(
                "contact: taken from the contact state (p > 0); pass a gap array to set it",
                argument="contact",
            )
        # A solver's gap may dip below 0 by its tolerance (KKT ~1e-11 h_s): clip it.
        gap_in = np.maximum(_validate.real_array("gap", state.gap, finite=False), 0.0)
        contact, dx = state.contact, state.dx
        boundary = getattr(state, "boundary", None)
    else:
        gap_in = state_or_gap
        if dx is None:
            raise InvalidArgumentError(
                "dx: the grid spacing is required when a gap array is given; pass dx=",
                argument="dx",
            )
    dx_f = _number("dx", dx, positive=True)

    gap_arr = np.asarray(gap_in)
    if gap_arr.dtype == np.bool_ or not (
        np.issubdtype(gap_arr.dtype, np.floating) or np.issubdtype(gap_arr.dtype, np.integer)
    ):
        raise InvalidArgumentError(
            f"gap: must be a 2-D array of real numbers, got dtype {gap_arr.dtype}",
            argument="gap",
        )
    gap = np.ascontiguousarray(gap_arr, dtype=np.float64)
    if gap.ndim != 2 or gap.size == 0:
        raise InvalidArgumentError(
            f"gap: must be a non-empty 2-D array, got shape {gap.shape}", argument="gap"
        )
    if contact is not None:
        contact = np.asarray(contact)
        if contact.dtype != np.bool_:
            raise InvalidArgumentError(
                f"contact: must be a boolean mask (e.g. pressure > 0), got dtype {contact.dtype}",
                argument="contact",
            )
        if contact.shape != gap.shape:
            raise InvalidArgumentError(
                f"contact: must have the gap's shape {gap.shape}, got {contact.shape}",
                argument="contact",
            )
        contact = np.ascontiguousarray(contact)

    if periodic is None:
        wrap = boundary == "periodic"
    elif isinstance(periodic, (bool, np.bool_)):
        wrap = bool(periodic)
    else:
        raise InvalidArgumentError(
            f"periodic: must be True, False or None, got {periodic!r}", argument="periodic"
        )

    gap = _prepare_gaps(gap, contact)

    if solver not in ("auto", "cholesky", "multigrid"):
        raise InvalidArgumentError(
            f"solver: must be 'auto', 'cholesky' or 'multigrid', got {solver!r}",
            argument="solver",
        )
    threads = _validate.threads(threads)
    if limit is None:
        limit = default_memory_limit()
    labels = None
    if state is not None:
        # The state's one labelling of its open cells (4-connectivity, wrap across the flow),
        # shared with its percolation classes: the solve does not label again.
        from ._percolation import _wrap_for, state_labelling

        labels = state_labelling(
            state, connectivity=4, wrap=_wrap_for(axis, wrap), threads=threads
        )
    res = _core.solve_reynolds_flow(
        gap,
        dx_f,
        contact=contact,
        axis=axis,
        viscosity=eta,
        pressure_drop=dp,
        periodic=wrap,
        tol=tol_f,
        max_iter=max_iter,
        memory_limit=limit,
        solver=solver,
        threads=None if threads is None else int(threads),
        labels=labels,
        analysis=_KEPT_ANALYSIS.get(),
    )
    conductance = float(res.conductance)
    permeability = float(res.permeability)
    q_out, q_in = float(res.flow_rate), float(res.inlet_flow_rate)
    pressure, f0, f1 = res.pressure, res.flux_axis0, res.flux_axis1
    gas_fields: dict[str, Any] = {}
    if gas:
        # The solve ran at unit Δφ: its rates are C and the fluxes C-scaled. Mass flow
        # ṁ = C (p_in − p_out)(p_in + p_out)/(2 R_s T); volume flow at the outlet ṁ R_s T/p_out.
        diff, tot = p_in - p_out, p_in + p_out
        pair = (diff, tot) if diff != 0.0 else (0.0,)
        spans = bool(res.n_unknowns)
        mass_s = _scaled((q_out, *pair), (2.0, r_s, temp))
        mass = _value(*mass_s)
        if spans:
            mass = _representable(
                "inlet_pressure",
                "mass flow rate",
                mass_s,
                f"ṁ = C (p_in² − p_out²)/(2 R_s T) ≈ {_approx(mass_s)}",
            )
        if p_out > 0:
            vol_s = _scaled((q_out, *pair), (2.0, p_out))
            q_vol = _value(*vol_s)
            q_in = _value(*_scaled((q_in, *pair), (2.0, p_out)))
            if spans:
                q_vol = _representable(
                    "outlet_pressure",
                    "volume flow rate at the outlet",
                    vol_s,
                    f"ṁ R_s T/p_out ≈ {_approx(vol_s)}",
                )
            q_out = q_vol
        else:
            q_out = q_in = math.inf
        pm = max(p_in, p_out)
        with np.errstate(invalid="ignore"):
            if pm > 0:
                a, b = p_in / pm, p_out / pm
                pressure = pm * np.sqrt(np.maximum(b * b + (a * a - b * b) * pressure, 0.0))
            else:
                pressure = pressure * 0.0
        fm, fe = _scaled(pair, (2.0, r_s, temp))
        with np.errstate(over="ignore", under="ignore"):
            f0, f1 = np.ldexp(f0 * fm, fe), np.ldexp(f1 * fm, fe)
        dp = diff
        gas_fields = {
            "gas": True,
            "mass_flow_rate": mass,
            "inlet_pressure": p_in,
            "outlet_pressure": p_out,
            "gas_constant": r_s,
            "temperature": temp,
        }
    return Flow(
        flow_rate=q_out,
        inlet_flow_rate=q_in,
        conductance=conductance,
        permeability=permeability,
        hydraulic_aperture=float(_elementary.cbrt(12.0) * _elementary.cbrt(permeability)),
        pressure=pressure,
        flux_axis0=f0,
        flux_axis1=f1,
        residual=float(res.residual),
        conservation=float(res.conservation),
        iterations=int(res.iterations),
        n_unknowns=int(res.n_unknowns),
        solver=str(res.solver),
        axis=axis,
        viscosity=eta,
        pressure_drop=dp,
        periodic=wrap,
        dx=dx_f,
        seconds=float(res.seconds),
        **gas_fields,
        unit=None if state is None else getattr(state, "unit", None),
    )
