"""The default paths a user gets, side by side with ContactMechanics 1.8.3 in one run.

Sections (``--only`` picks some; each writes its part of ``results/fast_defaults.md``):

``sweep``
    The paper's 20-level sweep (``Δ_k = k·h_s/20``, free boundary) on 129² surfaces: the RMD
    surface of the paper (D = 2.1, seed 0: 31 % contact at ``h_s``) and an RMD surface that
    reaches ≈ 50 % at ``h_s`` (seed 3), both scaled to unit rms height. leakpath's default
    ``sweep(surface, levels=20)`` (solves, percolation along both axes, moments, leak rate:
    the whole table; also without the leak rate) against ContactMechanics
    ``FreeFFTElasticHalfSpace`` + ``minimize_proxy`` at
    tolerance 1e-8·h_s for the 20 solves alone; also leakpath's cold replay
    (``warm_start=False``) and the former default (Polonsky–Keer to 1e-9, then an exact
    active-set finish from its contact set). Exactness: every level of the default sweep is
    re-solved by the exact active set started from the default's contact set; the contact
    sets must be identical.
``threshold``
    Percolation threshold along axis 1 of 5 periodic 256² spectral surfaces (H = 0.8, unit
    rms height): ``percolation_threshold(surface, axis=1, boundary="periodic")`` with its
    defaults against a bisection with ContactMechanics ``PeriodicFFTElasticHalfSpace`` to the
    same bracket width (1e-4·h_s in approach), cold solves, its gaps labelled by leakpath's
    own cluster labelling (tested against scipy.ndimage.label).
``large``
    Free boundary, Δ = 0.1/0.3/0.6 h_s, tolerance 1e-8·h_s: 1025² (spectral H = 0.9, unit rms
    height; ContactMechanics beside it) and 4097² (RMD D = 2.1, each solve in a fresh
    process for its peak memory): Polonsky–Keer before (``precondition=False``, the former
    default iteration) and after (preconditioned), iterations, FFT products (operator
    applications on the padded grid), preconditioner applications (FFT pairs on the unpadded
    grid), time per iteration against the time of one operator application (a forward and an
    inverse real FFT of the padded grid), measured in the same run.
``ensemble``
    ``leakpath ensemble --D 2.1 --m 7 --surfaces 100 --levels 20 --workers 2``: wall time.

Run (benchmark environment with ``pip install contactmechanics==1.8.3``; a missing
ContactMechanics is skipped): ``python benchmarks/fast_defaults_bench.py [--only sweep ...]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# Run as a script: the benchmarks folder is on sys.path.
from large_grid_bench import available, machine  # noqa: E402

import leakpath
from leakpath.contact import ContactProblem

RESULTS = Path(__file__).parent / "results"
OUT = RESULTS / "fast_defaults.md"


def have(mod: str) -> bool:
    return available(mod)


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def unit_rms(s: leakpath.Surface) -> np.ndarray:
    h = s.heights - s.heights.mean()
    return h / np.sqrt(np.mean(h**2))


# ------------------------------------------------------------------ ContactMechanics
def cm_free_system(h):
    from ContactMechanics import FreeFFTElasticHalfSpace, make_system
    from SurfaceTopography import Topography

    ny, nx = h.shape
    topo = Topography(h, physical_sizes=(float(ny), float(nx)))
    sub = FreeFFTElasticHalfSpace((ny, nx), young=1.0, physical_sizes=(float(ny), float(nx)))
    return make_system(substrate=sub, surface=topo)


def cm_free_solve(system, h, approach, tol):
    ny, nx = h.shape
    hs = h.max() - h.min()
    res = system.minimize_proxy(offset=approach - h.max(), pentol=tol * hs, maxiter=100000)
    forces = res.jac[:ny, :nx]
    disp = res.x[:ny, :nx]
    gap = disp - (h + approach - h.max())
    return forces > 0, gap


# ------------------------------------------------------------------ sweep
def leakpath_solves(h, approaches, *, precondition=True):
    """The default warm solve sequence alone, with counters."""
    prob = ContactProblem(h, dx=1.0)
    prev = None
    its = applies = pre = 0
    t0 = time.perf_counter()
    for a in approaches:
        start = {"start": "cold"} if prev is None else {
            "start": "pressure", "initial_pressure": prev}
        out = prob._core.solve(
            approach=a, solver="polonsky-keer", tol=1e-12, precondition=precondition, **start
        )
        prev = out.pressure
        its += out.iterations
        applies += out.fft_products
        pre += out.preconditioner_products
    return time.perf_counter() - t0, its, applies, pre


def section_sweep(repeats: int) -> list[str]:
    lines = ["## The paper's 20-level sweep, 129², free boundary", ""]
    lines.append(
        "Times are medians of "
        f"{repeats} runs. leakpath `sweep()` is the whole default table (20 solves + the Δ = 0 "
        "reference, percolation along both axes, moments, and the leak rate Q, K, K* of "
        "every level: 21 sparse Cholesky flow solves); `flow=False` is the same table without "
        "the leak rate; ContactMechanics is the 20 solves "
        "alone (tolerance 1e-8·h_s, every level from its default start)."
    )
    lines.append("")
    lines.append(
        "| surface | contact at h_s | ContactMechanics 1.8.3 | leakpath `sweep()` default | "
        "speed-up | `sweep(flow=False)` | cold replay (`warm_start=False`) | former default "
        "(PK 1e-9 + active-set "
        "finish) | default solves alone: time, iterations, FFT products, preconditioner "
        "FFTs | same contact sets as the exact solver | max rel. diff. free volume |"
    )
    lines.append("|---|---|---|---|---|---|---|---|---|---|---|")
    for name, s in (
        ("RMD D=2.1 seed 3 (≈ 50 %)", leakpath.rmd(7, 2.1, seed=3)),
        ("RMD D=2.1 seed 0 (the paper's)", leakpath.rmd(7, 2.1, seed=0)),
    ):
        h = unit_rms(s)
        surf = leakpath.Surface(h, 1.0)
        hs = surf.height_range
        approaches = [k * hs / 20 for k in range(21)]
        t_default = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            res = leakpath.sweep(surf, levels=20)
            t_default.append(time.perf_counter() - t0)
        t_noflow = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            leakpath.sweep(surf, levels=20, flow=False)
            t_noflow.append(time.perf_counter() - t0)
        t_cold = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            leakpath.sweep(surf, levels=20, warm_start=False)
            t_cold.append(time.perf_counter() - t0)
        # The former default: Polonsky–Keer to 1e-9, exact active-set finish from its set.
        prob = ContactProblem(surf)
        t0 = time.perf_counter()
        for a in approaches[1:]:
            rough = prob.solve(a, solver="polonsky-keer", tol=1e-9)
            prob.solve(a, solver="active-set", warm_start=rough.contact)
        t_former = time.perf_counter() - t0
        solves = [leakpath_solves(h, approaches[1:]) for _ in range(repeats)]
        t_solves = statistics.median(x[0] for x in solves)
        _, its, applies, pre = solves[0]
        # Exactness against the exact active set, level by level.
        same = True
        worst = 0.0
        for k, a in enumerate(approaches):
            exact = prob.solve(a, solver="active-set", warm_start=res.contact_mask(k))
            same &= bool(np.array_equal(exact.contact, res.contact_mask(k)))
            v = res.rows[k]["free_volume"]
            worst = max(worst, abs(v - exact.free_volume) / exact.free_volume)
        frac = res.rows[-1]["contact_fraction"]
        if have("ContactMechanics"):
            system = cm_free_system(h)
            t_cm = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                for a in approaches[1:]:
                    cm_free_solve(system, h, a, 1e-8)
                t_cm.append(time.perf_counter() - t0)
            cm = statistics.median(t_cm)
            cm_text = f"{cm:.2f} s"
            speed = f"**{cm / statistics.median(t_default):.1f}×**"
        else:
            cm_text, speed = "—", "—"
        lines.append(
            f"| {name} | {frac:.3f} | {cm_text} | {statistics.median(t_default):.3f} s | "
            f"{speed} | {statistics.median(t_noflow):.3f} s | "
            f"{statistics.median(t_cold):.3f} s | {t_former:.2f} s | "
            f"{t_solves:.3f} s, {its}, {applies}, {pre} | {'yes' if same else 'NO'} | "
            f"{worst:.1e} |"
        )
        print(lines[-1], flush=True)
    return lines + [""]


# ------------------------------------------------------------------ threshold
def cm_periodic_threshold(h, atol_rel=1e-4):
    """Bisection on ContactMechanics' offset for the loss of spanning along axis 1."""
    from ContactMechanics import PeriodicFFTElasticHalfSpace, make_system
    from SurfaceTopography import Topography

    ny, nx = h.shape
    topo = Topography(h, physical_sizes=(float(ny), float(nx)))
    sub = PeriodicFFTElasticHalfSpace((ny, nx), young=1.0, physical_sizes=(float(ny), float(nx)))
    system = make_system(substrate=sub, surface=topo)
    hs = h.max() - h.min()

    def solve(a):
        res = system.minimize_proxy(offset=a - h.max(), pentol=1e-8 * hs, maxiter=100000)
        contact = res.jac > 0
        gap = np.where(contact, 0.0, 1.0)
        perc = leakpath.percolation(gap, dx=1.0, axis=1, periodic=True, contact=contact)
        return bool(perc.percolates), contact.mean()

    lo, hi = 0.0, h.max() - h.mean()
    spans_hi, frac_hi = solve(hi)
    solves = 1
    while spans_hi:
        lo, hi = hi, 2 * hi
        spans_hi, frac_hi = solve(hi)
        solves += 1
    while hi - lo > atol_rel * hs:
        mid = 0.5 * (lo + hi)
        sp, fr = solve(mid)
        solves += 1
        if sp:
            lo = mid
        else:
            hi, frac_hi = mid, fr
    return frac_hi, solves


