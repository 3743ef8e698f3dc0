"""Cell conductances of a cached contact gap, for ``cargo bench --bench cycle_bench``.

Usage (from the repository root, after ``benchmarks/flow_gaps.py`` has cached the gap)::

    python benchmarks/flow_conductances.py spectral_4097_1.01 /tmp/c4097.bin

Writes ``(g / g_max)³`` (dimensionless; ``g_max`` the largest gap of a spanning cell) as
little-endian ``float64`` in row-major order, 0 outside the spanning clusters of
:func:`leakpath.percolation` (flow along axis 0, wrapped across the columns): the cells on
which ``leakpath.flow(..., periodic=True)`` solves for the pressure.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import leakpath
from leakpath._percolation import SPANNING


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("case", help="cached gap, e.g. spectral_4097_1.01")
    ap.add_argument("out", type=Path, help="output file (raw float64)")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/lp_gaps"))
    a = ap.parse_args()
    d = np.load(a.cache / f"{a.case}.npz")
    gap, contact = d["gap"], d["contact"]
    n = gap.shape[0]
    perc = leakpath.percolation(gap, contact=contact, axis=0, periodic=True, dx=1.0 / n)
    # Cluster k is entry k − 1 of `classes`; label 0 (contact) is never spanning.
    spanning = np.concatenate([[False], perc.classes == SPANNING])[perc.labels]
    g_max = gap[spanning].max()
    c = np.where(spanning, (gap / g_max) ** 3, 0.0).astype("<f8")
    tmp = a.out.with_name(a.out.name + ".part")
    c.tofile(tmp)
    tmp.replace(a.out)
    print(f"{a.out}: {gap.shape[0]}×{gap.shape[1]} cells, {int(spanning.sum())} spanning "
          f"(the flow's unknowns)")


if __name__ == "__main__":
    main()
