"""Reynolds flow through the gap: exact cases and an independent scipy assembly."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy import ndimage

import leakpath
from leakpath.errors import InvalidArgumentError


def _reference(gap, closed, dp, eta, periodic):
    """Independent finite-volume assembly (flow along axis 0) solved by spsolve.

    Returns (pressure with NaN off the spanning cells, outlet flow rate).
    """
    ny, nx = gap.shape
    c = np.where(closed, 0.0, gap**3 / (12.0 * eta))
    open_ = c > 0
    structure = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]])
    lab, n = ndimage.label(open_, structure=structure)
    if periodic and nx > 1:
        # Join clusters across the wrap with a tiny union-find on labels.
        parent = list(range(n + 1))

        def find(a):
            while parent[a] != a:
                parent[a] = parent[parent[a]]
                a = parent[a]
            return a

        for i in range(ny):
            a, b = lab[i, 0], lab[i, -1]
            if a and b:
                parent[find(a)] = find(b)
        lab = np.vectorize(find)(lab) * open_
    inlet = set(lab[0][lab[0] > 0].tolist())
    outlet = set(lab[-1][lab[-1] > 0].tolist())
    spanning = np.isin(lab, list(inlet & outlet)) & open_
    idx = -np.ones(gap.shape, dtype=np.int64)
    idx[spanning] = np.arange(spanning.sum())
    m = int(spanning.sum())
    p = np.full(gap.shape, np.nan)
    if m == 0:
        return p, 0.0
    rows, cols, vals = [], [], []
    b = np.zeros(m)

    def hm(c1, c2):
        return 2 * c1 * c2 / (c1 + c2) if c1 > 0 and c2 > 0 else 0.0

    for i, j in zip(*np.nonzero(spanning), strict=True):
        k = idx[i, j]
        nbs = []
        if i > 0:
            nbs.append((i - 1, j))
        if i < ny - 1:
            nbs.append((i + 1, j))
        if j > 0:
            nbs.append((i, j - 1))
        elif periodic and nx > 1:
            nbs.append((i, nx - 1))
        if j < nx - 1:
            nbs.append((i, j + 1))
        elif periodic and nx > 1:
            nbs.append((i, 0))
        diag = 0.0
        for a, bb in nbs:
            cf = hm(c[i, j], c[a, bb])
            if cf > 0:
                diag += cf
                rows.append(k)
                cols.append(idx[a, bb])
                vals.append(-cf)
        if i == 0:
            diag += 2 * c[i, j]
            b[k] += 2 * c[i, j] * dp
        if i == ny - 1:
            diag += 2 * c[i, j]
        rows.append(k)
        cols.append(k)
        vals.append(diag)
    A = sp.csr_matrix((vals, (rows, cols)), shape=(m, m))
    x = spla.spsolve(A.tocsc(), b)
    p[spanning] = x
    last = spanning[-1]
    q = float(np.sum(2 * c[-1][last] * p[-1][last]))
    return p, q


def _random_gap(seed, shape, closed_fraction):
    rng = np.random.default_rng(seed)
    g = 0.05 + rng.random(shape)
    g[rng.random(shape) < closed_fraction] = 0.0
    return g


@pytest.mark.parametrize("shape", [(1, 1), (8, 5), (33, 70), (129, 64)])
@pytest.mark.parametrize("axis", [0, 1])
@pytest.mark.parametrize("periodic", [False, True])
def test_parallel_plates(shape, axis, periodic):
    g, dx, eta, dp = 0.3, 0.25, 1.7, 2.5
    f = leakpath.flow(
        np.full(shape, g), dx=dx, axis=axis, viscosity=eta, pressure_drop=dp, periodic=periodic
    )
    ny, nx = shape
    W, L = (nx * dx, ny * dx) if axis == 0 else (ny * dx, nx * dx)
    exact = W * g**3 * dp / (12 * eta * L)
    assert f.flow_rate == pytest.approx(exact, rel=1e-12, abs=0)
    assert f.inlet_flow_rate == pytest.approx(exact, rel=1e-12, abs=0)
    assert f.permeability == pytest.approx(g**3 / 12, rel=1e-12, abs=0)
    assert f.hydraulic_aperture == pytest.approx(g, rel=1e-12, abs=0)
    assert f.conductance == pytest.approx(exact / dp, rel=1e-12, abs=0)


def test_linear_gap_along_the_flow_is_series_conductances():
    ny, nx, eta, dp = 80, 7, 0.9, 4.0
    gi = np.linspace(0.1, 0.9, ny)
    gap = np.repeat(gi[:, None], nx, axis=1)
    f = leakpath.flow(gap, dx=1.0, viscosity=eta, pressure_drop=dp)
    c = gi**3 / (12 * eta)
    resistance = 1 / (2 * c[0]) + 1 / (2 * c[-1]) + np.sum((c[:-1] + c[1:]) / (2 * c[:-1] * c[1:]))
    assert f.flow_rate == pytest.approx(nx * dp / resistance, rel=1e-12, abs=0)
    assert np.abs(f.flux_axis1).max() <= 1e-13 * f.flow_rate
    # Every cross-section carries Q.
    np.testing.assert_allclose(f.flux_axis0.sum(axis=1), f.flow_rate, rtol=1e-11)


def test_transposed_field_along_axis1_equals_axis0():
    gap = _random_gap(1, (40, 57), 0.3)
    for periodic in (False, True):
        a = leakpath.flow(gap, dx=0.5, axis=0, periodic=periodic)
        b = leakpath.flow(gap.T.copy(), dx=0.5, axis=1, periodic=periodic)
        assert a.flow_rate == b.flow_rate
        np.testing.assert_array_equal(a.pressure, b.pressure.T)
        np.testing.assert_array_equal(a.flux_axis0, b.flux_axis1.T)
        np.testing.assert_array_equal(a.flux_axis1, b.flux_axis0.T)


def test_nothing_spans_gives_exactly_zero():
    gap = _random_gap(2, (30, 30), 0.1)
    gap[12, :] = 0.0
    f = leakpath.flow(gap, dx=1.0, periodic=True)
    assert f.flow_rate == 0.0 and f.inlet_flow_rate == 0.0 and f.conductance == 0.0
    assert f.n_unknowns == 0 and not f.percolates
    assert not np.any(f.flux_axis0) and not np.any(f.flux_axis1)
    assert np.all(np.isnan(f.pressure[12]))
    # Dead ends sit at the reservoir pressures.
    open0 = gap[0] > 0
    assert np.all(f.pressure[0][open0] == 1.0)


@pytest.mark.parametrize("solver", ["cholesky", "multigrid"])
@pytest.mark.parametrize("seed,shape,closed,periodic", [
    (3, (40, 40), 0.3, False),
    (4, (64, 48), 0.35, True),
    (5, (25, 90), 0.2, False),
])
def test_random_gap_matches_spsolve(seed, shape, closed, periodic, solver):
    gap = _random_gap(seed, shape, closed)
    eta, dp = 1.3, 2.0
    f = leakpath.flow(
        gap, dx=0.1, viscosity=eta, pressure_drop=dp, periodic=periodic, solver=solver
    )
    p, q = _reference(gap, gap <= 0, dp, eta, periodic)
    assert q > 0
    assert f.flow_rate == pytest.approx(q, rel=1e-10, abs=0)
    spanning = ~np.isnan(p)
    np.testing.assert_allclose(f.pressure[spanning], p[spanning], rtol=0, atol=1e-10 * dp)
    assert abs(f.inlet_flow_rate - f.flow_rate) <= 1e-9 * f.flow_rate
    assert f.conservation <= 1e-9


@pytest.mark.parametrize("solver", ["auto", "cholesky", "multigrid"])
@pytest.mark.parametrize("boundary", ["free", "periodic"])
def test_contact_gap_matches_spsolve(boundary, solver):
    s = leakpath.spectral(64, 0.8, seed=7, rms_height=1.0)
    st = leakpath.solve(s, 0.35 * (s.heights.max() - s.heights.min()), solver="polonsky-keer",
                        boundary=boundary)
    assert 0.05 < st.contact_fraction < 0.6
    f = st.flow(viscosity=2.0, pressure_drop=3.0, solver=solver)
    gap = np.maximum(st.gap, 0.0)
    p, q = _reference(gap, st.contact, 3.0, 2.0, boundary == "periodic")
    assert f.periodic == (boundary == "periodic")
    if q == 0:
        assert f.flow_rate == 0.0
    else:
        assert f.flow_rate == pytest.approx(q, rel=1e-10, abs=0)
        spanning = ~np.isnan(p)
        np.testing.assert_allclose(f.pressure[spanning], p[spanning], rtol=0, atol=1e-10 * 3.0)
    assert abs(f.inlet_flow_rate - f.flow_rate) <= 1e-9 * abs(f.flow_rate)


def test_flows_iff_percolates_along_the_axis():
    s = leakpath.spectral(64, 0.8, seed=3, rms_height=1.0)
    h = s.heights
    for level in np.linspace(0.2, 0.8, 7):
        gap = np.maximum(np.quantile(h, level) - h, 0.0)
        for axis in (0, 1):
            f = leakpath.flow(gap, dx=s.dx, axis=axis)
            perc = leakpath.percolation(gap, dx=s.dx, axis=axis)
            assert (f.flow_rate > 0) == perc.percolates


def test_pressure_drop_and_viscosity_scale_linearly():
    gap = _random_gap(8, (32, 32), 0.2)
    a = leakpath.flow(gap, dx=1.0)
    b = leakpath.flow(gap, dx=1.0, viscosity=4.0, pressure_drop=-2.0)
    assert b.flow_rate == pytest.approx(-0.5 * a.flow_rate, rel=1e-12, abs=0)
    assert b.permeability == pytest.approx(a.permeability, rel=1e-12, abs=0)
    z = leakpath.flow(gap, dx=1.0, pressure_drop=0.0)
    assert z.flow_rate == 0.0 and z.conductance == pytest.approx(a.conductance, rel=1e-12, abs=0)


@pytest.mark.parametrize("kwargs,argument", [
    ({"viscosity": 0.0}, "viscosity"),
    ({"viscosity": -1.0}, "viscosity"),
    ({"viscosity": True}, "viscosity"),
    ({"viscosity": "1"}, "viscosity"),
    ({"pressure_drop": float("nan")}, "pressure_drop"),
    ({"pressure_drop": float("inf")}, "pressure_drop"),
    ({"pressure_drop": False}, "pressure_drop"),
    ({"axis": 2}, "axis"),
    ({"axis": True}, "axis"),
    ({"axis": "0"}, "axis"),
    ({"dx": 0.0}, "dx"),
    ({"dx": "1"}, "dx"),
    ({"tol": 0.0}, "tol"),
    ({"periodic": "yes"}, "periodic"),
    ({"max_iter": 0}, "max_iter"),
    ({"solver": "lu"}, "solver"),
    ({"contact": np.zeros((3, 3), dtype=bool)}, "contact"),
    ({"contact": np.zeros((8, 8))}, "contact"),
])
def test_bad_arguments(kwargs, argument):
    kw = {"dx": 1.0, **kwargs}
    with pytest.raises(InvalidArgumentError) as e:
        leakpath.flow(np.ones((8, 8)), **kw)
    assert e.value.argument == argument


@pytest.mark.parametrize("gap", [
    np.array([[1.0, np.nan], [1.0, 1.0]]),
    np.array([[1.0, -0.5], [1.0, 1.0]]),
    np.array([[1.0, np.inf], [1.0, 1.0]]),
    np.ones(5),
    np.ones((0, 3)),
    np.array([["a", "b"]]),
    np.ones((2, 2), dtype=bool),
])
def test_bad_gaps(gap):
    with pytest.raises(InvalidArgumentError) as e:
        leakpath.flow(gap, dx=1.0)
    assert e.value.argument == "gap"


def test_missing_dx_and_too_large():
    with pytest.raises(InvalidArgumentError) as e:
        leakpath.flow(np.ones((4, 4)))
    assert e.value.argument == "dx"
    with pytest.raises(leakpath.errors.ProblemTooLargeError):
        leakpath.flow(np.ones((64, 64)), dx=1.0, memory_limit=1000)


def test_not_converged():
    gap = _random_gap(9, (128, 128), 0.3)
    with pytest.raises(leakpath.errors.NotConvergedError):
        leakpath.flow(gap, dx=1.0, max_iter=1, solver="multigrid")


def test_repr_is_short():
    f = leakpath.flow(np.ones((4, 6)), dx=1.0)
    r = repr(f)
    assert r.startswith("Flow(Q=") and len(r) < 400


def test_cli_flow_json(capsys):
    import json

    from leakpath.cli import main

    rc = main(["flow", "spectral:n=64,hurst=0.8,seed=2,rms_height=1", "--approach", "1.0",
               "--boundary", "periodic", "--viscosity", "2", "--pressure-drop", "3", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    s = leakpath.spectral(64, 0.8, seed=2, rms_height=1.0)
    st = leakpath.solve(s, 1.0, boundary="periodic", solver="polonsky-keer")
    f = st.flow(viscosity=2.0, pressure_drop=3.0)
    assert out["flow_rate"] == pytest.approx(f.flow_rate, rel=1e-9, abs=0)
    assert out["contact_fraction"] == pytest.approx(st.contact_fraction)
    rc = main(["flow", "spectral:n=64,hurst=0.8,seed=2", "--approach", "1", "--viscosity", "0"])
    assert rc == 2
    assert "viscosity" in capsys.readouterr().err
