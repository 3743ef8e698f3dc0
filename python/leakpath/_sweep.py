"""Sweeps over the imposed approach: the paper's experiment as a table (``docs/conventions.md``).

A sweep presses one rough surface against the rigid flat at a sequence of increasing imposed
approaches ``Δ_0 < Δ_1 < …`` and records, per level, the contact, the free volume, its
percolation classes along both in-plane axes and Nayak's moments of the deformed surface.

Levels
------
By default ``Δ_k = k·Δ_max/levels``, ``k = 0 … levels`` (``levels + 1`` rows), where
``Δ_max = h_s = max h − min h`` for ``boundary="free"`` (the paper: ``k·h_s/20``) and
``Δ_max = max h − mean h`` (full contact) for ``boundary="periodic"``. Row ``k = 0`` is the
undeformed state (the flat just touches the highest point; ``p = 0``).

Columns (lengths ``L`` in the surface's unit, pressures in the unit of ``E``)
------------------------------------------------------------------------------
=====================  ================================================================  =====
column                 definition                                                        unit
=====================  ================================================================  =====
``k``                  level index
``branch``             ``loading``, or ``unloading`` (``unload=True``, after the last
                       loading row, on its permanently deformed surface)
``approach``           imposed approach ``Δ`` (referenced to the original surface's      L
                       highest point on both branches)
``approach_star``      ``Δ* = Δ/h_s``
``n_contact``          ``#(p > 0)``
``contact_fraction``   ``a = #(p > 0)/N``
``contact_area``       ``A = #(p > 0)·dx²``                                              L²
``load``               ``F = dx² Σ p``                                                   E·L²
``mean_pressure``      ``p̄ = F/A0``, ``A0 = N·dx²``                                      E
``plastic_fraction``   ``#(w_p > 0)/N``, area deformed plastically (``hardness``; else 0)
``plastic_volume``     ``V_pl = dx² Σ w_p``, plastic displacement ``w_p``                  L³
``free_volume``        ``V = dx² Σ g``, gap ``g = max h − Δ − h + u``                    L³
``free_volume_star``   ``V* = V/(A0·σ)``, ``σ = √m0`` of the undeformed surface
``mean_gap``           ``ḡ = V/A0``                                                      L
``mean_gap_star``      ``ḡ* = ḡ/ḡ(Δ = 0)``
``V_pg``               percolating volume for the chosen ``axis``                        L³
``V_pg_star``          ``V_pg* = V_pg/V_pg(Δ = 0)`` (chosen ``axis``)
``V_pg_axis0``         volume of the free clusters spanning axis 0 (first to last row)   L³
``V_dead_axis0``       clusters touching the boundary without spanning axis 0            L³
``V_trapped_axis0``    clusters touching no boundary                                     L³
``n_spanning_axis0``   number of clusters spanning axis 0
``…_axis1``            the same for flow along axis 1 (first to last column)
``m0 m2 m4 alpha``     Nayak's moments of the deformed surface ``s = h − u``             L², 1,
                       (:func:`leakpath.moments.nayak_moments`, finite differences)      L⁻², 1
``m0_star`` …          each divided by its value for the undeformed surface
``solver``             the solver that ran (``"auto"``: ``polonsky-keer+active-set``)
``iterations``         solver iterations (summed over restarts)
``kkt_restarts``       exact re-solves from the returned contact set needed to reach the
                       KKT acceptance threshold :data:`KKT_ACCEPT` (normally 0)
``kkt``                KKT certificate of the accepted solution, relative to ``h_s``
``Q K K_star``         leak rate, permeability and ``K/K(Δ = 0)`` along ``flow_axis``     L³, L³,
                       (:mod:`leakpath.leakage`; NaN with ``flow=False``)                1
=====================  ================================================================  =====

``V = V_pg + V_dead + V_trapped`` for each axis (to round-off).

Hardness and unloading
----------------------
``hardness=H`` caps the contact pressure at ``p ≤ H`` on every level (elastic–perfectly-plastic
contact; ``docs/plasticity.md``). Each loading level is solved on the original surface (the
path-independence of monotonic loading under this model). ``unload=True`` appends an
unloading branch: the levels of the loading branch in reverse order (without the last one),
solved on the permanently deformed surface ``h − w_p`` of the last loading level, where the
plastic part does not recover. The recommended use is load control (``mean_pressures``): the
unloading rows then sit at the same nominal pressures as loading rows, which is where the
leak rates of the two branches are compared. Wall-clock ``seconds`` per
level are kept in :attr:`SweepResult.seconds` and in the JSON metadata, not in the CSV: the
CSV holds only numbers that a rerun reproduces bit for bit.

Warm starts and reproducibility
-------------------------------
``warm_start=True`` (default) starts level ``k`` from the levels before it: Polonsky–Keer
from the linear extrapolation of the last two pressure fields (:func:`_warm_start_for`), the
exact solvers from the previous contact mask. Checkpoints store what a start uses (pressure
fields, masks), so a sweep resumed from a checkpoint produces a byte-identical CSV.
``warm_start=False`` solves every level from ``p = 0`` ("without warm starting", as in the
paper). Polonsky–Keer solves each level to the KKT certificate :data:`SOLVE_TOL` (``1e-9``
relative to ``h_s``), a tenth of the :data:`KKT_ACCEPT` a level must meet; the ``kkt`` column
bounds how far each row can be from the exact solution (``docs/conventions.md``).

The leak-rate columns of each level are computed by :class:`leakpath.leakage.LevelFlows`,
beside the next contact solve when there are two or more solver threads; a level is written
to the checkpoint once its flow is done.

Checkpoints
-----------
With ``checkpoint_dir``, a ``manifest.json`` records what the sweep is (surface hash,
approaches, solver options); each finished level is written atomically as
``level_KKKK.json`` (its row, its wall time, its contact mask and percolation class map, both
compressed) and, with ``keep_fields``, ``level_KKKK.npz`` (pressure, gap, labels). Rerunning
the same sweep with the same ``checkpoint_dir`` loads the finished levels instead of solving
them again; a different sweep in that directory is refused (``ValueError``).
"""

