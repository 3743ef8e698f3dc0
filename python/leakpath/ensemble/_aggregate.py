"""Aggregation of finished tasks: per-level bands of the dimensionless columns, the
percolation threshold of each surface, and :class:`EnsembleResult`."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from .. import _validate
from .._core import __version__
from .._io import atomic_write_text, machine_info
from .._io import dumps as _dumps
from .._outputs import OutputRecord
from ._layout import (
    _FORMAT,
    QUANTITIES,
    _csv,
    _param_sets_from_manifest,
    _read_manifest,
    _read_task,
    _run_id,
    _task_csv,
)
from ._leakage import write_leak_statistics
from ._params import ParamSet
from ._stats import CONFIDENCE, _describe, t_critical

PathLike = str | os.PathLike[str]



#: Statistics per quantity in ``aggregate.csv`` (column ``<quantity>_<stat>``).
STATS: tuple[str, ...] = ("mean", "std", "ci_low", "ci_high")


#: Columns of ``thresholds.csv`` after the parameter columns.
THRESHOLD_COLUMNS: tuple[str, ...] = (
    "seed",
    "found",
    "k_c",
    "contact_fraction_c",
    "contact_fraction_below",
    "contact_fraction_mid",
    "approach_star_c",
    "approach_star_below",
    "respans",
)


def _spans(row: Mapping[str, Any], axis: Any) -> bool:
    """Whether the free region of a sweep row spans ``axis`` (see the module docstring);
    ``axis`` is read by :func:`leakpath._validate.axis`."""
    axis = _validate.axis(axis)
    if axis == "both":  # one cluster spanning both axes: only the V_pg column knows
        return float(row["V_pg"]) > 0.0
    spans = [int(row[f"n_spanning_axis{a}"]) > 0 for a in (0, 1)]
    return any(spans) if axis == "either" else spans[axis]


def threshold_from_rows(rows: Sequence[Mapping[str, Any]], axis: Any = 0) -> dict[str, Any]:
    """Percolation threshold of one sweep from its rows (module docstring, no extra solves).

    Returns ``found``, ``k_c`` (first level whose free region does not span ``axis``; −1 if
    none), ``contact_fraction_c = a(k_c)``, ``contact_fraction_below = a(k_c − 1)`` (NaN for
    ``k_c = 0``), ``contact_fraction_mid`` (their mean: linear interpolation of the spanning
    indicator), ``approach_star_c``, ``approach_star_below`` and ``respans`` (a later level
    spans again, which a monotonically growing contact set rules out).
    """
    nan = math.nan
    k_c = next((k for k, row in enumerate(rows) if not _spans(row, axis)), -1)
    if k_c < 0:
        return {
            "found": False,
            "k_c": -1,
            "contact_fraction_c": nan,
            "contact_fraction_below": nan,
            "contact_fraction_mid": nan,
            "approach_star_c": nan,
            "approach_star_below": nan,
            "respans": False,
        }
    a_c = float(rows[k_c]["contact_fraction"])
    d_c = float(rows[k_c]["approach_star"])
    a_b = float(rows[k_c - 1]["contact_fraction"]) if k_c > 0 else nan
    d_b = float(rows[k_c - 1]["approach_star"]) if k_c > 0 else nan
    return {
        "found": True,
        "k_c": k_c,
        "contact_fraction_c": a_c,
        "contact_fraction_below": a_b,
        "contact_fraction_mid": 0.5 * (a_b + a_c) if k_c > 0 else a_c,
        "approach_star_c": d_c,
        "approach_star_below": d_b,
        "respans": any(_spans(row, axis) for row in rows[k_c + 1 :]),
    }


# ============================================================================ tasks


#: Parameter-set keys and directory characters an :class:`EnsembleResult` repr shows.
_REPR_KEYS = 4
_REPR_PATH = 120


@dataclass(frozen=True, eq=False)
class EnsembleResult:
    """Aggregated ensemble (see the module docstring for the files and definitions).

    Attributes
    ----------
    directory : Path
        The ensemble directory ``DIR``.
    param_sets : list of ParamSet
        In natural order of their parameters (numbers compare as numbers).
    identity : dict
        Generator and sweep options (``levels``, ``solver``, ``warm_start``, ``axis``, …).
    aggregate : list of dict
        Rows of ``aggregate.csv``: ``param_key``, the parameters, ``k``, ``n`` and
        ``<quantity>_<stat>`` for :data:`QUANTITIES` × :data:`STATS`.
    thresholds : list of dict
        Rows of ``thresholds.csv`` (one per surface).
    threshold_summary : dict
        Per key: ``n``, ``n_found``, ``mean``, ``std``, ``ci_low``, ``ci_high``, ``min``,
        ``max`` and ``quantiles`` of ``contact_fraction_c`` (and the same for
        ``approach_star_c`` under ``"approach_star"``).
    run : dict or None
        How the run went (executor, workers, tasks run/resumed, pool restarts, wall time);
        ``None`` for :func:`aggregate` alone.
    """

    directory: Path
    param_sets: list[ParamSet]
    identity: dict[str, Any]
    aggregate: list[dict[str, Any]]
    thresholds: list[dict[str, Any]]
    threshold_summary: dict[str, dict[str, Any]]
    run: dict[str, Any] | None = None
    figures: list[Path] = field(default_factory=list)

    def __repr__(self) -> str:
        # The aggregate and threshold tables have hundreds of rows: summarise them.
        # A long parameter grid or directory is cut short as well.
        surfaces = sum(len(ps.seeds) for ps in self.param_sets)
        keys = self.keys
        shown = ", ".join(keys[:_REPR_KEYS])
        if len(keys) > _REPR_KEYS:
            shown += f", … {len(keys) - _REPR_KEYS} more"
        directory = str(self.directory)
        if len(directory) > _REPR_PATH:
            directory = "…" + directory[-(_REPR_PATH - 1):]
        return (
            f"EnsembleResult(directory={directory!r}, "
            f"param_sets=[{shown}], surfaces={surfaces}, "
            f"levels={self.identity.get('levels')}, aggregate_rows={len(self.aggregate)}, "
            f"figures={len(self.figures)})"
        )

    @property
    def keys(self) -> list[str]:
        return [ps.key for ps in self.param_sets]

    def param_set(self, key: str) -> ParamSet:
        for ps in self.param_sets:
            if ps.key == key:
                return ps
        raise KeyError(key)

    def curve(self, key: str, quantity: str) -> dict[str, np.ndarray]:
        """``k``, ``mean``, ``std``, ``ci_low``, ``ci_high`` of ``quantity`` over the levels."""
        if quantity not in QUANTITIES:
            raise ValueError(f"quantity: must be one of {', '.join(QUANTITIES)}, got {quantity!r}")
        rows = [r for r in self.aggregate if r["param_key"] == key]
        if not rows:
            raise KeyError(key)
        out = {"k": np.array([r["k"] for r in rows], dtype=np.int64)}
        for stat in STATS:
            out[stat] = np.array([r[f"{quantity}_{stat}"] for r in rows], dtype=np.float64)
        return out

    def threshold_values(self, key: str, column: str = "contact_fraction_c") -> np.ndarray:
        """Per-surface thresholds of one parameter set (found ones only), in seed order."""
        return np.array(
            [r[column] for r in self.thresholds if r["param_key"] == key and r["found"]],
            dtype=np.float64,
        )

    def table(self, key: str, seed: int) -> list[dict[str, Any]]:
        """The per-surface sweep table of task ``(key, seed)``, read from its CSV (checked
        against the checksum in its JSON)."""
        for ps in self.param_sets:
            if ps.key == key:
                if seed not in ps.seeds:
                    raise KeyError(f"seed: {seed!r} is not a seed of {key!r}")
                return _read_task(self.directory, _run_id(self.identity), ps, seed)
        raise KeyError(f"key: {key!r} is not a parameter set of this ensemble")

    @property
    def aggregate_path(self) -> Path:
        return self.directory / "aggregate.csv"

    @property
    def thresholds_path(self) -> Path:
        return self.directory / "thresholds.csv"

    @property
    def json_path(self) -> Path:
        return self.directory / "ensemble.json"

    def summary(self) -> dict[str, Any]:
        """The content of ``ensemble.json``."""
        return json.loads(self.json_path.read_text(encoding="utf-8"))

    def plot(
        self, outdir: PathLike | None = None, formats: Sequence[str] = ("png", "pdf")
    ) -> list[Path]:
        """Write the ensemble figures (default ``DIR/figures``); see
        :func:`save_ensemble_figures`."""
        from ..plotting.ensemble import save_ensemble_figures

        paths = save_ensemble_figures(self, outdir, formats=formats)
        record = _existing_record(self.directory)
        if record is not None:  # files outside the directory are not added
            record.add(paths)
        return paths


# ============================================================================ aggregation


def _aggregate_set(
    ps: ParamSet, tables: list[list[dict[str, Any]]], param_names: Sequence[str]
) -> list[dict[str, Any]]:
    """Rows of ``aggregate.csv`` for one parameter set (tables in seed order)."""
    n_levels = {len(t) for t in tables}
    if len(n_levels) != 1:
        raise ValueError(
            f"{ps.key}: the per-surface tables have different numbers of levels "
            f"({sorted(n_levels)})"
        )
    levels = n_levels.pop()
    n = len(tables)
    tcrit = t_critical(n)
    data = {
        q: np.array([[row[q] for row in t] for t in tables], dtype=np.float64) for q in QUANTITIES
    }  # (n surfaces, levels)
    rows = []
    for k in range(levels):
        row: dict[str, Any] = {"param_key": ps.key}
        row.update({name: ps.params.get(name, "") for name in param_names})
        row["k"] = k
        row["n"] = n
        for q in QUANTITIES:
            x = data[q][:, k]
            mean = float(np.mean(x))
            if n > 1:
                std = float(np.std(x, ddof=1))
                half = tcrit * std / math.sqrt(n)
            else:
                std = half = math.nan
            row[f"{q}_mean"] = mean
            row[f"{q}_std"] = std
            row[f"{q}_ci_low"] = mean - half
            row[f"{q}_ci_high"] = mean + half
        rows.append(row)
    return rows


def _existing_record(directory: Path) -> OutputRecord | None:
    """The record of ``directory`` when a run left one (files written later are added to
    it); ``None`` for a directory without one, where a partial record would mislead."""
    record = OutputRecord(directory)
    return record if record.read() else None


def aggregate(
    out: PathLike,
    *,
    figures: bool = True,
    run: Mapping[str, Any] | None = None,
    _record: OutputRecord | None = None,
) -> EnsembleResult:
    """Aggregate the finished ensemble in ``out`` (every task of its manifest must exist).

    Writes ``aggregate.csv``, ``thresholds.csv`` and ``ensemble.json`` atomically (and the
    figures with ``figures=True``), adds them to the directory's record of written files
    (when it has one) and returns the :class:`EnsembleResult`. The output depends
    only on the per-surface CSVs and the manifest: tables are read in the order of the
    parameter sets (natural order of their values) and seeds (ascending).

    Raises
    ------
    ValueError
        ``out`` holds no ensemble, or a task's table is missing or malformed.
    """
    directory = Path(out)
    manifest = _read_manifest(directory)
    record = _record if _record is not None else _existing_record(directory)
    written: list[Path] = []
    identity = dict(manifest["identity"])
    axis = identity.get("axis")  # an edited identity fails every task's run check below
    run_id = _run_id(identity)
    param_sets = _param_sets_from_manifest(manifest, directory / "manifest.json")
    missing = [
        f"{ps.key}/seed-{s}"
        for ps in param_sets
        for s in ps.seeds
        if not _task_csv(directory, ps.key, s).is_file()
    ]
    if missing:
        more = f" (and {len(missing) - 5} more)" if len(missing) > 5 else ""
        raise ValueError(
            f"out: {len(missing)} task(s) not finished: {', '.join(missing[:5])}{more}; "
            "run the ensemble with resume=True (CLI --resume) to finish them"
        )
    param_names = sorted({name for ps in param_sets for name in ps.params})
    agg_rows: list[dict[str, Any]] = []
    thr_rows: list[dict[str, Any]] = []
    summary: dict[str, dict[str, Any]] = {}
    leak_sets = []  # leak-rate statistics (_leakage)
    for ps in param_sets:
        seeds = sorted(ps.seeds)
        tables = [_read_task(directory, run_id, ps, s) for s in seeds]
        leak_sets.append((ps, seeds, tables))  # leak-rate statistics (_leakage)
        agg_rows += _aggregate_set(ps, tables, param_names)
        set_thr = []
        for seed, table in zip(seeds, tables, strict=True):
            thr = threshold_from_rows(table, axis)
            row = {
                "param_key": ps.key,
                **{n: ps.params.get(n, "") for n in param_names},
                "seed": seed,
                **thr,
            }
            set_thr.append(row)
        thr_rows += set_thr
        a_c = np.array([r["contact_fraction_c"] for r in set_thr], dtype=np.float64)
        d_c = np.array([r["approach_star_c"] for r in set_thr], dtype=np.float64)
        summary[ps.key] = {
            "params": ps.params,
            "surfaces": len(seeds),
            "n_found": int(sum(1 for r in set_thr if r["found"])),
            "n_respans": int(sum(1 for r in set_thr if r["respans"])),
            "contact_fraction": _describe(a_c),
            "approach_star": _describe(d_c),
        }

    agg_columns = ["param_key", *param_names, "k", "n"] + [
        f"{q}_{s}" for q in QUANTITIES for s in STATS
    ]
    thr_columns = ["param_key", *param_names, *THRESHOLD_COLUMNS]
    written.append(atomic_write_text(directory / "aggregate.csv", _csv(agg_rows, agg_columns)))
    written.append(atomic_write_text(directory / "thresholds.csv", _csv(thr_rows, thr_columns)))

    leak_summary = write_leak_statistics(directory, leak_sets, param_names, axis, figures)
    if leak_summary:
        files = leak_summary["files"]
        names = [files["bands"], files["thresholds"], *files.get("figures", [])]
        written += [directory / name for name in names]
    if record is not None:
        record.add(written)

    result = EnsembleResult(
        directory=directory,
        param_sets=param_sets,
        identity=identity,
        aggregate=agg_rows,
        thresholds=thr_rows,
        threshold_summary=summary,
        run=dict(run) if run is not None else None,
    )
    if figures:
        from ..plotting.ensemble import save_ensemble_figures

        result = replace(result, figures=save_ensemble_figures(result))
        if record is not None:
            record.add(result.figures)
    doc = {
        "format": _FORMAT,
        "kind": "leakpath-ensemble-summary",
        "leakpath_version": __version__,
        "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "directory": str(directory.resolve()),
        "identity": identity,
        "param_sets": [
            {"key": ps.key, "params": ps.params, "seeds": sorted(ps.seeds)} for ps in param_sets
        ],
        "quantities": list(QUANTITIES),
        "statistics": {
            "mean": "sum(x_i)/n over the surfaces of a parameter set, per level k",
            "std": "sqrt(sum((x_i - mean)^2)/(n - 1))",
            "ci": f"mean -/+ t_((1+c)/2, n-1) * std/sqrt(n), c = {CONFIDENCE}",
        },
        "threshold_definition": (
            "k_c = first level whose free region does not span the flow axis (n_spanning == 0);"
            " contact_fraction_c = a(k_c) (primary); contact_fraction_below = a(k_c - 1); "
            "contact_fraction_mid = their mean (linear interpolation of the spanning "
            "indicator); distribution statistics over surfaces with found = true"
        ),
        "thresholds": summary,
        "leakage": leak_summary,  # leak-rate statistics (_leakage)
        "run": result.run,
        "files": {
            "aggregate": "aggregate.csv",
            "thresholds": "thresholds.csv",
            "tasks": "tasks/<param_key>/seed-<s>.csv (+ .json)",
            "figures": [str(p.relative_to(directory)) for p in result.figures],
        },
        "machine": machine_info(),
    }
    summary_path = atomic_write_text(directory / "ensemble.json", _dumps(doc))
    if record is not None:
        record.add([summary_path])
    return result


# ============================================================================ executors
