"""Which choices of units the contact solvers survive: the basis of ``contact_scales``.

Run from the repository root (after ``pip install .``)::

    python benchmarks/unit_scales_scan.py      # writes benchmarks/results/unit_scales.md

One 9 × 9 RMD surface (m = 3, D = 2.3, seed 1), normalised to a height range of 1, is
rescaled to heights ``10^a``, spacing ``10^b`` and Young's modulus ``10^c`` (ν = 0) for
``a, b ∈ {−140, −120, …, 140}`` and ``c ∈ {−300, −250, …, 300}`` (2,925 unit choices), and
solved at half its height range with the ``auto``, ``active-set`` and ``polonsky-keer``
solvers, with leakpath's own unit check switched off. A choice passes when all three return
a KKT certificate ≤ 1e-9 with a finite, positive load and a finite free volume.

The table then compares the outcome with :func:`leakpath._validate.contact_scales` (every
derived scale within ``10^±SCALE_EXPONENT``): an accepted choice that fails would be a
silent wrong answer or an unexplained error, so that count must be 0.
"""

from __future__ import annotations

import argparse
import itertools
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

import leakpath
from leakpath import _validate, rmd, solve
from leakpath.errors import InvalidArgumentError

SOLVERS = ("auto", "active-set", "polonsky-keer")


def machine_table() -> list[tuple[str, str]]:
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    cpu = platform.processor() or "unknown"
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            cpu = next(
                (ln.split(":", 1)[1].strip() for ln in fh if ln.lower().startswith("model name")),
                cpu,
            )
    except OSError:
        pass
    return [
        ("platform", platform.platform()),
        ("CPU", cpu),
        ("CPU count", str(os.cpu_count())),
        ("load average (1 min) at start", f"{load[0]:.2f}" if load else "n/a"),
        ("python", sys.version.split()[0]),
        ("numpy", np.__version__),
        ("leakpath", leakpath.__version__),
    ]


def passes(h0: np.ndarray, a: int, b: int, c: int) -> bool:
    for solver in SOLVERS:
        try:
            with np.errstate(all="ignore"):
                st = solve(h0 * 10.0**a, 0.5 * 10.0**a, dx=10.0**b, E=10.0**c, solver=solver)
                good = (
                    st.kkt <= 1e-9
                    and np.isfinite(st.load)
                    and st.load > 0
                    and np.isfinite(st.free_volume)
                )
        except Exception:  # noqa: BLE001 - any failure counts
            return False
        if not good:
            return False
    return True


def accepted(a: int, b: int, c: int) -> bool:
    try:
        _validate.contact_scales(10.0**c, 10.0**b, 10.0**a)
    except InvalidArgumentError:
        return False
    return True


def table(rows: list[tuple[str, ...]], header: tuple[str, ...]) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]

    def line(cells: tuple[str, ...]) -> str:
        return "| " + " | ".join(c.ljust(w) for c, w in zip(cells, widths, strict=True)) + " |"

    return "\n".join(
        [line(header), "|" + "|".join("-" * (w + 2) for w in widths) + "|"]
        + [line(r) for r in rows]
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/unit_scales.md"))
    args = parser.parse_args()
    machine = machine_table()
    s = rmd(3, 2.3, seed=1)
    h0 = np.asarray(s.heights) / s.height_range
    check = _validate.contact_scales
    _validate.contact_scales = lambda *a, **k: None  # the solvers unguarded
    t0 = time.perf_counter()
    results = []
    try:
        for a, b, c in itertools.product(
            range(-140, 141, 20), range(-140, 141, 20), range(-300, 301, 50)
        ):
            results.append((a, b, c, passes(h0, a, b, c)))
    finally:
        _validate.contact_scales = check
    seconds = time.perf_counter() - t0
    counts = {(acc, ok): 0 for acc in (True, False) for ok in (True, False)}
    for a, b, c, ok in results:
        counts[(accepted(a, b, c), ok)] += 1
    rows = [
        ("accepted by contact_scales", str(counts[(True, True)]), str(counts[(True, False)])),
        ("refused by contact_scales", str(counts[(False, True)]), str(counts[(False, False)])),
    ]
    text = [
        "# Unit choices the contact solvers survive",
        "",
        "Produced by `python benchmarks/unit_scales_scan.py` "
        f"({len(results)} unit choices, {seconds:.0f} s).",
        "",
        "## Machine",
        "",
        table([(k, v) for k, v in machine], ("item", "value")),
        "",
        "## Outcome",
        "",
        "Heights 10^a (h_s = 10^a), dx = 10^b, E = 10^c (ν = 0), a, b ∈ [−140, 140] step 20, "
        "c ∈ [−300, 300] step 50; solvers auto, active-set and polonsky-keer at Δ = h_s/2; "
        f"`SCALE_EXPONENT = {_validate.SCALE_EXPONENT}`.",
        "",
        table(rows, ("", "all solvers certified", "a solver failed")),
        "",
        "An accepted choice where a solver failed would be a silent wrong answer or an "
        "unexplained error: that count must be 0.",
        "",
    ]
    args.out.write_text("\n".join(text), encoding="utf-8")
    print("\n".join(text))


if __name__ == "__main__":
    main()
