"""Elastic–perfectly-plastic contact (hardness cap) against ContactMechanics, its cost, and the
leak-rate hysteresis of loading and unloading.

Sections (results in ``benchmarks/results/plastic.md``):

1. agreement with ContactMechanics ``constrained_conjugate_gradients(hardness=)`` on 128²
   spectral surfaces, free and periodic, displacement and load control, three hardnesses:
   max |p − p_CM| / H and whether the plastic sets ``p = H`` are identical;
2. the cost of a capped load-controlled sweep against the elastic one on the same surface;
3. one capped solve at 1025² (free, displacement control) against ContactMechanics;
4. hysteresis: leak rate after unloading to a nominal pressure against the leak rate on
   loading to it, on a seal-like surface; the loading path accumulated level by level
   against each level solved on the original surface.

Run (ContactMechanics from a separate environment):
``PYTHONPATH=python /work/benchvenv-plastic/bin/python benchmarks/plastic_bench.py``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from large_grid_bench import available, machine  # noqa: E402

import leakpath  # noqa: E402
from leakpath._sweep import sweep  # noqa: E402
from leakpath.contact import ContactProblem  # noqa: E402
from leakpath.surfaces import Surface  # noqa: E402

OUT = Path(__file__).parent / "results" / "plastic.md"


def spectral(n: int, seed: int, hurst: float = 0.8) -> np.ndarray:
    """Self-affine heights with unit rms (dx = 1)."""
    rng = np.random.default_rng(seed)
    k = np.hypot(*np.meshgrid(np.fft.fftfreq(n), np.fft.fftfreq(n), indexing="ij"))
    k[0, 0] = 1.0
    filt = k ** (-(1.0 + hurst))
    filt[k < 4.0 / n] = (4.0 / n) ** (-(1.0 + hurst))  # roll-off
    filt[0, 0] = 0.0
    h = np.real(np.fft.ifft2(np.fft.fft2(rng.standard_normal((n, n))) * filt))
    return h / h.std()


# ------------------------------------------------------------------ ContactMechanics
def cm_solve(h, boundary, hardness, *, approach=None, mean_pressure=None, tol=1e-10):
    """ContactMechanics' capped constrained CG, dx = 1, E* = 1 (forces = pressures)."""
    from ContactMechanics import FreeFFTElasticHalfSpace, PeriodicFFTElasticHalfSpace
    from ContactMechanics.Optimization import constrained_conjugate_gradients
    from SurfaceTopography import Topography

    ny, nx = h.shape
    size = (float(ny), float(nx))
    topo = Topography(h, physical_sizes=size)
    cls = FreeFFTElasticHalfSpace if boundary == "free" else PeriodicFFTElasticHalfSpace
    sub = cls((ny, nx), young=1.0, physical_sizes=size)
    hs = h.max() - h.min()
    kw = {"hardness": hardness, "pentol": tol * hs, "forcetol": 1e-10, "maxiter": 100000}
    if mean_pressure is not None:
        kw["external_force"] = mean_pressure * ny * nx
        kw["thermotol"] = 1e-12
    else:
        kw["offset"] = approach - h.max()
    t0 = time.perf_counter()
    res = constrained_conjugate_gradients(sub, topo, **kw)
    sec = time.perf_counter() - t0
    f = np.asarray(res.jac)[:ny, :nx]
    p = -f if f.sum() < 0 else f
    return p, sec, bool(res.success)


def lp_solve(h, boundary, hardness, *, approach=None, mean_pressure=None):
    prob = ContactProblem(Surface(h, 1.0), boundary=boundary, hardness=hardness)
    t0 = time.perf_counter()
    if mean_pressure is not None:
        s = prob.solve(mean_pressure=mean_pressure)
    else:
        s = prob.solve(approach)
    return s, time.perf_counter() - t0


