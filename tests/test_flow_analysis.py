"""The factor's analysis kept from flow to flow (``_core.FlowAnalysis``, docs/flow.md).

A sequence of gaps closing like a contact sweep's levels: each rate on a kept analysis
against a fresh analysis (round-off, ≤ 1e-10) and against scipy's ``spsolve`` of an
independently assembled system (tests/test_flow_solver.py).
"""

from __future__ import annotations

import numpy as np
import pytest

import leakpath
from leakpath import _core
from leakpath._flow import kept_analysis

pytest.importorskip("scipy.sparse")
from test_flow_solver import oracle_rate  # noqa: E402


def _kept(kept: _core.FlowAnalysis, gap: np.ndarray, **kwargs) -> leakpath.Flow:
    with kept_analysis(kept):
        return leakpath.flow(gap, **kwargs)


def _levels(ny: int, nx: int, seed: int, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Gaps of a rough surface under a flat pushed ``k`` steps down: ``g = max(h0 − kδ, 0)``
    (contact where it reaches 0), the open cells shrinking from level to level."""
    h = leakpath.spectral(max(ny, nx), 0.8, seed=seed, rms_height=1.0).heights[:ny, :nx]
    g0 = float(h.max()) - h + 1e-3
    out = []
    for k in range(n):
        g = g0 - 0.12 * k
        contact = g <= 0
        out.append((np.where(contact, 0.0, g), contact))
    return out


@pytest.mark.parametrize("periodic", [False, True])
def test_kept_analysis_gives_the_fresh_and_the_oracle_rate(periodic):
    levels = _levels(96, 80, 3, 6)
    kept = _core.FlowAnalysis(min_cells=0)
    for gap, contact in levels:
        with kept_analysis(kept):
            a = leakpath.flow(gap, contact=contact, dx=1.0, periodic=periodic)
        f = leakpath.flow(gap, contact=contact, dx=1.0, periodic=periodic)
        assert a.solver == f.solver == "cholesky"
        assert a.n_unknowns == f.n_unknowns
        assert abs(a.flow_rate - f.flow_rate) <= 1e-10 * f.flow_rate
        assert abs(a.inlet_flow_rate - f.inlet_flow_rate) <= 1e-10 * f.flow_rate
        # Same pressures on the same cells (NaN where there is none).
        assert np.array_equal(np.isnan(a.pressure), np.isnan(f.pressure))
        np.testing.assert_allclose(
            np.nan_to_num(a.pressure), np.nan_to_num(f.pressure), rtol=0, atol=1e-10
        )
        if not periodic:
            q = oracle_rate(gap, contact)
            assert abs(a.flow_rate - q) <= 1e-9 * q
    # Each level's unknowns shrink by under 5 % a step here, most by more than nothing: the
    # first analysis is made, and later ones reused or remade by the 95 % rule.
    assert kept.analyses >= 1 and kept.analyses + kept.reuses == len(levels)
    assert kept.reuses >= 1
    assert kept.unknowns > 0 and kept.entries > 0
    kept.clear()
    assert kept.unknowns == 0


def test_kept_analysis_is_remade_when_unknowns_are_not_a_subset():
    (g0, c0), (g1, c1) = _levels(64, 64, 5, 2)
    kept = _core.FlowAnalysis(min_cells=0)
    # The more closed gap first, then the more open one: its unknowns are not among the
    # kept analysis's, so a new analysis is made.
    _kept(kept, g1, contact=c1, dx=1.0)
    a = _kept(kept, g0, contact=c0, dx=1.0)
    assert (kept.analyses, kept.reuses) == (2, 0)
    assert abs(a.flow_rate - oracle_rate(g0, c0)) <= 1e-9 * a.flow_rate
    # A different grid: a new analysis too.
    _kept(kept, g0[:, :60], contact=c0[:, :60], dx=1.0)
    assert (kept.analyses, kept.reuses) == (3, 0)
    # The same gap again: reused, the same rate to round-off.
    b = _kept(kept, g0[:, :60], contact=c0[:, :60], dx=1.0)
    assert (kept.analyses, kept.reuses) == (3, 1)
    assert abs(b.flow_rate - oracle_rate(g0[:, :60], c0[:, :60])) <= 1e-9 * b.flow_rate


def test_small_grids_do_not_use_the_kept_analysis_by_default():
    gap, contact = _levels(64, 64, 5, 1)[0]
    kept = _core.FlowAnalysis()
    _kept(kept, gap, contact=contact, dx=1.0)
    assert (kept.analyses, kept.reuses, kept.unknowns) == (0, 0, 0)
    assert "FlowAnalysis(" in repr(kept)


def test_kept_analysis_is_the_same_bits_on_one_and_two_threads():
    levels = _levels(80, 96, 7, 4)
    rates = []
    for threads in (1, 2):
        kept = _core.FlowAnalysis(min_cells=0)
        rates.append(
            [
                _kept(kept, g, contact=c, dx=1.0, threads=threads).flow_rate
                for g, c in levels
            ]
        )
    assert rates[0] == rates[1]


def test_nested_dissection_is_the_same_bits_on_one_and_two_threads():
    # 400² cells, 95 % open: ordered by nested dissection, its halves in parallel.
    gap, contact = _levels(400, 400, 11, 1)[0]
    contact = contact | (np.random.default_rng(0).random(gap.shape) < 0.05)
    a, b = (
        leakpath.flow(gap, contact=contact, dx=1.0, threads=t, periodic=True) for t in (1, 2)
    )
    assert a.n_unknowns > 0.6 * gap.size
    assert a.flow_rate == b.flow_rate
    assert np.array_equal(a.pressure, b.pressure, equal_nan=True)
    assert abs(a.flow_rate - a.inlet_flow_rate) <= 1e-9 * a.flow_rate
