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
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np

from ._flow import flow
from .errors import InvalidArgumentError

__all__ = [
    "FLOW_AUTO_MAX_POINTS",
    "FLOW_COLUMNS",
    "FLOW_LEVEL_COLUMNS",
    "flow_axis_for",
    "flow_columns",
    "flow_enabled",
    "flow_star",
    "reference_permeability",
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
    when that is 0 or 1, else 0."""
    if flow_axis is None:
        return int(axis) if axis in (0, 1) and not isinstance(axis, str) else 0
    if (
        isinstance(flow_axis, (bool, np.bool_))
        or not isinstance(flow_axis, numbers.Integral)
        or int(flow_axis) not in (0, 1)
    ):
        raise InvalidArgumentError(
            f"flow_axis: must be 0 or 1 (the leak flows along one axis), got {flow_axis!r}",
            argument="flow_axis",
        )
    return int(flow_axis)


def flow_columns(state: Any, flow_axis: int, enabled: bool = True) -> dict[str, float]:
    """``{"Q": ..., "K": ...}`` of a solved contact state (NaN when not ``enabled``):
    :func:`leakpath.flow` on the state along ``flow_axis`` with ``η = Δp = 1``."""
    if not enabled:
        return {"Q": math.nan, "K": math.nan}
    f = flow(state, axis=flow_axis)
    return {"Q": float(f.flow_rate), "K": float(f.permeability)}


def reference_permeability(ref_state: Any, flow_axis: int, enabled: bool = True) -> float:
    """``K(Δ = 0)``: the permeability of the undeformed state's gap (NaN when not
    ``enabled``)."""
    return flow_columns(ref_state, flow_axis, enabled)["K"]


def flow_star(row: dict[str, Any], k_ref: float) -> float:
    """``K* = K/K(Δ = 0)`` (NaN when either is NaN or the reference is 0)."""
    k = row["K"]
    if not (math.isfinite(k) and math.isfinite(k_ref)) or k_ref == 0:
        return math.nan
    return k / k_ref


# ---------------------------------------------------------------------------- command line
#: Figure files of :mod:`leakpath.flow_figures` (for ``--overwrite`` to clear).
FIGURE_PATTERNS: tuple[str, ...] = ("flux_k*.png", "flux_k*.pdf")


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
