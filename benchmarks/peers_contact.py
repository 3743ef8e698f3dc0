"""Free-boundary elastic contact of leakpath side by side with ASPHER.

Run from the repository root::

    PYTHONPATH=python /work/benchvenv-peers/bin/python benchmarks/peers_contact.py \\
        --sizes 256 512 1024 2048 --repeats 3  # appends to benchmarks/results/peers_contact.md

ASPHER (``pip install aspher``, built from its sdist with CMake and Eigen) lives in a
separate benchmark environment, never a leakpath dependency.

Same problem for both codes. Surface: ``leakpath.rmd(m, 2.2, seed=0)`` (``2^m + 1``
points a side, its own ``dx``), cropped to its first ``2^m`` rows and columns because
ASPHER's nested solve needs ``grid_size = coarsest · 2^k`` (``coarsest = 64``); ``--sizes``
names the cropped size ``n = 2^m``. Rigid flat on an elastic half-space with ``E* = 1``
(leakpath ``E = 1, ν = 0``; ASPHER ``E_star = 1``, ``domain_size = n·dx``), the same
Love influence coefficients (uniform pressure on ``dx × dx`` squares, free space: both
evaluate the linear convolution exactly). Initial gap ``max h − h``: ASPHER's gap is
``u + g0 − approach`` and leakpath's ``max h − Δ − h + u``, so the approaches compare
directly. ``h_s`` is leakpath's height scale ``max h − min h`` (docs/conventions.md) unless
``--hs rms``.

Cases per size:

- displacement control ``Δ = 0.1, 0.3, 0.6 h_s`` (leakpath only: ASPHER's normal solver
  takes an imposed mean pressure, ``p_nominal``, and returns the approach);
- load control at the mean pressures ``p̄`` those leakpath solves return, for both codes;
- a light load with about 0.1 % contact: ``p̄ = p̄(0.1 h_s) · 0.001 / a(0.1 h_s)`` (the
  contact fraction grows about linearly with the load at small loads), for both codes.

Tolerance ``--tol`` (default 1e-8) in each code's own measure: leakpath's KKT certificate
relative to ``h_s``; ASPHER's normalised Frank–Wolfe certificate ``fw_error``. Every result
also gets leakpath's KKT measure computed from its returned pressure and gap,
``max(−min g, max_{p>0} |g|, Σ p|g| / Σ p) / h_s`` (column ``KKT/h_s``), so the two are
compared at a common accuracy. The contact fraction is ``p > 0`` on the returned pressure
for both; ``Δa`` and ``rel p̄`` are against leakpath at the same load, ``‖Δp‖`` the relative
L2 difference of the pressure fields.

ASPHER backends: ``h2`` (matrix-free H²/FMM, its default) and ``fft`` (exact zero-padded
convolution) through ``solve_nested`` (its recommended entry point: coarse-to-fine,
spectral preconditioner), double precision; ``hmatrix`` (ACA) through
``ContactSolver(...).solve(..., precond="fourier")`` up to ``--hmatrix-max``. ``dense`` is
for validation on small grids and ``periodic`` is doubly periodic: neither is run.

Each measurement is one child process (the surface loaded from a cache under ``--cache``)
timing the one solve call (operator construction included for both), reporting its peak
resident set (``VmHWM``); medians of ``--repeats`` children. Native threads:
``--threads`` (``RAYON_NUM_THREADS`` for leakpath, ``OMP_NUM_THREADS`` for ASPHER).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
FRACTIONS = [0.1, 0.3, 0.6]

CHILD = r"""
import json, sys, time
import numpy as np
code, spec, path, fields = sys.argv[1], json.loads(sys.argv[2]), sys.argv[3], sys.argv[4]
def hwm():
    return [int(x.split()[1]) for x in open("/proc/self/status") if x.startswith("VmHWM")][0]
d = np.load(path)
h, dx, hs = d["h"], float(d["dx"]), float(d["hs"])
n = h.shape[0]
tol = spec["tol"]
out = dict(base_kib=hwm())
def kkt(p, g):
    pos = p > 0
    s = p.sum()
    return max(-g.min(), np.abs(g[pos]).max() if pos.any() else 0.0,
               (p * np.abs(g)).sum() / s if s > 0 else 0.0) / hs
