"""Figures of an ensemble: bands of the mean against the mean approach, histograms of the
percolation thresholds. They read an :class:`~leakpath.ensemble.EnsembleResult`
structurally (its parameter sets, aggregate rows and thresholds) and import no ensemble
module."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..ensemble._params import _format_value
from ..ensemble._stats import CONFIDENCE
from .paper import save_figure

PathLike = str | os.PathLike[str]

EnsembleResult = Any  # structural: see leakpath.ensemble.EnsembleResult

# ============================================================================ figures
_BAND_ALPHA = 0.22


def _colours(n: int) -> list[Any]:
    from matplotlib import colormaps

    if n <= 10:
        cmap = colormaps["tab10"]
        return [cmap(i) for i in range(n)]
    cmap = colormaps["viridis"]
    return [cmap(i / max(1, n - 1)) for i in range(n)]


def _varying(result: EnsembleResult) -> list[str]:
    names = sorted({n for ps in result.param_sets for n in ps.params})
    varying = [
        n for n in names if len({_format_value(ps.params.get(n)) for ps in result.param_sets}) > 1
    ]
    return varying or names


def _mean_band(result: EnsembleResult, ax: Any, xq: str, xlabel: str, title: str) -> None:
    names = _varying(result)
    for ps, colour in zip(result.param_sets, _colours(len(result.param_sets)), strict=True):
        x = result.curve(ps.key, xq)
        y = result.curve(ps.key, "V_pg_star")
        n = len(ps.seeds)
        ax.plot(
            x["mean"],
            y["mean"],
            color=colour,
            marker="o",
            markersize=3,
            linewidth=1.3,
            label=f"{ps.label(names)} (n = {n})",
        )
        if n > 1:
            ax.fill_between(
                x["mean"], y["ci_low"], y["ci_high"], color=colour, alpha=_BAND_ALPHA, linewidth=0
            )
            ax.errorbar(
                x["mean"],
                y["mean"],
                xerr=[x["mean"] - x["ci_low"], x["ci_high"] - x["mean"]],
                fmt="none",
                ecolor=colour,
                elinewidth=0.8,
                alpha=0.7,
            )
    ax.set_xlabel(xlabel)
    ax.set_ylabel(r"$V_{pg}^* = V_{pg} / V_{pg}(\Delta = 0)$")
    ax.set_title(title)
    ax.set_ylim(-0.03, 1.05)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small", title=f"mean, {int(CONFIDENCE * 100)} % band")


def figure_vpg_volume_gap(result: EnsembleResult) -> Any:
    """Fig. 2 over the ensemble: mean ``V_pg*`` against mean (a) ``V*``, (b) ``ḡ*``.

    One colour per parameter set; the shaded band is the 95 % confidence band of the mean
    ``V_pg*`` per level, the horizontal bars that of the abscissa.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.5, 4.4), layout="constrained")
    ax_a, ax_b = fig.subplots(1, 2)
    _mean_band(
        result,
        ax_a,
        "free_volume_star",
        r"$V^* = V / (A_0 \sigma)$",
        "(a) percolating vs free volume",
    )
    _mean_band(
        result,
        ax_b,
        "mean_gap_star",
        r"$\bar g^* = \bar g / \bar g(\Delta = 0)$",
        "(b) percolating volume vs mean gap",
    )
    return fig


