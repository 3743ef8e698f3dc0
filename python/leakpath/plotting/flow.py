"""Leak-rate figures of a sweep (matplotlib, object-oriented, no pyplot state).

In the style of :mod:`leakpath.plotting`; columns as in :mod:`leakpath.leakage`.

==========================  ==============================================================
file stem                   content
==========================  ==============================================================
``fig4_leak_rate``           ``K* = K/K(Δ = 0)`` (log scale) against (a) the contact
                             fraction, (b) ``V_pg*`` and (c) ``p̄/E*``; levels with no leak
                             (``K* = 0``) are marked on the lower edge
``flux_kKK``                 magnitude of the volume flux per unit width ``|q|/dx`` (log
                             colour scale) at level ``KK`` along the sweep's flow axis;
                             contact and closed cells grey
==========================  ==============================================================

A flux map needs the level's gap: it is taken from the sweep's fields
(``keep_fields=True``) or, without them, the level is solved again at its approach (the same
minimiser to the solver's tolerance; under load control at its mean pressure).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure

from .. import _validate
from .._flow import DEFAULT_TOL, Flow, flow
from ..errors import InvalidArgumentError
from ._types import SweepLike as SweepResult

__all__ = [
    "flux_magnitude",
    "plot_kstar",
    "plot_flux_map",
    "figure_leak_rate",
    "figure_flux_map",
    "level_flow",
    "flow_figures",
    "save_flow_figures",
]

_LINE = {"marker": "o", "markersize": 3.5, "linewidth": 1.2}


def _has_flow(result: SweepResult) -> bool:
    k = result.column("K")
    return bool(np.isfinite(k).any())


def flux_magnitude(f: Flow) -> np.ndarray:
    """``|q|/dx`` at the cell centres (volume per time per unit width; the mean of the two
    faces of each cell along each axis); NaN where the pressure is undefined."""
    f0, f1 = np.asarray(f.flux_axis0), np.asarray(f.flux_axis1)
    qy = 0.5 * (f0[:-1, :] + f0[1:, :])
    qx = 0.5 * (f1[:, :-1] + f1[:, 1:])
    mag = np.hypot(qx, qy) / f.dx
    return np.where(np.isfinite(f.pressure), mag, np.nan)


def plot_kstar(result: SweepResult, ax: Axes, column: str, xlabel: str, title: str) -> None:
    """``K*`` (log) against ``column``; levels without leak (``K* = 0``) as crosses on the
    lower edge."""
    x, y = result.column(column), result.column("K_star")
    leak = np.isfinite(y) & (y > 0)
    if leak.any():
        ax.plot(x[leak], y[leak], **_LINE, label="leaking levels")
    ax.set_yscale("log")
    shut = np.isfinite(y) & (y == 0)
    if shut.any():
        ax.plot(
            x[shut],
            np.full(int(shut.sum()), 0.0),
            "x",
            color="#d55e00",
            transform=ax.get_xaxis_transform(),
            clip_on=False,
            label="no leak (K* = 0)",
        )
    ax.set_xlabel(xlabel)
    ax.set_ylabel(r"$K^* = K / K(\Delta = 0)$")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize="small")


def figure_leak_rate(result: SweepResult) -> Figure:
    """Fig. 4: ``K*`` against (a) contact fraction, (b) ``V_pg*``, (c) ``p̄/E*``."""
    fig = Figure(figsize=(14.0, 4.2), layout="constrained")
    ax_a, ax_b, ax_c = fig.subplots(1, 3)
    axis = result.parameters.get("flow_axis", 0)
    plot_kstar(result, ax_a, "contact_fraction", "contact fraction a", "(a) against contact")
    plot_kstar(result, ax_b, "V_pg_star", r"$V_{pg}^*$", "(b) against percolating volume")
    plot_kstar(result, ax_c, "mean_pressure_star", r"$\bar p / E^*$", "(c) against pressure")
    fig.suptitle(f"leak permeability, flow along axis {axis}")
    return fig


def level_flow(result: SweepResult, k: int) -> Flow:
    """The flow of row ``k`` along the sweep's flow axis (``η = Δp = 1``): from the kept
    fields, or by solving the level again."""
    axis = int(result.parameters.get("flow_axis", 0))
    periodic = result.parameters.get("boundary") == "periodic"
    # The sweep's own flow tolerance (leakpath.leakage.FLOW_TOL), so the map is its row's flow.
    tol = result.parameters.get("flow_tol") or DEFAULT_TOL
    if result.fields is not None:
        gap = np.maximum(result.fields["gap"][k], 0.0)
        contact = result.fields["pressure"][k] > 0
        return flow(
            gap, dx=result.surface.dx, contact=contact, axis=axis, periodic=periodic, tol=tol
        )
    from ..contact import ContactProblem

    par = result.parameters
    prob = ContactProblem(
        result.surface,
        E=par.get("E", 1.0),
        nu=par.get("nu", 0.0),
        boundary=par["boundary"],
        hardness=par.get("hardness"),
    )
    row = result.rows[k]
    solver = par.get("solver", "auto")

    def solve_row(problem: ContactProblem, r: dict[str, Any]) -> Any:
        if par.get("mean_pressures"):
            return problem.solve(mean_pressure=r["mean_pressure"], solver=solver)
        return problem.solve(r["approach"], solver=solver)

    if row.get("branch") == "unloading":
        # The unloading rows are solved on the permanent surface of the last loading row.
        top = max(i for i, r in enumerate(result.rows) if r.get("branch") == "loading")
        prob = prob.unloading(solve_row(prob, result.rows[top]))
    return flow(solve_row(prob, row), axis=axis, tol=tol)


def plot_flux_map(
    f: Flow, ax: Axes, *, unit: str = "length units", title: str | None = None
) -> Any:
    """``|q|/dx`` on a log colour scale, undefined cells grey; returns the image."""
    mag = flux_magnitude(f)
    ny, nx = mag.shape
    pos = mag[np.isfinite(mag) & (mag > 0)]
    ax.set_facecolor("#4d4d4d")
    if pos.size:
        vmax = float(pos.max())
        norm = LogNorm(vmin=max(float(pos.min()), vmax * 1e-8), vmax=vmax)
        shown = np.where(mag > 0, mag, np.nan)
        im = ax.imshow(
            shown,
            origin="lower",
            extent=(0.0, nx * f.dx, 0.0, ny * f.dx),
            cmap="magma",
            norm=norm,
            interpolation="nearest",
        )
        cbar = ax.figure.colorbar(im, ax=ax, shrink=0.9)
        # q = c_f Δp with c = g³/(12 η): at η = Δp = 1 (one pressure unit, one pressure
        # unit × s), |q|/dx is in length²/s.
        cbar.set_label(rf"$|q|/dx$ [{unit}$^2$/s] at $\eta = \Delta p = 1$")
    else:
        im = None
        ax.set_xlim(0.0, nx * f.dx)
        ax.set_ylim(0.0, ny * f.dx)
        ax.text(0.5, 0.5, "no leak", transform=ax.transAxes, ha="center", color="white")
    ax.set_xlabel(f"x [{unit}]")
    ax.set_ylabel(f"y [{unit}]")
    if title:
        ax.set_title(title)
    return im


def figure_flux_map(result: SweepResult, k: int) -> Figure:
    """Flux magnitude at row ``k``, titled with ``Δ*``, contact fraction and ``K*``."""
    from .paper import _unit

    row = result.rows[k]
    f = level_flow(result, k)
    fig = Figure(figsize=(6.6, 5.0), layout="constrained")
    ax = fig.subplots()
    title = (
        f"level k = {row['k']}: $\\Delta^*$ = {row['approach_star']:.3g}, "
        f"contact {100 * row['contact_fraction']:.1f} %\n"
        f"$K^*$ = {row['K_star']:.3g}, flow along axis {f.axis}"
    )
    plot_flux_map(f, ax, unit=_unit(result.surface), title=title)
    return fig


def _flux_levels(result: SweepResult, flux_levels: Iterable[int] | None) -> list[int] | None:
    """The rows to draw flux maps of (default: the last leaking row), checked; ``None`` when
    the sweep has no leak-rate columns (refused if ``flux_levels`` asks for maps)."""
    if not _has_flow(result):
        if flux_levels:
            raise InvalidArgumentError(
                "flux_levels: the sweep has no leak-rate columns (flow=False); run it with "
                "flow=True (--flow)",
                argument="flux_levels",
            )
        return None
    n = len(result.rows)
    if flux_levels is None:
        leaking = [i for i, r in enumerate(result.rows) if r["Q"] > 0]
        levels = leaking[-1:]
    else:
        levels = list(flux_levels)
    for k in levels:
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= k < n:
            raise InvalidArgumentError(
                f"flux_levels: row indices must lie in 0…{n - 1}, got {k!r}",
                argument="flux_levels",
            )
    return [int(k) for k in levels]


def flow_figures(
    result: SweepResult, *, flux_levels: Iterable[int] | None = None
) -> dict[str, Figure]:
    """``fig4_leak_rate`` and one flux map per row in ``flux_levels`` (default: the last
    leaking row), drawn but not written: file stem → Figure, in the order
    :func:`save_flow_figures` writes them; empty when the sweep has no leak-rate columns."""
    levels = _flux_levels(result, flux_levels)
    if levels is None:
        return {}
    figures = {"fig4_leak_rate": figure_leak_rate(result)}
    for k in levels:
        figures[f"flux_k{k:02d}"] = figure_flux_map(result, k)
    return figures


def save_flow_figures(
    result: SweepResult,
    outdir: str | os.PathLike[str],
    *,
    formats: Sequence[str] = ("png", "pdf"),
    flux_levels: Iterable[int] | None = None,
    dpi: int = 150,
) -> list[Path]:
    """Write ``fig4_leak_rate`` and one flux map per row in ``flux_levels`` (default: the
    last leaking row) into ``outdir``; nothing when the sweep has no leak-rate columns."""
    from .paper import save_figure

    if isinstance(formats, str):
        formats = (formats,)
    levels = _flux_levels(result, flux_levels)
    if levels is None:
        return []
    out = _validate.path("outdir", outdir)
    _validate.make_directory("outdir", out)
    paths = save_figure(figure_leak_rate(result), out / "fig4_leak_rate", formats, dpi)
    for k in levels:
        paths += save_figure(figure_flux_map(result, int(k)), out / f"flux_k{int(k):02d}",
                             formats, dpi)
    return paths
