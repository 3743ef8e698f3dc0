"""Connected-component labelling and percolation classes: leakpath against the usual tools.

Run from the repository root (after ``pip install .``)::

    python benchmarks/clusters_bench.py                   # writes benchmarks/results/clusters.md
    python benchmarks/clusters_bench.py --sizes 1025 4097 --repeats 7

Input: a random mask, 60 % of the cells free (i.i.d., seed 0) — just above the site
percolation threshold of the square lattice (0.5927), so there is one giant cluster and very
many small ones, and runs of free cells are short: a hard case for run-based labelling.

* **Labelling** (4-connectivity): ``leakpath._core.label_clusters`` (all cores) against
  ``scipy.ndimage.label``, ``cc3d.connected_components(connectivity=4)`` and
  ``skimage.measure.label(connectivity=1)``; a ``mask.sum()`` pass is shown as a floor (one
  read of the mask, no output).
* **Classification** (labels + per-cluster areas and volumes + spanning / dead-end / trapped
  classes for flow along axis 0, from a gap field and a contact mask):
  ``leakpath.percolation.percolation`` against the same done with scipy + numpy
  (``ndimage.label`` of the free cells, ``np.bincount`` for areas and volumes, ``np.unique``
  on the edge rows and columns for the classes). The two results are checked to agree.

Each timing is the median of ``--repeats`` runs after one warm-up run. The optional
competitors (``connected-components-3d``, ``scikit-image``) are skipped when not installed;
they are benchmark-only tools, not leakpath dependencies. The machine is shared in CI-like
settings, so the load average before and after is recorded with the results.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from leakpath import _core
from leakpath._percolation import percolation

try:
    import scipy.ndimage as ndimage
except ImportError:  # pragma: no cover - scipy is a test dependency
    ndimage = None
try:
    import cc3d
except ImportError:
    cc3d = None
try:
    import skimage.measure as skmeasure
except ImportError:
    skmeasure = None

FREE_FRACTION = 0.6


def median_ms(fn: Callable[[], object], repeats: int, clock=time.perf_counter) -> float:
    fn()  # warm-up: page faults of first allocations, lazy imports, thread pools
    times = []
    for _ in range(repeats):
        t0 = clock()
        fn()
        times.append(clock() - t0)
    return 1e3 * statistics.median(times)


def cpu_ms(fn: Callable[[], object], repeats: int) -> float:
    """Median CPU time of the process (all threads): with single-threaded runs, a measure of
    the work done that a busy machine inflates far less than wall time."""
    return median_ms(fn, repeats, clock=time.process_time)


def version(dist: str) -> str:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def load_average() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def scipy_classify(gap: np.ndarray, contact: np.ndarray, dx: float) -> dict[str, float]:
    """Labels, per-cluster areas and volumes, and classes for flow along axis 0, with
    scipy + numpy (the reference for the classification benchmark)."""
    lab, n = ndimage.label(~contact)
    flat = lab.ravel()
    areas = np.bincount(flat, minlength=n + 1)
    volumes = np.bincount(flat, weights=gap.ravel(), minlength=n + 1) * dx * dx
    top, bottom = np.unique(lab[0]), np.unique(lab[-1])
    left, right = np.unique(lab[:, 0]), np.unique(lab[:, -1])
    cls = np.full(n + 1, 3, dtype=np.int8)  # trapped
    cls[np.concatenate([top, bottom, left, right])] = 2  # dead-end
    cls[np.intersect1d(top, bottom)] = 1  # spanning
    cls[0] = 0
    return {
        "n_clusters": n,
        "spanning_volume": float(volumes[cls == 1].sum()),
        "dead_end_volume": float(volumes[cls == 2].sum()),
        "trapped_volume": float(volumes[cls == 3].sum()),
        "free_area": int(areas[1:].sum()),
    }


def bench_size(n: int, repeats: int, threads: int | None) -> dict[str, object]:
    rng = np.random.default_rng(0)
    free = rng.random((n, n)) < FREE_FRACTION
    contact = ~free
    gap = np.where(free, rng.random((n, n)), 0.0)
    dx = 1.0 / (n - 1)

    row: dict[str, object] = {"n": n}
    row["floor"] = median_ms(lambda: free.sum(), repeats)
    row["leakpath"] = median_ms(lambda: _core.label_clusters(free, 4, threads=threads), repeats)
    row["leakpath_1"] = median_ms(lambda: _core.label_clusters(free, 4, threads=1), repeats)
    row["cpu_leakpath_1"] = cpu_ms(lambda: _core.label_clusters(free, 4, threads=1), repeats)
    if ndimage is not None:
        row["scipy"] = median_ms(lambda: ndimage.label(free), repeats)
        row["cpu_scipy"] = cpu_ms(lambda: ndimage.label(free), repeats)
    if cc3d is not None:
        row["cc3d"] = median_ms(lambda: cc3d.connected_components(free, connectivity=4), repeats)
        row["cpu_cc3d"] = cpu_ms(lambda: cc3d.connected_components(free, connectivity=4), repeats)
    if skmeasure is not None:
        row["skimage"] = median_ms(lambda: skmeasure.label(free, connectivity=1), repeats)
        row["cpu_skimage"] = cpu_ms(lambda: skmeasure.label(free, connectivity=1), repeats)

    # Sanity: the same clusters as scipy.
    lab, k = _core.label_clusters(free, 4, threads=threads)
    if ndimage is not None:
        ref, k_ref = ndimage.label(free)
        assert k == k_ref, (k, k_ref)
    row["clusters"] = k

    row["classify"] = median_ms(
        lambda: percolation(gap, dx=dx, contact=contact, threads=threads), repeats
    )
    row["cpu_classify_1"] = cpu_ms(
        lambda: percolation(gap, dx=dx, contact=contact, threads=1), repeats
    )
    if ndimage is not None:
        row["classify_scipy"] = median_ms(lambda: scipy_classify(gap, contact, dx), repeats)
        row["cpu_classify_scipy"] = cpu_ms(lambda: scipy_classify(gap, contact, dx), repeats)
        ours = percolation(gap, dx=dx, contact=contact, threads=threads)
        ref = scipy_classify(gap, contact, dx)
        assert ours.n_clusters == ref["n_clusters"]
        assert ours.free_cells == ref["free_area"]  # cells
        for key in ("spanning_volume", "dead_end_volume", "trapped_volume"):
            assert np.isclose(getattr(ours, key), ref[key], rtol=1e-9), key
    return row


def fmt(ms: float | None) -> str:
    return "—" if ms is None else (f"{ms:,.1f}" if ms < 100 else f"{ms:,.0f}")


def table(rows: list[dict[str, object]]) -> str:
    comps = [c for c in ("scipy", "cc3d", "skimage") if c in rows[0]]
    lines = [
        "### Labelling (4-connectivity), median ms",
        "",
        "| grid | clusters | mask.sum() floor | leakpath (all cores) | leakpath (1 thread) | "
        + " | ".join(comps)
        + " | fastest other / leakpath |",
        "|---|---:|---:|---:|---:|" + "---:|" * len(comps) + "---:|",
    ]
    for r in rows:
        best = min(r[c] for c in comps) if comps else None  # type: ignore[type-var]
        ratio = f"{best / r['leakpath']:.1f}×" if best else "—"  # type: ignore[operator]
        lines.append(
            f"| {r['n']}² | {r['clusters']:,} | {fmt(r['floor'])} | **{fmt(r['leakpath'])}** "
            f"| {fmt(r['leakpath_1'])} | "
            + " | ".join(fmt(r[c]) for c in comps)  # type: ignore[arg-type]
            + f" | **{ratio}** |"
        )
    lines += [
        "",
        "### Classification (labels + areas + volumes + classes, flow along axis 0), median ms",
        "",
        "| grid | leakpath `percolation()` | scipy + numpy | scipy+numpy / leakpath |",
        "|---|---:|---:|---:|",
    ]
    for r in rows:
        ref = r.get("classify_scipy")
        ratio = f"{ref / r['classify']:.1f}×" if ref else "—"  # type: ignore[operator]
        lines.append(
            f"| {r['n']}² | **{fmt(r['classify'])}** | {fmt(ref)} | **{ratio}** |"  # type: ignore[arg-type]
        )
    cpu = [c for c in ("scipy", "cc3d", "skimage") if f"cpu_{c}" in rows[0]]
    lines += [
        "",
        "### Single-thread CPU time (process time, median ms)",
        "",
        "Work done on one core, leakpath with `threads=1`; on a shared machine this is "
        "inflated far less than wall time by other processes.",
        "",
        "| grid | leakpath label | "
        + " | ".join(f"{c} label" for c in cpu)
        + " | fastest other / leakpath | leakpath classify | scipy + numpy classify | ratio |",
        "|---|---:|" + "---:|" * len(cpu) + "---:|---:|---:|---:|",
    ]
    for r in rows:
        best = min(r[f"cpu_{c}"] for c in cpu) if cpu else None  # type: ignore[type-var]
        lab = r["cpu_leakpath_1"]
        ratio = f"{best / lab:.1f}×" if best else "—"  # type: ignore[operator]
        ref = r.get("cpu_classify_scipy")
        cratio = f"{ref / r['cpu_classify_1']:.1f}×" if ref else "—"  # type: ignore[operator]
        lines.append(
            f"| {r['n']}² | {fmt(lab)} | "  # type: ignore[arg-type]
            + " | ".join(fmt(r[f"cpu_{c}"]) for c in cpu)  # type: ignore[arg-type]
            + f" | {ratio} | {fmt(r['cpu_classify_1'])} | {fmt(ref)} | {cratio} |"  # type: ignore[arg-type]
        )
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1025, 4097, 8193])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, default=None, help="leakpath threads (all cores)")
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/clusters.md"))
    args = ap.parse_args()

    load_before = load_average()
    rows = []
    for n in args.sizes:
        print(f"{n}² ...", file=sys.stderr, flush=True)
        rows.append(bench_size(n, args.repeats, args.threads))
    load_after = load_average()

    header = [
        "# Cluster labelling and percolation classes",
        "",
        "Produced by `python benchmarks/clusters_bench.py` "
        f"(`--sizes {' '.join(map(str, args.sizes))} --repeats {args.repeats}`).",
        f"Random mask, {FREE_FRACTION:.0%} free (seed 0); medians of {args.repeats} runs after "
        "a warm-up. Ratios > 1 mean leakpath is faster.",
        "",
        f"- machine: {platform.platform()}; CPU: {cpu_model()}; "
        f"{os.cpu_count()} logical CPUs; load average before / after: "
        f"{load_before} / {load_after}",
        f"- Python {platform.python_version()}; leakpath {version('leakpath')}; "
        f"numpy {version('numpy')}; scipy {version('scipy')}; "
        f"connected-components-3d {version('connected-components-3d')}; "
        f"scikit-image {version('scikit-image')}",
        f"- leakpath threads: {args.threads or 'all cores'}",
        "",
    ]
    text = "\n".join(header) + table(rows) + "\n"
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(f"wrote {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
