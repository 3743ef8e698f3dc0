"""Leak rate against contact fraction, and the contact fraction where the leak stops.

Run from the repository root::

    python benchmarks/flow_threshold.py              # writes benchmarks/results/flow_threshold.md
    python benchmarks/flow_threshold.py --surfaces 40 --n 512

For each of ``--surfaces`` periodic spectral surfaces (H = 0.8, ``--n``², rms height 1,
seeds 0, 1, ...), bisection on the approach between 0 and full contact for the smallest
approach at which the leak rate along axis 0 is zero (``leakpath.solve(...,
boundary="periodic", solver="polonsky-keer")``, each solve warm-started from the nearest
leaking level below, to 1e-4 of the height range — the same bisection as
``leakpath.percolation_threshold``). The contact fraction there is compared with
``leakpath.percolation_threshold(surface, boundary="periodic", solver="polonsky-keer")``
(they must be equal: the flow has unknowns exactly on the spanning clusters of the same
4-connectivity) and with the value ≈ 0.42 of Dapp, Lücke, Persson and Müser, PRL 108,
244301 (2012), also found by Wang and Müser (2021). Every solved level also gives a point
of the leak rate (``η = Δp = 1``, flow solved to a relative residual of 1e-8) against the
contact fraction.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import leakpath
from leakpath.contact import ContactProblem

DAPP_2012 = 0.42


def flow_threshold(surface, atol_rel=1e-4, max_solves=60):
    prob = ContactProblem(surface, boundary="periodic")
    tol = atol_rel * surface.height_range
    points = []

    def leak(state):
        f = state.flow(tol=1e-8)
        points.append((state.contact_fraction, f.flow_rate))
        return f.flow_rate > 0

    lo_state = prob.solve(0.0, solver="polonsky-keer")
    solves = 1
    if not leak(lo_state):
        return 0.0, lo_state.contact_fraction, points, solves
    hi = prob.max_approach
    hi_state = prob.solve(hi, solver="polonsky-keer")
    solves += 1
    if leak(hi_state):
        return float("nan"), float("nan"), points, solves
    lo = 0.0
    while hi - lo > tol and solves < max_solves:
        mid = 0.5 * (lo + hi)
        st = prob.solve(mid, solver="polonsky-keer", warm_start=lo_state if lo > 0 else None)
        solves += 1
        if leak(st):
            lo, lo_state = mid, st
        else:
            hi, hi_state = mid, st
    return hi, hi_state.contact_fraction, points, solves


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--surfaces", type=int, default=20)
    ap.add_argument("--n", type=int, default=256)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/flow_threshold.md"))
    args = ap.parse_args()
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    rows, fracs, all_points = [], [], []
    for seed in range(args.surfaces):
        s = leakpath.spectral(args.n, 0.8, seed=seed, rms_height=1.0)
        d_flow, a_flow, points, solves = flow_threshold(s)
        pt = leakpath.percolation_threshold(s, boundary="periodic", solver="polonsky-keer")
        same = d_flow == pt.approach and a_flow == pt.contact_fraction
        rows.append((seed, d_flow, a_flow, pt.approach, pt.contact_fraction, same, solves))
        fracs.append(a_flow)
        all_points += points
        print(f"seed {seed}: a_c(flow) {a_flow:.4f}, a_c(percolation) {pt.contact_fraction:.4f}, "
              f"equal {same}", flush=True)
    wall = time.perf_counter() - t0
    ok = [a for a in fracs if np.isfinite(a)]
    mean, std = statistics.mean(ok), statistics.stdev(ok)
    lines = [
        "# Leak rate and the contact fraction where it stops",
        "",
        f"Command: `python benchmarks/flow_threshold.py {' '.join(sys.argv[1:])}`".rstrip(),
        "",
        f"{args.surfaces} periodic spectral surfaces, H = 0.8, {args.n}², rms height 1, seeds "
        f"0–{args.surfaces - 1}; leakpath {leakpath.__version__}; wall time {wall:.0f} s; load "
        f"average before {load0[0]:.2f}, after {os.getloadavg()[0]:.2f}.",
        "",
        f"**Contact fraction at which the leak stops (axis 0): mean {mean:.4f}, std {std:.4f}, "
        f"standard error {std / len(ok) ** 0.5:.4f}** over {len(ok)} surfaces; Dapp et al. "
        f"(PRL 2012) and Wang & Müser (2021): ≈ {DAPP_2012}. Open cell (flow and "
        f"percolation alike): p = 0 and g > 0 (docs/conventions.md). Equal to "
        f"`leakpath.percolation_threshold` (approach and "
        f"contact fraction, bit for bit) on {sum(r[5] for r in rows)} of {len(rows)} surfaces.",
        "",
        "| seed | Δ_c (flow) | a_c (flow) | Δ_c (percolation_threshold) | a_c (percolation) | "
        "equal | solves |",
        "|---|---|---|---|---|---|---|",
    ]
    for seed, d1, a1, d2, a2, same, solves in rows:
        lines.append(f"| {seed} | {d1:.6f} | {a1:.4f} | {d2:.6f} | {a2:.4f} | {same} | {solves} |")
    pts = np.array(all_points)
    edges = np.arange(0.0, 0.65, 0.05)
    lines += [
        "",
        "Leak rate against contact fraction (all solved levels of all surfaces, η = Δp = 1, "
        "binned by contact fraction; Q in the surfaces' units):",
        "",
        "| contact fraction | levels | median Q | leaking |",
        "|---|---|---|---|",
    ]
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        sel = (pts[:, 0] >= a) & (pts[:, 0] < b)
        if sel.any():
            lines.append(
                f"| {a:.2f}–{b:.2f} | {int(sel.sum())} | {np.median(pts[sel, 1]):.3e} | "
                f"{int((pts[sel, 1] > 0).sum())} |"
            )
    lines.append("")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