def section_threshold() -> list[str]:
    lines = ["## Percolation threshold, 5 periodic 256² surfaces (spectral H = 0.8), axis 1", ""]
    lines.append(
        "| seed | leakpath default: time, solves, contact fraction | ContactMechanics "
        "bisection: time, solves, contact fraction | speed-up | |Δ fraction| |"
    )
    lines.append("|---|---|---|---|---|")
    ratios = []
    for seed in range(5):
        s = leakpath.spectral(256, 0.8, seed=seed, rms_height=1.0)
        t0 = time.perf_counter()
        res = leakpath.percolation_threshold(s, axis=1, boundary="periodic")
        t_lp = time.perf_counter() - t0
        row = f"| {seed} | {t_lp:.2f} s, {res.solves}, {res.contact_fraction:.5f} |"
        if have("ContactMechanics"):
            t0 = time.perf_counter()
            frac, n = cm_periodic_threshold(np.asarray(s.heights))
            t_cm = time.perf_counter() - t0
            ratios.append(t_cm / t_lp)
            row += (
                f" {t_cm:.2f} s, {n}, {frac:.5f} | **{t_cm / t_lp:.1f}×** | "
                f"{abs(frac - res.contact_fraction):.1e} |"
            )
        else:
            row += " — | — | — |"
        lines.append(row)
        print(row, flush=True)
    if ratios:
        lines.append("")
        lines.append(f"Median speed-up {statistics.median(ratios):.1f}×.")
    return lines + [""]


