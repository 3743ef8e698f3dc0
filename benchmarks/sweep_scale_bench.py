"""Wall time of a whole sweep with the leak rate on a large grid, as a user runs it.

Each run is a child process that generates the surface, then calls
``leakpath.sweep(surface, levels=L, flow=True)`` with every other argument at its default
(solver ``auto``, warm start, flow along axis 0); a second child runs the same sweep with
``flow=False`` so the table splits the time between the contact part (contact solves,
clusters, moments) and the flow. Surfaces: ``rmd`` = ``leakpath.rmd(m, 2.2, seed=0)`` with
the free boundary (``2^m + 1`` points a side), ``spectral`` =
``leakpath.spectral(n, 0.8, seed=0, rms_height=1.0)`` with the periodic one.

    python benchmarks/sweep_scale_bench.py --sizes 1025 2049 --kind rmd --repeats 1 \
        --out benchmarks/results/sweep_scale.md

Reports, per size: median seconds with and without the flow, the flow's share, peak RSS
of the child, its CPU time (both cores: up to twice the wall time on an idle machine; on
a shared one the CPU time is the steadier figure), the levels that percolate and the
solvers that ran, with the machine, its load average and the versions.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

CHILD = r"""
import json, math, resource, sys, time
import numpy as np
import leakpath
kind, n, levels, flow = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4] == "1"
if kind == "rmd":
    s = leakpath.rmd(int(round(math.log2(n - 1))), 2.2, seed=0)
    boundary = "free"
else:
    s = leakpath.spectral(n, 0.8, seed=0, rms_height=1.0)
    boundary = "periodic"
t, cpu = time.perf_counter(), time.process_time()
r = leakpath.sweep(s, levels=levels, boundary=boundary, flow=flow)
dt, dcpu = time.perf_counter() - t, time.process_time() - cpu
out = {
    "seconds": dt,
    "cpu_seconds": dcpu,
    "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    "solvers": sorted(set(map(str, r.column("solver")))),
}
if flow:
    out["percolating_levels"] = int(np.count_nonzero(np.asarray(r.column("Q")) > 0))
print(json.dumps(out))
"""


def run_child(kind: str, n: int, levels: int, flow: bool) -> dict:
    env = dict(os.environ)
    proc = subprocess.run(
        [sys.executable, "-c", CHILD, kind, str(n), str(levels), "1" if flow else "0"],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"child failed ({kind} {n}, flow={flow}): {proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[2049])
    ap.add_argument("--kind", choices=["rmd", "spectral"], default="rmd")
    ap.add_argument("--levels", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args()
    for n in a.sizes:
        if a.kind == "rmd" and 2 ** round(math.log2(n - 1)) + 1 != n:
            ap.error(f"--sizes: rmd needs 2^m + 1 points a side, got {n}")

    import numpy

    import leakpath

    load_before = os.getloadavg()
    lines = [
        f"## Run: `python benchmarks/sweep_scale_bench.py --sizes "
        f"{' '.join(map(str, a.sizes))} --kind {a.kind} --levels {a.levels} "
        f"--repeats {a.repeats}` ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())})",
        "",
        f"- machine: {platform.processor() or platform.machine()}, {os.cpu_count()} logical "
        f"cores, {platform.system()} {platform.release()}; load average before: "
        f"{' '.join(f'{x:.2f}' for x in load_before)}",
        f"- leakpath {getattr(leakpath, '__version__', '?')}, numpy {numpy.__version__}, "
        f"Python {platform.python_version()}",
        f"- times: medians of {a.repeats} child processes (the `sweep` call only); peak RSS "
        "of the child",
        "",
        "| grid | levels | sweep with flow [s] | CPU [s] | sweep without flow [s] | CPU [s] "
        "| flow share | peak RSS with flow [MiB] | percolating levels | solvers |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n in a.sizes:
        with_flow = [run_child(a.kind, n, a.levels, True) for _ in range(a.repeats)]
        without = [run_child(a.kind, n, a.levels, False) for _ in range(a.repeats)]
        tf = statistics.median(r["seconds"] for r in with_flow)
        tc = statistics.median(r["seconds"] for r in without)
        cf = statistics.median(r["cpu_seconds"] for r in with_flow)
        cc = statistics.median(r["cpu_seconds"] for r in without)
        peak = max(r["peak_mib"] for r in with_flow)
        row = (
            f"| {n}² | {a.levels + 1} | {tf:.1f} | {cf:.1f} | {tc:.1f} | {cc:.1f} | "
            f"{(tf - tc) / tf:.0%} | "
            f"{peak:.0f} | {with_flow[0].get('percolating_levels', '')} | "
            f"{', '.join(with_flow[0]['solvers'])} |"
        )
        lines.append(row)
        print(row, flush=True)
    lines += ["", f"Load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}", ""]
    text = "\n".join(lines)
    print(text)
    if a.out is not None:
        with a.out.open("a", encoding="utf-8") as f:
            f.write(text + "\n")


if __name__ == "__main__":
    main()
