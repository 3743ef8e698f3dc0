"""`leakpath paper` benchmark: wall time and peak memory of the paper's experiment.

Run from the repository root (after ``pip install .``)::

    python benchmarks/paper_timing.py                          # writes benchmarks/results/paper.md
    python benchmarks/paper_timing.py --include-paper-solver   # also --solver lawson-hanson

Each configuration runs ``python -m leakpath paper --out DIR --overwrite --json`` in a fresh
subprocess (RMD D = 2.1, m = 7: 129 × 129 points, 21 levels, table + metadata + 14 figures):

* ``cold``: the default — the fast exact solver (``auto`` = active-set block pivoting), every
  level from ``p = 0`` as in the paper;
* ``warm``: ``--warm-start`` — each level starts from the previous level's contact set;
* ``paper solver`` (optional): ``--solver lawson-hanson`` — the paper's Lawson–Hanson
  algorithm itself (one point enters per iteration), cold. Takes many minutes.

Wall time is measured around the whole subprocess (interpreter start, imports, solves,
percolation, files and figures); "sweep" is the solve-and-analyse time the command reports.
Peak memory is the child's maximum resident set size from ``os.wait4`` (``ru_maxrss``).
The fast configurations run ``--repeats`` times (default 3) and report the median (and the
range); every run's table is compared with the first cold run's to show that all
configurations find the same minimiser.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import leakpath
from leakpath._io import machine_info

CONFIGS: dict[str, list[str]] = {
    "cold (default: auto solver, no warm start)": [],
    "warm (--warm-start)": ["--warm-start"],
}
PAPER_SOLVER = ("paper's solver (--solver lawson-hanson, cold)", ["--solver", "lawson-hanson"])
COMPARED = ("contact_fraction", "load", "free_volume_star", "V_pg_star", "m0_star", "m2_star")


def run_paper(extra: list[str], out: Path) -> dict[str, float | str]:
    """One ``leakpath paper`` run in a subprocess; wall seconds, peak RSS (MiB), table."""
    cmd = [sys.executable, "-m", "leakpath", "paper", "--out", str(out), "--overwrite", "--json"]
    cmd += extra
    with tempfile.TemporaryFile() as out_f, tempfile.TemporaryFile() as err_f:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=out_f, stderr=err_f)
        _, status, usage = os.wait4(proc.pid, 0)  # this child's own rusage
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        out_f.seek(0)
        err_f.seek(0)
        stdout, stderr = out_f.read().decode(), err_f.read().decode()
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{stderr}")
    summary = json.loads(stdout)
    # ru_maxrss is in KiB on Linux, bytes on macOS.
    scale = 1.0 if sys.platform == "darwin" else 1024.0
    return {
        "wall": wall,
        "sweep": float(summary["seconds"]),
        "rss_mib": usage.ru_maxrss * scale / 2**20,
        "table": (out / "table.csv").read_text(encoding="utf-8"),
    }


def table_columns(text: str) -> dict[str, np.ndarray]:
    rows = list(csv.DictReader(io.StringIO(text)))
    return {c: np.array([float(r[c]) for r in rows]) for c in COMPARED}


def max_difference(a: str, b: str) -> float:
    """Largest relative difference ``|x − y| / max(|x|, |y|)`` over the compared columns."""
    ca, cb = table_columns(a), table_columns(b)
    worst = 0.0
    for c in COMPARED:
        scale = np.maximum(np.abs(ca[c]), np.abs(cb[c]))
        diff = np.abs(ca[c] - cb[c])
        rel = np.divide(diff, scale, out=np.zeros_like(diff), where=scale > 0)
        worst = max(worst, float(rel.max()))
    return worst


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(header[i]), *(len(r[i]) for r in rows)) for i in range(len(header))]
    fmt = "| " + " | ".join(f"{{:{w}}}" for w in widths) + " |"
    lines = [fmt.format(*header), "|" + "|".join("-" * (w + 2) for w in widths) + "|"]
    lines += [fmt.format(*r) for r in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--out",
        type=Path,
        default=Path(__file__).resolve().parent / "results" / "paper.md",
        help="markdown output file (default: benchmarks/results/paper.md)",
    )
    parser.add_argument("--repeats", type=int, default=3, help="runs per fast configuration")
    parser.add_argument(
        "--include-paper-solver",
        action="store_true",
        help="also time --solver lawson-hanson (the paper's algorithm; many minutes)",
    )
    args = parser.parse_args(argv)

    configs = list(CONFIGS.items())
    if args.include_paper_solver:
        configs.append(PAPER_SOLVER)
    load_start = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    results: dict[str, list[dict[str, float | str]]] = {}
    with tempfile.TemporaryDirectory(prefix="leakpath-paper-bench-") as tmp:
        for name, extra in configs:
            repeats = 1 if extra[:1] == ["--solver"] else args.repeats
            results[name] = []
            for i in range(repeats):
                run = run_paper(extra, Path(tmp) / f"run{len(results)}-{i}")
                results[name].append(run)
                print(
                    f"{name} #{i + 1}: wall {run['wall']:.2f} s, sweep {run['sweep']:.2f} s, "
                    f"peak RSS {run['rss_mib']:.0f} MiB",
                    flush=True,
                )
    load_end = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")

    reference = next(iter(results.values()))[0]["table"]
    rows = []
    for name, runs in results.items():
        walls = [float(r["wall"]) for r in runs]
        sweeps = [float(r["sweep"]) for r in runs]
        rss = [float(r["rss_mib"]) for r in runs]
        diff = max(max_difference(str(reference), str(r["table"])) for r in runs)
        identical = all(r["table"] == reference for r in runs)
        rows.append(
            [
                name,
                str(len(runs)),
                f"{statistics.median(walls):.2f}",
                f"{min(walls):.2f}–{max(walls):.2f}",
                f"{statistics.median(sweeps):.2f}",
                f"{max(rss):.0f}",
                "identical" if identical else f"max rel. diff {diff:.1e}",
            ]
        )
    timing = markdown_table(
        [
            "configuration",
            "runs",
            "wall, median [s]",
            "wall, range [s]",
            "sweep, median [s]",
            "peak RSS [MiB]",
            "table vs first cold run",
        ],
        rows,
    )
    info = machine_info()
    machine = markdown_table(
        ["item", "value"],
        [
            ["platform", str(info["platform"])],
            ["CPU", str(info["cpu"])],
            ["CPU count", str(info["cpu_count"])],
            ["memory", f"{(info['memory_bytes'] or 0) / 2**30:.1f} GiB"],
            ["load average (1 min) at start / end", f"{load_start:.2f} / {load_end:.2f}"],
            ["python", str(info["python"])],
            ["numpy", str(info["numpy"])],
            ["matplotlib", str(info["matplotlib"])],
            ["leakpath", leakpath.__version__],
        ],
    )
    busy = max(load_start, load_end) > (os.cpu_count() or 1)
    busy_note = (
        f"\nThe machine was shared while this ran (1-min load average {load_start:.1f} at the "
        f"start, {load_end:.1f} at the end, on {os.cpu_count()} cores): the wall times are "
        "upper bounds for an idle machine.\n"
        if busy
        else ""
    )
    skipped = (
        ""
        if args.include_paper_solver
        else "\nThe paper's own solver (`--solver lawson-hanson`) was not timed in this run; "
        "pass `--include-paper-solver` (it takes many minutes: one contact point enters per "
        "iteration).\n"
    )
    text = "\n".join(
        [
            "# `leakpath paper`: wall time and peak memory",
            "",
            f"Produced by `python benchmarks/paper_timing.py` on {time.strftime('%Y-%m-%d')}.",
            "",
            "The paper's experiment: RMD surface D = 2.1, m = 7 (129 × 129), 21 levels "
            "Δ_k = k·h_s/20, free boundary; each run writes the table, the metadata and 14 "
            "figures (PNG + PDF). *Wall* is the whole subprocess (interpreter start, imports, "
            "solves, percolation, files, figures); *sweep* is the solve-and-analyse part the "
            "command reports; peak RSS is the child's `ru_maxrss` from `os.wait4`.",
            "",
            "## Machine",
            "",
            machine,
            "",
            "## Results",
            "",
            timing,
            busy_note + skipped,
            "All configurations solve the same convex problem, whose minimiser is unique; the "
            "last column compares each run's table with the first cold run's: *identical* "
            "means byte for byte, otherwise the largest relative difference over the columns "
            "contact fraction, load, V*, V_pg*, m0*, m2*.",
            "",
            f"Python {platform.python_version()}, command: "
            f"`{' '.join([Path(sys.executable).name, *sys.argv])}`.",
            "",
        ]
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp_out = args.out.with_suffix(args.out.suffix + ".tmp")
    tmp_out.write_text(text, encoding="utf-8")
    os.replace(tmp_out, args.out)
    print(text)
    print(f"written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
