"""Large-grid elastic contact: displacement vs load control, FFT products, time and memory.

Surface: ``leakpath.rmd(m, 2.2, seed=0)`` on ``(2^m + 1)²`` nodes, free boundary (``--boundary
periodic`` for the periodic one), Polonsky–Keer
(``solver="polonsky-keer"``, preconditioned, coarse start, chord steps: the defaults) at KKT
tolerance ``--tol`` (default 1e-8, relative to the height range). For each size and each
approach ``Δ = f · h_s`` (``f`` from ``--deltas``; ``h_s`` from ``--hs``: ``range``, the
default, is leakpath's height range ``max h − min h`` (docs/conventions.md), ``rms`` the rms
height, about a sixth of it on these surfaces, so the same ``f`` is a much lighter load):

* displacement control at ``Δ`` (``displacement``: the default, rescaled load steps from the
  coarse start; ``plain``: ``rescaled_steps=False``, the plain displacement-controlled steps,
  docs/conventions.md "Rescaled load steps");
* load control at the mean pressure ``p̄`` the displacement solve returned (the same contact
  state), so the two times compare like for like.

With ``--fft-reference`` each worker also times numpy's ``rfft2`` + ``irfft2`` of a real field
on the fine product's FFT grid (``2n − 2`` per side free, ``n`` periodic; median of 5, after
the solves and the peak-memory reading) and reports the solve's median time in those round
trips.

Every (size, Δ, control) runs in a fresh Python process (its peak RSS is that solve's, plus the
surface and the problem); the time is the median of ``--repeats`` solves on one problem
(the problem's kernel and operator are built once, outside the timing). FFT products are
counted in products of the padded fine grid: ``fft_products`` of the fine solve plus the coarse
levels' ``fft_products_fine_equivalent`` (``Σ products · N_level / N``). The preconditioner's
FFT pairs (on the unpadded grid rounded up to a 2,3,5-smooth size ``P``) are counted apart:
``preconditioner_products`` (fine + coarse levels' fine equivalent) and their share of a fine
product by transform size, ``pre_fine_eq = preconditioner_products · P_y P_x / (F_y F_x)``
(``F`` the fine product's FFT grid: ``2n − 2`` per side for the free boundary, ``n`` for the
periodic one), so that ``products + pre_fine_eq`` counts every FFT pair of the solve.

Run: ``python benchmarks/contact_scale_bench.py --sizes 1025 2049 --deltas 0.1 0.3 0.6
--repeats 3 [--out benchmarks/results/contact_scale_after.json]``. Prints one row per
solve and, with ``--out``, writes the rows as JSON lines.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time

import numpy as np


def smooth_size(n: int) -> int:
    """Smallest 2,3,5-smooth integer ≥ n (the preconditioner's FFT size)."""
    m = n
    while True:
        k = m
        for f in (2, 3, 5):
            while k % f == 0:
                k //= f
        if k == 1:
            return m
        m += 1


def worker(
    n: int,
    frac: float,
    control: str,
    pbar: float | None,
    repeats: int,
    tol: float,
    hs_kind: str,
    boundary: str = "free",
    fft_reference: bool = False,
) -> dict:
    import leakpath
    from leakpath import _core

    m = int(round(np.log2(n - 1)))
    s = leakpath.rmd(m, 2.2, seed=0)
    h = np.ascontiguousarray(s.heights, dtype=np.float64)
    if hs_kind == "rms":
        hs = float(np.sqrt(((h - h.mean()) ** 2).mean()))
    else:
        hs = float(h.max() - h.min())
    prob = _core.ContactProblem(h, s.dx, 1.0, boundary)
    times = []
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        if control in ("displacement", "plain"):
            out = prob.solve(
                approach=frac * hs,
                solver="polonsky-keer",
                tol=tol,
                rescaled_steps=control == "displacement",
            )
        else:
            out = prob.solve(mean_pressure=pbar, solver="polonsky-keer", tol=tol)
        times.append(time.perf_counter() - t0)
    assert out is not None
    rss_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    seconds = statistics.median(times)
    fft_side = 2 * n - 2 if boundary == "free" else n
    pre_total = out.preconditioner_products + out.coarse.preconditioner_products_fine_equivalent
    round_trip = None
    if fft_reference:
        field = np.random.default_rng(0).standard_normal((fft_side, fft_side))
        trips = []
        for _ in range(5):
            t0 = time.perf_counter()
            np.fft.irfft2(np.fft.rfft2(field), s=field.shape)
            trips.append(time.perf_counter() - t0)
        round_trip = statistics.median(trips)
        del field
    return {
        "size": n,
        "boundary": boundary,
        "delta_over_hs": frac,
        "hs": hs_kind,
        "control": control,
        "seconds_median": seconds,
        "seconds_all": times,
        "iterations": out.iterations,
        "chord_steps": out.chord_steps,
        "fft_products": out.fft_products,
        "coarse_fft_products_fine_eq": out.coarse.fft_products_fine_equivalent,
        "products_fine_total": out.fft_products + out.coarse.fft_products_fine_equivalent,
        "preconditioner_products": out.preconditioner_products,
        "preconditioner_products_total": pre_total,
        "pre_fine_eq": pre_total * smooth_size(n) ** 2 / fft_side**2,
        "contact_fraction": out.contact_points / h.size,
        "mean_pressure": out.mean_pressure,
        "approach_over_hs": out.approach / hs,
        "kkt": out.kkt,
        "peak_rss_gib": rss_kib / 2**20,
        "numpy_round_trip_s": round_trip,
        "solve_in_round_trips": None if round_trip is None else seconds / round_trip,
    }


def machine() -> str:
    import leakpath

    load = os.getloadavg()
    return (
        f"{platform.node()} {platform.machine()}, {os.cpu_count()} cores (shared), "
        f"load average {load[0]:.2f}/{load[1]:.2f}/{load[2]:.2f}, Python "
        f"{platform.python_version()}, numpy {np.__version__}, leakpath "
        f"{getattr(leakpath, '__version__', '?')}, solver threads "
        f"{leakpath._core.solver_threads()}"
    )


def run_one(args, n: int, frac: float, control: str, pbar: float | None) -> dict:
    cmd = [
        sys.executable,
        __file__,
        "--worker",
        json.dumps(
            [
                n,
                frac,
                control,
                pbar,
                args.repeats,
                args.tol,
                args.hs,
                args.boundary,
                args.fft_reference,
            ]
        ),
    ]
    res = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if res.returncode != 0:
        return {"size": n, "delta_over_hs": frac, "control": control, "error": res.stderr[-2000:]}
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1025, 2049])
    ap.add_argument("--deltas", type=float, nargs="+", default=[0.1, 0.3, 0.6])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tol", type=float, default=1e-8)
    ap.add_argument("--hs", choices=["range", "rms"], default="range")
    ap.add_argument("--boundary", choices=["free", "periodic"], default="free")
    ap.add_argument(
        "--controls",
        nargs="+",
        default=["displacement", "load"],
        choices=["displacement", "plain", "load"],
    )
    ap.add_argument(
        "--fft-reference",
        action="store_true",
        help="also time numpy rfft2 + irfft2 on the fine FFT grid (solve time in round trips)",
    )
    ap.add_argument("--out", type=str, default=None, help="append JSON lines here")
    ap.add_argument("--worker", type=str, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker is not None:
        print(json.dumps(worker(*json.loads(args.worker))))
        return
    print(f"# {machine()}; h_s = {args.hs}; boundary = {args.boundary}", flush=True)
    print(
        "# size | Δ/h_s | control | s (median) | iterations (chord) | products fine + coarse "
        "= total [fine product FFT grid] | preconditioner pairs (fine-product equivalent) "
        "| contact fraction | peak RSS [GiB]",
        flush=True,
    )
    for n in args.sizes:
        for frac in args.deltas:
            pbar = None
            for control in args.controls:
                if control == "load" and pbar is None:
                    d = run_one(args, n, frac, "displacement", None)
                    pbar = d.get("mean_pressure")
                row = run_one(args, n, frac, control, pbar)
                row["machine"] = machine()
                if "error" in row:
                    print(f"{n} | {frac} | {control} | ERROR {row['error']}", flush=True)
                else:
                    if control in ("displacement", "plain"):
                        pbar = row["mean_pressure"]
                    trips = ""
                    if row.get("numpy_round_trip_s") is not None:
                        trips = (
                            f" | numpy round trip {row['numpy_round_trip_s']:.3f} s, solve = "
                            f"{row['solve_in_round_trips']:.1f} round trips"
                        )
                    print(
                        f"{n} | {frac} | {control} | {row['seconds_median']:.2f} s | "
                        f"{row['iterations']} ({row['chord_steps']}) | {row['fft_products']} + "
                        f"{row['coarse_fft_products_fine_eq']:.1f} = "
                        f"{row['products_fine_total']:.1f} | "
                        f"{row['preconditioner_products_total']:.1f} ({row['pre_fine_eq']:.1f}) | "
                        f"{row['contact_fraction']:.4f} | "
                        f"{row['peak_rss_gib']:.2f}{trips}",
                        flush=True,
                    )
                if args.out:
                    with open(args.out, "a") as f:
                        f.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
