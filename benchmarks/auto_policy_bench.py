"""Where ``solver="auto"`` switches from the exact active set to Polonsky–Keer.

One solve from ``p = 0`` at Δ = 0.3, 0.6 and 1.0 h_s (free boundary, RMD D = 2.1, seed 3),
both solvers to the default KKT tolerance, medians of ``--repeats`` runs, on grids from 17²
to 129². The ratio active-set / Polonsky–Keer above 1 means Polonsky–Keer is faster; the
policy (``leakpath.contact.AUTO_ACTIVE_SET_MAX_POINTS``) takes the active set where it is
faster at every approach. Contact sets are compared too.

Run: ``python benchmarks/auto_policy_bench.py`` → ``results/auto_policy.md``.
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
from leakpath.contact import AUTO_ACTIVE_SET_MAX_POINTS, ContactProblem

RESULTS = Path(__file__).parent / "results"


def timed(prob: ContactProblem, a: float, solver: str, repeats: int):
    times = []
    state = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        state = prob.solve(a, solver=solver)
        times.append(time.perf_counter() - t0)
    return statistics.median(times), state


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    lines = [
        "# `solver=\"auto\"`: active set or Polonsky–Keer",
        "",
        f"Machine: {platform.platform()}; {os.cpu_count()} cores; Python "
        f"{platform.python_version()}; leakpath {leakpath.__version__}, numpy {np.__version__}",
        f"Load average at the start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}",
        "",
        f"Policy: active set up to {AUTO_ACTIVE_SET_MAX_POINTS} points "
        f"({int(AUTO_ACTIVE_SET_MAX_POINTS**0.5)}²), Polonsky–Keer above. Medians of "
        f"{args.repeats} cold solves.",
        "",
        "| grid | Δ/h_s | contact | active-set | polonsky-keer | active-set / PK | same set |",
        "|---|---|---|---|---|---|---|",
    ]
    for m in (4, 5, 6, 7):
        n = 2**m + 1
        for extra in ((0,) if m < 5 else (0, 16)):
            size = n + extra
            s = leakpath.rmd(m, 2.1, seed=3) if extra == 0 else leakpath.spectral(
                size, 0.9, seed=3, rms_height=1.0
            )
            prob = ContactProblem(s)
            hs = s.height_range
            for frac in (0.3, 0.6, 1.0):
                t_as, st_as = timed(prob, frac * hs, "active-set", args.repeats)
                t_pk, st_pk = timed(prob, frac * hs, "polonsky-keer", args.repeats)
                same = np.array_equal(st_as.contact, st_pk.contact)
                row = (
                    f"| {size}² | {frac} | {st_as.contact_fraction:.3f} | {t_as * 1e3:.2f} ms | "
                    f"{t_pk * 1e3:.2f} ms | {t_as / t_pk:.2f} | {'yes' if same else 'NO'} |"
                )
                lines.append(row)
                print(row, flush=True)
    lines.append("")
    lines.append(f"Load average at the end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "auto_policy.md").write_text("\n".join(lines) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