# ------------------------------------------------------------------ large grids
CHILD = r"""
import json, resource, sys, time
import numpy as np
import leakpath
from leakpath.contact import ContactProblem
n, frac = int(sys.argv[1]), float(sys.argv[2])
pre, coarse = sys.argv[3] == "1", sys.argv[4] == "1"
# The plain variant is the regular Polonsky–Keer iteration: no chord steps either.
chords = pre or coarse
if n == 4097:
    s = leakpath.rmd(12, 2.1, seed=0)
else:
    s = leakpath.spectral(n, 0.9, seed=0, rms_height=1.0)
h = np.ascontiguousarray(s.heights)
prob = ContactProblem(h, dx=1.0)
# The reference product on a field without zero rows (a zero row skips its forward FFT).
p = np.random.default_rng(0).random(h.shape)
prob._core.apply(p)
t0 = time.perf_counter()
for _ in range(3):
    prob._core.apply(p)
t_apply = (time.perf_counter() - t0) / 3
del p
hs = h.max() - h.min()
t0 = time.perf_counter()
out = prob._core.solve(approach=frac * hs, solver="polonsky-keer", tol=1e-8,
                       precondition=pre, coarse_start=coarse, chord_steps=chords)
dt = time.perf_counter() - t0
print(json.dumps({
    "seconds": dt, "iterations": out.iterations, "applies": out.fft_products,
    "chord": out.chord_steps,
    "pre": out.preconditioner_products, "contact_fraction": out.contact_points / h.size,
    "free_volume": float(out.gap.sum()), "apply_ms": t_apply * 1e3,
    "peak_MiB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    "coarse_levels": out.coarse.levels, "coarse_applies": out.coarse.fft_products,
    "coarse_equiv": out.coarse.fft_products_fine_equivalent,
    "coarse_pre": out.coarse.preconditioner_products,
    "coarse_pre_equiv": out.coarse.preconditioner_products_fine_equivalent,
}))
"""