from __future__ import annotations

import math
import os
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from . import _validate, leakage  # leakage: leak-rate columns Q, K, K_star
from ._checkpoint import CHECKPOINT_FORMAT, CheckpointMismatch, _Checkpoint, _Level
from ._core import __version__
from ._percolation import percolations
from ._table import COLUMNS, CSV_COLUMNS, SweepResult, _finish_row, surface_sha256
from .contact import SOLVERS, ContactProblem, ContactState
from .errors import InvalidArgumentError, NotConvergedError
from .moments import nayak_moments
from .surfaces import Surface

if TYPE_CHECKING:  # pragma: no cover
    from ._percolation import Percolation
    from .surface import Surface

__all__ = [
    "sweep",
    "SweepResult",
    "CheckpointMismatch",
    "COLUMNS",
    "CSV_COLUMNS",
    "KKT_ACCEPT",
    "SOLVE_TOL",
]

PathLike = str | os.PathLike[str]

#: Largest KKT certificate (relative to ``h_s``) a sweep accepts from a solve. A larger one
#: triggers an exact re-solve warm-started from the returned contact set; if that does not
#: reach it either, the sweep raises ``RuntimeError``.
KKT_ACCEPT = 1e-8

#: Tolerance of the sweep's Polonsky–Keer solves (the solver stops at a KKT certificate
#: ``kkt ≤ SOLVE_TOL``, relative to ``h_s``; ``docs/conventions.md``): a tenth of
#: :data:`KKT_ACCEPT`, so every solve is accepted with a margin, instead of the single
#: solve's default ``1e-12``. What a certificate ``kkt`` bounds (``docs/conventions.md``,
#: "Warm starts"): the level is the exact solution for heights moved by at most
#: ``ε = kkt·h_s`` at each point, so every gap lies within ``ε`` of the exact gaps at the
#: approaches ``Δ ± ε`` and the free volume within ``2ε·A0`` of the exact one; the load lies
#: between the exact loads at ``Δ ∓ ε``. Against ``1e-10`` (RMD D = 2.2, 20 levels, free
#: boundary) it takes a tenth fewer iterations (836 → 750 at 257², 1140 → 1023 at 513²,
#: 1526 → 1381 at 1025²) and moves the columns by ≤ 7e-9 relative in load, ≤ 1.7e-9 in free
#: volume and V_pg, ≤ 8e-10 in the moments, ≤ 4.5e-8 in Q and K, ≤ 4.4e-7 in the small
#: dead-end and trapped volumes, and not at all in the contact counts.
#: The exact solvers (``active-set``, ``lawson-hanson``) keep their own criterion.
SOLVE_TOL = KKT_ACCEPT / 10

