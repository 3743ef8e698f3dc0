"""Leak rate on small grids: one flow solve per contact gap, and where a sweep's time goes.

Part 1: ``leakpath.flow(state, threads=1)`` (sparse Cholesky, the default solver) on the
contact gaps of spectral surfaces (H = 0.9, unit rms height, free boundary) at
Δ = 0, 0.15, 0.3 and 0.45 h_s, sizes 97² to 257²: median of ``--repeats`` calls each. The
minimum-degree order is computed over 2 × 2 blocks of cells on grids of at most 20,000
cells and cell by cell above (``src/flow/direct.rs``), so 97² and 129² use blocks.

Part 2: the default 20-level sweep of RMD surfaces (D = 2.1; seeds 0 and 3 at 129², seed 3
at 257² and 513²): ``sweep()`` (each level's leak rate, percolation and moments computed
beside the next contact solve), the same with them computed after each level in turn
(``LevelFlows(background=False)``), and ``sweep(flow=False)``; medians of ``--repeats``
runs (one run at 513²).

Usage: ``python benchmarks/flow_small_bench.py [--repeats 5] [--out results/flow_small.md]``
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np

import leakpath
from leakpath import leakage


def median_time(f, repeats: int) -> float:
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def part_flows(repeats: int) -> list[str]:
    lines = [
        "## One flow solve per contact gap (spectral H = 0.9, free boundary)",
        "",
        f"`leakpath.flow(state, threads=1)`, median of {repeats} calls, milliseconds.",
        "",
        "| size | Δ/h_s = 0 | 0.15 | 0.3 | 0.45 | contact fractions |",
        "|---|---|---|---|---|---|",
    ]
    for n in (97, 129, 161, 193, 225, 257):
        s = leakpath.spectral(n, 0.9, seed=1, rms_height=1.0)
        problem = leakpath.ContactProblem(s)
        states = [problem.solve(a * s.height_range) for a in (0.0, 0.15, 0.3, 0.45)]
        times = [
            median_time(lambda st=st: leakpath.flow(st, threads=1), repeats) for st in states
        ]
        fracs = ", ".join(f"{st.contact_fraction:.2f}" for st in states)
        lines.append(
            f"| {n}² | " + " | ".join(f"{t * 1e3:.1f}" for t in times) + f" | {fracs} |"
        )
        print(lines[-1], flush=True)
    return lines + [""]


def part_sweeps(repeats: int) -> list[str]:
    lines = [
        "## The 20-level sweep: leak rate beside the contact solves or in turn",
        "",
        f"Medians of {repeats} runs (513²: one run), seconds.",
        "",
        "| surface | `sweep()` (default) | leak rate in turn | `sweep(flow=False)` |",
        "|---|---|---|---|",
    ]
    defaults = leakage.LevelFlows.__init__.__defaults__
    for m, seed in ((7, 3), (7, 0), (8, 3), (9, 3)):
        s = leakpath.rmd(m, 2.1, seed=seed)
        if m < 9:
            leakpath.sweep(s, levels=20)
        reps = repeats if m < 9 else 1
        beside = median_time(lambda s=s: leakpath.sweep(s, levels=20), reps)
        leakage.LevelFlows.__init__.__defaults__ = (False,)
        try:
            in_turn = median_time(lambda s=s: leakpath.sweep(s, levels=20), reps)
        finally:
            leakage.LevelFlows.__init__.__defaults__ = defaults
        off = median_time(lambda s=s: leakpath.sweep(s, levels=20, flow=False), reps)
        lines.append(
            f"| RMD D = 2.1 seed {seed}, {s.shape[0]}² | {beside:.3f} | {in_turn:.3f} | "
            f"{off:.3f} |"
        )
        print(lines[-1], flush=True)
    return lines + [""]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "flow_small.md"))
    args = ap.parse_args()
    head = [
        "# Leak rate on small grids",
        "",
        f"Machine: {platform.platform()}; {os.cpu_count()} cores; Python "
        f"{platform.python_version()}; leakpath {leakpath.__version__}, numpy "
        f"{np.__version__}. Load average at the start: "
        + " ".join(f"{x:.2f}" for x in os.getloadavg()),
        "",
    ]
    lines = head + part_flows(args.repeats) + part_sweeps(args.repeats)
    Path(args.out).write_text("\n".join(lines))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
