"""Leak rate against contact fraction, and the contact fraction where the leak stops.

Run from the repository root::

    python benchmarks/flow_threshold.py              # writes benchmarks/results/flow_threshold.md
    python benchmarks/flow_threshold.py --surfaces 40 --n 1024 --rolloff 4 \\
        --short-cutoff-points 16 --axes 0 1 --flow-check bracket \\
        --out benchmarks/results/flow_threshold_1024.md

For each of ``--surfaces`` periodic spectral surfaces (H = 0.8, ``--n``², rms height 1,
seeds ``--seed0``, ``--seed0`` + 1, ...; box ``L = 500`` µm, roll-off wavelength
``λ_r = L/--rolloff`` (default: none, the power law down from the box size) and short
cut-off ``λ_s = --short-cutoff-points · dx`` (default 2, Nyquist)), the contact fraction at
which the free region stops spanning along each of ``--axes``
(``leakpath.percolation_thresholds(surface, axes=..., boundary="periodic",
solver="polonsky-keer")``, bisection on the approach to 1e-4 of the height range, both axes
sharing the solved states).

``--flow-check bisection`` (the default) repeats the bisection on the leak rate instead of
the percolation (``η = Δp = 1``, flow solved to a relative residual of 1e-8, the same solves
and warm starts as the threshold search) and checks that both give the same threshold;
every solved level also gives a point of the leak rate against the contact fraction.
``--flow-check bracket`` solves the flow only on the two states bracketing each threshold
(the leak must be positive below and zero above): what a large grid can afford;
``--flow-check none`` skips the flow (the percolation thresholds only).

The results are compared with the value ≈ 0.42 of Dapp, Lücke, Persson and Müser, PRL 108,
244301 (2012), also found by Wang and Müser (2021). The results file is rewritten after every
surface (and each surface's numbers appended to ``<out>.jsonl``), so an interrupted run
leaves its partial results.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import leakpath
from leakpath.contact import ContactProblem
from leakpath.errors import NotConvergedError
from leakpath.threshold import DEFAULT_ATOL_REL, MAX_SOLVE_TOL, SOLVE_TOL_PER_ATOL

DAPP_2012 = 0.42
LENGTH = 500.0  # µm, leakpath.generators.DEFAULT_LENGTH
FLOW_TOL = 1e-8


def flow_threshold(surface, axis=0, atol_rel=DEFAULT_ATOL_REL, max_solves=60):
    """Bisection on ``Q > 0`` with the solves and warm starts of ``percolation_threshold``."""
    prob = ContactProblem(surface, boundary="periodic")
    tol = atol_rel * surface.height_range
    solve_tol = min(max(SOLVE_TOL_PER_ATOL * atol_rel, 1e-12), MAX_SOLVE_TOL)
    points = []

    def leak(state):
        f = state.flow(axis=axis, tol=FLOW_TOL)
        points.append((state.contact_fraction, f.flow_rate))
        return f.flow_rate > 0

    def solve(a, lo_state, hi_state):
        start = lo_state if lo_state is not None and lo_state.approach > 0 else None
        if start is not None and hi_state is not None:
            t = (a - lo_state.approach) / (hi_state.approach - lo_state.approach)
            start = (1.0 - t) * lo_state.pressure + t * hi_state.pressure
        return prob.solve(a, solver="polonsky-keer", warm_start=start, tol=solve_tol)

    lo_state = solve(0.0, None, None)
    solves = 1
    if not leak(lo_state):
        return 0.0, lo_state.contact_fraction, points, solves
    hi, hi_state = prob.max_approach, None
    lo = 0.0
    while hi - lo > tol and solves < max_solves:
        mid = 0.5 * (lo + hi)
        st = solve(mid, lo_state, hi_state)
        solves += 1
        if leak(st):
            lo, lo_state = mid, st
        else:
            hi, hi_state = mid, st
    return hi, hi_state.contact_fraction, points, solves


def leak_rate(state, axis):
    """``Q`` of the state along ``axis``, or NaN when the flow solver cannot resolve it."""
    try:
        return state.flow(axis=axis, tol=FLOW_TOL).flow_rate
    except NotConvergedError:
        return float("nan")


def surface_for(args, seed):
    n = args.n
    dx = LENGTH / n
    kw = {}
    if args.rolloff is not None:
        kw["rolloff"] = LENGTH / args.rolloff
    if args.short_cutoff_points is not None:
        kw["short_cutoff"] = args.short_cutoff_points * dx
    return leakpath.spectral(n, 0.8, seed=seed, rms_height=1.0, length=LENGTH, **kw)


def run_surface(args, seed):
    t0 = time.perf_counter()
    s = surface_for(args, seed)
    res = leakpath.percolation_thresholds(
        s, axes=args.axes, boundary="periodic", solver="polonsky-keer"
    )
    row = {"seed": seed, "axes": {}}
    points = []
    for axis, pt in zip(args.axes, res, strict=True):
        entry = {
            "approach": pt.approach, "a_c": pt.contact_fraction, "solves": pt.solves,
            "below": pt.below.approach, "a_below": pt.below.contact_fraction,
        }
        if args.flow_check == "bisection":
            d_flow, a_flow, pts, fsolves = flow_threshold(s, axis=axis)
            points += [p for p in pts if np.isfinite(p[1])]
            entry.update(approach_flow=d_flow, a_flow=a_flow, flow_solves=fsolves,
                         agree=bool(d_flow == pt.approach and a_flow == pt.contact_fraction))
        elif args.flow_check == "bracket":
            q_below = leak_rate(pt.below, axis)
            q_above = leak_rate(pt.above, axis)
            points += [(pt.below.contact_fraction, q_below), (pt.above.contact_fraction, q_above)]
            # NaN: the flow solver refused a neck too narrow to balance in double precision
            # (just below the threshold the last channel is nearly closed).
            agree = None if np.isnan(q_below) else bool(q_below > 0 and q_above == 0)
            entry.update(q_below=q_below, q_above=q_above, agree=agree)
        row["axes"][str(axis)] = entry
    row["seconds"] = time.perf_counter() - t0
    row["points"] = points
    return row


def seed_ranges(seeds):
    """``0–9, 20–29`` for the sorted seeds."""
    out, seeds = [], sorted(seeds)
    for x in seeds:
        if out and x == out[-1][1] + 1:
            out[-1][1] = x
        else:
            out.append([x, x])
    return ", ".join(f"{a}–{b}" if b > a else f"{a}" for a, b in out)


def mean_se(values):
    v = [x for x in values if np.isfinite(x)]
    if len(v) < 2:
        return (v[0] if v else float("nan")), float("nan"), float("nan"), len(v)
    sd = statistics.stdev(v)
    return statistics.mean(v), sd, sd / len(v) ** 0.5, len(v)


def write(args, rows, wall, load0, done):
    n = args.n
    dx = LENGTH / n
    lam_r = "none (box size)" if args.rolloff is None else f"L/{args.rolloff:g}"
    lam_s = args.short_cutoff_points or 2
    lines = [
        "# Leak rate and the contact fraction where it stops",
        "",
        f"Command: `python benchmarks/flow_threshold.py {' '.join(sys.argv[1:])}`".rstrip(),
        "",
        f"{len(rows)} of {args.surfaces} periodic spectral surfaces "
        f"{'(complete)' if done else '(run in progress or interrupted: partial results)'}, "
        f"H = 0.8, {n}², box L = {LENGTH:g} µm (dx = {dx:.4g} µm), rms height 1 µm, roll-off "
        f"λ_r = {lam_r}, short cut-off λ_s = {lam_s:g}·dx, seeds "
        f"{seed_ranges([r['seed'] for r in rows])}; leakpath {leakpath.__version__}; "
        f"{'summed ' if args.merge else ''}wall time {wall:.0f} s; RAYON_NUM_THREADS="
        f"{os.environ.get('RAYON_NUM_THREADS', 'all cores')}; load average before "
        f"{load0:.2f}, now {os.getloadavg()[0]:.2f} (2 cores shared with "
        "other work).",
        "",
        "Contact fraction a_c at which the free region stops spanning (the first solved level "
        "that does not span, bisection to 1e-4·h_s), by flow axis; Dapp et al. (PRL 2012) and "
        f"Wang & Müser (2021): ≈ {DAPP_2012}. Open cell (flow and percolation alike): p = 0 "
        "and g > 0 (docs/conventions.md).",
        "",
        "| axis | surfaces | mean a_c | std | standard error | flow check passed |",
        "|---|---|---|---|---|---|",
    ]
    both = []
    for axis in args.axes:
        vals = [r["axes"][str(axis)]["a_c"] for r in rows]
        m, sd, se, k = mean_se(vals)
        checks = [r["axes"][str(axis)].get("agree", False) for r in rows]
        ok = sum(c is True for c in checks)
        unresolved = sum(c is None for c in checks)
        note = f" ({unresolved} unresolved neck below)" if unresolved else ""
        passed = "—" if args.flow_check == "none" else f"{ok} of {len(rows)}{note}"
        lines.append(f"| {axis} | {k} | {m:.4f} | {sd:.4f} | {se:.4f} | {passed} |")
        both.append(vals)
    if len(args.axes) > 1:
        per_surface = [float(np.mean(v)) for v in zip(*both, strict=True)]
        m, sd, se, k = mean_se(per_surface)
        lines.append(f"| mean of the axes per surface | {k} | {m:.4f} | {sd:.4f} | {se:.4f} | |")
    check = {
        "bisection": "flow bisection on Q > 0 gives the same Δ_c and a_c bit for bit",
        "bracket": "Q > 0 on the state below and Q = 0 on the state above",
        "none": "not run (percolation only)",
    }[args.flow_check]
    lines += [
        "",
        f"Flow check: {check}"
        + ("." if args.flow_check == "none" else f" (η = Δp = 1, flow tolerance {FLOW_TOL:g})."),
        "",
        "| seed | axis | Δ_c (µm) | a_c | a below | solves | flow check | wall (s) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        for axis in args.axes:
            e = r["axes"][str(axis)]
            check = "unresolved" if e.get("agree", False) is None else e.get("agree", "—")
            lines.append(
                f"| {r['seed']} | {axis} | {e['approach']:.6f} | {e['a_c']:.4f} | "
                f"{e['a_below']:.4f} | {e['solves']} | {check} | {r['seconds']:.0f} |"
            )
    pts = np.array([p for r in rows for p in r["points"] if np.isfinite(p[1])])
    if pts.size:
        edges = np.arange(0.0, 0.75, 0.05)
        lines += [
            "",
            "Leak rate against contact fraction (all flow solves of all surfaces, η = Δp = 1, "
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
    tmp = args.out.with_suffix(".tmp")
    tmp.write_text("\n".join(lines))
    os.replace(tmp, args.out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--surfaces", type=int, default=20)
    ap.add_argument("--seed0", type=int, default=0, help="first seed")
    ap.add_argument("--n", type=int, default=256, help="grid points per side")
    ap.add_argument("--rolloff", type=float, default=None,
                    help="roll-off wavelength as a fraction of the box: λ_r = L/ROLLOFF")
    ap.add_argument("--short-cutoff-points", type=float, default=None,
                    help="short cut-off in grid points: λ_s = K·dx (default 2, Nyquist)")
    ap.add_argument("--axes", type=int, nargs="+", default=[0], choices=[0, 1])
    ap.add_argument(
        "--flow-check", choices=["bisection", "bracket", "none"], default="bisection"
    )
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/flow_threshold.md"))
    ap.add_argument("--merge", type=Path, nargs="+", default=None,
                    help="write --out from the .jsonl files of runs split by seed instead of "
                    "running (give the same surface options as the runs)")
    args = ap.parse_args()
    load0 = os.getloadavg()[0]
    if args.merge:
        rows = [json.loads(line) for p in args.merge for line in p.read_text().splitlines()]
        rows.sort(key=lambda r: r["seed"])
        for r in rows:
            r["points"] = []
        args.seed0 = rows[0]["seed"]
        write(args, rows, sum(r["seconds"] for r in rows), load0,
              done=len(rows) >= args.surfaces)
        print(f"wrote {args.out} from {len(rows)} surfaces")
        return
    t0 = time.perf_counter()
    rows = []
    raw = args.out.with_suffix(".jsonl")
    raw.unlink(missing_ok=True)
    for seed in range(args.seed0, args.seed0 + args.surfaces):
        row = run_surface(args, seed)
        rows.append(row)
        with raw.open("a") as f:
            f.write(json.dumps({k: v for k, v in row.items() if k != "points"}) + "\n")
        per_axis = (
            f"axis {a}: a_c {row['axes'][str(a)]['a_c']:.4f} "
            f"(check {row['axes'][str(a)].get('agree', '—')})"
            for a in args.axes
        )
        print(f"seed {seed}: {', '.join(per_axis)}; {row['seconds']:.0f} s", flush=True)
        write(args, rows, time.perf_counter() - t0, load0, done=False)
    write(args, rows, time.perf_counter() - t0, load0, done=True)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
