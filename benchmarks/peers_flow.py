"""Leak rate (Reynolds flow) of leakpath side by side with ReynoldsFlow, on contact gaps.

Run from the repository root after ``benchmarks/flow_gaps.py --sizes 257 513 1025 2049``
has cached the gaps (``/tmp/lp_gaps/spectral_N_1.01.npz``: a periodic spectral surface,
H = 0.8, rms height 1, seed 0, pressed to 1.01 times the 513² threshold separation)::

    PYTHONPATH=python /work/benchvenv-peers/bin/python benchmarks/peers_flow.py \\
        --sizes 257 513 1025 2049 --repeats 3     # appends to benchmarks/results/peers_flow.md

ReynoldsFlow (``pip install reynoldsflow``; optional ``pypardiso``, ``scikit-sparse``,
``petsc4py``) lives in a separate benchmark environment, never a leakpath dependency.
``--petsc-python`` names a second interpreter whose ``petsc4py`` has Hypre and MUMPS; the
PETSc solvers run there (skipped when it is missing).

Same problem for both codes: the gap ``g`` of the cache on ``n × n`` cells of side
``dx = 1/n``, flow along axis 0 from an inlet reservoir at ``p = 1`` to an outlet at
``p = 0``, wrapped (periodic) across axis 1. Both use the same cell-centred finite volumes:
cell conductance ``g³/(12η)`` (ReynoldsFlow: ``g³``, so leakpath runs with
``η = 1/12``), harmonic means on internal faces, ``2c`` on the reservoir faces, the flux
through a face ``c_f Δp`` (``dx`` cancels). ReynoldsFlow has no contact mask and closes
only ``g ≤ 0``: its gap is ``g`` with the contact cells set to 0 (a contact solve leaves
round-off up to ~1e-12 on them, which it would otherwise count as open cells). Both then
solve on the cells of the spanning clusters (the same count), and ``Q`` is the volume rate
through the outlet (ReynoldsFlow: the mean of its inlet and outlet rates from
``compute_total_flux``). ``inlet/outlet rel. diff`` is each code's own check of that rate:
``|Q − Q_in|/Q`` for leakpath, the ``conservation`` error ``compute_total_flux`` returns
(``|Q_in − Q_out|/Q``) for ReynoldsFlow.

Each measurement is one child process: imports, the gap loaded, one warm-up solve of the
same solver on a 32² gap with a dead end and an island (ReynoldsFlow compiles its Numba
kernels there, or loads them from ``NUMBA_CACHE_DIR``, the harness turning on Numba's
cache; PETSc initialises), then the timed call: ``leakpath.flow(...)`` against
``solve_fluid_problem(...)`` + ``compute_total_flux(...)`` (assembly, connectivity,
factor or preconditioner, solve and fluxes for both). The child reports the wall time of
that call, ``Q``, the unknowns and its peak resident set (``VmHWM``, whole process); a
child that only imports and loads the gap gives the baseline. With ``--calls N`` the child
then calls the same solve ``N − 1`` more times on the same gap and also reports the median
of those (column ``repeat s``): the time of a sweep's later calls, once the process holds
the memory a solve of that size uses (neither code keeps anything else from one call to
the next). Every native library runs on
``--threads`` threads (``RAYON_NUM_THREADS``, ``OMP``/``MKL``/``OPENBLAS``/``NUMBA``).
leakpath's methods are its solvers at their default rate tolerance (1e-12), and
``auto@1e-9``: the default solver at the tolerance a sweep's levels pass (1e-9, still
far below the peers' own inlet/outlet differences), reported in a table of its own; the
comparison of the best of each code uses the defaults only.
Times are medians of ``--repeats`` children, run round-robin (each method's k-th run
before any method's next), so the medians of a ratio share the same stretch of a shared
machine's load; ``Q rel. diff`` is against leakpath ``solver="auto"``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

LEAKPATH = ["auto", "cholesky", "multigrid", "auto@1e-9"]
# "SOLVER@TOL": leakpath at a rate tolerance other than its default (1e-12). A sweep's
# levels pass 1e-9 (``leakpath.leakage.FLOW_TOL``), so "auto@1e-9" is what one level's
# flow costs inside a sweep; it is reported apart from the default's comparison.
# ReynoldsFlow solver strings (0.1.3); the PETSc ones run under --petsc-python.
PEERS = ["scipy.amg-rs", "scipy.amg-smooth_aggregation", "scipy-spsolve", "cholesky",
         "pardiso", "petsc-cg.hypre", "petsc-cg.gamg", "petsc-mumps"]
PEER_MODULE = {"cholesky": "sksparse", "pardiso": "pypardiso"}

CHILD = r"""
import json, sys, time
import numpy as np
code, solver, path, calls = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
def hwm():
    return [int(x.split()[1]) for x in open("/proc/self/status") if x.startswith("VmHWM")][0]
