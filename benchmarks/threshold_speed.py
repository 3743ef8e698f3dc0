"""Time of ``leakpath.percolation_threshold`` on one periodic surface, with its profile.

Run from the repository root::

    python benchmarks/threshold_speed.py --label after      # appends to the results file
    PYTHONPATH=<other checkout>/python python benchmarks/threshold_speed.py --label before

Surface ``leakpath.spectral(n, 0.8, seed=0, rms_height=1.0)`` (default ``n = 1025``),
``percolation_threshold(surface, boundary="periodic")`` with its defaults. Every contact solve
and every labelling is timed (wall clock, s) by wrapping ``ContactProblem.solve`` and
``leakpath._percolation.percolation`` for the run; the process CPU time (s, all threads)
is reported beside the wall time because the machine may be shared. ``--repeats`` runs the
search that many times and reports the median.
"""

from __future__ import annotations

import argparse
import inspect
import os
import statistics
import sys
import time
from pathlib import Path

import leakpath
from leakpath import _percolation
from leakpath import contact as _contact


def profile(n: int, seed: int, threads: str) -> dict:
    log: list[dict] = []
    solve0 = _contact.ContactProblem.solve
    perc0 = _percolation.percolation

    def solve(self, approach=None, **kw):
        t = time.perf_counter()
        st = solve0(self, approach, **kw)
        ws = kw.get("warm_start")
        log.append({
            "kind": "solve", "approach": approach, "seconds": time.perf_counter() - t,
            "iterations": st.iterations, "fft": st.fft_products, "kkt": st.kkt,
            "solver": st.solver, "a": st.contact_fraction,
            "start": "cold" if ws is None else type(ws).__name__,
        })
        return st

    def perc(*a, **k):
        t = time.perf_counter()
        r = perc0(*a, **k)
        log.append({"kind": "label", "seconds": time.perf_counter() - t})
        return r

    s = leakpath.spectral(n, 0.8, seed=seed, rms_height=1.0)
    _contact.ContactProblem.solve = solve
    _percolation.percolation = perc
    try:
        c0, t0 = time.process_time(), time.perf_counter()
        res = leakpath.percolation_threshold(s, boundary="periodic")
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    finally:
        _contact.ContactProblem.solve = solve0
        _percolation.percolation = perc0
    solves = [e for e in log if e["kind"] == "solve"]
    labels = [e for e in log if e["kind"] == "label"]
    return {
        "wall": wall, "cpu": cpu, "result": res, "solves": solves,
        "label_seconds": sum(e["seconds"] for e in labels), "labels": len(labels),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=1025, help="grid points per side")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--label", default="after", help="name of this run in the results file")
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/threshold_speed.md"))
    args = ap.parse_args()
    threads = os.environ.get("RAYON_NUM_THREADS", "all cores")
    load0 = os.getloadavg()[0]
    runs = [profile(args.n, args.seed, threads) for _ in range(args.repeats)]
    med = sorted(runs, key=lambda r: r["wall"])[len(runs) // 2]
    res = med["result"]
    params = inspect.signature(leakpath.percolation_threshold).parameters
    lines = [
        f"## {args.label}: {args.n}², seed {args.seed}",
        "",
        f"Command: `{' '.join(['python', *sys.argv])}` (RAYON_NUM_THREADS={threads}; "
        f"leakpath from `{Path(leakpath.__file__).parent}`; percolation_threshold keywords: "
        f"{', '.join(k for k in params if k != 'surface')}). Load average before "
        f"{load0:.2f}, after {os.getloadavg()[0]:.2f} on 2 shared cores.",
        "",
        f"**Wall time {statistics.median(r['wall'] for r in runs):.1f} s (median of "
        f"{len(runs)}), CPU time {med['cpu']:.1f} s**; {len(med['solves'])} contact solves, "
        f"{sum(e['iterations'] for e in med['solves'])} solver iterations, "
        f"{sum(e['fft'] for e in med['solves'])} operator products; {med['labels']} "
        f"labellings in {med['label_seconds']:.2f} s. Result: Δ_c = {res.approach:.6f} "
        f"(length), a_c = {res.contact_fraction:.4f}, bracket [{res.below.approach:.6f}, "
        f"{res.above.approach:.6f}].",
        "",
        "| # | approach (length) | start | solver | iterations | operator products | KKT/h_s "
        "| contact fraction | wall (s) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for i, e in enumerate(med["solves"]):
        lines.append(
            f"| {i} | {e['approach']:.6f} | {e['start']} | {e['solver']} | {e['iterations']} | "
            f"{e['fft']} | {e['kkt']:.1e} | {e['a']:.4f} | {e['seconds']:.2f} |"
        )
    lines.append("")
    text = "\n".join(lines) + "\n"
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    if not args.out.exists():
        args.out.write_text(
            "# Speed of the percolation threshold search\n\n"
            "`percolation_threshold(spectral(n, 0.8, seed=0, rms_height=1.0), "
            "boundary=\"periodic\")`; written by `benchmarks/threshold_speed.py`.\n\n"
        )
    with args.out.open("a") as f:
        f.write(text)


if __name__ == "__main__":
    main()
