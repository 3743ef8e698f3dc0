"""The ensemble directory: one CSV and JSON per task, the manifest that binds a directory
to its run, and reading them back for resume and aggregation."""

from __future__ import annotations

import csv
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._io import atomic_write_text, csv_quote, csv_text
from .._io import dumps as _dumps
from ._params import ParamSet, _format_value, _generator_name, _natural_order

PathLike = str | os.PathLike[str]


#: Dimensionless sweep columns aggregated per level (see the module docstring).
QUANTITIES: tuple[str, ...] = (
    "approach_star",
    "contact_fraction",
    "free_volume_star",
    "mean_gap_star",
    "V_pg_star",
    "m0_star",
    "m2_star",
    "m4_star",
    "alpha_star",
)
_FORMAT = 1
_OWN_FILES = ("manifest.json", "aggregate.csv", "thresholds.csv", "ensemble.json")
_OWN_FILES += ("leakage.csv", "leak_thresholds.csv")  # leak-rate statistics (_leakage)
_OWN_DIRS = ("tasks", "figures")


@dataclass(frozen=True)
class _TaskSpec:
    """Everything a worker needs for one task (picklable, no surface arrays)."""

    generator: Any
    params: dict[str, Any]
    key: str
    seed: int
    levels: int
    solver: str
    warm_start: bool
    axis: Any
    connectivity: int
    E: float  # noqa: N815 - Young's modulus
    nu: float
    boundary: str
    kill_once: str | None = None


@dataclass(frozen=True)
class _TaskOutput:
    key: str
    seed: int
    csv_text: str
    meta: dict[str, Any]
    seconds: float


def _task_dir(out: Path, key: str) -> Path:
    return out / "tasks" / key


def _task_csv(out: Path, key: str, seed: int) -> Path:
    return _task_dir(out, key) / f"seed-{seed}.csv"


def _task_json(out: Path, key: str, seed: int) -> Path:
    return _task_dir(out, key) / f"seed-{seed}.json"


def _write_task(out: Path, result: _TaskOutput) -> None:
    """Write a finished task: its JSON, then its CSV (the completion marker), atomically."""
    directory = _task_dir(out, result.key)
    directory.mkdir(parents=True, exist_ok=True)
    atomic_write_text(_task_json(out, result.key, result.seed), _dumps(result.meta))
    atomic_write_text(_task_csv(out, result.key, result.seed), result.csv_text)


def _task_done(out: Path, key: str, seed: int) -> bool:
    return _task_csv(out, key, seed).is_file() and _task_json(out, key, seed).is_file()


def _clean_stale_temporaries(out: Path) -> None:
    """Remove the hidden temporaries of atomic writes cut short by a killed run: in the task
    directories, ``figures/`` and ``DIR`` itself."""
    patterns = ("tasks/*/.*.tmp", "figures/.*.tmp", ".*.tmp")
    for pattern in patterns:
        for stale in out.glob(pattern):
            try:
                stale.unlink()
            except OSError:
                pass


def _parse_cell(text: str) -> Any:
    """CSV cell → int (no point/exponent), float (``repr`` text, exact) or the string."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def _read_table(path: Path) -> list[dict[str, Any]]:
    """A per-surface CSV as rows of ints/floats/strings (the CSV floats round-trip exactly)."""
    with open(path, encoding="utf-8", newline="") as fh:
        rows = [
            {name: _parse_cell(text) for name, text in raw.items()} for raw in csv.DictReader(fh)
        ]
    if not rows:
        raise ValueError(f"{str(path)!r}: empty table")
    missing = [c for c in (*QUANTITIES, "n_spanning_axis0", "n_spanning_axis1") if c not in rows[0]]
    if missing:
        raise ValueError(f"{str(path)!r}: missing columns {', '.join(missing)}")
    return rows


# ============================================================================ manifest
def _identity(
    generator: Any,
    levels: int,
    solver: str,
    warm_start: bool,
    axis: Any,
    connectivity: int,
    E: float,
    nu: float,
    boundary: str,  # noqa: N803
) -> dict[str, Any]:
    return {
        "generator": _generator_name(generator),
        "levels": levels,
        "solver": solver,
        "warm_start": warm_start,
        "axis": axis,
        "connectivity": connectivity,
        "E": E,
        "nu": nu,
        "boundary": boundary,
    }


def _read_manifest(out: Path) -> dict[str, Any]:
    path = out / "manifest.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ValueError(
            f"out: {str(out)!r} holds no leakpath ensemble (no manifest.json)"
        ) from None
    except (OSError, ValueError) as exc:
        raise ValueError(f"out: cannot read {str(path)!r} ({exc})") from None
    if data.get("kind") != "leakpath-ensemble" or data.get("format") != _FORMAT:
        raise ValueError(f"out: {str(path)!r} is not a leakpath ensemble manifest")
    return data


def _param_sets_from_manifest(manifest: Mapping[str, Any]) -> list[ParamSet]:
    sets = [
        ParamSet(str(p["key"]), dict(p["params"]), tuple(int(s) for s in p["seeds"]))
        for p in manifest["param_sets"]
    ]
    return sorted(sets, key=lambda ps: _natural_order(ps.params))


# ============================================================================ result


def _cell(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    return csv_quote(_format_value(value))


def _csv(rows: Sequence[Mapping[str, Any]], columns: Sequence[str]) -> str:
    return csv_text(rows, columns, lambda _, value: _cell(value))