def run_child(n, frac, pre, coarse=False):
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(n), str(frac), "1" if pre else "0",
         "1" if coarse else "0"],
        capture_output=True, text=True, check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def section_large(sizes, variants=("plain", "pre", "coarse")) -> list[str]:
    lines = ["## Free boundary, large grids, tolerance 1e-8·h_s", ""]
    lines.append(
        "plain = Polonsky–Keer without preconditioner, coarse start or chord steps "
        "(`precondition=False, coarse_start=False, chord_steps=False`); pre = preconditioned, "
        "cold start with chord steps (`coarse_start=False`); coarse = the default "
        "(preconditioned, coarse-to-fine start, chord steps while the contact set changes "
        "wholesale). FFT "
        "products = operator applications on the padded fine grid; pairs = preconditioner FFT "
        "pairs on the unpadded grid (smooth-padded). Coarse levels: raw products / pairs over "
        "all levels (each on its own, smaller grid) and their fine-grid equivalents "
        "(Σ count · N_level / N). total = fine products + fine-equivalent coarse products. "
        "raw total = fine products + coarse products, every coarse product counted as one. "
        "ms/it ÷ apply = the whole solve's time (coarse levels included) per fine iteration "
        "over the time of one operator application (forward + inverse real FFT of the padded "
        "grid, on a dense field), same process. A run absent from a row is marked —; "
        "FFT-product counts are deterministic, timings depend on the machine's load (load "
        "average at the row's start and end)."
    )
    lines.append("")
    lines.append(
        "| grid | Δ/h_s | plain: time, its, products | pre: time, its, products, pairs | "
        "coarse: time, its (chord steps), products, pairs | "
        "coarse levels: products, pairs raw (fine-equiv.) "
        "| total products (fine-equiv.) | plain ÷ coarse total | raw total | plain ÷ raw total "
        "| pre ÷ coarse total | ms/it ÷ apply (plain / pre / coarse) | ContactMechanics | "
        "contact fraction (plain / pre / coarse / CM) | peak MiB (plain / coarse) | load at "
        "start / end |"
    )
    lines.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for n in sizes:
        for frac in (0.1, 0.3, 0.6):
            start_load = load()
            b = run_child(n, frac, False, False) if "plain" in variants else None
            a = run_child(n, frac, True, False) if "pre" in variants else None
            c = run_child(n, frac, True, True) if "coarse" in variants else None
            total = c["applies"] + c["coarse_equiv"] if c else None
            raw = c["applies"] + c["coarse_applies"] if c else None

            def per_it(r):
                return r["seconds"] / max(r["iterations"], 1) * 1e3 / r["apply_ms"]

            cm_text, cf_cm = "—", "—"
            if n <= 1025 and have("ContactMechanics"):
                s = leakpath.spectral(n, 0.9, seed=0, rms_height=1.0)
                h = np.ascontiguousarray(s.heights)
                system = cm_free_system(h)
                t0 = time.perf_counter()
                contact, _ = cm_free_solve(system, h, frac * (h.max() - h.min()), 1e-8)
                cm_text = f"{time.perf_counter() - t0:.2f} s"
                cf_cm = f"{contact.mean():.6f}"
            def num(r, key, fmt):
                return format(r[key], fmt) if r else "—"

            def ratio(r):
                return f"{per_it(r):.2f}" if r else "—"

            row = (
                f"| {n}² | {frac} | "
                + (f"{b['seconds']:.2f} s, {b['iterations']}, {b['applies']} | " if b else "— | ")
                + (f"{a['seconds']:.2f} s, {a['iterations']}, {a['applies']}, {a['pre']} | "
                   if a else "— | ")
                + (f"{c['seconds']:.2f} s, {c['iterations']} ({c['chord']}), {c['applies']}, "
                   f"{c['pre']} | "
                   f"{c['coarse_applies']}, {c['coarse_pre']} ({c['coarse_equiv']:.1f}, "
                   f"{c['coarse_pre_equiv']:.1f}) | {total:.1f} | " if c else "— | — | — | ")
                + (f"{b['applies'] / total:.2f}× | " if b and c else "— | ")
                + (f"{raw} | " if c else "— | ")
                + (f"{b['applies'] / raw:.2f}× | " if b and c else "— | ")
                + (f"{a['applies'] / total:.2f}× | " if a and c else "— | ")
                + f"{ratio(b)} / {ratio(a)} / {ratio(c)} | {cm_text} | "
                + f"{num(b, 'contact_fraction', '.6f')} / {num(a, 'contact_fraction', '.6f')} / "
                + f"{num(c, 'contact_fraction', '.6f')} / {cf_cm} | "
                + f"{num(b, 'peak_MiB', '.0f')} / {num(c, 'peak_MiB', '.0f')} | "
                + f"{start_load} / {load()} |"
            )
            lines.append(row)
            print(row, flush=True)
    return lines + [""]