if code == "leakpath":
    import leakpath
    name, _, tol = solver.partition("@")
    opts = dict(tol=float(tol)) if tol else {}
    def run(g, c):
        n = g.shape[0]
        f = leakpath.flow(g, dx=1.0 / n, contact=c, periodic=True, axis=0,
                          viscosity=1.0 / 12.0, pressure_drop=1.0, solver=name, **opts)
        return dict(Q=f.flow_rate, Q_in=f.inlet_flow_rate, unknowns=f.n_unknowns,
                    ran=f.solver, iterations=f.iterations)
elif code == "reynoldsflow":
    import logging
    import numba  # its kernels are @njit without cache=True: cached here, so that a
    _nj, _j = numba.njit, numba.jit  # child does not spend ~40 s compiling them again
    def _cached(dec):
        def wrap(*a, **k):
            if len(a) == 1 and callable(a[0]) and not k:
                return dec(cache=True)(a[0])
            return dec(*a, **{**k, "cache": True})
        return wrap
    numba.njit, numba.jit = _cached(_nj), _cached(_j)
    from reynoldsflow import transport
    transport.set_verbosity("warning")
    logging.getLogger("reynoldsflow").setLevel(logging.WARNING)
    def run(g, c):
        n = g.shape[0]
        gr = np.where(c, 0.0, g)
        fg, p, fl = transport.solve_fluid_problem(gr, solver=solver, p_west=1.0, p_east=0.0)
        if fg is None:
            return dict(Q=0.0, unknowns=0, ran=solver)
        Q, err = transport.compute_total_flux(fg, fl, n)
        return dict(Q=float(Q), conservation=float(err), unknowns=int((fg > 0).sum()),
                    ran=solver)