def figure_vpg_moments(result: EnsembleResult) -> Any:
    """Fig. 3 over the ensemble: mean ``V_pg*`` against mean (a) ``m0*``, (b) ``m2*``."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.5, 4.4), layout="constrained")
    ax_a, ax_b = fig.subplots(1, 2)
    _mean_band(
        result, ax_a, "m0_star", r"$m_0^* = m_0 / m_0(h)$", "(a) percolating volume vs $m_0^*$"
    )
    _mean_band(
        result, ax_b, "m2_star", r"$m_2^* = m_2 / m_2(h)$", "(b) percolating volume vs $m_2^*$"
    )
    return fig


def figure_threshold_histograms(result: EnsembleResult) -> Any:
    """Histogram of the per-surface thresholds ``a_c`` (one panel per parameter set).

    Shared bins; the solid line is the mean, the shaded span its 95 % band, dashed lines
    the 5 % and 95 % quantiles.
    """
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    sets = result.param_sets
    n = len(sets)
    ncols = min(3, n)
    nrows = math.ceil(n / ncols)
    fig = Figure(figsize=(max(6.0, 4.2 * ncols), 3.5 * nrows + 0.4), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols, sharex=True, squeeze=False)).ravel()
    values = [result.threshold_values(ps.key) for ps in sets]
    pooled = np.concatenate([v for v in values if v.size] or [np.zeros(0)])
    if pooled.size:
        lo, hi = float(pooled.min()), float(pooled.max())
        if hi - lo < 1e-12:
            lo, hi = lo - 0.01, hi + 0.01
        bins = np.linspace(lo, hi, int(np.clip(np.sqrt(pooled.size / max(n, 1)) * 2, 5, 30)) + 1)
    else:
        bins = np.linspace(0.0, 1.0, 11)
    names = _varying(result)
    for ax, ps, v, colour in zip(axes, sets, values, _colours(n), strict=False):
        s = result.threshold_summary[ps.key]["contact_fraction"]
        ax.hist(v, bins=bins, color=colour, alpha=0.75, edgecolor="white")
        if v.size:
            ax.axvline(s["mean"], color="black", linewidth=1.2, label=f"mean {s['mean']:.4f}")
            if math.isfinite(s["ci_low"]):
                ax.axvspan(
                    s["ci_low"],
                    s["ci_high"],
                    color="black",
                    alpha=0.15,
                    label=f"{int(CONFIDENCE * 100)} % band of the mean",
                )
            for q in ("0.05", "0.95"):
                ax.axvline(s["quantiles"][q], color="black", linestyle="--", linewidth=0.8)
        found = result.threshold_summary[ps.key]["n_found"]
        ax.set_title(
            f"{ps.label(names)}: threshold reached on {found}/{len(ps.seeds)} surfaces",
            fontsize="medium",
        )
        pad = 0.05 * (bins[-1] - bins[0])
        ax.set_xlim(bins[0] - pad, bins[-1] + pad)  # a wide band of the mean is clipped
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel(r"contact fraction at the threshold $a_c$")
        ax.set_ylabel("surfaces")
        ax.grid(True, alpha=0.3)
        if v.size:
            ax.legend(fontsize="x-small")
    for ax in axes[n:]:
        ax.set_visible(False)
    axis = result.identity.get("axis", 0)
    fig.suptitle(
        f"Percolation threshold: first level without a spanning cluster (flow along axis "
        f"{axis})\nsurfaces still percolating at the last level are not in the histogram",
        fontsize="medium",
    )
    return fig


def save_ensemble_figures(
    result: EnsembleResult,
    outdir: PathLike | None = None,
    *,
    formats: Sequence[str] = ("png", "pdf"),
    dpi: int = 150,
) -> list[Path]:
    """Write ``fig2_vpg_volume_gap``, ``fig3_vpg_moments`` and ``thresholds_hist`` in every
    format (``png``, ``pdf``, ``svg``) into ``outdir`` (default ``DIR/figures``), atomically.
    """
    if isinstance(formats, str):
        formats = (formats,)
    bad = [f for f in formats if f not in ("png", "pdf", "svg")]
    if bad or not formats:
        raise ValueError(f"formats: choose from png, pdf, svg; got {list(formats)!r}")
    directory = Path(outdir) if outdir is not None else result.directory / "figures"
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for stem, make in (
        ("fig2_vpg_volume_gap", figure_vpg_volume_gap),
        ("fig3_vpg_moments", figure_vpg_moments),
        ("thresholds_hist", figure_threshold_histograms),
    ):
        paths += save_figure(make(result), directory / stem, formats, dpi)
    return paths