#: Grids of at most this many points solve their contacts on one thread while the leak
#: rates run on a background thread; larger ones on all solver threads. Measured on a
#: 2-core machine, 20-level sweeps with the default leak rates: one thread 0.43 s against
#: 0.45 s at 129², 1.01 against 1.07 s at 193², but 2.45 against 2.14 s at 257².
ONE_THREAD_CONTACT_MAX_POINTS = 200 * 200

#: Axes accepted by ``axis`` (``docs/conventions.md``).
AXES: tuple[Any, ...] = (0, 1, "either", "both")


def _check_levels(levels: Any, shape: tuple[int, int], keep_fields: bool) -> int:
    n = _validate.integer("levels", levels, low=1, high=2**1024, what="an integer ≥ 1")
    # Each level keeps its row (~16 KiB with its approach), its packed contact mask and
    # class map (≤ 2 bytes per point compressed) and, with keep_fields, pressure, gap and
    # labels twice over (20 bytes per point, stacked at the end): refuse before solving.
    points = shape[0] * shape[1]
    per_level = 16 * 1024 + 2 * points + (40 * points if keep_fields else 0)
    limit = _validate.memory_budget()
    if (n + 1) * per_level > limit:
        raise _validate.too_large(
            "levels",
            f"a sweep of {n} levels on {shape[0]} × {shape[1]} points",
            (n + 1) * per_level,
            limit,
            f"use at most {max(limit // per_level - 1, 1)} levels",
        )
    return n


def _resolve_approaches(problem: ContactProblem, levels: int, approaches: Any) -> list[float]:
    limit = problem.max_approach
    if approaches is None:
        return [float(limit * k / levels) for k in range(levels + 1)]
    full = limit if problem.boundary == "periodic" else None
    return _validate.increasing(
        "approaches",
        approaches,
        lambda v, name: _validate.approach(v, full_contact=full, name=name),
    )


def _resolve_hardness(hardness: Any, solver: str) -> float | None:
    from .contact import check_hardness

    h = check_hardness(hardness)
    if h is not None and solver in ("active-set", "lawson-hanson"):
        raise InvalidArgumentError(
            f"solver: {solver!r} cannot cap the pressure at a hardness; use solver='auto' or "
            "'polonsky-keer' with hardness=",
            argument="solver",
        )
    return h


def _resolve_mean_pressures(mean_pressures: Any) -> list[float]:
    return _validate.increasing("mean_pressures", mean_pressures, _validate.mean_pressure)


def _check_axis(axis: Any) -> Any:
    return _validate.axis(axis)


def _check_connectivity(connectivity: Any) -> int:
    return _validate.connectivity(connectivity)


