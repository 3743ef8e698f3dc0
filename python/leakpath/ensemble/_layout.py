"""The ensemble directory: one CSV and JSON per task, the manifest that binds a directory
to its run, and reading them back for resume and aggregation."""

from __future__ import annotations

import csv
import hashlib
import io
import json
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._checkpoint import _record_digest
from .._io import atomic_write_text, csv_quote, csv_text
from .._io import dumps as _dumps
from ..errors import InvalidArgumentError
from ._params import ParamSet, _format_value, _generator_name, _natural_order, param_key

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
#: Temporaries of atomic writes, ``.<name>.<pid>.<hex token>.tmp`` (any token length, as the
#: figure writer's clean-up accepts); a user's ``.notes.tmp`` does not match.
_TEMPORARY = re.compile(r"^\..+\.\d+\.[0-9a-f]+\.tmp$")


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


def _run_id(identity: Mapping[str, Any]) -> str:
    """SHA-256 binding task records to their run: the format and the options every task
    shares (generator, levels, solver, …), not the seeds, so that a resume may add seeds."""
    body = {"format": _FORMAT, "identity": json.loads(_dumps(identity))}
    text = json.dumps(body, sort_keys=True, allow_nan=False, ensure_ascii=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _write_task(out: Path, result: _TaskOutput, run_id: str) -> list[Path]:
    """Write a finished task: its JSON, then its CSV (the completion marker), atomically;
    returns both paths.

    The JSON carries the run id, the SHA-256 of the CSV and its own SHA-256 (as sweep
    checkpoints do), so that a table edited or damaged afterwards is never aggregated.
    """
    directory = _task_dir(out, result.key)
    directory.mkdir(parents=True, exist_ok=True)
    meta = dict(result.meta)
    meta["run"] = run_id
    meta["csv_sha256"] = hashlib.sha256(result.csv_text.encode("utf-8")).hexdigest()
    meta = json.loads(_dumps(meta))  # the JSON form that is hashed and read back
    meta["sha256"] = _record_digest(meta)
    return [
        atomic_write_text(_task_json(out, result.key, result.seed), _dumps(meta)),
        atomic_write_text(_task_csv(out, result.key, result.seed), result.csv_text),
    ]


def _own_task_files(out: Path) -> list[Path]:
    """The task files under ``out/tasks`` that leakpath wrote, recognised by content.

    A task JSON counts when it matches its own checksum and names the task of its place
    (``tasks/<key>/seed-<seed>.json``); its CSV when its bytes match the checksum that JSON
    records. A user's file there, or an edited one, is not listed.
    """
    own: list[Path] = []
    tasks = out.resolve() / "tasks"
    for meta_path in sorted(out.glob("tasks/*/seed-*.json")):
        if meta_path.is_symlink() or not meta_path.is_file():
            continue
        try:  # a linked directory leading elsewhere is not the ensemble's
            if meta_path.parent.resolve() != tasks / meta_path.parent.name:
                continue
        except OSError:
            continue
        try:
            meta = json.loads(meta_path.read_bytes().decode("utf-8"))
        except (OSError, ValueError):
            continue
        if (
            not isinstance(meta, dict)
            or meta.get("sha256") != _record_digest(meta)
            or not isinstance(meta.get("run"), str)
            or meta.get("key") != meta_path.parent.name
            or meta_path.name != f"seed-{meta.get('seed')}.json"
        ):
            continue
        own.append(meta_path)
        csv_path = meta_path.with_suffix(".csv")
        try:
            if csv_path.is_symlink():
                continue
            if hashlib.sha256(csv_path.read_bytes()).hexdigest() == meta.get("csv_sha256"):
                own.append(csv_path)
        except OSError:
            pass
    return own


class _BadTask(Exception):
    """A task's files that must not be used (the message says why)."""


def _read_task_file(path: Path, what: str) -> bytes:
    """The bytes of one of a task's files, or :class:`_BadTask` saying it is missing or
    unreadable."""
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise _BadTask(f"its {what} {path.name} is missing") from None
    except OSError as exc:
        raise _BadTask(f"its {what} {path.name} is unreadable ({exc})") from None


def _load_task(out: Path, run_id: str, ps: ParamSet, seed: int) -> list[dict[str, Any]]:
    """The checked table of task ``(ps, seed)``; raises :class:`_BadTask` saying why not.

    Checks, in order: the JSON is readable and matches its own checksum, belongs to this run
    and this task, and the CSV's bytes match the checksum the JSON records.
    """
    meta_path = _task_json(out, ps.key, seed)
    csv_path = _task_csv(out, ps.key, seed)
    raw_meta = _read_task_file(meta_path, "metadata file")
    try:
        meta = json.loads(raw_meta.decode("utf-8"))
    except ValueError:  # UnicodeDecodeError and JSONDecodeError alike
        raise _BadTask(f"its metadata file {meta_path.name} is not valid JSON") from None
    if not isinstance(meta, dict) or "sha256" not in meta:
        raise _BadTask(f"its metadata file {meta_path.name} carries no checksum")
    digest = meta.pop("sha256")
    if digest != _record_digest(meta):
        raise _BadTask(f"its metadata file {meta_path.name} does not match its checksum")
    if meta.get("run") != run_id:
        raise _BadTask("it belongs to another run (generator or sweep options differ)")
    if meta.get("key") != ps.key or meta.get("seed") != seed or meta.get("params") != ps.params:
        raise _BadTask("it belongs to another task (parameters or seed differ)")
    raw = _read_task_file(csv_path, "table")
    if hashlib.sha256(raw).hexdigest() != meta.get("csv_sha256"):
        raise _BadTask(f"its table {csv_path.name} does not match its checksum")
    try:
        return _parse_table(raw.decode("utf-8"))
    except ValueError as exc:  # checksummed yet malformed: written by a broken leakpath
        raise _BadTask(f"its table {csv_path.name} is malformed ({exc})") from None


def _task_problem(out: Path, run_id: str, ps: ParamSet, seed: int) -> str | None:
    """Why task ``(ps, seed)`` must be run (again), or ``None`` if its files are good."""
    if not _task_csv(out, ps.key, seed).is_file():
        return "not finished"
    try:
        _load_task(out, run_id, ps, seed)
    except _BadTask as exc:
        return str(exc)
    return None


def _read_task(out: Path, run_id: str, ps: ParamSet, seed: int) -> list[dict[str, Any]]:
    """:func:`_load_task` for aggregation: a bad task is an error naming its file."""
    try:
        return _load_task(out, run_id, ps, seed)
    except _BadTask as exc:
        raise InvalidArgumentError(
            f"out: task {ps.key}/seed-{seed} ({str(_task_csv(out, ps.key, seed))!r}) cannot "
            f"be used: {exc}; run the ensemble again with resume=True (CLI --resume) to "
            "recompute it",
            argument="out",
        ) from None


def _clean_stale_temporaries(out: Path) -> None:
    """Remove the hidden temporaries of atomic writes cut short by a killed run: in the task
    directories, ``figures/`` and ``DIR`` itself (only files named like them, never a user's
    own ``.notes.tmp``)."""
    patterns = ("tasks/*/.*.tmp", "figures/.*.tmp", ".*.tmp")
    for pattern in patterns:
        for stale in out.glob(pattern):
            if not _TEMPORARY.match(stale.name) or not stale.is_file():
                continue
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


def _parse_table(text: str) -> list[dict[str, Any]]:
    """A per-surface CSV's text as rows of ints/floats/strings (floats round-trip exactly)."""
    try:
        rows = [
            {name: _parse_cell(text) for name, text in raw.items()}
            for raw in csv.DictReader(io.StringIO(text, newline=""))
        ]
    except csv.Error as exc:
        raise ValueError(f"not a CSV table ({exc})") from None
    if not rows:
        raise ValueError("empty table")
    missing = [c for c in (*QUANTITIES, "n_spanning_axis0", "n_spanning_axis1") if c not in rows[0]]
    if missing:
        raise ValueError(f"missing columns {', '.join(missing)}")
    if any(None in row or None in row.values() for row in rows):
        raise ValueError("rows of different lengths")
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
        raise InvalidArgumentError(
            f"out: {str(out)!r} holds no leakpath ensemble (no manifest.json)", argument="out"
        ) from None
    except (OSError, ValueError) as exc:  # ValueError: not UTF-8, or not JSON
        raise InvalidArgumentError(
            f"out: cannot read {str(path)!r} ({exc.__class__.__name__}); restore it, or run "
            "the ensemble again with overwrite=True (CLI --overwrite)",
            argument="out",
        ) from None
    if (
        not isinstance(data, dict)
        or data.get("kind") != "leakpath-ensemble"
        or data.get("format") != _FORMAT
        or not isinstance(data.get("identity"), dict)
    ):
        raise InvalidArgumentError(
            f"out: {str(path)!r} is not a leakpath ensemble manifest", argument="out"
        )
    return data


def _param_sets_from_manifest(manifest: Mapping[str, Any], path: Path) -> list[ParamSet]:
    """The parameter sets of a manifest read from ``path``, checked.

    A key must be the :func:`param_key` of its parameters: keys name directories under
    ``tasks/``, so an edited key (``../..``, an absolute path) must never be followed.
    """
    where = f"{str(path)!r}"
    entries = manifest.get("param_sets")
    if not isinstance(entries, list) or not entries:
        raise InvalidArgumentError(
            f"out: {where} lists no parameter sets; the manifest is damaged, run the "
            "ensemble again with overwrite=True (CLI --overwrite)",
            argument="out",
        )
    sets = []
    for p in entries:
        key = p.get("key") if isinstance(p, dict) else None
        params = p.get("params") if isinstance(p, dict) else None
        seeds = p.get("seeds") if isinstance(p, dict) else None
        if not isinstance(params, dict) or not params or key != param_key(params):
            raise InvalidArgumentError(
                f"out: {where} has the parameter-set key {key!r}, which is not the key of its "
                "parameters (keys name directories under tasks/, so it is not followed); the "
                "manifest was edited or is damaged: restore it, or run the ensemble again with "
                "overwrite=True (CLI --overwrite)",
                argument="out",
            )
        if (
            not isinstance(seeds, list)
            or not seeds
            or any(isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in seeds)
        ):
            raise InvalidArgumentError(
                f"out: {where} has bad seeds for {key!r} (expected non-negative integers); "
                "restore the manifest, or run the ensemble again with overwrite=True "
                "(CLI --overwrite)",
                argument="out",
            )
        sets.append(ParamSet(key, dict(params), tuple(seeds)))
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

