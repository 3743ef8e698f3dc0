"""Whether ``leakpath.flow(solver="auto")`` takes the faster of the factor and the multigrid.

Run from the repository root::

    python benchmarks/flow_gaps.py --sizes 1025 2049 --separation 1.01
    python benchmarks/flow_gaps.py --sizes 1025 2049 --separation 2.5
    python benchmarks/flow_gaps.py --sizes 2049 --kind synthetic
    python benchmarks/flow_auto_bench.py --repeats 3   # appends to results/flow_auto.md

Below 2^22 unknowns ``auto`` weighs the factor against the multigrid once the factor's
symbolic analysis is known (``src/flow/cost.rs``: the multiply-adds on the factor's
critical path against the unknowns). The cases: the contact gaps of ``flow_gaps.py``
(``spectral_N_S``: a periodic contact solve at ``S`` times the 513² threshold separation;
``synthetic_2049_1.01``: ``max(t − h, 0)`` near the threshold) and gaps made here,
``open_N_H_c``: ``max(t − h, 0)`` of a periodic spectral surface (Hurst exponent ``H``,
rms height 1, seed 1) with ``t`` at the height above which a fraction ``c`` of the surface
lies — light contact over large open regions, the gaps whose factor fills most. Each solver
runs in child processes (``flow_amg_bench.CHILD``: wall time of the ``leakpath.flow`` call,
flow along axis 0, wrap across); times are medians of ``--repeats`` children. The table
gives, per gap, both solvers' times, which ``auto`` ran and its time, and the time ``auto``
lost against the faster of the two; the summary, the total over the cases.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
from pathlib import Path

from flow_amg_bench import child, machine

RESULTS = Path(__file__).parent / "results"
CONTACT = [
    "spectral_1025_1.01",
    "spectral_1025_2.5",
    "spectral_2049_1.01",
    "spectral_2049_1.5",
    "spectral_2049_2.5",
    "synthetic_2049_1.01",
]
OPEN = [
    (1025, 0.3, 0.1),
    (1537, 0.5, 0.0),
    (1537, 0.5, 0.15),
    (1537, 0.5, 0.3),
    (2049, 0.3, 0.1),
    (2049, 0.3, 0.2),
    (2049, 0.3, 0.3),
    (2049, 0.8, 0.1),
    (2049, 0.8, 0.2),
    (2049, 0.8, 0.3),
]


def open_gap(cache: Path, n: int, hurst: float, c: float) -> str:
    """Caches the gap ``open_N_H_c`` (module docstring) and returns its name."""
    import warnings

    import numpy as np

    import leakpath

    # Steep synthetic surfaces: only their gaps' topology matters here.
    warnings.filterwarnings("ignore", category=leakpath.errors.SlopeWarning)
    name = f"open_{n}_{hurst}_{c}"
    if not (cache / f"{name}.npz").exists():
        h = leakpath.spectral(n, hurst, seed=1, rms_height=1.0).heights
        t = np.quantile(h, 1.0 - c) if c > 0 else h.max() + 1e-3
        g = np.maximum(t - h, 0.0)
        contact = g <= 0
        np.savez(cache / f"{name}.npz", gap=g, contact=contact)
        meta = {"kind": "open", "n": n, "hurst": hurst, "contact_fraction": float(contact.mean())}
        (cache / f"{name}.json").write_text(json.dumps(meta))
    return name


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/lp_gaps"))
    ap.add_argument("--out", type=Path, default=RESULTS / "flow_auto.md")
    a = ap.parse_args()
    import numpy as np

    import leakpath

    a.cache.mkdir(parents=True, exist_ok=True)
    missing = [c for c in CONTACT if not (a.cache / f"{c}.npz").exists()]
    if missing:
        sys.exit(
            f"--cache {a.cache}: no {', '.join(missing)}; run benchmarks/flow_gaps.py "
            "first (module docstring)"
        )
    cases = CONTACT + [open_gap(a.cache, *o) for o in OPEN]
    lines = [
        "",
        f"## Run: `python benchmarks/flow_auto_bench.py {' '.join(sys.argv[1:])}`",
        "",
        f"- machine: {machine()} (load average before: "
        f"{' '.join(f'{v:.2f}' for v in os.getloadavg())})",
        f"- leakpath {leakpath.__version__}, numpy {np.__version__}, "
        f"Python {platform.python_version()}",
        f"- times: medians of {a.repeats} child processes (the `leakpath.flow` call)",
        "",
        "| case | contact fraction | unknowns | cholesky s | multigrid s | faster | "
        "auto ran | auto s | auto lost s | rel. diff. Q auto to factor |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    print("\n".join(lines), flush=True)
    lost_total = best_total = auto_total = 0.0
    right = 0
    for case in cases:
        info = json.loads((a.cache / f"{case}.json").read_text())
        path = a.cache / f"{case}.npz"
        med, first = {}, {}
        for solver in ["cholesky", "multigrid", "auto"]:
            runs = [child(path, solver) for _ in range(a.repeats)]
            bad = [r for r in runs if "error" in r]
            if bad:
                sys.exit(f"{case}, {solver}: {bad[0]['error']}")
            med[solver] = statistics.median(r["seconds"] for r in runs)
            first[solver] = runs[0]
        faster = min(("cholesky", "multigrid"), key=lambda s: med[s])
        ran = first["auto"]["solver"]
        best = med[faster]
        lost = max(med["auto"] - best, 0.0)
        right += ran == faster
        lost_total += lost
        best_total += best
        auto_total += med["auto"]
        q, ref = first["auto"]["Q"], first["cholesky"]["Q"]
        row = (
            f"| {case} | {info['contact_fraction']:.3f} | {first['auto']['unknowns']} | "
            f"{med['cholesky']:.2f} | {med['multigrid']:.2f} | {faster} | {ran} | "
            f"{med['auto']:.2f} | {lost:.2f} | {abs(q - ref) / abs(ref):.1e} |"
        )
        print(row, flush=True)
        lines.append(row)
    summary = [
        "",
        f"`auto` ran the faster solver on {right} of {len(cases)} gaps; total over the gaps: "
        f"`auto` {auto_total:.1f} s, the faster of the two {best_total:.1f} s, lost "
        f"{lost_total:.1f} s. Load average after: "
        f"{' '.join(f'{v:.2f}' for v in os.getloadavg())}",
    ]
    print("\n".join(summary))
    with a.out.open("a") as f:
        f.write("\n".join(lines + summary) + "\n")


if __name__ == "__main__":
    main()
