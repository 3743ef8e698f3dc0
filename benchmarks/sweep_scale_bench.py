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


# --profile: the same sweep with timers wrapped around the sweep's steps (module-level names
# of leakpath._sweep and leakpath.leakage, replaced in the child only). Each record is
# (step, level, thread, start, end) with the level's counts for the contact solve.
PROFILE = r"""
import leakpath._sweep as S, leakpath.leakage as L, threading
records, by_state, solves = [], {}, [0]
def timed(step, fn, level_of):
    def wrapper(*a, **kw):
        t0 = time.perf_counter()
        out = fn(*a, **kw)
        t1 = time.perf_counter()
        records.append({"step": step, "k": level_of(a, kw, out), "start": t0 - T0,
                        "end": t1 - T0, "thread": threading.current_thread().name})
        return out
    return wrapper
def solve_level(a, kw, out):
    state = out[0]
    k = solves[0]
    solves[0] += 1
    by_state[id(state)] = k
    records.append({"step": "counts", "k": k, "iterations": out[1], "restarts": out[2],
                    "fft": state.fft_products, "pre": state.preconditioner_products,
                    "coarse": state.coarse_fft_products, "contact": state.contact_fraction,
                    "warm": not isinstance(a[3], bool)})
    return k
S._solve_accepted = timed("contact", S._solve_accepted, solve_level)
S._warm_start_for = timed("warm start", S._warm_start_for, lambda a, kw, out: a[2])
S.percolations = timed("percolation", S.percolations, lambda a, kw, out: by_state.get(id(a[0])))
S.nayak_moments = timed("moments", S.nayak_moments, lambda a, kw, out: None)
S._analyse = timed("analysis", S._analyse, lambda a, kw, out: a[0])
L._state_digest = timed("flow digest", L._state_digest, lambda a, kw, out: by_state.get(id(a[0])))
L._timed_columns = timed("flow", L._timed_columns, lambda a, kw, out: by_state.get(id(a[0])))
"""