try:
    if code == "leakpath":
        import leakpath
        kw = dict(approach=spec["approach"]) if "approach" in spec else dict(
            mean_pressure=spec["mean_pressure"])
        t = time.perf_counter()
        st = leakpath.solve(h, E=1.0, nu=0.0, boundary="free", dx=dx, tol=tol, **kw)
        out["seconds"] = time.perf_counter() - t
        p, g = np.asarray(st.pressure), np.asarray(st.gap)
        out.update(approach=st.approach, mean_pressure=float(p.mean()),
                   iterations=st.iterations, own=st.kkt, converged=True)
    else:
        import aspher
        b = spec["backend"]
        g0 = np.ascontiguousarray((h.max() - h).ravel())
        t = time.perf_counter()
        if b == "hmatrix":
            s = aspher.ContactSolver(grid_size=n, domain_size=n * dx, E_star=1.0,
                                     backend="hmatrix")
            r = s.solve(g0, p_nominal=spec["mean_pressure"], tol=tol, precond="fourier")
        else:
            r = aspher.solve_nested(grid_size=n, gap=g0, p_nominal=spec["mean_pressure"],
                                    domain_size=n * dx, E_star=1.0, tol=tol, backend=b)
        out["seconds"] = time.perf_counter() - t
        p, g = np.asarray(r.pressure), np.asarray(r.gap)
        out.update(approach=r.approach, mean_pressure=float(p.mean()),
                   iterations=r.iterations, own=r.fw_error, converged=bool(r.converged),
                   status=r.status)
    out.update(kkt=float(kkt(p, g)), a=float((p > 0).mean()))
    if fields:
        np.save(fields, p)
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


def env(threads: int) -> dict[str, str]:
    e = dict(os.environ)
    pp = str(ROOT / "python")
    e["PYTHONPATH"] = pp + (os.pathsep + e["PYTHONPATH"] if e.get("PYTHONPATH") else "")
    for k in ["RAYON_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
              "OPENBLAS_NUM_THREADS"]:
        e[k] = str(threads)
    return e


def versions(python: str) -> str:
    code = (
        "import importlib.metadata as m, json, sys\n"
        "out = {'python': sys.version.split()[0]}\n"
        "for p in ['leakpath', 'aspher', 'numpy']:\n"
        "    try: out[p] = m.version(p)\n"
        "    except Exception: pass\n"
        "print(json.dumps(out))\n"
    )
    r = subprocess.run([python, "-c", code], capture_output=True, text=True, env=env(1))
    try:
        return ", ".join(f"{k} {v}" for k, v in json.loads(r.stdout).items())
    except json.JSONDecodeError:
        return "?"


def child(python: str, code: str, spec: dict, path: Path, fields: str, threads: int,
          timeout: float) -> dict:
    try:
        r = subprocess.run([python, "-c", CHILD, code, json.dumps(spec), str(path), fields],
                           capture_output=True, text=True, env=env(threads), timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"timeout after {timeout:.0f} s"}
    for line in r.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    return {"error": f"exit {r.returncode}: {r.stderr.strip()[-300:]}"}


def surface(n: int, hs_kind: str, cache: Path) -> Path:
    """The cropped RMD surface of ``n = 2^m`` points a side, cached as .npz."""
    path = cache / f"rmd_{n}_{hs_kind}.npz"
    if not path.exists():
        sys.path.insert(0, str(ROOT / "python"))
        import leakpath

        m = int(round(math.log2(n)))
        if 2**m != n:
            raise SystemExit(f"--sizes: {n} is not a power of two")
        s = leakpath.rmd(m, 2.2, seed=0)
        h = np.ascontiguousarray(s.heights[:n, :n])
        hs = float(h.max() - h.min()) if hs_kind == "range" else float(h.std())
        np.savez(path, h=h, dx=s.dx, hs=float(h.max() - h.min()), scale=hs)
    return path


def measure(a, code, spec, path, fields, label, n) -> dict:
    runs = []
    for k in range(a.repeats):
        r = child(a.python, code, spec, path, fields if k == 0 else "", a.threads, a.timeout)
        runs.append(r)
        print(n, label, json.dumps(r), flush=True)
        if "error" in r or (k == 0 and r["seconds"] > a.single_above):
            break
    ok = [r for r in runs if "error" not in r]
    row = dict(n=n, label=label, code=code, spec=spec, runs=len(runs))
    if ok:
        row.update(ok[0])
        row["seconds"] = statistics.median(r["seconds"] for r in ok)
        row["peak_mib"] = statistics.median(r["vmhwm_kib"] for r in ok) / 1024
        row["ok"] = len(ok)
    else:
        row["error"] = runs[-1]["error"]
    return row


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def main() -> None:
    signal.signal(signal.SIGTERM, _interrupt)  # a stopped run still writes what it measured
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[256, 512, 1024, 2048])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--only", nargs="+", default=None,
                    help="codes/backends to run among: leakpath aspher:h2 aspher:fft "
                         "aspher:hmatrix (leakpath always runs the displacement cases)")
    ap.add_argument("--tol", type=float, default=1e-8)
    ap.add_argument("--hs", choices=["range", "rms"], default="range",
                    help="h_s for the approaches: max h − min h (leakpath's) or rms height")
    ap.add_argument("--hmatrix-max", type=int, default=256)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/peers_contact"))
    ap.add_argument("--python", default=sys.executable)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=1800.0, help="per child, s")
    ap.add_argument("--single-above", type=float, default=30.0,
                    help="a solve slower than this (s) is not repeated")
    ap.add_argument("--out", type=Path,
                    default=ROOT / "benchmarks/results/peers_contact.md")
    a = ap.parse_args()
    a.cache.mkdir(parents=True, exist_ok=True)
    backends = ["h2", "fft", "hmatrix"]
    if a.only:
        backends = [b for b in backends if f"aspher:{b}" in a.only]

    load_before = loadavg()
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    rows = []
    note = ""
    try:
        measure_all(a, backends, rows)
    except KeyboardInterrupt:
        note = "interrupted: cases after the last row were not measured"
    write(a, rows, started, load_before, loadavg(), note)


