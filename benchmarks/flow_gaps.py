"""Contact gaps for the flow-solver benchmarks, cached as ``.npz`` under ``--cache``.

Each gap is the gap of ``leakpath.solve(surface, Δ, boundary="periodic")`` on a periodic
spectral surface (H = 0.8, rms height 1, seed 0) or, with ``--kind rmd``, a free-boundary
random-midpoint-displacement surface (``leakpath.rmd(m, D=2.2, seed=0)``, ``2^m + 1``
points a side). The flat sits ``--separation`` times the separation ``s_c`` from the mean
plane at the percolation threshold of the same statistics at 513²
(``leakpath.percolation_threshold``): ``Δ = max h − mean h − separation·s_c``. The
default 1.01 gives near-threshold gaps at 513² (the free region barely spans: a tortuous
channel), larger factors moderate contact; ``--separation 0`` takes this surface's own
threshold (``leakpath.percolation_threshold`` to ``10⁻³ h_s``, its last spanning state).
If the gap at the target size does not span along axis 0, the separation grows by 0.5 %
steps until it does. ``--kind synthetic`` skips the contact solve (minutes from 4097²
on): the gap ``max(t − h, 0)`` of the spectral surface with ``t`` at its percolation
threshold.

    python benchmarks/flow_gaps.py --sizes 513 1025 --separation 1.01
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

import leakpath


def surface(kind: str, n: int):
    if kind == "rmd":
        return leakpath.rmd(int(round(math.log2(n - 1))), 2.2, seed=0)
    return leakpath.spectral(n, 0.8, seed=0, rms_height=1.0)


def boundary(kind: str) -> str:
    return "free" if kind == "rmd" else "periodic"


def full(s) -> float:
    """Approach of full contact of a periodic surface, max h − mean h."""
    return float(s.heights.max() - s.heights.mean())


def threshold_separation(kind: str, cache: Path) -> float:
    """Separation of the flat from the mean plane at the percolation threshold, 513²."""
    path = cache / f"threshold_{kind}.json"
    if path.exists():
        return json.loads(path.read_text())["separation"]
    s = surface(kind, 513)
    th = leakpath.percolation_threshold(s, boundary=boundary(kind))
    sep = full(s) - th.approach
    path.write_text(json.dumps({"separation": sep, "contact_fraction": th.contact_fraction}))
    return sep


def synthetic(n: int) -> tuple[np.ndarray, np.ndarray, dict]:
    """Gap ``max(t − h, 0)`` of the spectral surface, ``t`` at the lowest height quantile
    (bisection to 1e-4) at which the open cells (``g > 0``) still span along axis 0 with
    wrap across axis 1: a near-threshold gap without a contact solve."""
    h = surface("spectral", n).heights
    spans = lambda q: leakpath.percolation(  # noqa: E731
        np.maximum(np.quantile(h, q) - h, 0.0), dx=1.0 / n, periodic=True
    ).percolates
    lo, hi = 0.3, 0.95
    while hi - lo > 1e-4:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if spans(mid) else (mid, hi)
    g = np.maximum(np.quantile(h, hi) - h, 0.0)
    contact = g <= 0
    return g, contact, {"quantile": hi, "contact_fraction": float(contact.mean())}


def gap(kind: str, n: int, separation: float, cache: Path):
    """(gap, contact, periodic, info) for the flow, from the cache when present."""
    stem = f"{kind}_{n}_{separation:g}"
    npz, js = cache / f"{stem}.npz", cache / f"{stem}.json"
    if npz.exists():
        d = np.load(npz)
        info = json.loads(js.read_text())
        return d["gap"], d["contact"], info["periodic"], info
    if kind == "synthetic":
        t0 = time.perf_counter()
        g, contact, info = synthetic(n)
        info.update(kind=kind, n=n, periodic=True, seconds=time.perf_counter() - t0)
        np.savez(npz, gap=g, contact=contact)
        js.write_text(json.dumps(info))
        return g, contact, True, info
    s = surface(kind, n)
    t0 = time.perf_counter()
    if separation == 0:
        # At the threshold of this surface: the last spanning state of the bisection.
        th = leakpath.percolation_threshold(
            s, boundary=boundary(kind), atol=1e-3 * s.height_range
        )
        st = th.below
        sep = full(s) - st.approach
        delta = st.approach
    else:
        sep = separation * threshold_separation(kind, cache)
    while separation != 0:
        delta = full(s) - sep
        st = leakpath.solve(s, delta, boundary=boundary(kind))
        if leakpath.percolation(st).percolates:
            break
        sep *= 1.005
    t = time.perf_counter() - t0
    g = np.maximum(st.gap, 0.0)
    info = {
        "kind": kind,
        "n": n,
        "separation_over_threshold": sep / threshold_separation(kind, cache),
        "approach": delta,
        "contact_fraction": float(st.contact_fraction),
        "periodic": kind != "rmd",
        "contact_solve_s": t,
    }
    np.savez(npz, gap=g, contact=np.asarray(st.contact))
    js.write_text(json.dumps(info))
    return g, np.asarray(st.contact), info["periodic"], info


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sizes", type=int, nargs="+", default=[513, 1025])
    ap.add_argument("--separation", type=float, default=1.01)
    ap.add_argument("--kind", choices=["spectral", "rmd", "synthetic"], default="spectral")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/lp_gaps"))
    a = ap.parse_args()
    a.cache.mkdir(parents=True, exist_ok=True)
    for n in a.sizes:
        t0 = time.perf_counter()
        _, _, _, info = gap(a.kind, n, a.separation, a.cache)
        print(n, f"{time.perf_counter() - t0:.1f} s", info, flush=True)


if __name__ == "__main__":
    main()
