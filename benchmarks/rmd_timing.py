"""RMD generator benchmark: wall time for m = 10, 11, 12 and measured-vs-target Hurst exponent.

Run from the repository root (after ``pip install .``)::

    python benchmarks/rmd_timing.py            # writes benchmarks/results/rmd.md

Timing: median (and min) of 5 calls of ``leakpath.rmd(m, 2.1, seed=k)`` per m, single
process, including the final ``min(h) = 0`` shift. Target: m = 12 (4097²) in under 2 s.

Hurst exponent: for each surface, fit ``log⟨(h(x + l) − h(x))²⟩ = 2H·log l + c`` over the
lags l = 2, 4, 8, 16, 32 (increments along both axes pooled), on m = 8 (257²) surfaces,
20 seeds per fractal dimension D ∈ {2.1, 2.3, 2.5, 2.7}; the table reports the mean and the
standard deviation over the seeds against the target ``H = 3 − D``.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import leakpath
from leakpath import rmd

LAGS = (2, 4, 8, 16, 32)
DIMENSIONS = (2.1, 2.3, 2.5, 2.7)


def cpu_model() -> str:
    """CPU model name from /proc/cpuinfo (Linux) or :func:`platform.processor`."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def machine_table() -> list[tuple[str, str]]:
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    return [
        ("platform", platform.platform()),
        ("CPU", cpu_model()),
        ("CPU count", str(os.cpu_count())),
        ("load average (1 min) at start", f"{load[0]:.2f}" if load else "n/a"),
        ("python", sys.version.split()[0]),
        ("numpy", np.__version__),
        ("leakpath", leakpath.__version__),
    ]


def time_rmd(m: int, repeats: int = 5) -> tuple[float, float]:
    """(median, min) wall time in seconds of ``rmd(m, 2.1, seed=k)``, k = 0 … repeats−1."""
    rmd(m, 2.1, seed=999)  # warm-up (page faults, imports)
    times = []
    for k in range(repeats):
        t0 = time.perf_counter()
        rmd(m, 2.1, seed=k)
        times.append(time.perf_counter() - t0)
    return statistics.median(times), min(times)


def hurst_from_increments(h: np.ndarray, lags: tuple[int, ...] = LAGS) -> float:
    """Slope/2 of log mean-square increment against log lag, both axes pooled."""
    msi = []
    for lag in lags:
        ax1 = np.mean((h[:, lag:] - h[:, :-lag]) ** 2)
        ax0 = np.mean((h[lag:, :] - h[:-lag, :]) ** 2)
        msi.append(0.5 * (ax0 + ax1))
    return float(np.polyfit(np.log(lags), np.log(msi), 1)[0] / 2.0)


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(header[i]), *(len(r[i]) for r in rows)) for i in range(len(header))]
    fmt = "| " + " | ".join(f"{{:{w}}}" for w in widths) + " |"
    lines = [fmt.format(*header), "|" + "|".join("-" * (w + 2) for w in widths) + "|"]
    lines += [fmt.format(*r) for r in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--out",
        type=Path,
        default=Path(__file__).resolve().parent / "results" / "rmd.md",
        help="markdown output file (default: benchmarks/results/rmd.md)",
    )
    parser.add_argument("--seeds", type=int, default=20, help="surfaces per D (default 20)")
    args = parser.parse_args(argv)

    machine = markdown_table(["item", "value"], [list(r) for r in machine_table()])

    timing_rows = []
    for m in (10, 11, 12):
        med, best = time_rmd(m)
        n = 2**m + 1
        timing_rows.append([str(m), f"{n}²", f"{med:.3f}", f"{best:.3f}"])
    timing = markdown_table(["m", "grid", "median of 5 [s]", "min [s]"], timing_rows)

    hurst_rows = []
    for d in DIMENSIONS:
        hs = np.array([hurst_from_increments(rmd(8, d, seed=s).heights) for s in range(args.seeds)])
        target = 3.0 - d
        hurst_rows.append(
            [
                f"{d:.1f}",
                f"{target:.1f}",
                f"{hs.mean():.3f}",
                f"{hs.std(ddof=1):.3f}",
                f"{round(hs.mean() - target, 3) + 0.0:+.3f}",
            ]
        )
    hurst = markdown_table(
        ["D", "target H = 3 − D", "measured H (mean)", "std over seeds", "measured − target"],
        hurst_rows,
    )

    text = "\n".join(
        [
            "# RMD generator: timing and Hurst exponent",
            "",
            "Produced by `python benchmarks/rmd_timing.py`.",
            "",
            "## Machine",
            "",
            machine,
            "",
            "## Wall time of `leakpath.rmd(m, D=2.1, seed=k)` (target: m = 12 under 2 s)",
            "",
            timing,
            "",
            f"## Hurst exponent, m = 8 (257²), {args.seeds} seeds per D",
            "",
            "Fit of log⟨(h(x+l) − h(x))²⟩ = 2H log l + c over l = 2, 4, 8, 16, 32, both axes "
            "pooled, per surface; mean and standard deviation over the seeds.",
            "",
            hurst,
            "",
            "Midpoint displacement without addition biases the measured H low for smooth "
            "surfaces (H → 1); the bias vanishes for rough ones.",
            "",
        ]
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_suffix(args.out.suffix + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, args.out)
    print(text)
    print(f"written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
