"""Figures of a sweep, after the paper (matplotlib, object-oriented, no pyplot state).

Every function draws on a given :class:`matplotlib.axes.Axes`; :func:`save_paper_figures`
creates :class:`matplotlib.figure.Figure` objects itself (never through ``pyplot``, so no
global figure registry, no GUI backend, nothing left open) and renders them with the Agg
(PNG) and PDF backends.

Figures (symbols as in :mod:`leakpath.sweep`; ``*`` marks a dimensionless quantity)
-------------------------------------------------------------------------------------
==========================  ==============================================================
file stem                   content
==========================  ==============================================================
``fig1_topography_moments``  (a) height map ``h(x, y)`` with colour bar, axes in length
                             units; (b) ``m0*, m2*, m4*, α*`` of ``s = h − u`` against
                             ``Δ* = Δ/h_s``
``fig2_vpg_volume_gap``      (a) ``V_pg* = V_pg/V_pg(0)`` against ``V* = V/(A0 σ)``;
                             (b) ``V_pg*`` against ``ḡ* = ḡ/ḡ(0)``
``fig3_vpg_moments``         (a) ``V_pg*`` against ``m0*``; (b) ``V_pg*`` against ``m2*``
``map_kKK``                  classes of the interface at level ``KK``: contact, spanning
                             (percolating), dead-end and trapped free cells
==========================  ==============================================================
"""

from __future__ import annotations

import io
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.colors import BoundaryNorm, ListedColormap
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from .. import _validate
from .._io import atomic_write_bytes
from ._types import SurfaceLike as Surface
from ._types import SweepLike as SweepResult

__all__ = [
    "CLASS_COLOURS",
    "CLASS_NAMES",
    "plot_topography",
    "plot_moments",
    "plot_vpg_vs_free_volume",
    "plot_vpg_vs_mean_gap",
    "plot_vpg_vs_m0",
    "plot_vpg_vs_m2",
    "plot_class_map",
    "figure_topography_moments",
    "figure_vpg_volume_gap",
    "figure_vpg_moments",
    "figure_class_map",
    "default_map_levels",
    "paper_figures",
    "save_figure",
    "save_paper_figures",
]

#: Names of the percolation classes 0–3 (:meth:`leakpath.percolation.Percolation.class_map`).
CLASS_NAMES: tuple[str, ...] = ("contact", "spanning (percolating)", "dead-end", "trapped")
#: Colours of the classes 0–3 (colour-blind safe: grey, blue, orange, vermilion).
CLASS_COLOURS: tuple[str, ...] = ("#4d4d4d", "#0072b2", "#e69f00", "#d55e00")

_FORMATS = ("png", "pdf", "svg")
_LINE = {"marker": "o", "markersize": 3.5, "linewidth": 1.2}


def _unit(surface: Surface) -> str:
    return surface.unit


def _axis_label(result: SweepResult) -> str:
    """``axis 0 (y)``, ``axis 1 (x)`` or ``either``/``both`` axes."""
    axis = result.parameters.get("axis", 0)
    return {0: "axis 0 (y)", 1: "axis 1 (x)"}.get(axis, f"{axis} axis")


# ---------------------------------------------------------------------------- panels
def plot_topography(surface: Surface, ax: Axes, *, cmap: str = "viridis") -> Any:
    """Colour map of the heights ``h(x, y)`` with a colour bar; returns the image.

    Axis 1 of the array is ``x`` (horizontal), axis 0 is ``y`` (vertical, row 0 at the
    bottom); both axes and the colour bar are in the surface's length unit
    (:attr:`leakpath.Surface.unit`).
    """
    ly, lx = surface.length
    unit = _unit(surface)
    im = ax.imshow(
        surface.heights,
        origin="lower",
        extent=(0.0, lx, 0.0, ly),
        cmap=cmap,
        interpolation="nearest",
    )
    ax.set_xlabel(f"x [{unit}]")
    ax.set_ylabel(f"y [{unit}]")
    ax.set_title("(a) topography")
    cbar = ax.figure.colorbar(im, ax=ax, shrink=0.9)
    cbar.set_label(f"h [{unit}]")
    return im


