"""Iterations and FFT products of capped (hardness) Polonsky–Keer solves, both controls.

Cases: free RMD (D = 2.2, seed 0) at 513² and 1025², periodic spectral (H = 0.8, seed 0,
rms height 1) at 1025²; approach Δ = 0.3·h_s (free) or 0.3·(max h − mean h) (periodic);
hardness H = ¼ and ½ of the elastic peak pressure there; load control at the elastic
solve's mean pressure, cold start; tolerance 1e-8. Prints one JSON line per solve
(iterations, fine FFT products, preconditioner FFT pairs, KKT certificate, contact and
plastic fractions, seconds) or the error. Run it with two builds on PYTHONPATH to compare:

    PYTHONPATH=python python benchmarks/capped_counts.py > after.jsonl
"""

from __future__ import annotations

import json

import numpy as np

import leakpath


def main() -> None:
    for n, boundary in ((513, "free"), (1025, "free"), (1025, "periodic")):
        if boundary == "free":
            s = leakpath.rmd(int(np.log2(n - 1)), 2.2, seed=0)
            approach = 0.3 * s.height_range
        else:
            s = leakpath.spectral(n, 0.8, seed=0, rms_height=1.0)
            approach = 0.3 * float(s.heights.max() - s.heights.mean())
        elastic = leakpath.ContactProblem(s, boundary=boundary).solve(approach, tol=1e-8)
        peak = float(elastic.pressure.max())
        for fraction in (0.25, 0.5):
            problem = leakpath.ContactProblem(s, boundary=boundary, hardness=fraction * peak)
            for control in ("approach", "load"):
                row: dict[str, object] = {
                    "n": n, "boundary": boundary, "H/p_peak": fraction, "control": control
                }
                try:
                    if control == "approach":
                        st = problem.solve(approach, tol=1e-8)
                    else:
                        st = problem.solve(
                            mean_pressure=elastic.mean_pressure, tol=1e-8, warm_start=False
                        )
                except leakpath.errors.NotConvergedError as e:
                    row["error"] = str(e)
                else:
                    row.update(
                        iterations=st.iterations, fft_products=st.fft_products,
                        preconditioner_pairs=st.preconditioner_products, kkt=st.kkt,
                        contact_fraction=round(st.contact_fraction, 6),
                        plastic_fraction=round(st.plastic_fraction, 6),
                        seconds=round(st.seconds, 2),
                    )
                print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