# ---------------------------------------------------------------------------- one level
def _solve_accepted(
    problem: ContactProblem,
    level: tuple[str, float],
    solver: str,
    warm: bool | np.ndarray,
    threads: int | None = None,
    tol: float | None = None,
) -> tuple[ContactState, int, int]:
    """Solve one level (``("approach", Δ)`` or ``("mean_pressure", p̄)``) to the KKT
    tolerance ``tol`` (``None``: the solver's default), and re-solve exactly from the
    returned contact set while ``kkt > KKT_ACCEPT``.

    Returns the state, the iterations summed over the solves and the number of re-solves.
    """
    kind, value = level[0], level[1]
    state = problem.solve(  # type: ignore[call-overload]
        **{kind: value}, solver=solver, warm_start=warm, threads=threads, tol=tol
    )
    approach = state.approach
    iterations = state.iterations
    restarts = 0
    while not (state.kkt <= KKT_ACCEPT):
        if restarts >= 2:
            raise NotConvergedError(
                f"solver: {solver!r} did not reach the KKT threshold {KKT_ACCEPT:g} at "
                f"approach {approach!r} (certificate {state.kkt:.3g} after {restarts} "
                "exact restarts); check the surface's units, or try solver='active-set'",
                solver=solver,
                iterations=iterations,
                residual=state.kkt,
            )
        if problem.hardness is not None:
            # The exact solvers take no cap: Polonsky–Keer again, from the returned pressure.
            state = problem.solve(  # type: ignore[call-overload]
                **{kind: value},
                solver="polonsky-keer",
                warm_start=state.pressure,
                threads=threads,
            )
            iterations += state.iterations
            restarts += 1
            continue
        restart_solver = "active-set" if solver in ("polonsky-keer", "auto") else solver
        state = problem.solve(  # type: ignore[arg-type]
            approach, solver=restart_solver, warm_start=state.contact, threads=threads
        )
        iterations += state.iterations
        restarts += 1
    return state, iterations, restarts


def _warm_start_for(
    done: Sequence[_Level], level_list: Sequence[tuple[Any, ...]], k: int, shape: Any
) -> np.ndarray:
    """Start of level ``k`` from the levels before it.

    With pressure fields (Polonsky–Keer): the linear extrapolation of the last two in the
    imposed value ``v`` (approach or mean pressure), clipped at 0,
    ``p = max(p₁ + (v_k − v₁)/(v₁ − v₀)·(p₁ − p₀), 0)`` — measured on the paper's sweep it
    saves about a fifth of the iterations over starting from ``p₁`` alone. Otherwise the
    previous contact mask (exact solvers). Only recorded fields enter, so a resumed sweep
    starts each level exactly as an uninterrupted one.
    """
    last = done[-1]
    if last.pressure is None:
        return last.contact_mask(shape)
    p1 = last.pressure
    if len(done) < 2 or done[-2].pressure is None or k < 2:
        return p1
    v0, v1, vk = level_list[k - 2][1], level_list[k - 1][1], level_list[k][1]
    if not (v1 > v0 and v0 > 0):  # the Δ = 0 level carries no information on the slope
        return p1  # (nor does the other branch: unloading starts from the last pressure)
    p0 = done[-2].pressure
    return np.maximum(p1 + (vk - v1) / (v1 - v0) * (p1 - p0), 0.0)


def _percolation_columns(perc: Percolation, suffix: str) -> dict[str, Any]:
    return {
        f"V_pg{suffix}": float(perc.spanning_volume),
        f"V_dead{suffix}": float(perc.dead_end_volume),
        f"V_trapped{suffix}": float(perc.trapped_volume),
        f"n_spanning{suffix}": int(perc.n_spanning),
    }


class _Analysis(NamedTuple):
    """What :func:`_analyse` adds to a solved level."""

    row: dict[str, Any]
    classes: np.ndarray
    fields: dict[str, np.ndarray] | None
    seconds: float