def plot_moments(result: SweepResult, ax: Axes) -> None:
    """``m0*, m2*, m4*, α*`` (moments of ``s = h − u`` over their undeformed values) vs ``Δ*``."""
    x = result.column("approach_star")
    for name, label in (
        ("m0_star", r"$m_0^*$"),
        ("m2_star", r"$m_2^*$"),
        ("m4_star", r"$m_4^*$"),
        ("alpha_star", r"$\alpha^*$"),
    ):
        ax.plot(x, result.column(name), label=label, **_LINE)
    ax.set_xlabel(r"$\Delta^* = \Delta / h_s$")
    ax.set_ylabel("moment / undeformed value")
    ax.set_title("(b) Nayak's moments of the deformed surface")
    ax.grid(True, alpha=0.3)
    ax.legend()


def _plot_vpg(
    result: SweepResult,
    ax: Axes,
    column: str,
    xlabel: str,
    title: str,
    *,
    bound: bool = False,
) -> None:
    """``V_pg*`` against ``column``; with ``bound``, also the line ``V_pg = V`` (every free
    cell percolating), i.e. ``V_pg* = x / x(Δ = 0)`` since ``V_pg(0) = V(0)``."""
    x = result.column(column)
    ax.plot(x, result.column("V_pg_star"), label=_axis_label(result), **_LINE)
    if bound and len(x) and result.rows[0]["approach"] == 0.0 and x[0] > 0:
        xs = np.array([0.0, x[0]])
        ax.plot(xs, xs / x[0], "--", color="0.55", linewidth=1.0, label=r"$V_{pg} = V$")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(r"$V_{pg}^* = V_{pg} / V_{pg}(\Delta = 0)$")
    ax.set_title(title)
    ax.set_ylim(-0.03, 1.05)
    ax.set_xlim(left=0.0)
    ax.grid(True, alpha=0.3)
    ax.legend(title="flow along")


def plot_vpg_vs_free_volume(result: SweepResult, ax: Axes) -> None:
    """Percolating volume ``V_pg*`` against the free volume ``V* = V/(A0 σ)``."""
    _plot_vpg(
        result,
        ax,
        "free_volume_star",
        r"$V^* = V / (A_0 \sigma)$",
        "(a) percolating vs free volume",
        bound=True,
    )


def plot_vpg_vs_mean_gap(result: SweepResult, ax: Axes) -> None:
    """Percolating volume ``V_pg*`` against the mean gap ``ḡ* = ḡ/ḡ(0)``."""
    _plot_vpg(
        result,
        ax,
        "mean_gap_star",
        r"$\bar g^* = \bar g / \bar g(\Delta = 0)$",
        "(b) percolating volume vs mean gap",
        bound=True,
    )


def plot_vpg_vs_m0(result: SweepResult, ax: Axes) -> None:
    """Percolating volume ``V_pg*`` against ``m0* = m0(s)/m0(h)``."""
    _plot_vpg(result, ax, "m0_star", r"$m_0^* = m_0 / m_0(h)$", "(a) percolating volume vs $m_0^*$")


def plot_vpg_vs_m2(result: SweepResult, ax: Axes) -> None:
    """Percolating volume ``V_pg*`` against ``m2* = m2(s)/m2(h)``."""
    _plot_vpg(result, ax, "m2_star", r"$m_2^* = m_2 / m_2(h)$", "(b) percolating volume vs $m_2^*$")