d = np.load(path)
g, c = d["gap"], d["contact"]
out = dict(base_kib=hwm())
if solver != "load":
    try:
        w = np.ones((32, 32))  # warm-up: JIT, library init; with a dead end and an island
        w[8, :28] = 0.0
        w[20:25, 10:15] = 0.0
        w[22, 12] = 1.0
        run(w, w == 0.0)
        out["warm_kib"] = hwm()
        t = time.perf_counter()
        out.update(run(g, c))
        out["seconds"] = time.perf_counter() - t
        again = []
        for _ in range(calls - 1):  # the same gap again, as the calls of a sweep would be
            t = time.perf_counter()
            run(g, c)
            again.append(time.perf_counter() - t)
        if again:
            out["repeat_seconds"] = sorted(again)[(len(again) - 1) // 2]
    except Exception as e:  # reported, not raised: the table says what failed
        out["error"] = f"{type(e).__name__}: {e}"[:300]
out["vmhwm_kib"] = hwm()
print("RESULT " + json.dumps(out))
"""


def machine() -> str:
    cpu = platform.processor() or "?"
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            cpu = line.split(":", 1)[1].strip()
            break
    mem = 0.0
    for line in Path("/proc/meminfo").read_text().splitlines():
        if line.startswith("MemTotal"):
            mem = int(line.split()[1]) / 2**20
    return (f"{cpu}, {os.cpu_count()} logical cores, {mem:.1f} GiB, "
            f"{platform.system()} {platform.release()}")


def loadavg() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def versions(python: str, petsc_python: str | None) -> dict[str, str]:
    code = (
        "import importlib.metadata as m, json, sys\n"
        "out = {'python': sys.version.split()[0]}\n"
        "for p in ['leakpath', 'reynoldsflow', 'numpy', 'scipy', 'pyamg', 'numba',"
        " 'scikit-image', 'pypardiso', 'mkl', 'scikit-sparse']:\n"
        "    try: out[p] = m.version(p)\n"
        "    except Exception: pass\n"
        "try:\n"
        "    import petsc4py; petsc4py.init(); from petsc4py import PETSc\n"
        "    out['petsc4py'] = petsc4py.__version__\n"
        "    out['PETSc'] = '.'.join(map(str, PETSc.Sys.getVersion()))\n"
        "except Exception: pass\n"
        "print(json.dumps(out))\n"
    )
    out = {}
    for label, py in [("benchmark env", python), ("PETSc env", petsc_python)]:
        if not py:
            continue
        r = subprocess.run([py, "-c", code], capture_output=True, text=True, env=env(1))
        try:
            out[label] = ", ".join(f"{k} {v}" for k, v in json.loads(r.stdout).items())
        except json.JSONDecodeError:
            out[label] = f"? ({r.stderr.strip()[-200:]})"
    return out


def env(threads: int) -> dict[str, str]:
    e = dict(os.environ)
    pp = str(ROOT / "python")
    e["PYTHONPATH"] = pp + (os.pathsep + e["PYTHONPATH"] if e.get("PYTHONPATH") else "")
    for k in ["RAYON_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
              "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"]:
        e[k] = str(threads)
    e.setdefault("NUMBA_CACHE_DIR", "/tmp/peers_numba_cache")
    return e


def child(python: str, code: str, solver: str, path: Path, threads: int,
          timeout: float, calls: int = 1) -> dict:
    t0 = time.perf_counter()
    try:
        r = subprocess.run([python, "-c", CHILD, code, solver, str(path), str(calls)],
                           capture_output=True, text=True, env=env(threads), timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"timeout after {timeout:.0f} s"}
    for line in r.stdout.splitlines():
        if line.startswith("RESULT "):
            out = json.loads(line[7:])
            out["wall"] = time.perf_counter() - t0
            return out
    return {"error": f"exit {r.returncode}: {r.stderr.strip()[-300:]}"}


def available(python: str, module: str) -> bool:
    r = subprocess.run([python, "-c", f"import {module}"], capture_output=True, env=env(1))
    return r.returncode == 0


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def main() -> None:
    signal.signal(signal.SIGTERM, _interrupt)  # a stopped run still writes what it measured
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[257, 513, 1025, 2049])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--calls", type=int, default=1,
                    help="timed calls per child on the same gap: the first is the table's "
                    "'median s', the median of the others its 'repeat call s' (a sweep's "
                    "later calls, the process's memory already in use)")
    ap.add_argument("--only", nargs="+", default=None,
                    help="run only these methods, e.g. leakpath:auto reynoldsflow:pardiso")
    ap.add_argument("--skip", nargs="+", default=[],
                    help="leave out these methods (same names as --only)")
    ap.add_argument("--separation", default="1.01", help="the cached gaps' separation tag")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/lp_gaps"))
    ap.add_argument("--python", default=sys.executable,
                    help="interpreter with leakpath's deps and reynoldsflow")
    ap.add_argument("--petsc-python", default="/work/benchvenv-peers-petsc/bin/python",
                    help="interpreter with reynoldsflow and petsc4py ('' to skip PETSc)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=900.0, help="per child, s")
    ap.add_argument("--single-above", type=float, default=60.0,
                    help="a solve slower than this (s) is not repeated")
    ap.add_argument("--growth", type=float, default=6.0,
                    help="a method is skipped at the next size when its time there times "
                         "this factor exceeds --timeout")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks/results/peers_flow.md")
    a = ap.parse_args()
    if a.calls < 1:
        ap.error("--calls must be at least 1")

    petsc_py = a.petsc_python if a.petsc_python and Path(a.petsc_python).exists() else None
    methods: list[tuple[str, str, str]] = [("leakpath", s, a.python) for s in LEAKPATH]
    for s in PEERS:
        py = petsc_py if s.startswith("petsc") else a.python
        mod = "petsc4py" if s.startswith("petsc") else PEER_MODULE.get(s)
        if py is None or (mod and not available(py, mod)):
            print(f"reynoldsflow:{s}: not available ({mod}), skipped", flush=True)
            continue
        methods.append(("reynoldsflow", s, py))
    if a.only:
        methods = [m for m in methods if f"{m[0]}:{m[1]}" in a.only]
    methods = [m for m in methods if f"{m[0]}:{m[1]}" not in a.skip]

    load_before = loadavg()
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    rows = []
    note = ""
    try:
        measure_all(a, methods, rows)
    except KeyboardInterrupt:
        note = "interrupted: sizes and solvers after the last row were not measured"
    write(a, rows, started, load_before, loadavg(), petsc_py, note)


def measure_all(a, methods, rows) -> None:
    last: dict[str, float] = {}  # method -> median s at the previous size
    for n in sorted(a.sizes):
        path = a.cache / f"spectral_{n}_{a.separation}.npz"
        if not path.exists():
            print(f"{path} missing: run benchmarks/flow_gaps.py --sizes {n}", flush=True)
            continue
        base = child(a.python, "leakpath", "load", path, a.threads, a.timeout)
        base_mib = base.get("vmhwm_kib", 0) / 1024
        # Round-robin: every method's k-th run before any method's (k+1)-th, so that the
        # medians of a ratio come from the same stretch of time on a shared machine.
        live: list[tuple[str, str, str]] = []
        for code, solver, py in methods:
            key = f"{code}:{solver}"
            if key in last and last[key] * a.growth > a.timeout:
                rows.append(dict(n=n, code=code, solver=solver, base_mib=base_mib, runs=0,
                                 error=f"skipped: {last[key]:.0f} s at the previous size, "
                                 f"projected above the {a.timeout:.0f} s timeout"))
                print(n, key, "skipped", flush=True)
                continue
            live.append((code, solver, py))
        runs: dict[tuple[str, str, str], list[dict]] = {m: [] for m in live}
        done: set[tuple[str, str, str]] = set()
        try:
            for k in range(a.repeats):
                for m in live:
                    if m in done:
                        continue
                    code, solver, py = m
                    r = child(py, code, solver, path, a.threads, a.timeout, a.calls)
                    runs[m].append(r)
                    print(n, code, solver, json.dumps(r), flush=True)
                    if "error" in r or (k == 0 and r["seconds"] > a.single_above):
                        done.add(m)
        finally:
            # Also when interrupted: the runs made so far are written.
            add_rows(n, base_mib, runs, last, rows)


def add_rows(n: int, base_mib: float, runs: dict, last: dict, rows: list) -> None:
    """One row per method with at least one run: medians over its runs at size ``n``."""
    for m, mruns in runs.items():
        if not mruns:
            continue
        code, solver, _ = m
        key = f"{code}:{solver}"
        ok = [r for r in mruns if "error" not in r]
        row = dict(n=n, code=code, solver=solver, base_mib=base_mib, runs=len(mruns))
        if ok:
            row.update(
                seconds=statistics.median(r["seconds"] for r in ok),
                peak_mib=statistics.median(r["vmhwm_kib"] for r in ok) / 1024,
                warm_mib=statistics.median(r.get("warm_kib", 0) for r in ok) / 1024,
                Q=ok[0]["Q"], unknowns=ok[0]["unknowns"], ran=ok[0].get("ran", ""),
                inout=(abs(ok[0]["Q"] - ok[0]["Q_in"]) / ok[0]["Q"] if "Q_in" in ok[0]
                       else ok[0].get("conservation")),
                iterations=ok[0].get("iterations"), ok=len(ok),
            )
            again = [r["repeat_seconds"] for r in ok if "repeat_seconds" in r]
            if again:
                row["repeat_seconds"] = statistics.median(again)
            last[key] = row["seconds"]
        if len(ok) < len(mruns):
            row["error"] = [r for r in mruns if "error" in r][0]["error"]
        rows.append(row)


def fmt_e(x: float | None) -> str:
    return "—" if x is None else f"{x:.1e}"


def fmt_q(q: float | None, ref: float | None) -> str:
    if q is None or not ref:
        return "—"
    return f"{abs(q - ref) / ref:.1e}"


def write(a, rows, started, load_before, load_after, petsc_py, note="") -> None:
    repeat = a.calls > 1
    lines = [
        f"\n## Run of {started}\n",
        f"- command: `{' '.join([Path(sys.executable).name] + sys.argv)}`",
        f"- machine: {machine()}; **shared with other jobs** (load average before "
        f"{load_before}, after {load_after}): absolute times are noisy, ratios less so",
        f"- threads per solve: {a.threads}; medians of {a.repeats} child processes, run "
        f"round-robin across the methods (one child when the first took over "
        f"{a.single_above:g} s: column 'runs')",
    ] + ([f"- timed calls per child: {a.calls}, on the same gap: 'median s' is each child's "
          f"first call, 'repeat s' the median over children of the median of its later "
          f"calls (a sweep's calls after the first, the process's memory already in use)"]
         if repeat else []) + ([f"- **{note}**"] if note else [])
    for k, v in versions(a.python, petsc_py).items():
        lines.append(f"- {k}: {v}")
    lines += [
        "- gaps: `" + f"{a.cache}/spectral_N_{a.separation}.npz" + "` (benchmarks/flow_gaps.py)",
        "",
        "| size | unknowns | code | solver | runs | median s | " + ("repeat s | " if repeat else "")
        + "peak MiB | Q | Q rel. diff vs leakpath auto | inlet/outlet rel. diff |",
        "|---|---|---|---|---|---|" + ("---|" if repeat else "") + "---|---|---|---|",
    ]
    by_n: dict[int, list[dict]] = {}
    for r in rows:
        by_n.setdefault(r["n"], []).append(r)
    for n, rs in by_n.items():
        ref = next((r.get("Q") for r in rs
                    if r["code"] == "leakpath" and r["solver"] == "auto"), None)
        for r in rs:
            name = r["solver"] + (f" ({r['ran']})" if r["code"] == "leakpath"
                                  and r["solver"] == "auto" and r.get("ran") else "")
            if "seconds" in r:
                again = f"| {r['repeat_seconds']:.3f} " if "repeat_seconds" in r else "| — "
                lines.append(
                    f"| {n}² | {r['unknowns']} | {r['code']} | {name} | {r['ok']} "
                    f"| {r['seconds']:.3f} " + (again if repeat else "")
                    + f"| {r['peak_mib']:.0f} | {r['Q']:.10e} | {fmt_q(r['Q'], ref)} "
                    f"| {fmt_e(r.get('inout'))} |"
                )
            else:
                lines.append(f"| {n}² | — | {r['code']} | {name} | {r['runs']} | "
                             f"{r.get('error', '?')[:120]} | " + ("— | " if repeat else "")
                             + "— | — | — | — |")
    lines += ["", "Best of each code per size (median s; ratio = peer best / leakpath best, "
              "> 1: leakpath faster):", "",
              "| size | leakpath best | s | ReynoldsFlow best | s | ratio |"
              + (" leakpath best, repeat s | ReynoldsFlow best, repeat s | repeat ratio |"
                 if repeat else ""),
              "|---|---|---|---|---|---|" + ("---|---|---|" if repeat else "")]
    for n, rs in by_n.items():
        lp = [r for r in rs if r["code"] == "leakpath" and "seconds" in r
              and "@" not in r["solver"]]
        pe = [r for r in rs if r["code"] == "reynoldsflow" and "seconds" in r]
        if lp and pe:
            b1 = min(lp, key=lambda r: r["seconds"])
            b2 = min(pe, key=lambda r: r["seconds"])
            line = (f"| {n}² | {b1['solver']} | {b1['seconds']:.3f} | {b2['solver']} | "
                    f"{b2['seconds']:.3f} | {b2['seconds'] / b1['seconds']:.2f} |")
            lr = [r for r in lp if "repeat_seconds" in r]
            pr = [r for r in pe if "repeat_seconds" in r]
            if repeat and lr and pr:
                c1 = min(lr, key=lambda r: r["repeat_seconds"])
                c2 = min(pr, key=lambda r: r["repeat_seconds"])
                line += (f" {c1['solver']} {c1['repeat_seconds']:.3f} | {c2['solver']} "
                         f"{c2['repeat_seconds']:.3f} | "
                         f"{c2['repeat_seconds'] / c1['repeat_seconds']:.2f} |")
            elif repeat:
                line += " — | — | — |"
            lines.append(line)
    swept = [(n, r, min((p for p in rs if p["code"] == "reynoldsflow" and "seconds" in p),
                        key=lambda p: p["seconds"], default=None))
             for n, rs in by_n.items() for r in rs
             if r["code"] == "leakpath" and "@" in r["solver"] and "seconds" in r]
    swept = [(n, r, p) for n, r, p in swept if p is not None]
    if swept:
        lines += ["", "leakpath at another rate tolerance (`SOLVER@TOL`; a sweep's levels pass "
                  "tol = 1e-9), against the same ReynoldsFlow best:", "",
                  "| size | leakpath | s | ratio |"
                  + (" repeat s | repeat ratio |" if repeat else ""),
                  "|---|---|---|---|" + ("---|---|" if repeat else "")]
        for n, r, p in swept:
            line = (f"| {n}² | {r['solver']} | {r['seconds']:.3f} | "
                    f"{p['seconds'] / r['seconds']:.2f} |")
            # The peer's best later calls, as in the best-of table (not its best first call's).
            pr = min((q for q in by_n[n] if q["code"] == "reynoldsflow"
                      and "repeat_seconds" in q), key=lambda q: q["repeat_seconds"],
                     default=None)
            if repeat and "repeat_seconds" in r and pr is not None:
                line += (f" {r['repeat_seconds']:.3f} | "
                         f"{pr['repeat_seconds'] / r['repeat_seconds']:.2f} |")
            elif repeat:
                line += " — | — |"
            lines.append(line)
    lines += ["", "Memory (MiB, median peak resident set of the child; baseline = a child "
              "that imports leakpath and numpy and loads the gap; 'after warm-up' = the "
              "peak before the timed call, imports and library state included):", "",
              "| size | code | solver | baseline | after warm-up | peak | peak − after "
              "warm-up |", "|---|---|---|---|---|---|---|"]
    for n, rs in by_n.items():
        for r in rs:
            if "seconds" in r:
                lines.append(
                    f"| {n}² | {r['code']} | {r['solver']} | {r['base_mib']:.0f} | "
                    f"{r['warm_mib']:.0f} | {r['peak_mib']:.0f} | "
                    f"{r['peak_mib'] - r['warm_mib']:.0f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if not a.out.exists():
        a.out.write_text("# Leak rate: leakpath and ReynoldsFlow side by side\n\n"
                         "Written by `benchmarks/peers_flow.py` (its docstring gives the "
                         "problem, the mapping of conventions and what is timed). Runs are "
                         "appended.\n")
    with a.out.open("a") as f:
        f.write(text)


if __name__ == "__main__":
    main()
