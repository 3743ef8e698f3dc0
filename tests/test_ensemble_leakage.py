"""Ensemble leak-rate statistics (leakpath.ensemble._leakage) against numpy written out here."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from leakpath.ensemble import ensemble, t_critical
from leakpath.ensemble._leakage import CONTACT_GRID, leak_threshold_from_rows, log_k_on_grid


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("ens") / "run"
    result = ensemble(
        generator="spectral",
        params={"shape": (32, 32), "hurst": 0.8, "rms_height": 1.0},
        surfaces=5,
        levels=12,
        boundary="periodic",
        out=out,
        workers=2,
        progress=False,
        figures=True,
    )
    return out, result


def test_leak_stops_at_each_surfaces_percolation_threshold(run):
    out, result = run
    thr = {r["seed"]: r for r in _rows(out / "thresholds.csv")}
    leak = _rows(out / "leak_thresholds.csv")
    assert len(leak) == 5
    for r in leak:
        assert r["found_q"] == "true" and r["equals_percolation"] == "true"
        assert float(r["contact_fraction_q"]) == float(thr[r["seed"]]["contact_fraction_c"])
        assert int(r["k_q"]) == int(thr[r["seed"]]["k_c"])
    doc = json.loads((out / "ensemble.json").read_text())
    (summary,) = doc["leakage"]["param_sets"].values()
    assert summary["n_equal_to_percolation"] == 5
    assert (out / "figures" / "leak_bands.png").exists()


def test_bands_against_numpy(run):
    out, _ = run
    tables = []
    for seed in range(5):
        tables.append(_rows(next((out / "tasks").glob(f"*/seed-{seed}.csv"))))
    # Independent interpolation: per surface, log10 K between its leaking levels.
    curves = []
    for t in tables:
        a = np.array([float(r["contact_fraction"]) for r in t])
        k = np.array([float(r["K"]) for r in t])
        ok = k > 0
        c = np.full(CONTACT_GRID.shape, np.nan)
        sel = (CONTACT_GRID >= a[ok].min()) & (CONTACT_GRID <= a[ok].max())
        # math.log10: the C library's, value by value, as leakpath's on every CPU.
        log_k = np.array([math.log10(v) for v in k[ok]])
        c[sel] = np.interp(CONTACT_GRID[sel], a[ok], log_k)
        curves.append(c)
        np.testing.assert_array_equal(c, log_k_on_grid(t))
    curves = np.array(curves)
    bands = _rows(out / "leakage.csv")
    assert len(bands) == len(CONTACT_GRID)
    checked = 0
    for j, row in enumerate(bands):
        x = curves[:, j][np.isfinite(curves[:, j])]
        assert int(row["log10_K_n"]) == x.size
        if x.size >= 2:
            mean, std = x.mean(), x.std(ddof=1)
            half = t_critical(x.size) * std / math.sqrt(x.size)
            assert float(row["log10_K_mean"]) == pytest.approx(mean, rel=1e-12, abs=1e-12)
            assert float(row["log10_K_ci_high"]) == pytest.approx(mean + half, rel=1e-12, abs=0)
            assert float(row["log10_K_q50"]) == pytest.approx(np.median(x), rel=1e-12, abs=0)
            checked += 1
    assert checked >= 10
    # Row 0 is Δ = 0: K* = 1 there, so log10 K* = 0 at a = 0 on every surface.
    assert float(bands[0]["log10_K_star_mean"]) == 0.0


def test_threshold_from_rows_without_leak_or_with_a_mismatch():
    rows = [
        {"Q": 1.0, "contact_fraction": 0.0, "n_spanning_axis0": 1},
        {"Q": 0.5, "contact_fraction": 0.2, "n_spanning_axis0": 1},
        {"Q": 0.0, "contact_fraction": 0.4, "n_spanning_axis0": 1},
        {"Q": 0.0, "contact_fraction": 0.6, "n_spanning_axis0": 0},
    ]
    r = leak_threshold_from_rows(rows, 0)
    assert r["k_q"] == 2 and r["contact_fraction_q"] == 0.4 and r["k_percolation"] == 3
    assert not r["equals_percolation"]
    r = leak_threshold_from_rows(rows[:2], 0)
    assert not r["found_q"] and math.isnan(r["contact_fraction_q"])
