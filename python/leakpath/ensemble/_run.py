"""The :func:`ensemble` entry point: validate, lay out the directory, run, aggregate."""

from __future__ import annotations

import json
import numbers
import os
import time
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._core import __version__
from .._io import atomic_write_text
from .._io import dumps as _dumps
from .._outputs import RECORD_NAME, OutputRecord, OverwriteNote, prune_empty_dirs
from ..contact import SOLVERS, contact_modulus
from ..surfaces import Surface
from ._aggregate import EnsembleResult, aggregate
from ._executors import (
    _cpus,
    _dask_client,
    _Driver,
    _is_dask_client,
    _run_dask,
    _run_processes,
    _run_serial,
)
from ._layout import (
    _FORMAT,
    _clean_stale_temporaries,
    _identity,
    _own_task_files,
    _read_manifest,
    _run_id,
    _task_problem,
    _TaskSpec,
)
from ._params import (
    ParamSet,
    _check_generator,
    _expand_params,
    _generate,
    _natural_order,
    param_key,
)

PathLike = str | os.PathLike[str]

_AXES: tuple[Any, ...] = (0, 1, "either", "both")


def _check_int(name: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        raise ValueError(f"{name}: must be an integer ≥ {minimum}, got {value!r}")
    return int(value)


def _resolve_seeds(surfaces: Any, seeds: Any) -> tuple[int, ...]:
    if seeds is None:
        n = 50 if surfaces is None else _check_int("surfaces", surfaces, 1)
        return tuple(range(n))
    if isinstance(seeds, (str, bytes)) or not isinstance(seeds, Iterable):
        raise ValueError(f"seeds: must be a sequence of non-negative integers, got {seeds!r}")
    out = tuple(_check_int("seeds", s, 0) for s in seeds)
    if not out:
        raise ValueError("seeds: must not be empty")
    if len(set(out)) != len(out):
        raise ValueError("seeds: must be distinct")
    if surfaces is not None and _check_int("surfaces", surfaces, 1) != len(out):
        raise ValueError(f"surfaces: {surfaces} does not match the {len(out)} seeds given")
    return tuple(sorted(out))


def _prepare_directory(
    out: Path, resume: bool, overwrite: bool
) -> tuple[dict[str, Any] | None, OutputRecord]:
    """Check/clean ``out`` for a new run or a resumed one; returns the old manifest if any,
    and the record of the files this run writes (a resumed run adds to the earlier one's)."""
    if resume and overwrite:
        raise ValueError("resume, overwrite: choose one (resume keeps finished tasks)")
    if out.exists() and not out.is_dir():
        raise ValueError(f"out: {str(out)!r} exists and is not a directory")
    record = OutputRecord(out)
    if not out.exists():
        out.mkdir(parents=True)
        return None, record
    if resume:
        if (out / "manifest.json").exists():
            manifest = _read_manifest(out)
            record.read()
            return manifest, record
        if any(out.iterdir()):
            raise ValueError(
                f"out: {str(out)!r} is not empty and holds no leakpath ensemble to resume"
            )
        return None, record
    if overwrite:
        _clear_earlier_run(out, record)
        return None, record
    if any(out.iterdir()):
        raise FileExistsError(
            f"out: {str(out)!r} is not empty; resume the ensemble there (resume=True, CLI "
            "--resume) or replace it (overwrite=True, CLI --overwrite)"
        )
    return None, record


def _listing(names: Sequence[str], limit: int = 5) -> str:
    shown = ", ".join(names[:limit])
    return shown + (f" and {len(names) - limit} more" if len(names) > limit else "")


def _clear_earlier_run(out: Path, record: OutputRecord) -> None:
    """Delete what an earlier ensemble in ``out`` provably wrote; warn
    (:class:`OverwriteNote`) about what stays.

    Task files recognised by their checksums go first, so that a task file the user only
    touched (same bytes, new time) is not reported as kept; then the recorded files still
    as the run left them. A user's file, even under ``tasks/`` or ``figures/``, stays.
    """
    had_record = record.read()
    removed = _own_task_files(out)
    for path in removed:
        path.unlink()
    kept = record.remove_unchanged() if had_record else []
    removed += record.removed
    _clean_stale_temporaries(out)
    prune_empty_dirs(out, removed)
    if kept:
        warnings.warn(
            f"overwrite: kept {len(kept)} file(s) in {str(out)!r} that changed since the "
            f"earlier run wrote them: {_listing(kept)}",
            OverwriteNote,
            stacklevel=4,
        )
    left = sorted(
        p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file() or p.is_symlink()
    )
    if not had_record and left:
        warnings.warn(
            f"overwrite: {str(out)!r} holds no record of the files an earlier run wrote "
            f"({RECORD_NAME}), so only its task files recognised by their checksums were "
            f"removed; {len(left)} other file(s) stay unless this run rewrites them: "
            f"{_listing(left)}",
            OverwriteNote,
            stacklevel=4,
        )


# ============================================================================ entry point
def ensemble(
    *,
    generator: str | Callable[..., Surface] = "rmd",
    params: Mapping[str, Any] | Sequence[Mapping[str, Any]],
    surfaces: int | None = None,
    seeds: Iterable[int] | None = None,
    levels: int = 20,
    solver: str = "auto",
    warm_start: bool = True,
    axis: int | str = 0,
    connectivity: int = 4,
    E: float = 1.0,  # noqa: N803 - Young's modulus
    nu: float = 0.0,
    boundary: str = "free",
    out: PathLike,
    executor: Any = None,
    workers: int | None = None,
    threads_per_worker: int | None = None,
    retries: int = 2,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool = True,
    figures: bool = True,
    _stop_after: int | None = None,
    _kill_once: str | None = None,
) -> EnsembleResult:
    """Run one sweep per (parameter set, seed) in parallel and aggregate them.

    Parameters
    ----------
    generator : "rmd", "spectral" or callable
        Surface generator: :func:`leakpath.rmd` (parameters ``m``, ``D``, optional
        ``sigma0``, ``length``), :func:`leakpath.spectral` (``shape``, ``hurst``, …) or a
        picklable callable ``f(*, seed, **params) -> Surface``.
    params : dict of lists, or list of dicts
        ``{"D": [2.1, 2.3, 2.5], "m": [7]}`` runs the Cartesian product (a scalar counts as a
        one-element list); a list of dicts gives the sets explicitly.
    surfaces : int, optional
        Surfaces per parameter set, seeds ``0 … surfaces − 1`` (default 50).
    seeds : sequence of int, optional
        Explicit seeds instead (the same for every parameter set).
    levels, solver, warm_start, axis, connectivity, E, nu, boundary
        Passed to :func:`leakpath.sweep.sweep` (``levels + 1`` rows from ``Δ = 0`` to
        ``h_s``); ``axis`` is also the flow axis of the threshold.
    out : path
        The ensemble directory ``DIR`` (created if needed). For a multi-machine Dask cluster
        it only needs to be on the driver's machine: the driver writes every file.
    executor : None, "processes", "serial", a ``dask.distributed.Client`` or an address
        Where tasks run (module docstring). Default: local processes.
    workers : int, optional
        Local worker processes (default: all CPUs available). Only for local processes.
    threads_per_worker : int, optional
        rayon threads per task (``RAYON_NUM_THREADS`` in each worker). Default 1 — one
        single-threaded task per core, reproducible across executors; for Dask the default
        also respects a ``RAYON_NUM_THREADS`` already set in the workers' environment.
    retries : int
        Dask: ``retries`` of a failed task; processes: how often a task whose worker process
        died is run again (after a worker dies, the unfinished tasks run one process each,
        so that a task that kills its worker fails alone and the others are saved).
    resume : bool
        Skip tasks whose files in ``DIR`` pass their checks (checksums, same run); run the
        missing ones, and again those whose files fail (named in a ``RuntimeWarning`` and in
        ``run["recomputed"]``).
    overwrite : bool
        Replace a previous ensemble in ``DIR``: delete the files its run recorded writing
        (``DIR/.leakpath-outputs.json``) that are still as it left them, and task files
        recognised by their checksums; a user's file stays, and an
        :class:`OverwriteNote` warning names recorded files kept because
        they changed (or says that a directory without a record lost only its task files).
    progress : bool
        tqdm progress bar over tasks on stderr (silent when stderr is not a terminal).
    figures : bool
        Write the figures into ``DIR/figures``.

    Returns
    -------
    EnsembleResult
        With ``run`` recording the executor, tasks run and resumed, wall and compute time.

    Raises
    ------
    ValueError
        A bad argument (the message names it), or ``resume`` on a different ensemble.
    FileExistsError
        ``DIR`` is not empty and neither ``resume`` nor ``overwrite`` was given.
    ImportError
        A scheduler address without ``dask.distributed`` installed.
    RuntimeError
        Some tasks failed (their errors are listed; the finished ones are on disk, so
        ``resume=True`` reruns only the failed ones), or local workers kept dying.
    """
    t_start = time.perf_counter()
    sets = _expand_params(params)
    _check_generator(generator, sets)
    seed_tuple = _resolve_seeds(surfaces, seeds)
    levels = _check_int("levels", levels, 1)
    if solver not in SOLVERS:
        raise ValueError(f"solver: must be one of {', '.join(SOLVERS)}; got {solver!r}")
    if not isinstance(warm_start, (bool, np.bool_)):
        raise ValueError(f"warm_start: must be True or False, got {warm_start!r}")
    if isinstance(axis, (bool, np.bool_)) or axis not in _AXES:
        raise ValueError(f"axis: must be 0, 1, 'either' or 'both', got {axis!r}")
    if isinstance(connectivity, bool) or connectivity not in (4, 8):
        raise ValueError(f"connectivity: must be 4 or 8, got {connectivity!r}")
    if boundary not in ("free", "periodic"):
        raise ValueError(f"boundary: must be 'free' or 'periodic', got {boundary!r}")
    # The elastic constants are used only inside the tasks: check them here, before any
    # worker starts or any file is written.
    for name, value in (("E", E), ("nu", nu)):
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
            raise ValueError(f"{name}: must be a number, got {value!r}")
    contact_modulus(E, nu)
    retries = _check_int("retries", retries, 0)
    if workers is not None:
        workers = _check_int("workers", workers, 1)
    if threads_per_worker is not None:
        threads_per_worker = _check_int("threads_per_worker", threads_per_worker, 1)

    mode: str
    if executor is None or executor == "processes":
        mode = "processes"
    elif executor == "serial":
        mode = "serial"
    elif isinstance(executor, str):
        if "://" not in executor and ":" not in executor:
            raise ValueError(
                "executor: must be None, 'processes', 'serial', a dask.distributed.Client or a "
                f"scheduler address like 'tcp://host:8786', got {executor!r}"
            )
        mode = "dask-address"
    elif _is_dask_client(executor):
        mode = "dask"
    else:
        raise ValueError(
            f"executor: expected None, 'processes', 'serial', a dask.distributed.Client or "
            f"an address, got {type(executor).__name__}"
        )
    if mode != "serial" and not isinstance(generator, str):
        import pickle

        try:
            pickle.dumps(generator)
        except Exception as exc:  # noqa: BLE001 - any pickling failure
            raise ValueError(
                f"generator: must be picklable to run in worker processes (a module-level "
                f"function, not a lambda or closure): {exc}"
            ) from None
    if workers is not None and mode not in ("processes",):
        raise ValueError("workers: applies to local processes only (size the Dask cluster itself)")

    # Parameter sets: keys, natural order, validity (one cheap trial generation per set).
    param_sets: list[ParamSet] = []
    seen: dict[str, dict[str, Any]] = {}
    for s in sets:
        key = param_key(s)
        if key in seen:
            raise ValueError(f"params: two parameter sets share the key {key!r}")
        seen[key] = s
        try:
            _generate(generator, s, seed_tuple[0])
        except ValueError as exc:
            raise ValueError(f"params ({key}): {exc}") from None
        param_sets.append(ParamSet(key, s, seed_tuple))
    param_sets.sort(key=lambda ps: _natural_order(ps.params))

    # Connect to a scheduler address first: a missing dask or an unreachable scheduler must
    # not leave a half-initialised output directory behind.
    client = executor if mode == "dask" else None
    own_client = _dask_client(executor) if mode == "dask-address" else None
    if own_client is not None:
        client = own_client
    try:
        identity = _identity(
            generator,
            levels,
            solver,
            bool(warm_start),
            axis,
            int(connectivity),
            float(E),
            float(nu),
            boundary,
        )
        directory = Path(out)
        old, record = _prepare_directory(directory, resume, overwrite)
        if old is not None and old.get("identity") != json.loads(_dumps(identity)):
            diff = sorted(k for k in identity if old["identity"].get(k) != identity[k])
            raise ValueError(
                f"resume: {str(directory)!r} holds an ensemble with different "
                f"{', '.join(diff) or 'options'}; use another directory or overwrite=True"
            )
        _clean_stale_temporaries(directory)
        manifest = {
            "format": _FORMAT,
            "kind": "leakpath-ensemble",
            "leakpath_version": __version__,
            "identity": identity,
            "param_sets": [
                {"key": ps.key, "params": ps.params, "seeds": list(ps.seeds)} for ps in param_sets
            ],
        }
        # Every file the run writes is recorded, so that a later overwrite removes exactly
        # those (and never a user's file kept beside them).
        record.add([atomic_write_text(directory / "manifest.json", _dumps(manifest))])

        kill_once = _kill_once
        run_id = _run_id(identity)
        all_tasks = [(ps, seed) for ps in param_sets for seed in ps.seeds]
        todo: list[_TaskSpec] = []
        resumed: list[tuple[str, int]] = []
        recomputed: list[tuple[str, int, str]] = []
        for ps, seed in all_tasks:
            if resume:
                problem = _task_problem(directory, run_id, ps, seed)
                if problem is None:
                    resumed.append((ps.key, seed))
                    continue
                if problem != "not finished":  # files there but not usable: run it again
                    recomputed.append((ps.key, seed, problem))
            todo.append(
                _TaskSpec(
                    generator=generator,
                    params=ps.params,
                    key=ps.key,
                    seed=seed,
                    levels=levels,
                    solver=solver,
                    warm_start=bool(warm_start),
                    axis=axis,
                    connectivity=int(connectivity),
                    E=float(E),
                    nu=float(nu),
                    boundary=boundary,
                    kill_once=kill_once if mode != "serial" else None,
                )
            )

        if recomputed:
            warnings.warn(
                "out: recomputing "
                + "; ".join(f"{k}/seed-{s} ({why})" for k, s, why in recomputed)
                + " — their files failed the integrity check and are not used",
                RuntimeWarning,
                stacklevel=2,
            )
        driver = _Driver(
            directory, run_id, len(all_tasks), len(resumed), progress, _stop_after, record
        )
        t_run = time.perf_counter()
        try:
            if not todo:
                info: dict[str, Any] = {"executor": mode}
            elif mode == "serial":
                info = _run_serial(todo, driver)
            elif mode == "processes":
                n_workers = min(workers or _cpus(), len(todo))
                threads = 1 if threads_per_worker is None else threads_per_worker
                info = _run_processes(todo, driver, n_workers, threads, retries)
            else:
                info = _run_dask(client, todo, driver, retries, threads_per_worker)
        finally:
            driver.close()
        run_seconds = time.perf_counter() - t_run
        if driver.failed:
            lines = "; ".join(f"{k}/seed-{s}: {msg}" for k, s, msg in driver.failed[:5])
            more = f" (and {len(driver.failed) - 5} more)" if len(driver.failed) > 5 else ""
            raise RuntimeError(
                f"{len(driver.failed)} of {len(todo)} task(s) failed: {lines}{more}; the "
                f"{len(driver.written)} finished task(s) are saved in {str(directory)!r}, rerun "
                "with resume=True to retry the rest"
            )
        run = {
            **info,
            "tasks_total": len(all_tasks),
            "tasks_run": len(driver.written),
            "tasks_resumed": len(resumed),
            "recomputed": [[k, s, why] for k, s, why in recomputed],
            "ran": [[k, s] for k, s in driver.written],
            "run_seconds": run_seconds,
            "compute_seconds": driver.compute_seconds,
            "wall_seconds": time.perf_counter() - t_start,
        }
        return aggregate(directory, figures=figures, run=run, _record=record)
    finally:
        if own_client is not None:
            own_client.close()
