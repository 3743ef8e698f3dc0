"""Exact contact solvers: the paper's sweep, scipy's NNLS, peak memory.

Runs, side by side in one process (medians of repeats):

1. the paper's sweep — RMD m = 7 (129²), D = 2.1, seed 0, approaches k·h_s/20, k = 1…20 — with
   ``warm_start=False`` (every level from p = 0, as in the paper) and ``True``, for the
   ``active-set`` solver (Lawson–Hanson with block pivoting) and, with
   ``--include-paper-solver``, the classic one-point-per-iteration ``lawson-hanson``;
2. m = 5 and 6: leakpath against ``scipy.optimize.nnls(R, R⁻ᵀb)`` (C = RᵀR) on the same
   problems (the dense C and its Cholesky factor are built outside the timed region);
3. peak resident memory of one solve at the largest approach (Δ = h_s) at 129² and 257², each
   in a fresh subprocess.

Usage: ``python benchmarks/lawson_hanson_bench.py [--repeats 3] [--include-paper-solver]``.
Writes ``benchmarks/results/lawson_hanson.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import leakpath
from leakpath.contact import ContactProblem

RESULTS = Path(__file__).parent / "results"


def sweep_time(surface, solver: str, warm: bool) -> tuple[float, float]:
    prob = ContactProblem(surface)
    hs = surface.height_range
    t0 = time.perf_counter()
    st = None
    for k in range(1, 21):
        st = prob.solve(k * hs / 20, solver=solver, warm_start=warm)
    assert st is not None
    return time.perf_counter() - t0, st.contact_fraction


def scipy_comparison(m: int, repeats: int) -> dict:
    from scipy.optimize import nnls

    s = leakpath.rmd(m, 2.1, seed=0)
    h = s.heights
    n = h.size
    prob = ContactProblem(s)
    idx = np.arange(n, dtype=np.int64)
    C = prob._core.block(idx)
    R = np.linalg.cholesky(C).T
    hs = s.height_range
    out = {"m": m, "grid": f"{h.shape[0]}²", "rows": []}
    for frac in (0.3, 0.6, 1.0):
        a = frac * hs
        b = a - (h.max() - h.ravel())
        d = np.linalg.solve(R.T, b)
        ts, tl = [], []
        for _ in range(repeats):
            t0 = time.perf_counter()
            p_ref, _ = nnls(R, d, maxiter=50 * n)
            ts.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            st = prob.solve(a, solver="lawson-hanson")
            tl.append(time.perf_counter() - t0)
        diff = np.abs(st.pressure.ravel() - p_ref).max() / np.abs(p_ref).max()
        out["rows"].append(
            {
                "approach/h_s": frac,
                "scipy_s": statistics.median(ts),
                "leakpath_lh_s": statistics.median(tl),
                "ratio": statistics.median(ts) / statistics.median(tl),
                "max_rel_diff": float(diff),
                "contact_fraction": st.contact_fraction,
            }
        )
    return out


def peak_memory(m: int) -> dict:
    code = (
        "import resource, time, leakpath\n"
        "from leakpath.contact import ContactProblem\n"
        f"s = leakpath.rmd({m}, 2.1, seed=0)\n"
        "t = time.perf_counter()\n"
        "st = ContactProblem(s).solve(s.height_range, solver='active-set')\n"
        "t = time.perf_counter() - t\n"
        "import json\n"
        "print(json.dumps({'seconds': t, 'contact_fraction': st.contact_fraction,"
        " 'n_contact': int(st.contact.sum()),"
        " 'peak_MiB': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    if res.returncode != 0:
        return {"m": m, "error": res.stderr.strip().splitlines()[-1]}
    d = json.loads(res.stdout)
    d["m"] = m
    return d


def machine() -> str:
    cpu = "unknown"
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (
        f"{platform.platform()}; {cpu}; {os.cpu_count()} cores; Python {platform.python_version()};"
        f" numpy {np.__version__}; leakpath {leakpath.__version__}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--include-paper-solver", action="store_true")
    args = ap.parse_args()
    lines = ["# Exact contact solvers", "", f"Machine: {machine()}", ""]

    surface = leakpath.rmd(7, 2.1, seed=0)
    solvers = ["active-set"] + (["lawson-hanson"] if args.include_paper_solver else [])
    lines += [
        "## The paper's sweep: RMD m = 7 (129²), D = 2.1, seed 0, Δ = k·h_s/20, k = 1…20",
        "",
        "| solver | warm_start | 20 solves, total (median) | runs | contact fraction at Δ = h_s |",
        "|---|---|---|---|---|",
    ]
    for solver in solvers:
        for warm in (False, True):
            reps = args.repeats if solver == "active-set" else 1
            times, frac = [], 0.0
            for _ in range(reps):
                t, frac = sweep_time(surface, solver, warm)
                times.append(t)
            row = f"| {solver} | {warm} | {statistics.median(times):.2f} s | {reps} | {frac:.4f} |"
            print(row, flush=True)
            lines.append(row)

    lines += [
        "",
        "## leakpath's Lawson–Hanson vs scipy.optimize.nnls (same problems, RMD D = 2.1)",
        "",
        "| grid | Δ/h_s | scipy nnls | leakpath lawson-hanson | speed-up | max rel. diff"
        " | contact fraction |",
        "|---|---|---|---|---|---|---|",
    ]
    for m in (5, 6):
        res = scipy_comparison(m, args.repeats)
        for r in res["rows"]:
            row = (
                f"| {res['grid']} | {r['approach/h_s']} | {r['scipy_s'] * 1e3:.1f} ms |"
                f" {r['leakpath_lh_s'] * 1e3:.2f} ms | {r['ratio']:.0f}×"
                f" | {r['max_rel_diff']:.1e} |"
                f" {r['contact_fraction']:.3f} |"
            )
            print(row, flush=True)
            lines.append(row)

    lines += [
        "",
        "## Peak memory, one active-set solve at Δ = h_s (fresh process)",
        "",
        "| grid | contact points | time | peak RSS |",
        "|---|---|---|---|",
    ]
    for m in (7, 8):
        d = peak_memory(m)
        n = 2**m + 1
        if "error" in d:
            row = f"| {n}² | — | — | {d['error']} |"
        else:
            row = (
                f"| {n}² | {d['n_contact']} ({d['contact_fraction']:.3f}) | {d['seconds']:.1f} s |"
                f" {d['peak_MiB']:.0f} MiB |"
            )
        print(row, flush=True)
        lines.append(row)

    RESULTS.mkdir(exist_ok=True)
    out = RESULTS / "lawson_hanson.md"
    tmp = out.with_suffix(".tmp")
    tmp.write_text("\n".join(lines) + "\n")
    os.replace(tmp, out)
    print(f"written {out}")


if __name__ == "__main__":
    main()