def run_child(kind: str, n: int, levels: int, flow: bool, profile: bool = False) -> dict:
    env = dict(os.environ)
    code = CHILD
    if profile:
        code = code.replace(
            "r = leakpath.sweep(", PROFILE + "T0 = time.perf_counter()\nr = leakpath.sweep("
        )
        code = code.replace(
            "print(json.dumps(out))", "out['records'] = records\nprint(json.dumps(out))"
        )
    proc = subprocess.run(
        [sys.executable, "-c", code, kind, str(n), str(levels), "1" if flow else "0"],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"child failed ({kind} {n}, flow={flow}): {proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def profile_table(n: int, levels: int, res: dict) -> list[str]:
    """Per-level table of one profiled sweep (seconds of each step, summed per level)."""
    recs = res["records"]
    counts = {r["k"]: r for r in recs if r["step"] == "counts"}
    steps = ["warm start", "contact", "percolation", "moments", "analysis", "flow digest", "flow"]
    # Moments carry no level: the analysis running on the same thread around them has it.
    analyses = [r for r in recs if r["step"] == "analysis"]
    for r in recs:
        if r["step"] == "moments":
            for a in analyses:
                if a["thread"] == r["thread"] and a["start"] <= r["start"] <= a["end"]:
                    r["k"] = a["k"]
    sums: dict[tuple[str, int], float] = {}
    threads: dict[tuple[str, int], str] = {}
    for r in recs:
        if r["step"] in steps and r["k"] is not None:
            key = (r["step"], r["k"])
            sums[key] = sums.get(key, 0.0) + r["end"] - r["start"]
            threads[key] = r["thread"]
    contact_end = {r["k"]: r["end"] for r in recs if r["step"] == "contact"}
    lines = [
        f"Per level, {n}² (`--profile`; sweep {res['seconds']:.1f} s wall, "
        f"{res['cpu_seconds']:.1f} s CPU, peak RSS {res['peak_mib']:.0f} MiB). Seconds of "
        "each step; `rest of row` = the analysis minus percolation and moments (volumes, "
        "counts, class map); `level` = wall time from the end of the previous contact solve "
        "to the end of this one. Steps on the `leakpath-flow` thread overlap the next contact "
        "solve.",
        "",
        "| k | contact fraction | start | iterations | FFT products | preconditioner products "
        "| contact solve [s] | warm start [s] | percolation [s] | moments [s] | rest of row [s] "
        "| flow digest [s] | flow [s] | level [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    tot = dict.fromkeys(steps + ["rest", "iter", "fft", "pre"], 0.0)
    prev = 0.0
    for k in range(levels + 1):
        c = counts.get(k, {})
        g = {st: sums.get((st, k), 0.0) for st in steps}
        rest = g["analysis"] - g["percolation"] - g["moments"]
        for st in steps:
            tot[st] += g[st]
        tot["rest"] += rest
        tot["iter"] += c.get("iterations", 0)
        tot["fft"] += c.get("fft", 0)
        tot["pre"] += c.get("pre", 0)
        end = contact_end.get(k, prev)
        lines.append(
            f"| {k} | {c.get('contact', float('nan')):.4f} | "
            f"{'warm' if c.get('warm') else 'cold'} | {c.get('iterations', '')} | "
            f"{c.get('fft', '')} | {c.get('pre', '')} | {g['contact']:.2f} | "
            f"{g['warm start']:.2f} | {g['percolation']:.2f} | {g['moments']:.2f} | "
            f"{rest:.2f} | {g['flow digest']:.2f} | {g['flow']:.2f} | {end - prev:.2f} |"
        )
        prev = end
    lines.append(
        f"| all | | | {tot['iter']:.0f} | {tot['fft']:.0f} | {tot['pre']:.0f} | "
        f"{tot['contact']:.1f} | {tot['warm start']:.1f} | {tot['percolation']:.1f} | "
        f"{tot['moments']:.1f} | {tot['rest']:.1f} | {tot['flow digest']:.1f} | "
        f"{tot['flow']:.1f} | {res['seconds']:.1f} |"
    )
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[2049])
    ap.add_argument("--kind", choices=["rmd", "spectral"], default="rmd")
    ap.add_argument("--levels", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument(
        "--profile",
        action="store_true",
        help="one sweep with the flow per size, timing each step per level (wrapped timers)",
    )
    ap.add_argument(
        "--no-flow",
        action="store_true",
        help="only the sweeps without the flow (with --profile: profile one without the flow)",
    )
    a = ap.parse_args()
    for n in a.sizes:
        if a.kind == "rmd" and 2 ** round(math.log2(n - 1)) + 1 != n:
            ap.error(f"--sizes: rmd needs 2^m + 1 points a side, got {n}")

    import numpy

    import leakpath

    load_before = os.getloadavg()
    no_flow_flag = " --no-flow" if a.no_flow and not a.profile else ""
    lines = [
        f"## Run: `python benchmarks/sweep_scale_bench.py --sizes "
        f"{' '.join(map(str, a.sizes))} --kind {a.kind} --levels {a.levels} "
        f"--repeats {a.repeats}{no_flow_flag}` "
        f"({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())})",
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
    if a.profile:
        lines = lines[:-3] + [""]
        lines[0] = lines[0].replace("` (", " --profile` (")
        if a.no_flow:
            lines[0] = lines[0].replace("--profile`", "--profile --no-flow`")
        for n in a.sizes:
            res = run_child(a.kind, n, a.levels, not a.no_flow, profile=True)
            table = profile_table(n, a.levels, res)
            lines += table + [""]
            print("\n".join(table), flush=True)
    for n in [] if a.profile else a.sizes:
        with_flow = [
            run_child(a.kind, n, a.levels, True) for _ in range(0 if a.no_flow else a.repeats)
        ]
        without = [run_child(a.kind, n, a.levels, False) for _ in range(a.repeats)]
        tc = statistics.median(r["seconds"] for r in without)
        cc = statistics.median(r["cpu_seconds"] for r in without)
        if with_flow:
            tf = statistics.median(r["seconds"] for r in with_flow)
            cf = statistics.median(r["cpu_seconds"] for r in with_flow)
            peak = max(r["peak_mib"] for r in with_flow)
            flow_cells = (
                f"{tf:.1f} | {cf:.1f} | {tc:.1f} | {cc:.1f} | {(tf - tc) / tf:.0%} | {peak:.0f}"
            )
            first = with_flow[0]
        else:  # --no-flow: the peak RSS column is the sweep's without the flow
            peak = max(r["peak_mib"] for r in without)
            flow_cells = f" | | {tc:.1f} | {cc:.1f} | | {peak:.0f} (no flow)"
            first = without[0]
        row = (
            f"| {n}² | {a.levels + 1} | {flow_cells} | "
            f"{first.get('percolating_levels', '')} | {', '.join(first['solvers'])} |"
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