def _analyse(
    k: int,
    state: ContactState,
    *,
    branch: str = "loading",
    iterations: int,
    restarts: int,
    axis: Any,
    connectivity: int,
    keep_fields: bool,
    threads: int | None = None,
) -> _Analysis:
    """Row, class map and fields of a solved level, without the leak-rate columns
    (:class:`leakpath.leakage.LevelFlows` adds them)."""
    t_start = time.perf_counter()
    # One labelling of the level's open cells, classified for both axes and `axis` in one
    # call; the level's flow reuses the labelling (leakpath._percolation.state_labelling).
    p0, p1, pa = percolations(state, (0, 1, axis), connectivity=connectivity, threads=threads)
    mom = nayak_moments(state.deformed, state.dx)
    n_contact = int(np.count_nonzero(state.contact))
    row: dict[str, Any] = {
        "k": k,
        "branch": branch,
        "approach": float(state.approach),
        "n_contact": n_contact,
        "contact_fraction": state.contact_fraction,
        "contact_area": state.contact_area,
        "load": state.load,
        "mean_pressure": state.mean_pressure,
        "plastic_fraction": state.plastic_fraction,
        "plastic_volume": state.plastic_volume,
        "free_volume": state.free_volume,
        "mean_gap": state.mean_gap,
        "V_pg": float(pa.spanning_volume),
        **_percolation_columns(p0, "_axis0"),
        **_percolation_columns(p1, "_axis1"),
        "m0": mom.m0,
        "m2": mom.m2,
        "m4": mom.m4,
        "alpha": mom.alpha,
        "solver": state.solver,
        "iterations": int(iterations),
        "kkt_restarts": int(restarts),
        "kkt": float(state.kkt),
    }
    classes = np.asarray(pa.class_map(), dtype=np.int8)
    fields = None
    if keep_fields:
        fields = {
            "pressure": np.array(state.pressure, dtype=np.float64),
            "gap": np.array(state.gap, dtype=np.float64),
            "labels": np.asarray(pa.labels, dtype=np.int32),
        }
    return _Analysis(row, classes, fields, time.perf_counter() - t_start)


# ---------------------------------------------------------------------------- checkpoints

