"""Fingerprints of one surface → contact → flow pipeline, to compare two CPUs bit for bit.

Prints SHA-256 prefixes of a spectral surface's heights, its contact solution (gap and
pressure, Polonsky–Keer at Δ = 2 h_s) and its flow (pressure field; Cholesky and multigrid),
with the flow rates, percolating volume and Nayak moments in full; then the exact contact
solvers (active set, Lawson–Hanson) and load control on a surface half as wide. Run it on
two machines, or on one natively and under user-mode emulation of a CPU without AVX-512,
and compare the lines (docs/conventions.md, "The same numbers on every
machine")::

    python benchmarks/same_bits.py > native.txt
    qemu-x86_64 -cpu Haswell "$(which python)" benchmarks/same_bits.py > haswell.txt
    diff native.txt haswell.txt

(``apt-get install qemu-user``; the emulated run takes a few minutes at the default 257².)
"""

from __future__ import annotations

import argparse
import hashlib

import numpy as np

import leakpath


def fingerprint(*arrays: np.ndarray) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=257, help="grid side (cells; default 257)")
    ap.add_argument("--seed", type=int, default=5, help="surface seed (default 5)")
    a = ap.parse_args()
    s = leakpath.spectral(a.size, 0.8, seed=a.seed)
    print(f"surface heights [{s.unit}]: {fingerprint(s.heights)}")
    h_s = float(np.std(s.heights))
    state = leakpath.ContactProblem(s, E=1.0, nu=0.0, boundary="periodic").solve(
        2.0 * h_s, solver="polonsky-keer"
    )
    print(f"contact gap, pressure: {fingerprint(state.gap)} {fingerprint(state.pressure)}")
    print(f"contact fraction [1]: {state.contact_fraction!r}")
    f = leakpath.flow(state, solver="cholesky")
    print(f"flow pressure: {fingerprint(f.pressure)}")
    print(f"flow rate [{s.unit}³/s at η = Δp = 1]: {f.flow_rate!r}")
    g = leakpath.flow(state, solver="multigrid")
    print(f"flow by multigrid: {fingerprint(g.pressure)} {g.flow_rate!r}")
    print(f"percolating volume [{s.unit}³]: {state.percolating_volume!r}")
    m = leakpath.nayak_moments(state.deformed, s.dx)
    u = s.unit
    print(f"deformed surface: m0 {m.m0!r} {u}², m2 {m.m2!r}, m4 {m.m4!r} {u}⁻², α {m.alpha!r}")
    # The exact solvers (dense Cholesky of the contact block) and load control, smaller.
    small = leakpath.spectral(a.size // 2 + 1, 0.8, seed=a.seed)
    problem = leakpath.ContactProblem(small, E=1.0, nu=0.3, boundary="periodic")
    delta = 1.5 * float(np.std(small.heights))
    for solver in ("active-set", "lawson-hanson"):
        st = problem.solve(delta, solver=solver)
        print(f"{solver}: {fingerprint(st.gap, st.pressure)} load {st.load!r} E·{u}²")
    st = problem.solve(mean_pressure=0.01, solver="polonsky-keer")
    fp = fingerprint(st.gap, st.pressure)
    print(f"load control (p̄ = 0.01 E): {fp} approach {st.approach!r} {u}")


if __name__ == "__main__":
    main()