# ------------------------------------------------------------------ ensemble
def section_ensemble() -> list[str]:
    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", "leakpath", "ensemble", "--D", "2.1", "--m", "7",
             "--surfaces", "100", "--levels", "20", "--workers", "2", "--no-figures",
             "--out", str(Path(d) / "e")],
            check=True, capture_output=True,
        )
        dt = time.perf_counter() - t0
    row = (
        "## Ensemble\n\n`leakpath ensemble --D 2.1 --m 7 --surfaces 100 --levels 20 "
        f"--workers 2 --no-figures`: **{dt:.1f} s** wall (100 sweeps of 21 levels, 129²)."
    )
    print(row, flush=True)
    return [row, ""]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", nargs="*", default=["sweep", "threshold", "large", "ensemble"])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--sizes", type=int, nargs="*", default=[1025, 4097])
    ap.add_argument(
        "--variants", nargs="*", default=["plain", "pre", "coarse"],
        help="large: which Polonsky–Keer runs (plain, pre, coarse)",
    )
    args = ap.parse_args()
    parts = ["# Default paths against ContactMechanics", "", f"Machine: {machine()}", ""]
    parts.append(f"Load average at the start: {load()}")
    parts.append("")
    for name in args.only:
        if name == "sweep":
            parts += section_sweep(args.repeats)
        elif name == "threshold":
            parts += section_threshold()
        elif name == "large":
            parts += section_large(args.sizes, args.variants)
        elif name == "ensemble":
            parts += section_ensemble()
    parts.append(f"Load average at the end: {load()}")
    RESULTS.mkdir(exist_ok=True)
    out = OUT if set(args.only) == {"sweep", "threshold", "large", "ensemble"} else (
        RESULTS / f"fast_defaults_{'_'.join(args.only)}.md"
    )
    out.write_text("\n".join(parts) + "\n", encoding="utf-8")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
