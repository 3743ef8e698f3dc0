"""leakpath flow: sparse Cholesky against the multigrid (classical AMG + CG) on contact gaps.

Run from the repository root after ``benchmarks/flow_gaps.py`` has cached the gaps::

    python benchmarks/flow_amg_bench.py --cases spectral_513_1.01 spectral_1025_1.01 \\
        --repeats 3            # appends to benchmarks/results/flow_amg.md

Each case is a gap cached by ``flow_gaps.py`` (``--cache``, default ``/tmp/lp_gaps``):
``spectral_N_S`` the gap of a periodic Polonsky–Keer contact solve at separation ``S``
times the 513² threshold separation, ``synthetic_N_0`` the near-threshold gap
``max(t − h, 0)`` (no contact solve). Every solve runs in a child process (``leakpath.flow``
on the gap and contact mask, flow along axis 0, wrap across axis 1), which reports its wall
time for the flow call, the iterations, the flow rates and its peak resident set
(``VmHWM`` of ``/proc/self/status``); a child that only loads the gap gives the baseline.
Times are medians of ``--repeats`` children; the rates are compared with the factor's.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
from pathlib import Path

CHILD = r"""
import json, sys, time
import numpy as np
import leakpath
path, solver = sys.argv[1], sys.argv[2]
d = np.load(path)
g, c = d["gap"], d["contact"]
n = g.shape[0]
out = {}
if solver != "load":
    t = time.perf_counter()
    try:
        f = leakpath.flow(g, dx=1.0 / n, contact=c, periodic=True, solver=solver)
        out = dict(seconds=time.perf_counter() - t, solver=f.solver,
                   iterations=f.iterations, Q=f.flow_rate, Q_in=f.inlet_flow_rate,
                   unknowns=f.n_unknowns)
    except Exception as e:  # reported, not raised: the table says what failed
        out = dict(seconds=time.perf_counter() - t, error=f"{type(e).__name__}: {e}"[:200])
out["vmhwm_kib"] = [int(x.split()[1]) for x in open("/proc/self/status")
                    if x.startswith("VmHWM")][0]
print(json.dumps(out))
"""


def machine() -> str:
    cpu = platform.processor() or "?"
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            cpu = line.split(":", 1)[1].strip()
            break
    return f"{cpu}, {os.cpu_count()} logical cores, {platform.system()} {platform.release()}"


def label(asked: str, ran: str) -> str:
    """The solver column: the one asked for, and the one that ran when they differ."""
    return asked if asked == ran else f"{asked} → {ran}"


def child(path: Path, solver: str) -> dict:
    env = dict(os.environ)
    r = subprocess.run(
        [sys.executable, "-c", CHILD, str(path), solver],
        capture_output=True, text=True, env=env, check=False,
    )
    if r.returncode != 0:
        return {"error": f"exit {r.returncode}: {r.stderr.strip().splitlines()[-1:]}"}
    return json.loads(r.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--cases", nargs="+", required=True)
    ap.add_argument("--solvers", nargs="+", default=["cholesky", "multigrid"])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/lp_gaps"))
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/flow_amg.md"))
    a = ap.parse_args()
    import numpy as np

    import leakpath

    lines = [
        "",
        f"## Run: `python benchmarks/flow_amg_bench.py {' '.join(sys.argv[1:])}`",
        "",
        f"- machine: {machine()}; shared with other jobs (load average before: "
        f"{' '.join(f'{v:.2f}' for v in os.getloadavg())}), so times are noisy",
        f"- leakpath {leakpath.__version__} (from `{Path(leakpath.__file__).parent}`), "
        f"numpy {np.__version__}, Python {platform.python_version()}",
        f"- times: medians of {a.repeats} child processes (time of the `leakpath.flow` call); "
        "peak RSS: largest VmHWM of those children, and of a child that only loads the gap",
        "",
        "| case | contact fraction | unknowns | solver | median s | iterations | "
        "peak RSS MiB (load only) | Q | rel. diff. Q to factor |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for case in a.cases:
        path = a.cache / f"{case}.npz"
        info = json.loads((a.cache / f"{case}.json").read_text())
        base = child(path, "load")["vmhwm_kib"] / 1024
        ref = None
        for solver in a.solvers:
            runs = [child(path, solver) for _ in range(a.repeats)]
            ok = [r for r in runs if "error" not in r]
            rss = max(r.get("vmhwm_kib", 0) for r in runs) / 1024
            if not ok:
                row = (f"| {case} | {info['contact_fraction']:.3f} | | {solver} | | | "
                       f"{rss:.0f} ({base:.0f}) | {runs[0]['error']} | |")
            else:
                t = statistics.median(r["seconds"] for r in ok)
                q = ok[0]["Q"]
                if solver == "cholesky":
                    ref = q
                diff = f"{abs(q - ref) / abs(ref):.1e}" if ref else ""
                row = (f"| {case} | {info['contact_fraction']:.3f} | {ok[0]['unknowns']} | "
                       f"{label(solver, ok[0]['solver'])} | {t:.2f} | {ok[0]['iterations']} | "
                       f"{rss:.0f} ({base:.0f}) | {q:.10e} | {diff} |")
            print(row, flush=True)
            lines.append(row)
    lines.append("")
    lines.append(f"Load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    with a.out.open("a") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