def sweep(
    surface: Surface,
    *,
    levels: int = 20,
    approaches: Sequence[float] | np.ndarray | None = None,
    mean_pressures: Sequence[float] | np.ndarray | None = None,
    solver: str = "auto",
    warm_start: bool = True,
    axis: int | str = 0,
    connectivity: int = 4,
    E: float = 1.0,  # noqa: N803 - Young's modulus
    nu: float = 0.0,
    boundary: str = "free",
    keep_fields: bool = False,
    progress: bool = False,
    checkpoint_dir: PathLike | None = None,
    flow: bool | None = None,
    flow_axis: int | None = None,
    hardness: float | None = None,
    unload: bool = False,
) -> SweepResult:
    """Solve the contact of ``surface`` at increasing approaches and tabulate each level.

    Parameters
    ----------
    surface : Surface
        The undeformed rough surface (heights and ``dx`` in one length unit).
    levels : int
        Number of equal steps: ``Δ_k = k·Δ_max/levels``, ``k = 0 … levels``, with
        ``Δ_max = h_s`` (free) or ``max h − mean h`` (periodic). Ignored with ``approaches``.
    approaches : sequence of float, optional
        Explicit approaches [length]: strictly increasing, ``≥ 0`` (periodic: ``≤`` full
        contact, :attr:`ContactProblem.max_approach`).
    mean_pressures : sequence of float, optional
        Load control instead: strictly increasing mean pressures ``p̄ = F/A0 > 0`` [E's
        unit], one row each; the approach of each row is then the solver's output. The seal
        engineer's curve against nominal pressure (``mean_pressure_star = p̄/E*``).
    solver : str
        ``"auto"`` (default: Polonsky–Keer above a few thousand points, the exact active set
        below; see :meth:`ContactProblem.solve`), ``"polonsky-keer"``, ``"active-set"`` or
        ``"lawson-hanson"`` (the paper's one-point-per-iteration algorithm).
    warm_start : bool
        Start level ``k`` from level ``k − 1`` (default: Polonsky–Keer from its pressure
        field, the exact solvers from its contact set), or every level from ``p = 0``
        (``False``, the paper's "without warm starting").
    axis : 0, 1, "either" or "both"
        Flow direction for ``V_pg``/``V_pg_star`` and the maps (both axes are always
        tabulated in ``*_axis0``/``*_axis1``).
    connectivity : 4 or 8
        Neighbourhood of free cells in a cluster.
    E, nu : float
        Young's modulus and Poisson's ratio, ``E* = E/(1 − ν²)`` (pressures in E's unit).
    boundary : "free" or "periodic"
        Elastic boundary condition (``docs/conventions.md``).
    keep_fields : bool
        Keep pressure, gap and cluster labels of every level (:meth:`SweepResult.save_fields`).
    progress : bool
        Show a tqdm progress bar (one step per level) on stderr.
    checkpoint_dir : path, optional
        Write each finished level there and reuse the levels found there (module docstring).
    flow : bool, optional
        Leak-rate columns ``Q``, ``K``, ``K_star`` (:mod:`leakpath.leakage`): ``True``,
        ``False`` (NaN columns), or ``None`` (default: on up to 513² points).
    flow_axis : 0 or 1, optional
        Direction of the leak (default: ``axis`` when it is 0 or 1, else 0).
    hardness : float, optional
        Hardness ``H`` [E's unit]: cap the pressure at ``p ≤ H`` (elastic–perfectly-plastic
        contact, Polonsky–Keer; ``docs/plasticity.md``). Mean pressures must be ``≤ H``.
    unload : bool
        Append an unloading branch (``branch = "unloading"`` rows): the loading levels in
        reverse order, without the last, solved on the permanently deformed surface of the
        last loading level (module docstring).

    Returns
    -------
    SweepResult

    Raises
    ------
    ValueError
        A bad argument (the message names it) or a checkpoint of a different sweep.
    RuntimeError
        A solve that does not reach the KKT threshold :data:`KKT_ACCEPT`.
    """
    if not isinstance(surface, Surface):
        raise InvalidArgumentError(
            f"surface: expected a leakpath Surface, got {type(surface).__name__}"
        )
    if min(surface.shape) < 3:
        raise InvalidArgumentError(
            f"surface: needs at least 3 points per axis, got {surface.shape}"
        )
    if not surface.height_range > 0:
        raise InvalidArgumentError(
            "surface: flat (h_s = max h − min h = 0): the flat touches every point at once "
            "and there is no approach to sweep; check the heights (units, a constant file)"
        )
    _validate.choice("solver", solver, SOLVERS)
    hardness = _resolve_hardness(hardness, solver)
    unload = _validate.flag("unload", unload)
    if checkpoint_dir is not None:  # before any solve
        checkpoint_dir = _validate.path("checkpoint_dir", checkpoint_dir)
    warm_start = _validate.flag("warm_start", warm_start)
    keep_fields = _validate.flag("keep_fields", keep_fields)
    n_levels = _check_levels(levels, surface.shape, keep_fields)
    axis = _check_axis(axis)
    connectivity = _check_connectivity(connectivity)
    flow_on = leakage.flow_enabled(flow, surface.shape)  # leakpath.leakage
    flow_axis = leakage.flow_axis_for(flow_axis, axis)
    problem = ContactProblem(
        surface, E=E, nu=nu, boundary=boundary, hardness=hardness  # type: ignore[arg-type]
    )
    if approaches is not None and mean_pressures is not None:
        raise InvalidArgumentError(
            "mean_pressures: give approaches= or mean_pressures=, not both",
            argument="mean_pressures",
        )
    if mean_pressures is not None:
        pressure_list = _resolve_mean_pressures(mean_pressures)
        for v in (pressure_list[0], pressure_list[-1]):  # refused up front, not mid-sweep
            _validate.load_scales(v, problem.e_star, surface.dx, name="mean_pressures")
        if hardness is not None and pressure_list[-1] > hardness:
            raise InvalidArgumentError(
                f"mean_pressures: {pressure_list[-1]!r} exceeds the hardness {hardness!r}; a "
                "perfectly plastic surface carries at most p̄ = hardness",
                argument="mean_pressures",
            )
        loading = [("mean_pressure", v, "loading") for v in pressure_list]
        approach_list = None
    else:
        approach_list = _resolve_approaches(problem, n_levels, approaches)
        loading = [("approach", v, "loading") for v in approach_list]
        pressure_list = None
    n_loading = len(loading)
    level_list = loading + (
        [(kind, v, "unloading") for kind, v, _ in reversed(loading[:-1])] if unload else []
    )
    run_solver = solver
    t_total = time.perf_counter()

    parameters: dict[str, Any] = {
        "levels": (
            len(approach_list) - 1
            if approach_list is not None and approaches is None
            else None
        ),
        "approaches": approach_list,
        "mean_pressures": pressure_list,
        "solver": solver,
        "warm_start": bool(warm_start),
        "axis": axis,
        "connectivity": connectivity,
        "E": float(E),
        "nu": float(nu),
        "e_star": problem.e_star,
        "boundary": boundary,
        "kkt_accept": KKT_ACCEPT,
        "keep_fields": bool(keep_fields),
        "flow": flow_on,  # leakpath.leakage
        "flow_axis": flow_axis,
        "hardness": hardness,
        "unload": bool(unload),
    }

    # Undeformed reference (Δ = 0: p = 0, u = 0, the whole interface is free).
    ref_state = problem.solve(0.0, solver=run_solver, warm_start=False)  # type: ignore[arg-type]
    # Polonsky–Keer warm-starts from the previous pressure field, which checkpoints keep. The
    # core resolves "auto" (the reference solve says which solver runs on this grid in
    # displacement control; load control always runs Polonsky–Keer).
    uses_pk = ref_state.solver == "polonsky-keer"
    keep_pressure = bool(warm_start) and (uses_pk or mean_pressures is not None)
    # Polonsky–Keer solves stop at SOLVE_TOL; the exact solvers keep their own criterion.
    solve_tol = SOLVE_TOL if uses_pk or mean_pressures is not None else None
    parameters["solve_tol"] = solve_tol
    parameters["flow_tol"] = leakage.FLOW_TOL if flow_on else None
    ref_mom = nayak_moments(surface.heights, surface.dx)
    reference = {
        "h_s": surface.height_range,
        "e_star": problem.e_star,
        "A0": surface.nominal_area,
        "sigma": math.sqrt(ref_mom.m0),
        "free_volume": ref_state.free_volume,
        "mean_gap": ref_state.mean_gap,
        "V_pg": float(ref_state.percolation(axis=axis, connectivity=connectivity).spanning_volume),
        "m0": ref_mom.m0,
        "m2": ref_mom.m2,
        "m4": ref_mom.m4,
        "alpha": ref_mom.alpha,
    }

    checkpoint = None
    if checkpoint_dir is not None:
        identity = {k: v for k, v in parameters.items() if k not in ("keep_fields",)}
        manifest = {
            "format": CHECKPOINT_FORMAT,
            "leakpath_version": __version__,
            "surface_sha256": surface_sha256(surface),
            "shape": list(surface.shape),
            "parameters": identity,
        }
        checkpoint = _Checkpoint(checkpoint_dir, manifest, keep_fields)

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(
            total=len(level_list), desc="sweep", unit="level", file=sys.stderr, leave=False
        )
    shape = surface.shape
    done: list[_Level] = []
    resumed: list[int] = []
    # Levels solved here whose leak rate is still being computed; saved once it is.
    waiting: dict[int, _Level] = {}
    flows = leakage.LevelFlows(flow_axis, flow_on)  # leakpath.leakage
    # With the leak rates on a background thread, small grids solve their contacts on one
    # thread of their own: two threads beside the background one keep preempting each other
    # inside every parallel loop (see ONE_THREAD_CONTACT_MAX_POINTS).
    threads = (
        1
        if flows.background and surface.heights.size <= ONE_THREAD_CONTACT_MAX_POINTS
        else None
    )

    def record(results: list[tuple[Any, Any, dict[str, float], float]]) -> None:
        for key, analysed, cols, seconds in results:
            if key == "reference":
                reference["K"] = cols["K"]
                continue
            # The level in `done` (its pressure and mask started the next levels) takes the
            # analysis made beside the contact solves.
            level = waiting.pop(key)
            level.row = {**analysed.row, **cols}
            level.classes = analysed.classes
            level.fields = analysed.fields
            level.seconds += analysed.seconds + seconds
            if checkpoint is not None:
                checkpoint.save(key, level, shape)
            if bar is not None:
                bar.update(1)
                bar.set_postfix(contact=f"{level.row['contact_fraction']:.3f}")
        # A warm start needs only the last two pressure fields; a level keeps its own until
        # it is saved.
        unsaved = {id(lv) for lv in waiting.values()}
        for lv in done[:-2]:
            if id(lv) not in unsaved:
                lv.pressure = None

    def analysis(
        k: int, state: ContactState, iterations: int, restarts: int, branch: str
    ) -> Callable[[int | None], _Analysis]:
        def run(threads: int | None) -> _Analysis:
            return _analyse(
                k,
                state,
                branch=branch,
                iterations=iterations,
                restarts=restarts,
                axis=axis,
                connectivity=connectivity,
                keep_fields=keep_fields,
                threads=threads,
            )

        return run

    # The problem each branch is solved on: the original surface while loading; on
    # unloading, the permanent surface of the last loading level.
    solving = problem
    top = n_loading - 1
    try:
        flows.submit("reference", ref_state)
        for k, target in enumerate(level_list):
            branch = target[2]
            if k == n_loading:
                plastic = done[top].plastic
                if plastic is None:  # pragma: no cover - kept by the loading branch
                    raise RuntimeError("the last loading level kept no plastic displacement")
                solving = problem._unloading_from(plastic)
            level = None
            if checkpoint is not None:
                level = checkpoint.load(
                    k, shape, need_pressure=keep_pressure, need_plastic=unload and k == top
                )
            if level is not None:
                resumed.append(k)
                if bar is not None:
                    bar.update(1)
            else:
                warm: bool | np.ndarray = False
                if warm_start and done:
                    warm = _warm_start_for(done, level_list, k, shape)
                t0 = time.perf_counter()
                state, iterations, restarts = _solve_accepted(
                    solving, target, run_solver, warm, threads, solve_tol
                )
                # What the next levels start from now; the row, class map and fields follow
                # with the leak rate (`record`).
                level = _Level(
                    row={},
                    seconds=time.perf_counter() - t0,
                    mask=np.packbits(state.contact.ravel()),
                    classes=np.zeros(0, dtype=np.int8),
                    pressure=(
                        np.array(state.pressure, dtype="<f8") if keep_pressure else None
                    ),
                    plastic=(
                        np.array(state.plastic_displacement, dtype="<f8")
                        if unload and k == top
                        else None
                    ),
                )
                waiting[k] = level
                flows.submit(k, state, analysis(k, state, iterations, restarts, branch))
            done.append(level)
            record(flows.finished())
        record(flows.finish())
    finally:
        flows.close()
        if bar is not None:
            bar.close()

    rows = [_finish_row(lv.row, reference, surface.nominal_area) for lv in done]
    fields = None
    if keep_fields:
        fields = {
            name: np.stack([lv.fields[name] for lv in done])  # type: ignore[index]
            for name in ("pressure", "gap", "labels")
        }
    if checkpoint is not None and checkpoint.recomputed:
        warnings.warn(
            "checkpoint_dir: recomputed "
            + "; ".join(f"level {k} ({why})" for k, why in checkpoint.recomputed)
            + " — their records failed the integrity check and were not used",
            stacklevel=2,
        )
    return SweepResult(
        rows=rows,
        parameters=parameters,
        surface=surface,
        reference=reference,
        seconds=[lv.seconds for lv in done],
        resumed=resumed,
        recomputed=[k for k, _ in checkpoint.recomputed] if checkpoint is not None else [],
        fields=fields,
        total_seconds=time.perf_counter() - t_total,
        _masks=[lv.mask for lv in done],
        _classes=[lv.classes for lv in done],
    )