def plot_class_map(
    classes: np.ndarray,
    ax: Axes,
    *,
    dx: float = 1.0,
    unit: str = "length units",
    title: str | None = None,
    legend: bool = True,
) -> Any:
    """Draw a class map (0 contact, 1 spanning, 2 dead-end, 3 trapped) in four colours.

    ``classes`` is ``(ny, nx)``; axes in length units (``dx`` per cell, row 0 at the bottom).
    With ``legend``, a legend with each class's share of the cells goes to the right of the
    axes (save with ``bbox_inches="tight"`` to keep it in the picture). Returns the image.
    """
    classes = np.asarray(classes)
    ny, nx = classes.shape
    cmap = ListedColormap(list(CLASS_COLOURS))
    norm = BoundaryNorm([-0.5, 0.5, 1.5, 2.5, 3.5], cmap.N)
    im = ax.imshow(
        classes,
        origin="lower",
        extent=(0.0, nx * dx, 0.0, ny * dx),
        cmap=cmap,
        norm=norm,
        interpolation="nearest",
    )
    ax.set_xlabel(f"x [{unit}]")
    ax.set_ylabel(f"y [{unit}]")
    if title:
        ax.set_title(title)
    if legend:
        counts = np.bincount(classes.ravel().astype(np.int64), minlength=4)[:4]
        handles = [
            Patch(facecolor=c, edgecolor="none", label=f"{n} ({100 * m / classes.size:.1f} %)")
            for c, n, m in zip(CLASS_COLOURS, CLASS_NAMES, counts, strict=True)
        ]
        ax.legend(
            handles=handles,
            loc="upper left",
            bbox_to_anchor=(1.03, 1.0),
            borderaxespad=0.0,
            frameon=False,
            title="cells",
        )
    return im


# ---------------------------------------------------------------------------- figures
def figure_topography_moments(result: SweepResult) -> Figure:
    """Fig. 1: (a) topography, (b) moments against ``Δ*``."""
    fig = Figure(figsize=(11.0, 4.4), layout="constrained")
    ax_a, ax_b = fig.subplots(1, 2)
    plot_topography(result.surface, ax_a)
    plot_moments(result, ax_b)
    return fig


def figure_vpg_volume_gap(result: SweepResult) -> Figure:
    """Fig. 2: ``V_pg*`` against (a) ``V*`` and (b) ``ḡ*``."""
    fig = Figure(figsize=(10.0, 4.2), layout="constrained")
    ax_a, ax_b = fig.subplots(1, 2)
    plot_vpg_vs_free_volume(result, ax_a)
    plot_vpg_vs_mean_gap(result, ax_b)
    return fig


def figure_vpg_moments(result: SweepResult) -> Figure:
    """Fig. 3: ``V_pg*`` against (a) ``m0*`` and (b) ``m2*``."""
    fig = Figure(figsize=(10.0, 4.2), layout="constrained")
    ax_a, ax_b = fig.subplots(1, 2)
    plot_vpg_vs_m0(result, ax_a)
    plot_vpg_vs_m2(result, ax_b)
    return fig


def figure_class_map(result: SweepResult, k: int) -> Figure:
    """Class map of row ``k`` (chosen flow axis), titled with ``Δ*``, ``a`` and ``V_pg*``."""
    row = result.rows[k]
    fig = Figure(figsize=(7.2, 5.0), layout="constrained")
    ax = fig.subplots()
    title = (
        f"level k = {row['k']}: $\\Delta^*$ = {row['approach_star']:.3g}, "
        f"contact {100 * row['contact_fraction']:.1f} %\n"
        f"$V_{{pg}}^*$ = {row['V_pg_star']:.3g}, flow along {_axis_label(result)}"
    )
    plot_class_map(
        result.class_map(k), ax, dx=result.surface.dx, unit=_unit(result.surface), title=title
    )
    return fig


def default_map_levels(result: SweepResult) -> list[int]:
    """Rows at about a quarter, half, three quarters and all of the sweep (no row 0)."""
    n = len(result.rows)
    if n <= 1:
        return list(range(n))
    picks = sorted({max(1, round(f * (n - 1))) for f in (0.25, 0.5, 0.75, 1.0)})
    return picks


def _map_levels(result: SweepResult, levels_to_map: Iterable[int] | None) -> list[int]:
    """``levels_to_map`` checked against the rows (default :func:`default_map_levels`)."""
    levels = default_map_levels(result) if levels_to_map is None else list(levels_to_map)
    n = len(result.rows)
    for k in levels:
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= k < n:
            raise ValueError(f"levels_to_map: row indices must lie in 0…{n - 1}, got {k!r}")
    return [int(k) for k in levels]


