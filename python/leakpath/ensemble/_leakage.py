"""Leak-rate statistics of an ensemble: bands of ``log10 K`` against the contact fraction and
the contact fraction where the leak stops, per surface.

Every task's sweep table carries ``Q``, ``K``, ``K_star`` (:mod:`leakpath.leakage`) along the
flow axis (the ensemble's ``axis`` when it is 0 or 1, else 0). From them, per parameter set:

* **Bands** (``leakage.csv``): each surface's ``log10 K`` is interpolated linearly in the
  contact fraction ``a`` between its leaking levels (``K > 0``) onto the grid
  :data:`CONTACT_GRID` (``a = 0, 0.01, …, 1``); outside its leaking range it has no value.
  At each grid point over the ``n`` surfaces with a value: ``mean``, ``std`` (ddof 1), the
  95 % band of the mean ``mean ± t_{0.975, n−1} std/√n`` (as for the other ensemble
  quantities) and the quantiles 5/25/50/75/95 %. The same for ``log10 K*``.
* **Where the leak stops** (``leak_thresholds.csv``): ``k_q``, the first level with
  ``Q = 0``, and ``contact_fraction_q = a(k_q)``. The flow and the percolation classes use
  one definition of an open cell and the same 4-connectivity (docs/flow.md), so with
  ``connectivity=4`` this equals the percolation threshold ``contact_fraction_c`` of
  ``thresholds.csv`` for the same axis; ``equals_percolation`` records the check.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .. import _elementary
from .._io import atomic_write_text
from ..leakage import flow_axis_for
from ._layout import _csv
from ._stats import _describe, t_critical

__all__ = [
    "BAND_QUANTILES",
    "CONTACT_GRID",
    "leak_bands",
    "leak_threshold_from_rows",
    "log_k_on_grid",
    "write_leak_statistics",
]

#: Contact fractions at which the bands are evaluated.
CONTACT_GRID = np.round(np.linspace(0.0, 1.0, 101), 12)
#: Quantiles of the bands.
BAND_QUANTILES: tuple[float, ...] = (0.05, 0.25, 0.5, 0.75, 0.95)
#: Columns of ``leak_thresholds.csv`` after the parameter columns and the seed.
LEAK_THRESHOLD_COLUMNS: tuple[str, ...] = (
    "found_q",
    "k_q",
    "contact_fraction_q",
    "contact_fraction_q_below",
    "k_percolation",
    "equals_percolation",
)
_QUANTILE_NAMES = tuple(f"q{int(q * 100):02d}" for q in BAND_QUANTILES)
_STATS = ("n", "mean", "std", "ci_low", "ci_high", *_QUANTILE_NAMES)


def has_flow(rows: Sequence[Mapping[str, Any]]) -> bool:
    """Whether a table carries finite leak-rate columns."""
    return bool(rows) and "K" in rows[0] and all(math.isfinite(float(r["K"])) for r in rows)


def leak_threshold_from_rows(
    rows: Sequence[Mapping[str, Any]], flow_axis: int = 0
) -> dict[str, Any]:
    """First level without leak (``Q = 0``) and its contact fraction, with the percolation
    check along ``flow_axis`` (``n_spanning_axis<flow_axis> == 0`` at the same level)."""
    k_q = next((k for k, r in enumerate(rows) if float(r["Q"]) == 0.0), -1)
    k_p = next(
        (k for k, r in enumerate(rows) if int(r[f"n_spanning_axis{flow_axis}"]) == 0), -1
    )
    if k_q < 0:
        a_q = a_b = math.nan
    else:
        a_q = float(rows[k_q]["contact_fraction"])
        a_b = float(rows[k_q - 1]["contact_fraction"]) if k_q > 0 else math.nan
    return {
        "found_q": k_q >= 0,
        "k_q": k_q,
        "contact_fraction_q": a_q,
        "contact_fraction_q_below": a_b,
        "k_percolation": k_p,
        "equals_percolation": k_q == k_p,
    }


def log_k_on_grid(
    rows: Sequence[Mapping[str, Any]], column: str = "K", grid: np.ndarray = CONTACT_GRID
) -> np.ndarray:
    """``log10`` of ``column`` interpolated linearly in the contact fraction between the
    leaking levels (``> 0``); NaN outside their range."""
    a = np.array([float(r["contact_fraction"]) for r in rows])
    k = np.array([float(r[column]) for r in rows])
    ok = np.isfinite(k) & (k > 0)
    out = np.full(grid.shape, np.nan)
    if ok.sum() == 0:
        return out
    a_ok, y_ok = a[ok], _elementary.log10(k[ok])
    order = np.argsort(a_ok, kind="stable")
    a_ok, y_ok = a_ok[order], y_ok[order]
    inside = (grid >= a_ok[0]) & (grid <= a_ok[-1])
    out[inside] = np.interp(grid[inside], a_ok, y_ok)
    return out


def leak_bands(values: np.ndarray) -> list[dict[str, float]]:
    """Statistics per grid point of ``values`` (surfaces × grid; NaN = no value)."""

    rows = []
    for j in range(values.shape[1]):
        x = values[:, j]
        x = x[np.isfinite(x)]
        n = int(x.size)
        row: dict[str, float] = {"n": n}
        if n == 0:
            row.update({s: math.nan for s in _STATS if s != "n"})
        else:
            mean = float(np.mean(x))
            if n > 1:
                std = float(np.std(x, ddof=1))
                half = t_critical(n) * std / math.sqrt(n)
            else:
                std = half = math.nan
            row.update(mean=mean, std=std, ci_low=mean - half, ci_high=mean + half)
            for q in BAND_QUANTILES:
                row[f"q{int(q * 100):02d}"] = float(np.quantile(x, q))
        rows.append(row)
    return rows


def write_leak_statistics(
    directory: Path,
    sets: Sequence[tuple[Any, Sequence[int], Sequence[Sequence[Mapping[str, Any]]]]],
    param_names: Sequence[str],
    axis: Any,
    figures: bool = True,
) -> dict[str, Any]:
    """Write ``leakage.csv`` and ``leak_thresholds.csv`` (and ``figures/leak_bands``) for the
    ensemble in ``directory``; ``sets`` holds ``(param_set, seeds, tables)``. Returns the
    summary for ``ensemble.json`` (empty when the tables carry no leak-rate columns)."""

    if not sets or not all(has_flow(t) for _, _, tables in sets for t in tables):
        return {}
    flow_axis = flow_axis_for(None, axis)
    band_rows: list[dict[str, Any]] = []
    thr_rows: list[dict[str, Any]] = []
    summary: dict[str, Any] = {"flow_axis": flow_axis, "param_sets": {}}
    curves: dict[str, dict[str, list[dict[str, float]]]] = {}
    for ps, seeds, tables in sets:
        head = {"param_key": ps.key, **{n: ps.params.get(n, "") for n in param_names}}
        per = {}
        for column in ("K", "K_star"):
            values = np.array([log_k_on_grid(t, column) for t in tables])
            per[column] = leak_bands(values)
        curves[ps.key] = per
        for j, a in enumerate(CONTACT_GRID):
            row = {**head, "contact_fraction": float(a)}
            for column, label in (("K", "log10_K"), ("K_star", "log10_K_star")):
                for s, v in per[column][j].items():
                    row[f"{label}_{s}"] = v
            band_rows.append(row)
        set_thr = []
        for seed, table in zip(seeds, tables, strict=True):
            set_thr.append({**head, "seed": seed, **leak_threshold_from_rows(table, flow_axis)})
        thr_rows += set_thr
        a_q = np.array([r["contact_fraction_q"] for r in set_thr], dtype=np.float64)
        summary["param_sets"][ps.key] = {
            "n_found": int(sum(r["found_q"] for r in set_thr)),
            "n_equal_to_percolation": int(sum(r["equals_percolation"] for r in set_thr)),
            "contact_fraction_q": _describe(a_q),
        }
    band_columns = ["param_key", *param_names, "contact_fraction"] + [
        f"{label}_{s}" for label in ("log10_K", "log10_K_star") for s in _STATS
    ]
    thr_columns = ["param_key", *param_names, "seed", *LEAK_THRESHOLD_COLUMNS]
    atomic_write_text(directory / "leakage.csv", _csv(band_rows, band_columns))
    atomic_write_text(directory / "leak_thresholds.csv", _csv(thr_rows, thr_columns))
    summary["files"] = {"bands": "leakage.csv", "thresholds": "leak_thresholds.csv"}
    if figures:
        paths = _save_band_figure(directory / "figures", curves)
        summary["files"]["figures"] = [str(p.relative_to(directory)) for p in paths]
    return summary


def _save_band_figure(outdir: Path, curves: Mapping[str, Any]) -> list[Path]:
    from matplotlib.figure import Figure

    from ..plotting.paper import save_figure

    fig = Figure(figsize=(7.0, 4.6), layout="constrained")
    ax = fig.subplots()
    for key, per in curves.items():
        rows = per["K_star"]
        mean = np.array([r["mean"] for r in rows])
        lo = np.array([r["ci_low"] for r in rows])
        hi = np.array([r["ci_high"] for r in rows])
        q05 = np.array([r["q05"] for r in rows])
        q95 = np.array([r["q95"] for r in rows])
        (line,) = ax.plot(CONTACT_GRID, mean, label=f"{key}: mean")
        ax.fill_between(CONTACT_GRID, lo, hi, color=line.get_color(), alpha=0.35,
                        label="95 % band of the mean")
        ax.fill_between(CONTACT_GRID, q05, q95, color=line.get_color(), alpha=0.12,
                        label="5–95 % of the surfaces")
    ax.set_xlabel("contact fraction a")
    ax.set_ylabel(r"$\log_{10} K^*$")
    ax.set_title("leak permeability over the ensemble")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small")
    outdir.mkdir(parents=True, exist_ok=True)
    return save_figure(fig, outdir / "leak_bands", ("png", "pdf"))