def measure_all(a, backends, rows) -> None:
    for n in sorted(a.sizes):
        path = surface(n, a.hs, a.cache)
        d = np.load(path)
        scale = float(d["scale"])
        loads = []
        for f in FRACTIONS:
            r = measure(a, "leakpath", dict(approach=f * scale, tol=a.tol), path, "",
                        f"Δ = {f} h_s", n)
            r["case"] = f"Δ = {f} h_s"
            rows.append(r)
            if "error" not in r:
                loads.append((f"p̄(Δ = {f} h_s)", r["mean_pressure"], r["a"]))
        if not loads:
            continue
        light = loads[0][1] * 0.001 / max(loads[0][2], 1e-12)
        loads.insert(0, ("light (~0.1 %)", light, None))
        for case, pbar, _ in loads:
            ref = None
            for code, b in [("leakpath", None)] + [("aspher", b) for b in backends]:
                if code == "leakpath" and a.only and "leakpath" not in a.only:
                    continue
                if b == "hmatrix" and n > a.hmatrix_max:
                    continue
                spec = dict(mean_pressure=pbar, tol=a.tol)
                if b:
                    spec["backend"] = b
                label = "leakpath" if b is None else f"aspher:{b}"
                fields = str(a.cache / f"p_{n}_{label.replace(':', '_')}.npy")
                r = measure(a, code, spec, path, fields, f"{label} {case}", n)
                r["case"], r["label"] = case, label
                if "error" not in r and Path(fields).exists():
                    p = np.load(fields)
                    if ref is None and code == "leakpath":
                        ref = (p, r)
                    elif ref is not None:
                        pr, rr = ref
                        r["dp"] = float(np.linalg.norm(p - pr) / np.linalg.norm(pr))
                        r["da"] = r["a"] - rr["a"]
                        r["dcells"] = int(((p > 0) != (pr > 0)).sum())
                        r["ratio"] = r["seconds"] / rr["seconds"]
                        r["dapp"] = (r["approach"] - rr["approach"]) / scale
                    Path(fields).unlink()
                rows.append(r)


def write(a, rows, started, load_before, load_after, note="") -> None:
    lines = [
        f"\n## Run of {started}\n",
        f"- command: `{' '.join([Path(sys.executable).name] + sys.argv)}`",
        f"- machine: {machine()}; **shared with other jobs** (load average before "
        f"{load_before}, after {load_after}): absolute times are noisy, ratios less so",
        f"- threads per solve: {a.threads}; medians of {a.repeats} child processes (one "
        f"when the first took over {a.single_above:g} s: column 'runs'); "
        f"tolerance {a.tol:g} in each code's own measure; h_s = "
        f"{'max h − min h' if a.hs == 'range' else 'rms height'}",
        f"- versions: {versions(a.python)}",
    ] + ([f"- **{note}**"] if note else []) + [
        "",
        "| size | case | code | runs | median s | peak MiB | iterations | own tol. measure "
        "| KKT/h_s | contact fraction | p̄ | approach/h_s | Δa | cells differing | ‖Δp‖ "
        "| time ratio to leakpath |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        n = r["n"]
        name = r.get("label", "leakpath") if "approach" not in r.get("spec", {}) else \
            "leakpath (displacement control)"
        if "seconds" not in r:
            lines.append(f"| {n}² | {r.get('case', '')} | {name} | {r['runs']} | failed: "
                         f"{r.get('error', '?')[:120]} |" + " — |" * 11)
            continue
        d = np.load(a.cache / f"rmd_{n}_{a.hs}.npz")
        scale = float(d["scale"])
        conv = "" if r.get("converged", True) else f" ({r.get('status', 'not converged')})"
        lines.append(
            f"| {n}² | {r['case']} | {name}{conv} | {r['ok']} | {r['seconds']:.3f} "
            f"| {r['peak_mib']:.0f} "
            f"| {r['iterations']} | {r['own']:.1e} | {r['kkt']:.1e} | {r['a']:.6f} | "
            f"{r['mean_pressure']:.6e} | {r['approach'] / scale:.6f} | "
            + (f"{r['da']:+.1e} | {r['dcells']} | {r['dp']:.1e} | {r['ratio']:.2f} |"
               if "dp" in r else "— | — | — | — |")
        )
    text = "\n".join(lines) + "\n"
    print(text)
    if not a.out.exists():
        a.out.write_text("# Free-boundary contact: leakpath and ASPHER side by side\n\n"
                         "Written by `benchmarks/peers_contact.py` (its docstring gives the "
                         "problem, the mapping of conventions and what is timed). Runs are "
                         "appended. `time ratio to leakpath` = this solve's median time / "
                         "leakpath's at the same load (> 1: leakpath faster).\n")
    with a.out.open("a") as f:
        f.write(text)


if __name__ == "__main__":
    main()