def section_agreement() -> list[str]:
    lines = [
        "## 1. Agreement with ContactMechanics, 128² spectral (H = 0.8) surfaces",
        "",
        "E* = 1, dx = 1, unit rms height. Hardness `H` as a fraction of the largest elastic "
        "pressure of the same control. ContactMechanics `constrained_conjugate_gradients("
        "hardness=H·dx², pentol=1e-10·h_s, forcetol=1e-10, thermotol=1e-12 in load "
        "control)`; leakpath default tolerance "
        "(KKT 1e-12). Plastic set: `p ≥ H` (both solvers set `p = H` exactly there). "
        "Periodic displacement control: the two codes reference the approach of a periodic "
        "surface differently (their elastic solutions at one offset differ by as much), so "
        "ContactMechanics is run at the load of leakpath's displacement-controlled state. "
        "Displacement control at Δ = 0.5 (max h − mean h); load control at p̄ = 0.05 E*.",
        "",
        "| boundary | control | H / p_max,el | plastic fraction | max abs(p − p_CM)/H | plastic "
        "sets identical | contact sets identical | leakpath s | ContactMechanics s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    h = spectral(128, 1)
    for boundary in ("free", "periodic"):
        for control in ("approach", "mean_pressure"):
            if control == "approach":
                kw = {"approach": 0.5 * (h.max() - h.mean())}
            else:
                kw = {"mean_pressure": 0.05}
            el, _ = lp_solve(h, boundary, None, **kw)
            pmax = float(el.pressure.max())
            for frac in (0.25, 0.5, 0.8):
                H = frac * pmax
                s, t_lp = lp_solve(h, boundary, H, **kw)
                if boundary == "periodic" and control == "approach":
                    # The periodic approach is referenced differently (u has zero mean
                    # here; the elastic solutions at one offset differ as much): compare at
                    # the load of the displacement-controlled state.
                    p_cm, t_cm, ok = cm_solve(h, boundary, H, mean_pressure=s.mean_pressure)
                else:
                    p_cm, t_cm, ok = cm_solve(h, boundary, H, **kw)
                diff = float(np.max(np.abs(s.pressure - p_cm)) / H)
                same_pl = bool(np.array_equal(s.pressure >= H, p_cm >= H))
                same_c = bool(np.array_equal(s.pressure > 0, p_cm > 0))
                lines.append(
                    f"| {boundary} | {control} | {frac} | {s.plastic_fraction:.4f} | "
                    f"{diff:.1e} | {'yes' if same_pl else 'no'} | "
                    f"{'yes' if same_c else 'no'} | {t_lp:.3f} | {t_cm:.2f}"
                    f"{'' if ok else ' (not converged)'} |"
                )
                print(lines[-1], flush=True)
    return lines + [""]


def section_cost(repeats: int) -> list[str]:
    n = 257
    h = spectral(n, 2)
    s = Surface(h, 1.0)
    pressures = list(np.geomspace(0.002, 0.05, 10))
    el = ContactProblem(s).solve(mean_pressure=pressures[-1])
    H = 0.5 * float(el.pressure.max())
    rows = []
    for label, kw in (
        ("elastic", {}),
        ("capped", {"hardness": H}),
        ("capped + unloading", {"hardness": H, "unload": True}),
    ):
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            r = sweep(s, mean_pressures=pressures, flow=False, **kw)
            times.append(time.perf_counter() - t0)
        its = int(sum(r.column("iterations")))
        rows.append((label, statistics.median(times), len(r), its))
        print(rows[-1], flush=True)
    base = rows[0][1]
    lines = [
        f"## 2. Cost of a capped sweep, {n}² spectral surface, free, load control",
        "",
        f"10 mean pressures 0.002–0.05 E* (log-spaced), H = {H:.4g} E* (half the largest "
        f"elastic pressure at the top load), `flow=False`; medians of {repeats} runs of the "
        "whole `sweep()`.",
        "",
        "| sweep | rows | median time | ÷ elastic | solver iterations (summed) |",
        "|---|---|---|---|---|",
    ]
    for label, t, nrow, its in rows:
        lines.append(f"| {label} | {nrow} | {t:.2f} s | {t / base:.2f} | {its} |")
    return lines + [""]


def section_large(with_cm: bool, repeats: int) -> list[str]:
    n = 1025
    h = spectral(n, 3)
    approach = 0.3 * (h.max() - h.min())
    runs = [lp_solve(h, "free", None, approach=approach) for _ in range(repeats)]
    el, t_el = runs[0][0], float(np.median([t for _, t in runs]))
    H = 0.5 * float(el.pressure.max())
    runs = [lp_solve(h, "free", H, approach=approach) for _ in range(repeats)]
    s, t_lp = runs[0][0], float(np.median([t for _, t in runs]))
    lines = [
        f"## 3. One capped solve at {n}², free, displacement control",
        "",
        f"Spectral H = 0.8, Δ = 0.3 h_s, hardness H = {H:.4g} E* (half the largest elastic "
        f"pressure); leakpath times are medians of {repeats} runs (each on a new "
        f"`ContactProblem`, set-up included), ContactMechanics one run, in the same process.",
        "",
        "| solver | time | iterations | FFT products | plastic fraction | contact fraction |",
        "|---|---|---|---|---|---|",
        f"| leakpath elastic (reference) | {t_el:.2f} s | {el.iterations} | "
        f"{el.fft_products} | — | {el.contact_fraction:.4f} |",
        f"| leakpath capped | {t_lp:.2f} s | {s.iterations} | {s.fft_products} | "
        f"{s.plastic_fraction:.4f} | {s.contact_fraction:.4f} |",
    ]
    print(lines[-2:], flush=True)
    if with_cm:
        p_cm, t_cm, ok = cm_solve(h, "free", H, approach=approach, tol=1e-8)
        diff = float(np.max(np.abs(s.pressure - p_cm)) / H)
        same = bool(np.array_equal(s.pressure >= H, p_cm >= H))
        lines.append(
            f"| ContactMechanics (pentol 1e-8 h_s) | {t_cm:.2f} s | — | — | "
            f"{np.count_nonzero(p_cm >= H) / p_cm.size:.4f} | "
            f"{np.count_nonzero(p_cm > 0) / p_cm.size:.4f} |"
        )
        lines += [
            "",
            f"Speed-up {t_cm / t_lp:.1f}×; max abs(p − p_CM)/H = {diff:.1e}; plastic sets "
            f"identical: {'yes' if same else 'no'}"
            f"{'' if ok else ' (ContactMechanics reported no convergence)'}.",
        ]
        print(lines[-1], flush=True)
    return lines + [""]


def section_hysteresis() -> list[str]:
    # A seal-like interface: self-affine (H = 0.8) with a roll-off, rms slope of the order
    # of 0.3, metal-like hardness H/E* = 0.02 ... 0.05; flow along axis 0.
    n = 256
    h0 = spectral(n, 4)
    slope0 = np.sqrt(np.mean(np.gradient(h0, axis=0) ** 2 + np.gradient(h0, axis=1) ** 2))
    lines = [
        f"## 4. Leak-rate hysteresis, {n}² seal-like surface (periodic)",
        "",
        "Spectral H = 0.8 with roll-off, rms slope as listed, E* = 1, periodic boundary; load "
        "control up to p_max, then unloading on the permanently deformed surface. "
        "`Q` is the Reynolds leak rate along axis 0 (η = Δp = 1, lengths in units of dx).",
        "",
        "| rms slope | hardness H/E* | p_max/E* | p/E* | Q loading | Q unloading | "
        "Q_load/Q_unload | contact loading → unloading | plastic fraction at p_max |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for slope, hard, pmax in ((0.3, 0.05, 0.02), (0.3, 0.02, 0.01), (0.1, 0.05, 0.01)):
        s = Surface(h0 * slope / slope0, 1.0)
        pressures = [pmax * f for f in (0.1, 0.25, 0.5, 1.0)]
        r = sweep(s, mean_pressures=pressures, hardness=hard, unload=True,
                  boundary="periodic", flow=True)
        rows = r.rows
        n_load = len(pressures)
        for j in range(n_load - 1):
            lo = rows[j]
            un = rows[2 * n_load - 2 - j]
            ratio = lo["Q"] / un["Q"] if un["Q"] > 0 else float("inf")
            lines.append(
                f"| {slope} | {hard} | {pmax} | {lo['mean_pressure']:.4g} | {lo['Q']:.3e} | "
                f"{un['Q']:.3e} | {ratio:.2f} | {lo['contact_fraction']:.4f} → "
                f"{un['contact_fraction']:.4f} | {rows[n_load - 1]['plastic_fraction']:.4f} |"
            )
            print(lines[-1], flush=True)
    # Path: each level on the original surface vs accumulated level by level.
    hard = 0.05
    s = Surface(h0 * 0.3 / slope0, 1.0)
    prob = ContactProblem(s, boundary="periodic", hardness=hard)
    pressures = [0.002, 0.005, 0.01, 0.02]
    acc = prob
    state = None
    for p in pressures:
        state = acc.solve(mean_pressure=p)
        acc = prob.unloading(state)
    direct = prob.solve(mean_pressure=pressures[-1])
    dv = abs(direct.plastic_volume - state.plastic_volume) / direct.plastic_volume
    da = abs(direct.contact_fraction - state.contact_fraction)
    dw = float(np.max(np.abs(direct.plastic_displacement - state.plastic_displacement)))
    lines += [
        "",
        f"Loading path (H = {hard} E*, p̄ = {', '.join(str(p) for p in pressures)} E*): "
        f"the top state solved directly on the original surface against the same level "
        f"reached by accumulating the plastic deformation level by level (each level on "
        f"the previous one's permanent surface): plastic volume {direct.plastic_volume:.5g} "
        f"vs {state.plastic_volume:.5g} (relative difference {dv:.1e}), contact fraction "
        f"{direct.contact_fraction:.5f} vs {state.contact_fraction:.5f} (difference "
        f"{da:.1e}), max abs difference of w_p {dw:.1e} dx (rms height 1 dx).",
        "",
    ]
    print(lines[-2], flush=True)
    return lines


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", nargs="*", default=None)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    only = set(args.only or ("agreement", "cost", "large", "hysteresis"))
    with_cm = available("ContactMechanics")
    parts = [
        "# Elastic–perfectly-plastic contact (hardness cap)",
        "",
        f"Machine: {machine()}. The machine was shared with other jobs; times are noisy.",
        f"Load average at the start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}",
        "",
        "Command: `PYTHONPATH=python /work/benchvenv-plastic/bin/python "
        "benchmarks/plastic_bench.py`",
        "",
    ]
    if "agreement" in only and with_cm:
        parts += section_agreement()
    if "cost" in only:
        parts += section_cost(args.repeats)
    if "large" in only:
        parts += section_large(with_cm, args.repeats)
    if "hysteresis" in only:
        parts += section_hysteresis()
    text = "\n".join(parts)
    if args.only:
        print(text)
    else:
        OUT.write_text(text)
        print(f"wrote {OUT}")
    _ = leakpath


if __name__ == "__main__":
    main()
