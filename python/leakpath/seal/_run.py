"""The seal run: realisations × nominal pressures × flow axes, in parallel, checkpointed.

For realisation ``k`` (``0 … N−1``) a task builds the composite surface
``h = h_upper + h_lower`` on the patch (:func:`leakpath.seal._bodies.composite_surface`,
deterministic in ``(seed, k)``), presses it on a rigid flat with the composite modulus
``E* = [(1−ν₁²)/E₁ + (1−ν₂²)/E₂]⁻¹`` (passed as ``E = E*, ν = 0``), solves load control at
the nominal pressures in ascending order, each solve warm-started from the previous one, and
solves the Reynolds flow through each gap along the requested axes (docs/flow.md). The
permeability ``K = Q η L_patch / (W_patch Δp)`` [m³] depends on the gap only, so it is
computed once and the leak rate follows from the seal's geometry and fluid
(:mod:`leakpath.seal._estimate`).

The convergence check runs the first ``check.realisations`` realisations again on the grid
refined ``check.refine`` times (same Fourier modes, plus those between the two Nyquist
wavelengths) and reports the relative change of the mean K of that subset at each pressure:
``|K_fine − K| / K``.

Executors: local processes (default; one rayon thread per process), this process
(``workers=1``), or a Dask cluster (``scheduler=`` a ``distributed.Client`` or an address).
Every task is a pure function of its inputs, and leakpath's solvers give the same bits for
any thread count, so the tables are identical whichever runs them.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import time
import warnings
from collections.abc import Callable, Mapping
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._checkpoint import _differences, _record_digest
from .._io import atomic_write_text, dumps, heights_sha256, machine_info
from .._outputs import OutputRecord, is_temporary
from ..errors import InvalidArgumentError
from ._config import UNITS, SealConfig, _roughness, as_config
from ._result import SealResult, Table

__all__ = ["seal_leakage", "SealValidityWarning", "SealConvergenceWarning"]

PathLike = str | os.PathLike[str]

#: Checkpoint record format of seal runs.
CHECKPOINT_FORMAT = 1
CHECKPOINT_DIR = "checkpoints"


class SealValidityWarning(UserWarning):
    """An input outside the method's validity (rms slope above ~0.3, a short cutoff resolved
    by fewer than ~4 grid points, a patch of too few roll-off wavelengths)."""


class SealConvergenceWarning(UserWarning):
    """The convergence check changed K by more than ``check.tolerance`` at some pressure."""


REALISATION_COLUMNS = (
    "realisation", "axis", "mean_pressure_Pa", "contact_fraction", "persson_contact_fraction",
    "mean_gap_m", "approach_m", "percolates", "leaks", "permeability_m3",
    "permeability_bruggeman_m3", "contact_iterations",
)


# ============================================================================ the task
@dataclass(frozen=True)
class _Task:
    """One realisation on one grid (picklable: the worker rebuilds the surface)."""

    kind: str  # "main" or "check"
    realisation: int
    refine: int
    upper: Any  # _bodies.Roughness
    lower: Any
    patch: Any  # _bodies.Patch
    seed: int
    pressures: tuple[float, ...]
    axes: tuple[int, ...]
    e_star: float
    rms_slope: float
    boundary: str
    hardness: float | None = None

    @property
    def name(self) -> str:
        return f"{self.kind}_{self.realisation:04d}"


@dataclass(frozen=True)
class _Output:
    kind: str
    realisation: int
    rows: list[dict[str, Any]]
    surface: dict[str, Any]  # sha256, shape, dx_m
    seconds: float


def _modules() -> tuple[Any, Any, Any]:
    from . import _bodies, _estimate, _theory

    return _bodies, _theory, _estimate


def _run_task(task: _Task) -> _Output:
    """Solve one realisation at every pressure (ascending, warm-started) and axis."""
    from ..contact import ContactProblem

    bodies, theory, _ = _modules()
    t0 = time.perf_counter()
    surface = bodies.composite_surface(
        task.upper, task.lower, task.patch, realisation=task.realisation, seed=task.seed,
        refine=task.refine,
    )
    problem = ContactProblem(
        surface, E=task.e_star, nu=0.0, boundary=task.boundary, hardness=task.hardness
    )
    state = None
    rows: list[dict[str, Any]] = []
    for p in task.pressures:
        state = problem.solve(mean_pressure=p, warm_start=state)
        contact = state.contact
        gap = np.where(contact, 0.0, np.clip(state.gap, 0.0, None))
        persson = float(theory.persson_contact_fraction(p, task.e_star, task.rms_slope))
        bruggeman = float(theory.bruggeman_permeability(gap, surface.dx, contact=contact))
        for axis in task.axes:
            flow = state.flow(axis=axis, viscosity=1.0, pressure_drop=1.0)
            k = float(flow.permeability)
            rows.append({
                "realisation": task.realisation,
                "axis": axis,
                "mean_pressure_Pa": float(p),
                "contact_fraction": state.contact_fraction,
                "persson_contact_fraction": persson,
                "mean_gap_m": float(gap.mean()),
                "approach_m": float(state.approach),
                "percolates": bool(state.percolation(axis=axis).percolates),
                "leaks": bool(k > 0.0),
                "permeability_m3": k,
                "permeability_bruggeman_m3": bruggeman,
                "contact_iterations": int(state.iterations),
            })
    info = {
        "sha256": heights_sha256(surface.heights, surface.dx),
        "shape": list(surface.shape),
        "dx_m": surface.dx,
    }
    return _Output(task.kind, task.realisation, rows, info, time.perf_counter() - t0)


def _run_task_dask(task: _Task) -> _Output:
    """:func:`_run_task` in a Dask worker, one rayon thread unless the worker sets more."""
    os.environ.setdefault("RAYON_NUM_THREADS", "1")
    return _run_task(task)


# ============================================================================ executors
def _execute(tasks: list[_Task], mode: str, client: Any, workers: int,
             done: Callable[[_Output], None]) -> dict[str, Any]:
    """Run ``tasks``; call ``done`` in this process as each finishes."""
    if not tasks:
        return {"executor": mode}
    if mode == "serial":
        for t in tasks:
            done(_run_task(t))
        return {"executor": "serial", "workers": 1}
    if mode == "dask":
        return _execute_dask(tasks, client, done)
    from ..ensemble._executors import _init_worker, _mp_context, _StartingChildren

    ctx = _mp_context()
    alive_r, alive_w = ctx.Pipe(duplex=False)
    try:
        with _StartingChildren():
            pool = ProcessPoolExecutor(max_workers=min(workers, len(tasks)), mp_context=ctx,
                                       initializer=_init_worker, initargs=(1, alive_r))
        clean = False
        try:
            with _StartingChildren():
                futures = {pool.submit(_run_task, t): t for t in tasks}
            pending = set(futures)
            while pending:
                finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                for fut in sorted(finished, key=lambda f: futures[f].name):
                    done(fut.result())
            clean = True
        finally:
            pool.shutdown(wait=clean, cancel_futures=True)
    finally:
        alive_r.close()
        alive_w.close()
    return {"executor": "processes", "start_method": ctx.get_start_method(),
            "workers": min(workers, len(tasks)), "threads_per_worker": 1}


def _execute_dask(tasks: list[_Task], client: Any, done: Callable[[_Output], None]
                  ) -> dict[str, Any]:
    from distributed import as_completed

    token = os.urandom(4).hex()
    futures = [client.submit(_run_task_dask, t, key=f"leakpath-seal-{token}-{t.name}",
                             pure=False) for t in tasks]
    try:
        for fut in as_completed(futures):
            done(fut.result())
            fut.release()
    except BaseException:
        for fut in futures:
            fut.cancel()
        raise
    try:
        n_workers = len(client.scheduler_info().get("workers", {}))
    except Exception:  # noqa: BLE001 - informational only
        n_workers = None
    return {"executor": "dask",
            "scheduler": getattr(getattr(client, "scheduler", None), "address", None),
            "workers": n_workers}


# ============================================================================ checkpoints
class _Checkpoints:
    """``out/checkpoints``: ``manifest.json`` (the run's identity) and one checksummed record
    per finished task (``main_KKKK.json``, ``check_KKKK.json``), the scheme of sweep
    checkpoints: each record carries the SHA-256 of the manifest (``run``) and of its own
    canonical JSON (``sha256``); a record failing either check is computed again."""

    def __init__(self, directory: Path, identity: dict[str, Any], resume: bool) -> None:
        self.dir = directory
        directory.mkdir(parents=True, exist_ok=True)
        for stale in directory.glob(".*.tmp"):
            if is_temporary(stale):
                stale.unlink(missing_ok=True)
        manifest = {"format": CHECKPOINT_FORMAT, "kind": "leakpath-seal", "identity": identity}
        text = dumps(manifest)
        self.run = hashlib.sha256(text.encode("utf-8")).hexdigest()
        self.recomputed: list[str] = []
        path = directory / "manifest.json"
        if path.exists() and resume:
            try:
                found = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                found = None
            diff = _differences(found, json.loads(text))
            if diff:
                raise InvalidArgumentError(
                    f"resume: {str(directory.parent)!r} holds a different seal run "
                    f"({', '.join(diff[:3])} differ); use another out directory or overwrite",
                    argument="resume",
                )
        self.manifest = atomic_write_text(path, text)

    def path(self, name: str) -> Path:
        return self.dir / f"{name}.json"

    def load(self, task: _Task) -> _Output | None:
        path = self.path(task.name)
        if not path.exists():
            return None
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            digest = data.pop("sha256", None)
            ok = (digest == _record_digest(data) and data.get("run") == self.run
                  and data.get("name") == task.name
                  and len(data["rows"]) == len(task.pressures) * len(task.axes))
            if ok:
                rows = [{c: r[c] for c in REALISATION_COLUMNS} for r in data["rows"]]
                return _Output(task.kind, task.realisation, rows, data["surface"],
                               float(data["seconds"]))
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            pass
        self.recomputed.append(task.name)
        return None

    def save(self, out: _Output) -> Path:
        name = f"{out.kind}_{out.realisation:04d}"
        record = {"run": self.run, "name": name, "rows": out.rows, "surface": out.surface,
                  "seconds": out.seconds}
        record = json.loads(dumps(record))
        record["sha256"] = _record_digest(record)
        return atomic_write_text(self.path(name), dumps(record))


def own_checkpoint_files(directory: Path) -> list[Path]:
    """The files of ``directory`` that seal checkpoints wrote, recognised by content (the
    manifest by its kind, records by their checksum); for ``--overwrite``."""
    own: list[Path] = []
    if not directory.is_dir():
        return own
    for p in sorted(directory.glob("*.json")):
        try:
            data = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if not isinstance(data, dict):
            continue
        if p.name == "manifest.json" and data.get("kind") == "leakpath-seal":
            own.append(p)
        elif data.get("sha256") == _record_digest(data) and "run" in data:
            own.append(p)
    own += [p for p in directory.glob(".*.tmp") if is_temporary(p)]
    return own


def _prepare_out(out: Path, resume: bool, overwrite: bool) -> tuple[OutputRecord, list[str]]:
    """Check and prepare the output directory; returns its record and the files an
    ``overwrite`` kept because they changed since the earlier run wrote them."""
    if resume and overwrite:
        raise InvalidArgumentError("resume: resume and overwrite exclude each other",
                                   argument="resume")
    if out.exists() and not out.is_dir():
        raise InvalidArgumentError(f"out: {str(out)!r} exists and is not a directory",
                                   argument="out")
    non_empty = out.is_dir() and any(out.iterdir())
    if non_empty and not (resume or overwrite):
        raise InvalidArgumentError(
            f"out: {str(out)!r} is not empty; resume the run there (resume=True) or replace "
            "its results (overwrite=True)", argument="out")
    record = OutputRecord(out)
    kept: list[str] = []
    if overwrite and non_empty:
        if record.read():
            kept = record.remove_unchanged()
        for f in own_checkpoint_files(out / CHECKPOINT_DIR):
            f.unlink(missing_ok=True)
    elif resume:
        record.read()
    out.mkdir(parents=True, exist_ok=True)
    return record, kept


# ============================================================================ conversion
def _file_hashes(cfg: SealConfig) -> dict[str, str]:
    out = {}
    for b in (cfg.upper, cfg.lower):
        for f in (b.files or ()) + ((b.psd,) if b.psd else ()):
            out[f] = hashlib.sha256(Path(f).read_bytes()).hexdigest()
    return out


# ============================================================================ aggregation
def _aggregate(cfg: SealConfig, estimate: Any, rows: list[dict[str, Any]],
               check_rows: list[dict[str, Any]]) -> tuple[list[dict[str, Any]], str]:
    """One summary row per pressure (see docs/seal.md, "Upscaling"), and the estimator's
    description."""
    fluid, seal = cfg.fluid, cfg.seal

    def rate(k: float) -> float:
        if fluid.gas:
            return float(estimate.gas_mass_flow(
                k, width=seal.width, length=seal.length, viscosity=fluid.viscosity,
                inlet_pressure=fluid.inlet_pressure, outlet_pressure=fluid.outlet_pressure,
                gas_constant=fluid.gas_constant, temperature=fluid.temperature))
        return float(estimate.liquid_leak_rate(
            k, width=seal.width, length=seal.length, viscosity=fluid.viscosity,
            pressure_drop=fluid.pressure_drop))

    stem, unit = ("mass_flow", "_kg_per_s") if fluid.gas else ("leak_rate", "_m3_per_s")
    summary = []
    method = ""
    n_real = cfg.realisations
    for p in cfg.mean_pressure:
        sel = [r for r in rows if r["mean_pressure_Pa"] == p]
        # Both flow axes are samples of the same K (an isotropic surface), pooled; the
        # bootstrap resamples whole realisations (groups), since the two axes of one patch
        # are not independent.
        k = np.array([r["permeability_m3"] for r in sel])
        groups = np.array([r["realisation"] for r in sel])
        frac = np.array([r["contact_fraction"] for r in sel if r["axis"] == cfg.axes[0]])
        gap = np.array([r["mean_gap_m"] for r in sel if r["axis"] == cfg.axes[0]])
        # The effective medium of the realisations' gap fields: the mean of the patch EMAs
        # (identically distributed patches; the EMA does not depend on the axis).
        k_bru = np.array([r["permeability_bruggeman_m3"] for r in sel
                          if r["axis"] == cfg.axes[0]])
        est = estimate.effective_permeability(k, groups=groups if len(cfg.axes) > 1 else None)
        bru_value = float(k_bru.mean())
        row: dict[str, Any] = {
            "mean_pressure_Pa": float(p),
            "n_realisations": n_real,
            "contact_fraction": float(frac.mean()),
            "contact_fraction_std": float(frac.std(ddof=1)) if n_real > 1 else 0.0,
            "persson_contact_fraction": float(sel[0]["persson_contact_fraction"]),
            "mean_gap_m": float(gap.mean()),
            "permeability_m3": float(est.value),
            "permeability_low_m3": float(est.low),
            "permeability_high_m3": float(est.high),
            "permeability_arithmetic_m3": float(est.arithmetic),
            "permeability_harmonic_m3": float(est.harmonic),
            "permeability_geometric_m3": float(est.geometric),
        }
        for axis in cfg.axes:
            ka = np.array([r["permeability_m3"] for r in sel if r["axis"] == axis])
            row[f"permeability_axis{axis}_m3"] = float(estimate.effective_permeability(ka).value)
        row.update({
            "n_patches": int(est.n),
            "n_leaking": int(est.n_leaking),
            "leak_fraction": float(est.leak_fraction),
            stem + unit: rate(est.value),
            stem + "_low" + unit: rate(est.low),
            stem + "_high" + unit: rate(est.high),
            "permeability_bruggeman_m3": bru_value,
            stem + "_bruggeman" + unit: rate(bru_value),
        })
        method = str(est.method)
        change = math.nan
        if check_rows:
            fine = [r["permeability_m3"] for r in check_rows if r["mean_pressure_Pa"] == p]
            ids = {r["realisation"] for r in check_rows}
            base = [r["permeability_m3"] for r in sel if r["realisation"] in ids]
            kb, kf = float(np.mean(base)), float(np.mean(fine))
            change = abs(kf - kb) / kb if kb > 0 else (0.0 if kf == 0 else math.inf)
        row["grid_check_relative_change"] = change
        row["converged"] = bool(not (change > cfg.check.tolerance))
        summary.append(row)
    return summary, method


# ============================================================================ entry point
def seal_leakage(
    config: SealConfig | Mapping[str, Any] | PathLike,
    *,
    out: PathLike | None = None,
    resume: bool = False,
    overwrite: bool = False,
    scheduler: Any = None,
    workers: int | None = None,
    progress: bool = True,
    _stop_after: int | None = None,
) -> SealResult:
    """A seal's leak rate with its confidence interval, from two rough elastic bodies.

    Parameters
    ----------
    config : SealConfig, dict or path
        The run (``docs/seal.md``; SI units): a :class:`SealConfig`, a dict with the TOML
        structure, or a TOML file.
    out : path, optional
        Output directory: ``checkpoints/`` (one record per finished realisation, written as
        it finishes), then ``summary.csv``, ``realisations.csv``, ``check.csv``,
        ``metadata.json`` and ``figures/`` — all written atomically and listed in
        ``.leakpath-outputs.json``. ``None``: nothing is written.
    resume : bool
        Continue a run in ``out``: finished realisations whose records pass their checks
        are read back, the others computed; the tables are identical to an uninterrupted
        run's.
    overwrite : bool
        Replace an earlier run's results in ``out`` (only the files it recorded writing and
        left unchanged, and its checkpoint records).
    scheduler : distributed.Client or str, optional
        Run the realisations on a Dask cluster (a client, or a scheduler address).
    workers : int, optional
        Local worker processes (default: the CPUs available); ``1`` runs in this process.
    progress : bool
        A tqdm progress bar over realisations on stderr.

    Returns
    -------
    SealResult
        ``summary`` (one row per nominal pressure: contact fraction against Persson's,
        K_eff [m³] with its interval and bounds, the leak fraction, the seal leak rate
        ``Q = K_eff (W/L) Δp/η`` [m³/s] or the gas mass flow [kg/s] with its interval, the
        Bruggeman estimate, the convergence check), ``realisations`` (one row per
        realisation × axis × pressure), ``metadata``.

    Warns
    -----
    SealValidityWarning
        Inputs outside the method's validity (refused instead with ``strict = true``).
    SealConvergenceWarning
        The grid check changed K by more than ``check.tolerance`` at some pressure.
    """
    t_start = time.perf_counter()
    cfg = as_config(config)
    bodies, _theory, estimate = _modules()
    upper = _roughness(bodies, cfg.upper, "surface.upper")
    lower = _roughness(bodies, cfg.lower, "surface.lower")
    e_star = float(bodies.contact_modulus_pair(
        bodies.Material(cfg.upper_material.E, cfg.upper_material.nu, name="material.upper"),
        bodies.Material(cfg.lower_material.E, cfg.lower_material.nu, name="material.lower"),
    ))
    patch = bodies.choose_patch(upper, lower, n=cfg.n, length=cfg.length)
    messages = list(bodies.validity_warnings(upper, lower, patch))
    if messages and cfg.strict:
        raise InvalidArgumentError("surface: " + "; ".join(messages)
                                   + " (refused because strict = true)", argument="surface")
    for m in messages:
        warnings.warn(m, SealValidityWarning, stacklevel=2)
    rms_slope = float(bodies.composite_rms_slope(upper, lower, length=patch.length))

    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise InvalidArgumentError(f"workers: must be an integer ≥ 1, got {workers!r}",
                                   argument="workers")
    if scheduler is not None and workers is not None:
        raise InvalidArgumentError("workers: sizes local processes; size a Dask cluster "
                                   "itself", argument="workers")
    from ..ensemble._executors import _cpus, _dask_client, _is_dask_client

    if scheduler is not None and not (_is_dask_client(scheduler) or isinstance(scheduler, str)):
        raise InvalidArgumentError("scheduler: expected a dask.distributed Client or an "
                                   f"address, got {type(scheduler).__name__}",
                                   argument="scheduler")
    n_workers = workers or _cpus()
    mode = "dask" if scheduler is not None else ("serial" if n_workers == 1 else "processes")

    common = dict(upper=upper, lower=lower, patch=patch, seed=cfg.seed,
                  pressures=cfg.mean_pressure, axes=cfg.axes, e_star=e_star,
                  rms_slope=rms_slope, boundary=cfg.boundary, hardness=cfg.hardness)
    tasks = [_Task("main", k, 1, **common) for k in range(cfg.realisations)]
    tasks += [_Task("check", k, cfg.check.refine, **common)
              for k in range(cfg.check.realisations)]

    identity = {"config": cfg.to_dict(), "files_sha256": _file_hashes(cfg),
                "patch": {"n": patch.n, "length_m": patch.length, "dx_m": patch.dx},
                "E_star_Pa": e_star}
    record: OutputRecord | None = None
    ckpt: _Checkpoints | None = None
    kept: list[str] = []
    if out is not None:
        out_dir = Path(out)
        record, kept = _prepare_out(out_dir, resume, overwrite)
        ckpt = _Checkpoints(out_dir / CHECKPOINT_DIR, identity, resume)
        record.add([ckpt.manifest])

    outputs: dict[str, _Output] = {}
    todo = []
    for t in tasks:
        found = ckpt.load(t) if (ckpt is not None and resume) else None
        if found is not None:
            outputs[t.name] = found
        else:
            todo.append(t)
    if ckpt is not None and ckpt.recomputed:
        warnings.warn("out: recomputing " + ", ".join(ckpt.recomputed) + " (their checkpoint "
                      "records failed the integrity check)", RuntimeWarning, stacklevel=2)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(tasks), initial=len(tasks) - len(todo), desc="seal",
                   unit="realisation", file=sys.stderr, disable=None, dynamic_ncols=True)
    finished = 0

    def done(o: _Output) -> None:
        nonlocal finished
        outputs[f"{o.kind}_{o.realisation:04d}"] = o
        if ckpt is not None and record is not None:
            record.add([ckpt.save(o)])
        if bar is not None:
            bar.update(1)
        finished += 1
        if _stop_after is not None and finished >= _stop_after:
            raise KeyboardInterrupt("stopped after the requested number of realisations")

    t_run = time.perf_counter()
    # A scheduler address is connected to only now: an unreachable one leaves the output
    # directory with its manifest alone, ready for --resume.
    own_client = None
    try:
        if isinstance(scheduler, str) and todo:
            own_client = _dask_client(scheduler)
        client = own_client if own_client is not None else scheduler
        info = _execute(todo, mode, client, n_workers, done)
    finally:
        if bar is not None:
            bar.close()
        if own_client is not None:
            own_client.close()
    run_seconds = time.perf_counter() - t_run

    def rows_of(kind: str) -> list[dict[str, Any]]:
        rows = [r for t in tasks if t.kind == kind for r in outputs[t.name].rows]
        return sorted(rows, key=lambda r: (r["realisation"], r["axis"],
                                           r["mean_pressure_Pa"]))

    main_rows, check_rows = rows_of("main"), rows_of("check")
    summary_rows, method = _aggregate(cfg, estimate, main_rows, check_rows)
    summary = Table(summary_rows, list(summary_rows[0]))
    realisations = Table(main_rows, REALISATION_COLUMNS)
    check = Table(check_rows, REALISATION_COLUMNS) if check_rows else None
    failed = [r["mean_pressure_Pa"] for r in summary_rows if not r["converged"]]
    if failed:
        warnings.warn(
            "check: the refined grid changed K by more than check.tolerance = "
            f"{cfg.check.tolerance:g} at mean_pressure = "
            + ", ".join(f"{p:g} Pa" for p in failed)
            + "; refine the grid (surface.n) or treat those rows with caution",
            SealConvergenceWarning, stacklevel=2)

    metadata = {
        "kind": "leakpath-seal",
        "inputs": cfg.to_dict(),
        "units": UNITS,
        "columns": {"summary": summary.units(), "realisations": realisations.units()},
        "E_star_Pa": e_star,
        "composite_rms_slope": rms_slope,
        "patch": {"n": patch.n, "length_m": patch.length, "dx_m": patch.dx,
                  "rule": patch.rule},
        "validity_warnings": messages,
        "estimator": {
            "pooling": "K of both flow axes pooled (an isotropic surface: both are samples "
                       "of the same K), bootstrap resampling whole realisations",
            "bruggeman": "mean over realisations of the effective-medium K of each patch's "
                         "gap field",
            "method": method,
        },
        "surfaces": [{"realisation": t.realisation, "kind": t.kind, "refine": t.refine,
                      **outputs[t.name].surface} for t in tasks],
        "files_sha256": identity["files_sha256"],
        "convergence_check": {
            "realisations": cfg.check.realisations,
            "refine": cfg.check.refine,
            "tolerance": cfg.check.tolerance,
            "relative_change": {f"{r['mean_pressure_Pa']:g} Pa": r["grid_check_relative_change"]
                                for r in summary_rows},
            "converged": not failed,
        },
        "run": {**info, "tasks": len(tasks), "tasks_run": len(todo),
                "tasks_resumed": len(tasks) - len(todo),
                "recomputed": [] if ckpt is None else ckpt.recomputed,
                "run_seconds": run_seconds,
                "compute_seconds": sum(o.seconds for o in outputs.values())},
        "versions": machine_info(),
    }
    result = SealResult(cfg, summary, realisations, check, metadata)
    metadata["run"]["wall_seconds"] = time.perf_counter() - t_start
    if out is not None and record is not None:
        record.add(result.save(out))
        if kept:
            metadata["overwrite_kept"] = kept
    return result
