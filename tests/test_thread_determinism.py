"""The default paths give byte-identical tables whatever the number of threads.

Each run is a fresh process with ``RAYON_NUM_THREADS`` set, so the Rust pool really has 1, 2
or 4 threads; the sweep's CSV and the threshold search's result must match byte for byte
(every reduction sums fixed chunks in a fixed order, and each FFT output is computed by the
same operations whatever the split).
"""

from __future__ import annotations

import os
import subprocess
import sys

SCRIPT = r"""
import sys, leakpath
s = leakpath.spectral(97, 0.8, seed=4, rms_height=1.0)
r = leakpath.sweep(s, levels=6)
sys.stdout.write(r.csv_text())
t = leakpath.percolation_threshold(s, axis=1, boundary="periodic", atol=1e-3 * s.height_range)
print(repr(t.approach), repr(t.contact_fraction))
# The exact solver's dense kernels (Cholesky updates large enough to run in parallel).
e = leakpath.rmd(6, 2.1, seed=3)
st = leakpath.solve(e, 0.8 * e.height_range, solver="active-set")
print(st.pressure.tobytes().hex()[:4000], st.pressure.sum().hex(), st.gap.sum().hex())
"""


def run(threads: int) -> str:
    env = dict(os.environ, RAYON_NUM_THREADS=str(threads))
    proc = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def test_default_paths_and_the_exact_solver_are_identical_for_1_2_4_threads():
    one = run(1)
    assert one.count("\n") >= 8
    assert run(2) == one
    assert run(4) == one
