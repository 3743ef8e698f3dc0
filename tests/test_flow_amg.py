"""The multigrid flow solver on contact gaps at the percolation threshold (257², 513²,
1025²).

Oracles: scipy's sparse LU of the same finite-volume system (``tests/test_flow_solver.py``
assembles it independently of leakpath) and leakpath's sparse Cholesky factor.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_flow_solver import oracle_rate

import leakpath


@pytest.fixture(scope="module")
def threshold_gap():
    """The last spanning state of the percolation-threshold bisection at 257² (periodic):
    the free region is one tortuous channel, conductances over many decades."""
    s = leakpath.spectral(257, 0.8, seed=3, rms_height=1.0)
    th = leakpath.percolation_threshold(s, boundary="periodic", atol=1e-4 * s.height_range)
    st = th.below
    return np.maximum(st.gap, 0.0), np.asarray(st.contact), st.contact_fraction


def test_threshold_gap_is_near_the_threshold(threshold_gap):
    _, _, a = threshold_gap
    assert 0.3 < a < 0.55


def test_multigrid_matches_the_factor_and_scipy_at_the_threshold(threshold_gap):
    gap, contact, _ = threshold_gap
    n = gap.shape[0]
    mg = leakpath.flow(gap, dx=1.0 / n, contact=contact, periodic=True, solver="multigrid")
    ch = leakpath.flow(gap, dx=1.0 / n, contact=contact, periodic=True, solver="cholesky")
    assert mg.solver == "multigrid" and ch.solver == "cholesky"
    assert 0 < mg.iterations < 200
    assert mg.flow_rate == pytest.approx(ch.flow_rate, rel=1e-8, abs=0)
    assert abs(mg.inlet_flow_rate / mg.flow_rate - 1) <= 1e-9
    assert mg.conservation <= 1e-6
    # The pressures agree where they are defined.
    ok = np.isfinite(ch.pressure)
    assert np.array_equal(ok, np.isfinite(mg.pressure))
    assert np.max(np.abs(mg.pressure[ok] - ch.pressure[ok])) <= 1e-6


@pytest.fixture(scope="module", params=[513, 1025])
def large_threshold_gap(request):
    """The last spanning state of the percolation-threshold bisection on a periodic
    spectral surface of 513² and 1025² cells: one tortuous channel at the resolutions the
    factored and multigrid paths are chosen between."""
    n = request.param
    s = leakpath.spectral(n, 0.8, seed=7, rms_height=1.0)
    th = leakpath.percolation_threshold(s, boundary="periodic", atol=1e-3 * s.height_range)
    st = th.below
    return np.maximum(st.gap, 0.0), np.asarray(st.contact), st.contact_fraction


def test_multigrid_matches_the_factor_at_the_threshold_on_large_grids(large_threshold_gap):
    gap, contact, a = large_threshold_gap
    n = gap.shape[0]
    assert 0.3 < a < 0.55
    kw = dict(dx=1.0 / n, contact=contact, periodic=True)
    mg = leakpath.flow(gap, solver="multigrid", **kw)
    ch = leakpath.flow(gap, solver="cholesky", **kw)
    assert mg.solver == "multigrid" and ch.solver == "cholesky"
    assert mg.n_unknowns == ch.n_unknowns > 0
    assert 0 < mg.iterations < 200
    assert mg.flow_rate == pytest.approx(ch.flow_rate, rel=1e-8, abs=0)
    assert abs(mg.inlet_flow_rate / mg.flow_rate - 1) <= 1e-9
    ok = np.isfinite(ch.pressure)
    assert np.array_equal(ok, np.isfinite(mg.pressure))
    assert np.max(np.abs(mg.pressure[ok] - ch.pressure[ok])) <= 1e-6


def test_multigrid_matches_scipy_without_wrap(threshold_gap):
    gap, contact, _ = threshold_gap
    q = oracle_rate(gap, contact)
    if q == 0:
        pytest.skip("no spanning cluster without the wrap")
    f = leakpath.flow(gap, dx=1.0, contact=contact, solver="multigrid")
    assert f.flow_rate == pytest.approx(q, rel=1e-8, abs=0)


def test_multigrid_bits_do_not_depend_on_threads(threshold_gap):
    gap, contact, _ = threshold_gap
    n = gap.shape[0]
    kw = dict(dx=1.0 / n, contact=contact, periodic=True, solver="multigrid")
    a = leakpath.flow(gap, threads=1, **kw)
    b = leakpath.flow(gap, threads=2, **kw)
    assert a.flow_rate == b.flow_rate and a.iterations == b.iterations
    assert np.array_equal(a.pressure, b.pressure, equal_nan=True)


def _pocket_gap(neck: float) -> tuple[np.ndarray, np.ndarray]:
    """A 257² gap of random width with a walled 21 × 21 pocket joined to the rest through
    one cell of gap ``neck`` (relative to the widest, 1)."""
    n = 257
    g = np.random.default_rng(1).uniform(0.5, 1.0, (n, n))
    c = np.zeros((n, n), bool)
    c[99, 99:122] = c[121, 99:122] = True
    c[99:122, 99] = c[99:122, 121] = True
    c[110, 121] = False
    g[110, 121] = neck
    return g, c


@pytest.mark.parametrize("neck", [1e-3, 2e-15])
def test_multigrid_solves_a_pocket_behind_a_narrow_neck(neck):
    # Down to a neck whose g³ is subnormal in single precision (the stored Schur complement
    # is then not faithful and CG applies it from the stencil): the factor's rate, in as
    # many iterations as without the neck (13; CG on the stored faces took 25 or more).
    g, c = _pocket_gap(neck)
    n = g.shape[0]
    mg = leakpath.flow(g, dx=1.0 / n, contact=c, periodic=True, solver="multigrid")
    ch = leakpath.flow(g, dx=1.0 / n, contact=c, periodic=True, solver="cholesky")
    assert mg.flow_rate == pytest.approx(ch.flow_rate, rel=1e-8, abs=0)
    assert mg.iterations < 20


def test_multigrid_refuses_rather_than_misreports_a_neck_below_single_precision():
    # g³ ~ 1e-51 underflows the single-precision levels (docs/flow.md, "Supported range of
    # gaps"): the multigrid may refuse, but never returns a rate the factor contradicts.
    g, c = _pocket_gap(1e-17)
    n = g.shape[0]
    ch = leakpath.flow(g, dx=1.0 / n, contact=c, periodic=True, solver="cholesky")
    try:
        mg = leakpath.flow(g, dx=1.0 / n, contact=c, periodic=True, solver="multigrid")
    except leakpath.errors.NotConvergedError:
        return
    assert mg.flow_rate == pytest.approx(ch.flow_rate, rel=1e-8, abs=0)
