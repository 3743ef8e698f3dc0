"""How fast Ctrl-C stops each long computation: KeyboardInterrupt latency after SIGINT.

Run from the repository root (after ``pip install .``)::

    python benchmarks/interrupt_bench.py                 # writes benchmarks/results/interrupt.md
    python benchmarks/interrupt_bench.py --repeats 5 --delays 2 10

For each case a subprocess starts a solve that runs for minutes uninterrupted, prints a line
when it begins, and gets a real SIGINT ``delay`` seconds later (each of ``--delays``; a case
still running at the largest delay took at least that long). Measured from the signal:

* **KeyboardInterrupt**: when the child's ``except KeyboardInterrupt`` ran (it prints
  ``time.time()``; parent and child share the wall clock);
* **exit**: when the child process had exited (interpreter shutdown included).

Medians over ``--repeats`` runs per delay. The machine is shared, so the load average before
and after is recorded with the results.
"""

from __future__ import annotations

import argparse
import os
import platform
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import leakpath

CHILD = """
import sys, time
import leakpath
{setup}
print("ready", flush=True)
try:
    {call}
except KeyboardInterrupt:
    print("interrupted", repr(time.time()), flush=True)
    sys.exit(130)
print("finished", flush=True)
"""

CASES = [
    (
        "Lawson–Hanson, 513², Δ = 0.5 h_s",
        "s = leakpath.rmd(9, 2.2, seed=1)",
        "leakpath.solve(s, 0.5 * s.height_range, solver='lawson-hanson')",
    ),
    (
        "active-set, 1025², Δ = 0.5 h_s",
        "s = leakpath.rmd(10, 2.2, seed=1)",
        "leakpath.solve(s, 0.5 * s.height_range, solver='active-set')",
    ),
    (
        "Polonsky–Keer, 2049², Δ = 0.5 h_s",
        "s = leakpath.rmd(11, 2.2, seed=1)",
        "leakpath.solve(s, 0.5 * s.height_range, solver='polonsky-keer', tol=1e-300, "
        "max_iter=10**7)",
    ),
    (
        "percolation_threshold, 513², auto",
        "s = leakpath.rmd(9, 2.2, seed=1)",
        "leakpath.percolation_threshold(s)",
    ),
    (
        "percolation_threshold, 513², active-set",
        "s = leakpath.rmd(9, 2.2, seed=1)",
        "leakpath.percolation_threshold(s, solver='active-set')",
    ),
]


def one(setup: str, call: str, delay: float) -> tuple[float, float] | None:
    """(KeyboardInterrupt latency, exit time) in seconds, or None if it finished first."""
    proc = subprocess.Popen(
        [sys.executable, "-c", CHILD.format(setup=setup, call=call)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        if proc.stdout.readline().strip() != "ready":
            raise RuntimeError(proc.stderr.read())
        time.sleep(delay)
        if proc.poll() is not None:
            return None
        sent = time.time()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=600)
        exited = time.time() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    caught = [ln for ln in out.splitlines() if ln.startswith("interrupted")]
    if proc.returncode != 130 or not caught:
        raise RuntimeError(f"unexpected end (status {proc.returncode}): {out} {err}")
    return float(caught[0].split()[1]) - sent, exited


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--delays", type=float, nargs="+", default=[2.0, 10.0])
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/interrupt.md"))
    args = ap.parse_args()

    load_before = os.getloadavg()
    rows = []
    for name, setup, call in CASES:
        for delay in args.delays:
            runs = [one(setup, call, delay) for _ in range(args.repeats)]
            done = [r for r in runs if r is not None]
            lat = statistics.median(r[0] for r in done) if done else float("nan")
            ext = statistics.median(r[1] for r in done) if done else float("nan")
            worst = max((r[0] for r in done), default=float("nan"))
            rows.append((name, delay, len(done), len(runs), lat, worst, ext))
            print(f"{name} @ {delay:g} s: KeyboardInterrupt {lat:.3f} s (worst {worst:.3f}), "
                  f"exit {ext:.3f} s, {len(done)}/{len(runs)} still running", flush=True)
    load_after = os.getloadavg()

    lines = [
        "# Ctrl-C latency",
        "",
        f"Produced by `python benchmarks/interrupt_bench.py` (`--repeats {args.repeats} "
        f"--delays {' '.join(f'{d:g}' for d in args.delays)}`). SIGINT sent to a subprocess "
        "`delay` s after its solve began; times from the signal, medians (and the worst) over "
        "the repeats.",
        "",
        f"- machine: {platform.platform()}; {os.cpu_count()} logical CPUs; load average "
        f"before / after: {' '.join(f'{x:.2f}' for x in load_before)} / "
        f"{' '.join(f'{x:.2f}' for x in load_after)}",
        f"- Python {platform.python_version()}; leakpath {leakpath.__version__}; "
        f"numpy {np.__version__}",
        "",
        "| case | signal after | still running | KeyboardInterrupt (median) | worst | "
        "process exit (median) |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for name, delay, n_done, n_runs, lat, worst, ext in rows:
        lines.append(
            f"| {name} | {delay:g} s | {n_done}/{n_runs} | {lat * 1000:.0f} ms | "
            f"{worst * 1000:.0f} ms | {ext * 1000:.0f} ms |"
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
