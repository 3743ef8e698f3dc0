"""Ensemble benchmark: process-level scaling and the per-task overhead of Dask vs processes.

Run from the repository root (after ``pip install .`` and ``pip install "dask[distributed]"``
for the Dask part)::

    python benchmarks/ensemble_bench.py          # writes benchmarks/results/ensemble.md

1. **Scaling.** ``leakpath.ensemble.ensemble`` over ``--surfaces`` (default 100) RMD surfaces,
   m = 7 (129²), D = 2.1, 20 levels, solver ``auto`` (active set), warm start, flow axis 0,
   on local processes with 1 and then 2 workers, one rayon thread per worker. Wall time
   ``T_w`` covers submitting every task until the last per-surface table is on disk (pool
   start-up included, aggregation and figures excluded). Scaling efficiency
   ``E = T_1 / (2·T_2)``. Both runs must give byte-identical ``aggregate.csv``. Each task
   also records its worker's CPU time: ``Σ cpu / (W·T_w)`` is the share of the W cores the
   workers actually got (below 1 on a loaded machine).
2. **Per-task overhead.** ``--tiny`` (default 200) tiny tasks (m = 3, 9² grid, 2 levels)
   through local processes and through a Dask ``LocalCluster(n_workers=2,
   threads_per_worker=1, processes=True)`` (cluster start-up excluded, reported apart).
   Overhead per task ``= (T_wall − Σ t_task / W) / n``, with ``t_task`` the wall time each
   task measures itself (surface + sweep + CSV) and ``W = 2`` workers: the wall time not
   spent computing, per task (scheduling, serialisation, the driver's atomic writes).

The machine is shared with whatever else runs on it: the load average at start and end is
recorded; compare runs only on an idle machine.
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

import leakpath
from leakpath.ensemble import ensemble


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def load_average() -> str:
    return " / ".join(f"{x:.2f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else "n/a"


def versions() -> list[tuple[str, str]]:
    rows = [
        ("platform", platform.platform()),
        ("CPU", cpu_model()),
        ("CPU count", str(os.cpu_count())),
        ("python", sys.version.split()[0]),
        ("numpy", np.__version__),
        ("leakpath", leakpath.__version__),
    ]
    try:
        import dask
        import distributed

        rows.append(("dask / distributed", f"{dask.__version__} / {distributed.__version__}"))
    except ImportError:
        rows.append(("dask / distributed", "not installed"))
    return rows


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(header[i]), *(len(r[i]) for r in rows)) for i in range(len(header))]
    fmt = "| " + " | ".join(f"{{:{w}}}" for w in widths) + " |"
    lines = [fmt.format(*header), "|" + "|".join("-" * (w + 2) for w in widths) + "|"]
    lines += [fmt.format(*r) for r in rows]
    return "\n".join(lines)


def task_seconds(out: Path, field: str = "task_seconds") -> list[float]:
    """Wall (``task_seconds``) or CPU (``task_cpu_seconds``) time each task measured itself,
    from the per-task JSON files (NaN where a file lacks the field)."""
    import json

    return [
        float(json.loads(p.read_text(encoding="utf-8")).get(field, float("nan")))
        for p in sorted(out.glob("tasks/*/seed-*.json"))
    ]


def run(out: Path, **kwargs: Any) -> tuple[Any, float]:
    if out.exists():
        shutil.rmtree(out)
    t0 = time.perf_counter()
    result = ensemble(out=out, progress=True, figures=False, **kwargs)
    return result, time.perf_counter() - t0


def scaling(work: Path, surfaces: int) -> tuple[str, list[str]]:
    params = {"D": [2.1], "m": [7]}
    common = dict(params=params, surfaces=surfaces, levels=20, solver="auto", warm_start=True)
    rows, notes = [], []
    results = {}
    cpu_time: dict[int, float] = {}
    for workers in (1, 2):
        print(f"scaling: {surfaces} surfaces, {workers} worker(s) …", flush=True)
        res, _ = run(work / f"scale-w{workers}", workers=workers, threads_per_worker=1, **common)
        results[workers] = res
        t = res.run["run_seconds"]
        ts = task_seconds(res.directory)
        cpu = task_seconds(res.directory, "task_cpu_seconds")
        cpu_time[workers] = float(np.mean(cpu))
        rows.append(
            [
                str(workers),
                f"{t:.1f}",
                f"{sum(ts):.1f}",
                f"{sum(cpu):.1f}",
                f"{np.mean(ts):.2f} / {np.median(ts):.2f} / {np.max(ts):.1f}",
                f"{sum(cpu) / (workers * t):.2f}",
                f"{surfaces / t * 60:.2f}",
            ]
        )
    t1 = results[1].run["run_seconds"]
    t2 = results[2].run["run_seconds"]
    same = results[1].aggregate_path.read_bytes() == results[2].aggregate_path.read_bytes()
    table = markdown_table(
        [
            "workers",
            "wall T_w [s]",
            "Σ task wall [s]",
            "Σ task CPU [s]",
            "task wall mean / median / max [s]",
            "CPU utilisation Σcpu/(W·T_w)",
            "surfaces / min",
        ],
        rows,
    )
    s = results[2].threshold_summary["D=2.1_m=7"]
    a = s["contact_fraction"]
    notes += [
        f"Speed-up T_1/T_2 = {t1 / t2:.2f}; scaling efficiency E = T_1/(2·T_2) = "
        f"{t1 / (2 * t2):.2f}.",
        f"CPU time per task, 1 worker / 2 workers: {cpu_time[1]:.2f} s / {cpu_time[2]:.2f} s "
        f"(ratio {cpu_time[1] / cpu_time[2]:.2f}: below 1 when the two workers slow each "
        "other down through shared caches and memory bandwidth). A CPU utilisation below 1 "
        "means other processes took the cores; E is then a property of the machine's load, "
        "not of leakpath.",
        f"aggregate.csv of the 1- and 2-worker runs byte-identical: {'yes' if same else 'NO'}.",
        f"Percolation threshold over the {surfaces} surfaces (first level without a spanning "
        f"cluster, axis 0; found on {s['n_found']}): a_c = {a['mean']:.4f}, 95 % band of the "
        f"mean [{a['ci_low']:.4f}, {a['ci_high']:.4f}], std {a['std']:.4f}, quantiles 5/50/95 % "
        f"{a['quantiles']['0.05']:.4f} / {a['quantiles']['0.5']:.4f} / "
        f"{a['quantiles']['0.95']:.4f}.",
    ]
    return table, notes


def overhead(work: Path, tiny: int) -> tuple[str, list[str]]:
    params = {"D": [2.3], "m": [3]}
    common = dict(params=params, surfaces=tiny, levels=2, solver="auto")
    rows, notes = [], []

    print(f"overhead: {tiny} tiny tasks on local processes …", flush=True)
    res, _ = run(work / "tiny-processes", workers=2, **common)
    t = res.run["run_seconds"]
    ts = sum(task_seconds(res.directory))
    rows.append(
        ["local processes (2)", f"{t:.2f}", f"{ts:.3f}", f"{(t - ts / 2) / tiny * 1e3:.1f}"]
    )
    reference = res.aggregate_path.read_bytes()

    try:
        import distributed
    except ImportError:
        notes.append("Dask: not installed, skipped.")
        return markdown_table(["executor", "wall [s]", "Σ compute [s]", "ms/task"], rows), notes
    print(f"overhead: {tiny} tiny tasks on a Dask LocalCluster …", flush=True)
    t0 = time.perf_counter()
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        startup = time.perf_counter() - t0
        res, _ = run(work / "tiny-dask", executor=client, **common)
    t = res.run["run_seconds"]
    ts = sum(task_seconds(res.directory))
    rows.append(
        ["Dask LocalCluster (2×1)", f"{t:.2f}", f"{ts:.3f}", f"{(t - ts / 2) / tiny * 1e3:.1f}"]
    )
    same = res.aggregate_path.read_bytes() == reference
    notes += [
        f"Dask cluster start-up (not in the table): {startup:.2f} s. The local-process wall "
        "time includes starting the pool (forkserver + 2 workers importing leakpath).",
        f"aggregate.csv of the two executors byte-identical: {'yes' if same else 'NO'}.",
    ]
    table = markdown_table(
        ["executor", "wall [s]", "Σ task compute [s]", "overhead per task [ms]"], rows
    )
    return table, notes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--out",
        type=Path,
        default=Path(__file__).resolve().parent / "results" / "ensemble.md",
        help="markdown output file (default: benchmarks/results/ensemble.md)",
    )
    parser.add_argument("--surfaces", type=int, default=100, help="m = 7 surfaces (default 100)")
    parser.add_argument("--tiny", type=int, default=200, help="tiny tasks (default 200)")
    parser.add_argument("--workdir", type=Path, default=None, help="scratch directory")
    parser.add_argument("--keep", action="store_true", help="keep the ensemble directories")
    args = parser.parse_args(argv)

    work = args.workdir or Path(tempfile.mkdtemp(prefix="leakpath-ensemble-bench-"))
    work.mkdir(parents=True, exist_ok=True)
    load_start = load_average()
    t_start = time.perf_counter()
    over_table, over_notes = overhead(work, args.tiny)
    scale_table, scale_notes = scaling(work, args.surfaces)
    load_end = load_average()
    machine = markdown_table(
        ["item", "value"],
        [list(r) for r in versions()]
        + [["load average 1/5/15 min at start", load_start], ["… at end", load_end]],
    )
    text = "\n".join(
        [
            "# Ensembles: scaling over local processes, per-task overhead of Dask",
            "",
            f"Produced by `python benchmarks/ensemble_bench.py` (total "
            f"{(time.perf_counter() - t_start) / 60:.1f} min).",
            "",
            "## Machine",
            "",
            machine,
            "",
            f"## Scaling: {args.surfaces} RMD surfaces, m = 7 (129²), D = 2.1, 20 levels, "
            "solver auto, warm start",
            "",
            "Local processes (forkserver), one rayon thread per worker; wall time from the "
            "first submission to the last per-surface table on disk.",
            "",
            scale_table,
            "",
            *[f"- {n}" for n in scale_notes],
            "",
            f"## Per-task overhead: {args.tiny} tiny tasks (m = 3, 2 levels), 2 workers",
            "",
            "Overhead per task = (wall − Σ task compute / 2) / tasks.",
            "",
            over_table,
            "",
            *[f"- {n}" for n in over_notes],
            "",
        ]
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_suffix(args.out.suffix + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, args.out)
    if not args.keep and args.workdir is None:
        shutil.rmtree(work, ignore_errors=True)
    print(text)
    print(f"written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