def paper_figures(
    result: SweepResult, *, levels_to_map: Iterable[int] | None = None
) -> dict[str, Figure]:
    """Figs. 1–3 and one class map per level in ``levels_to_map`` (default
    :func:`default_map_levels`), drawn but not written: file stem → Figure, in the order
    :func:`save_paper_figures` writes them."""
    figures = {
        "fig1_topography_moments": figure_topography_moments(result),
        "fig2_vpg_volume_gap": figure_vpg_volume_gap(result),
        "fig3_vpg_moments": figure_vpg_moments(result),
    }
    for k in _map_levels(result, levels_to_map):
        figures[f"map_k{k:02d}"] = figure_class_map(result, k)
    return figures


def save_figure(
    fig: Figure, stem: Path, formats: Sequence[str], dpi: int = 150, *, tight: bool = False
) -> list[Path]:
    """Render ``fig`` to ``stem.<fmt>`` for every format, each file written atomically.

    ``tight`` crops to the drawn artists (``bbox_inches="tight"``), for figures with
    content outside their axes grid such as the class maps' legend. The figure's layout
    engine (constrained layout) places the axes for the first format; the other formats
    reuse those positions, in figure fractions, instead of measuring every label again
    (about a seventh of ``leakpath paper``'s time). The engine is back on the figure
    afterwards.
    """
    extra: dict[str, Any] = {"bbox_inches": "tight", "pad_inches": 0.08} if tight else {}
    engine = fig.get_layout_engine()
    paths = []
    try:
        for i, fmt in enumerate(formats):
            buf = io.BytesIO()
            fig.savefig(buf, format=fmt, dpi=dpi, **extra)
            paths.append(
                atomic_write_bytes(stem.with_name(f"{stem.name}.{fmt}"), buf.getvalue())
            )
            if i == 0 and engine is not None:
                fig.set_layout_engine("none")
    finally:
        if engine is not None:
            fig.set_layout_engine(engine)
    return paths


def remove_stale_temporaries(directory: Path) -> list[Path]:
    """Delete the hidden ``.<name>.<pid>.<token>.tmp`` files that atomic writes of a killed
    process left in ``directory`` (those of live processes are kept). Returns those removed."""
    removed = []
    for tmp in directory.glob(".*.tmp"):
        parts = tmp.name.split(".")
        try:
            pid = int(parts[-3])
        except (IndexError, ValueError):
            continue
        if pid != os.getpid() and _process_alive(pid):
            continue
        try:
            tmp.unlink()
        except OSError:
            continue
        removed.append(tmp)
    return removed


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists, owned by someone else
        return True
    return True


def save_paper_figures(
    result: SweepResult,
    outdir: str | os.PathLike[str],
    *,
    formats: Sequence[str] = ("png", "pdf"),
    levels_to_map: Iterable[int] | None = None,
    dpi: int = 150,
) -> list[Path]:
    """Write Figs. 1–3 and one class map per level in ``levels_to_map`` into ``outdir``.

    ``outdir`` is created if needed. ``formats`` ⊆ {"png", "pdf", "svg"}; ``levels_to_map``
    are row indices (default :func:`default_map_levels`). Returns the paths written.
    """
    if isinstance(formats, str):
        formats = (formats,)
    bad = [f for f in formats if f not in _FORMATS]
    if bad or not formats:
        raise ValueError(f"formats: choose from {', '.join(_FORMATS)}; got {list(formats)!r}")
    levels = _map_levels(result, levels_to_map)
    out = _validate.path("outdir", outdir)
    _validate.make_directory("outdir", out)
    remove_stale_temporaries(out)
    paths: list[Path] = []
    paths += save_figure(
        figure_topography_moments(result), out / "fig1_topography_moments", formats, dpi
    )
    paths += save_figure(figure_vpg_volume_gap(result), out / "fig2_vpg_volume_gap", formats, dpi)
    paths += save_figure(figure_vpg_moments(result), out / "fig3_vpg_moments", formats, dpi)
    for k in levels:
        paths += save_figure(
            figure_class_map(result, int(k)), out / f"map_k{int(k):02d}", formats, dpi, tight=True
        )
    return paths
