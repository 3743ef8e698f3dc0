"""Large grids: leakpath's Polonsky–Keer solver against ContactMechanics and Tamaas.

Same surface, same tolerance, side by side in one run, medians of repeats:

1. free boundary, displacement control, a self-affine surface (H = 0.9, unit rms height) at
   257², 513², 1025², approaches 0.1, 0.3, 0.6 of the height range: leakpath
   (``solver="polonsky-keer"``) vs ContactMechanics ``FreeFFTElasticHalfSpace`` with
   ``make_system(...).minimize_proxy(offset=Δ − max h, pentol=tol·h_s)``; contact fraction
   and free volume compared;
2. periodic, load control at the mean pressure of leakpath's Δ = 0.3·(max h − mean h) state,
   1024² and 2048²: leakpath vs ContactMechanics ``PeriodicFFTElasticHalfSpace`` and Tamaas
   ``PolonskyKeerRey``;
3. 4097² free boundary, one approach: time and peak memory (fresh process);
4. time per iteration against N, 129² … 4097².

The competitors are installed into the benchmark environment only:
``pip install contactmechanics==1.8.3 tamaas`` — they are not leakpath dependencies; a
missing one is skipped. Run: ``python benchmarks/large_grid_bench.py [--quick]``.
Writes ``benchmarks/results/large_grids.md``.
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
from leakpath import _core

RESULTS = Path(__file__).parent / "results"
TOL = 1e-8  # relative to the height range, for every solver


def self_affine(n: int, seed: int = 0) -> np.ndarray:
    """Self-affine heights, H = 0.9, unit rms height, on n × n (leakpath's spectral generator)."""
    return leakpath.spectral(n, 0.9, seed=seed, rms_height=1.0).heights


def leakpath_pk(h, approach=None, mean_pressure=None, boundary="free"):
    t0 = time.perf_counter()
    # The whole call a user makes: the problem (kernel, operator) and one Polonsky–Keer solve.
    prob = _core.ContactProblem(h, 1.0, 1.0, boundary)
    out = prob.solve(
        approach=approach, mean_pressure=mean_pressure, solver="polonsky-keer", tol=TOL
    )
    dt = time.perf_counter() - t0
    return dt, out


def cm_free(h, approach):
    from ContactMechanics import FreeFFTElasticHalfSpace, make_system
    from SurfaceTopography import Topography

    ny, nx = h.shape
    topo = Topography(h, physical_sizes=(float(ny), float(nx)))
    sub = FreeFFTElasticHalfSpace((ny, nx), young=1.0, physical_sizes=(float(ny), float(nx)))
    system = make_system(substrate=sub, surface=topo)
    hs = h.max() - h.min()
    t0 = time.perf_counter()
    res = system.minimize_proxy(offset=approach - h.max(), pentol=TOL * hs, maxiter=100000)
    dt = time.perf_counter() - t0
    forces = res.jac[:ny, :nx]
    disp = res.x[:ny, :nx]
    gap = disp - (h + approach - h.max())
    return dt, {"contact_fraction": np.count_nonzero(forces > 0) / h.size, "free_volume": gap.sum()}


def cm_periodic(h, mean_pressure):
    from ContactMechanics import PeriodicFFTElasticHalfSpace, make_system
    from SurfaceTopography import Topography

    ny, nx = h.shape
    topo = Topography(h, physical_sizes=(float(ny), float(nx)))
    sub = PeriodicFFTElasticHalfSpace(
        (ny, nx), young=1.0, physical_sizes=(float(ny), float(nx)), stiffness_q0=0.0
    )
    system = make_system(substrate=sub, surface=topo)
    hs = h.max() - h.min()
    t0 = time.perf_counter()
    res = system.minimize_proxy(
        external_force=mean_pressure * h.size, pentol=TOL * hs, maxiter=100000
    )
    dt = time.perf_counter() - t0
    return dt, {"contact_fraction": np.count_nonzero(res.jac > 0) / h.size}


def tamaas_periodic(h, mean_pressure):
    import tamaas as tm

    ny, nx = h.shape
    model = tm.ModelFactory.createModel(tm.model_type.basic_2d, [float(ny), float(nx)], [ny, nx])
    model.E = 1.0
    model.nu = 0.0
    solver = tm.PolonskyKeerRey(
        model,
        np.ascontiguousarray(h),
        TOL,
        tm.PolonskyKeerRey.pressure,
        tm.PolonskyKeerRey.pressure,
    )
    t0 = time.perf_counter()
    solver.solve(mean_pressure)
    dt = time.perf_counter() - t0
    p = np.asarray(model.traction).reshape(ny, nx)
    return dt, {"contact_fraction": np.count_nonzero(p > 0) / h.size}


def available(mod: str) -> bool:
    try:
        __import__(mod)
        return True
    except Exception:
        return False


def median_time(fn, repeats):
    times, out = [], None
    for _ in range(repeats):
        t, out = fn()
        times.append(t)
    return statistics.median(times), out


def machine() -> str:
    cpu = "unknown"
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    vers = [f"leakpath {leakpath.__version__}", f"numpy {np.__version__}"]
    for mod in ("ContactMechanics", "tamaas"):
        if available(mod):
            vers.append(f"{mod} {__import__(mod).__version__}")
    return (
        f"{platform.platform()}; {cpu}; {os.cpu_count()} cores; Python "
        f"{platform.python_version()}; " + ", ".join(vers)
    )


def peak_4097() -> dict:
    code = (
        "import json, resource, time, leakpath\n"
        "from leakpath import _core\n"
        "h = leakpath.rmd(12, 2.1, seed=0).heights\n"
        "hs = h.max() - h.min()\n"
        "t = time.perf_counter()\n"
        "out = _core.ContactProblem(h, 1.0, 1.0, 'free').solve(\n"
        f"    approach=0.3 * hs, solver='polonsky-keer', tol={TOL})\n"
        "t = time.perf_counter() - t\n"
        "print(json.dumps({'seconds': t, 'iterations': out.iterations,"
        " 'contact_fraction': out.contact_points / h.size,"
        " 'peak_MiB': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    if res.returncode:
        return {"error": res.stderr.strip().splitlines()[-1]}
    return json.loads(res.stdout)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="smaller sizes, for a smoke test")
    args = ap.parse_args()
    rep = args.repeats
    lines = [
        "# Large grids: Polonsky–Keer",
        "",
        f"Machine: {machine()}",
        "",
        f"Tolerance: {TOL:g} × h_s for every solver.",
        "",
        f"Load average at the start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}",
        "",
    ]

    sizes = (65, 129) if args.quick else (257, 513, 1025)
    lines += [
        "## Free boundary, displacement control (H = 0.9, unit rms height)",
        "",
        "| grid | Δ/h_s | leakpath | ContactMechanics | speed-up | contact fraction (lp / CM)"
        " | rel. diff free volume |",
        "|---|---|---|---|---|---|---|",
    ]
    for n in sizes:
        h = self_affine(n)
        hs = h.max() - h.min()
        for frac in (0.1, 0.3, 0.6):
            a = frac * hs
            t_lp, o_lp = median_time(lambda h=h, a=a: leakpath_pk(h, approach=a), rep)
            a_lp = o_lp.contact_points / h.size
            v_lp = float(o_lp.gap.sum())
            if available("ContactMechanics"):
                t_cm, o_cm = median_time(lambda h=h, a=a: cm_free(h, a), 1 if n > 513 else rep)
                row = (
                    f"| {n}² | {frac} | {t_lp:.2f} s | {t_cm:.2f} s | {t_cm / t_lp:.1f}× |"
                    f" {a_lp:.6f} / {o_cm['contact_fraction']:.6f} |"
                    f" {abs(v_lp - o_cm['free_volume']) / abs(o_cm['free_volume']):.1e} |"
                )
            else:
                row = f"| {n}² | {frac} | {t_lp:.2f} s | — | — | {a_lp:.6f} | — |"
            print(row, flush=True)
            lines.append(row)

    psizes = (128, 256) if args.quick else (1024, 2048)
    lines += [
        "",
        "## Periodic, load control (mean pressure of the Δ = 0.3·(max h − mean h) state)",
        "",
        "| grid | leakpath | ContactMechanics | Tamaas | speed-up vs faster | contact fraction"
        " (lp / CM / Tamaas) |",
        "|---|---|---|---|---|---|",
    ]
    for n in psizes:
        h = self_affine(n, seed=1)
        limit = h.max() - h.mean()
        _, ref = leakpath_pk(h, approach=0.3 * limit, boundary="periodic")
        pm = float(ref.mean_pressure)
        t_lp, o_lp = median_time(
            lambda h=h, pm=pm: leakpath_pk(h, mean_pressure=pm, boundary="periodic"), rep
        )
        cells = [f"{t_lp:.2f} s"]
        fracs = [f"{o_lp.contact_points / h.size:.6f}"]
        others = []
        for name, fn in (("ContactMechanics", cm_periodic), ("tamaas", tamaas_periodic)):
            if available(name):
                t, o = median_time(lambda h=h, pm=pm, fn=fn: fn(h, pm), rep)
                cells.append(f"{t:.2f} s")
                fracs.append(f"{o['contact_fraction']:.6f}")
                others.append(t)
            else:
                cells.append("—")
                fracs.append("—")
        speed = f"{min(others) / t_lp:.1f}×" if others else "—"
        row = f"| {n}² | {' | '.join(cells)} | {speed} | {' / '.join(fracs)} |"
        print(row, flush=True)
        lines.append(row)

    d: dict = {}
    if not args.quick:
        d = peak_4097()
        lines += ["", "## 4097² free boundary (RMD D = 2.1), Δ = 0.3 h_s, fresh process", ""]
        lines.append("```")
        lines.append(json.dumps(d))
        lines.append("```")
        print(d, flush=True)

    lines += [
        "",
        "## Time per iteration against N (free boundary, Δ = 0.3 h_s; H = 0.9, 4097²: RMD above)",
        "",
        "| grid | N | iterations | time | ms / iteration | ms / iteration / (N log₂ N) × 10⁶ |",
        "|---|---|---|---|---|---|",
    ]
    for n in (129, 257, 513, 1025, 2049) + (() if args.quick else (4097,)):
        N = n * n
        if n == 4097:
            # The fresh-process solve above: the same problem, not solved twice.
            if "error" in d:
                continue
            t, iterations = d["seconds"], d["iterations"]
        else:
            h = self_affine(n)
            hs = h.max() - h.min()
            t, o = leakpath_pk(h, approach=0.3 * hs)
            iterations = o.iterations
        per = 1e3 * t / max(iterations, 1)
        row = (
            f"| {n}² | {N} | {iterations} | {t:.2f} s | {per:.2f} |"
            f" {per / (N * np.log2(N)) * 1e6:.3f} |"
        )
        print(row, flush=True)
        lines.append(row)

    lines += ["", f"Load average at the end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}"]
    RESULTS.mkdir(exist_ok=True)
    out = RESULTS / ("large_grids_quick.md" if args.quick else "large_grids.md")
    tmp = out.with_suffix(".tmp")
    tmp.write_text("\n".join(lines) + "\n")
    os.replace(tmp, out)
    print(f"written {out}")


if __name__ == "__main__":
    main()
