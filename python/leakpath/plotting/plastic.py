"""Figures of elastic–perfectly-plastic sweeps (``sweep(hardness=…, unload=True)``): the leak
rate against the nominal pressure on the loading and unloading branches, and the contact and
plastic area fractions against the nominal pressure (``docs/plasticity.md``)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from .. import _validate
from ._types import SweepLike as SweepResult

__all__ = [
    "figure_plastic_leak_rate",
    "figure_plastic_area",
    "plastic_figures",
    "save_plastic_figures",
]

_BRANCH_STYLE = {
    "loading": {"marker": "o", "color": "#0072b2", "linestyle": "-"},
    "unloading": {"marker": "s", "color": "#d55e00", "linestyle": "--"},
}


def _is_plastic(result: SweepResult) -> bool:
    return result.parameters.get("hardness") is not None or any(
        r.get("branch") == "unloading" for r in result.rows
    )


def _branches(result: SweepResult) -> dict[str, np.ndarray]:
    branch = np.array([r.get("branch", "loading") for r in result.rows])
    return {b: np.flatnonzero(branch == b) for b in ("loading", "unloading") if (branch == b).any()}


def _units(result: SweepResult) -> tuple[str, str]:
    meta = result.surface.metadata
    length = str(meta.get("unit", meta.get("length_unit", "L")))
    return length, "E's unit"


def figure_plastic_leak_rate(result: SweepResult) -> Figure:
    """Leak rate ``Q`` (log) against the nominal pressure ``p̄ = F/A0`` on the loading and
    unloading branches; rows without leak (``Q = 0``) as crosses on the lower edge."""
    length, pressure = _units(result)
    fig = Figure(figsize=(6.4, 4.6), layout="constrained")
    ax = fig.subplots()
    x, q = result.column("mean_pressure"), result.column("Q")
    for b, idx in _branches(result).items():
        leak = idx[np.isfinite(q[idx]) & (q[idx] > 0)]
        ax.plot(x[leak], q[leak], label=b, markersize=4, **_BRANCH_STYLE[b])  # type: ignore[arg-type]
        shut = idx[np.isfinite(q[idx]) & (q[idx] == 0)]
        if shut.size:
            ax.plot(
                x[shut],
                np.zeros(shut.size),
                "x",
                color=_BRANCH_STYLE[b]["color"],
                transform=ax.get_xaxis_transform(),
                clip_on=False,
                label=f"{b}: no leak",
            )
    ax.set_yscale("log")
    ax.set_xlabel(rf"nominal pressure $\bar p = F/A_0$ [{pressure}]")
    ax.set_ylabel(rf"leak rate $Q$ [{length}$^3$ per unit time, $\eta = \Delta p = 1$]")
    h = result.parameters.get("hardness")
    ax.set_title("leak rate, loading and unloading" + (f" (H = {h:.4g})" if h else ""))
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize="small")
    return fig


def figure_plastic_area(result: SweepResult) -> Figure:
    """Contact and plastic area fractions against the nominal pressure, per branch."""
    _, pressure = _units(result)
    fig = Figure(figsize=(6.4, 4.6), layout="constrained")
    ax = fig.subplots()
    x = result.column("mean_pressure")
    a, apl = result.column("contact_fraction"), result.column("plastic_fraction")
    for b, idx in _branches(result).items():
        st = dict(_BRANCH_STYLE[b])
        ax.plot(x[idx], a[idx], label=f"contact, {b}", markersize=4, **st)  # type: ignore[arg-type]
        st["marker"] = "^" if b == "loading" else "v"
        st["linestyle"] = ":"
        ax.plot(x[idx], apl[idx], label=f"plastic, {b}", markersize=4, **st)  # type: ignore[arg-type]
    ax.set_xlabel(rf"nominal pressure $\bar p = F/A_0$ [{pressure}]")
    ax.set_ylabel("area fraction [1]")
    ax.set_title(r"contact $\#(p>0)/N$ and plastic $\#(w_p>0)/N$ area fractions")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small")
    return fig


def plastic_figures(result: SweepResult) -> dict[str, Figure]:
    """``fig5_plastic_leak_rate`` (when the sweep has leak rates) and ``fig6_plastic_area``,
    drawn but not written; empty for an elastic sweep without unloading."""
    if not _is_plastic(result):
        return {}
    figures = {}
    if np.isfinite(result.column("Q")).any():
        figures["fig5_plastic_leak_rate"] = figure_plastic_leak_rate(result)
    figures["fig6_plastic_area"] = figure_plastic_area(result)
    return figures


def save_plastic_figures(
    result: SweepResult,
    outdir: str | os.PathLike[str],
    *,
    formats: Sequence[str] = ("png", "pdf"),
    dpi: int = 150,
) -> list[Path]:
    """Write :func:`plastic_figures` into ``outdir`` (nothing for an elastic sweep)."""
    from .paper import save_figure

    if isinstance(formats, str):
        formats = (formats,)
    figures = plastic_figures(result)
    if not figures:
        return []
    out = _validate.path("outdir", outdir)
    _validate.make_directory("outdir", out)
    paths: list[Path] = []
    for stem, fig in figures.items():
        paths += save_figure(fig, out / stem, formats, dpi)
    return paths
