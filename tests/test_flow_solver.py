"""Reynolds-flow solvers near the percolation threshold against scipy's sparse LU.

scipy is used only as an independent oracle: the finite-volume system of docs/flow.md is
assembled here from the gap with scipy.sparse and solved with ``spsolve``.
"""

from __future__ import annotations

import numpy as np
import pytest

import leakpath

sp = pytest.importorskip("scipy.sparse")
spla = pytest.importorskip("scipy.sparse.linalg")
ndimage = pytest.importorskip("scipy.ndimage")


def _system(gap: np.ndarray, contact: np.ndarray):
    """The finite-volume system on the spanning cells along axis 0 (η = Δp = dx = 1, side
    walls closed): the matrix (COO), the inlet right-hand side and the outlet weights."""
    c = np.where(contact, 0.0, gap**3 / 12.0)
    lab, _ = ndimage.label(c > 0)
    span = np.intersect1d(lab[0][lab[0] > 0], lab[-1][lab[-1] > 0])
    cells = np.isin(lab, span)
    idx = -np.ones(gap.shape, dtype=np.int64)
    m = int(cells.sum())
    idx[cells] = np.arange(m)
    rows, cols, vals = [], [], []
    diag = np.zeros(gap.shape)
    for a, b, ca, cb, sa, sb in (
        (idx[:-1], idx[1:], c[:-1], c[1:], np.s_[:-1], np.s_[1:]),
        (idx[:, :-1], idx[:, 1:], c[:, :-1], c[:, 1:], np.s_[:, :-1], np.s_[:, 1:]),
    ):
        ok = (a >= 0) & (b >= 0)
        cf = np.zeros(a.shape)
        cf[ok] = 2 * ca[ok] * cb[ok] / (ca[ok] + cb[ok])
        rows += [a[ok], b[ok]]
        cols += [b[ok], a[ok]]
        vals += [-cf[ok], -cf[ok]]
        diag[sa] += cf
        diag[sb] += cf
    diag[0] += 2 * c[0]
    diag[-1] += 2 * c[-1]
    rows.append(idx[cells])
    cols.append(idx[cells])
    vals.append(diag[cells])
    a = sp.coo_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(m, m)
    )
    first = np.arange(gap.shape[0])[:, None] == 0
    last = np.arange(gap.shape[0])[:, None] == gap.shape[0] - 1
    return a, np.where(first, 2 * c, 0.0)[cells], np.where(last, 2 * c, 0.0)[cells]


def oracle_rate(gap: np.ndarray, contact: np.ndarray) -> float:
    """Q through the gap along axis 0 (η = Δp = dx = 1, side walls closed)."""
    a, b_in, b_out = _system(gap, contact)
    if a.shape[0] == 0:
        return 0.0
    return float(b_out @ spla.spsolve(a.tocsc(), b_in))


def near_threshold_gap(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A solved contact's gap at the highest approach (of a coarse scan) that still leaks."""
    s = leakpath.spectral(128, 0.8, seed=seed, rms_height=1.0)
    full = float(s.heights.max() - s.heights.min())
    best = None
    for frac in np.linspace(0.3, 0.8, 11):
        st = leakpath.solve(s, frac * full, solver="polonsky-keer")
        gap, contact = np.maximum(st.gap, 0.0), np.asarray(st.contact)
        if leakpath.percolation(np.where(contact, 0.0, gap), dx=1.0).percolates:
            best = (gap, contact)
        else:
            break
    assert best is not None
    return best


def test_a_looser_tol_keeps_the_factors_first_answer_within_it():
    # A gap whose factored answer has a first-order rate error of ~3e-11 (the gap raised to
    # the fourth power: conductances over more decades), 30 times either bound, so that the
    # rounding of another CPU's dense kernels cannot move it across one: the default tol
    # (1e-12) refines it in two doubles, tol=1e-9 keeps it (docs/flow.md, "Accuracy").
    s = leakpath.spectral(256, 0.8, seed=1, rms_height=1.0)
    g0 = s.heights.max() - s.heights
    g = g0 - np.quantile(g0, 0.45)
    contact = g <= 0
    gap = np.where(contact, 0.0, g) ** 4
    tight = leakpath.flow(gap, dx=1.0, contact=contact)
    loose = leakpath.flow(gap, dx=1.0, contact=contact, tol=1e-9)
    assert tight.solver == loose.solver == "cholesky"
    # Refined: the residual of two doubles; kept: the residual of one.
    assert tight.residual < 1e-20 < loose.residual < 1e-9
    q = oracle_rate(gap, contact)
    assert abs(tight.flow_rate - q) <= 1e-9 * q
    assert 0 < abs(loose.flow_rate - tight.flow_rate) <= 1e-9 * tight.flow_rate
    assert abs(loose.inlet_flow_rate - loose.flow_rate) <= 1e-9 * loose.flow_rate


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("solver", ["auto", "cholesky", "multigrid"])
def test_contact_gap_near_threshold_matches_spsolve(seed, solver):
    gap, contact = near_threshold_gap(seed)
    q = oracle_rate(gap, contact)
    assert q > 0
    f = leakpath.flow(gap, dx=1.0, contact=contact, solver=solver)
    assert f.flow_rate == pytest.approx(q, rel=1e-8, abs=0)
    assert abs(f.inlet_flow_rate / f.flow_rate - 1) <= 1e-9


def extended_oracle_rates(gap: np.ndarray, contact: np.ndarray) -> tuple[float, float]:
    """Outlet and inlet rates of the same system by scipy's sparse LU with iterative
    refinement whose residuals are summed in numpy's extended precision (``longdouble``):
    the digits a double-precision factor loses when ``g³`` spans many decades come back."""
    a, b_in, b_out = _system(gap, contact)
    m = a.shape[0]
    lu = spla.splu(a.tocsc())
    ld = np.longdouble
    data = a.data.astype(ld)

    def solve(b):
        x = lu.solve(b).astype(ld)
        for _ in range(6):
            ax = np.zeros(m, ld)
            np.add.at(ax, a.row, data * x[a.col])
            x += lu.solve(np.asarray(b.astype(ld) - ax, dtype=float)).astype(ld)
        return x

    phi, psi = solve(b_in), solve(b_out)
    return float(np.sum(b_out.astype(ld) * phi)), float(np.sum(b_in.astype(ld) * psi))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_default_rates_match_an_extended_precision_oracle(seed):
    gap, contact = near_threshold_gap(seed)
    q_out, q_in = extended_oracle_rates(gap, contact)
    assert q_out == pytest.approx(q_in, rel=1e-11, abs=0)
    f = leakpath.flow(gap, dx=1.0, contact=contact)
    assert f.solver == "cholesky"
    assert f.flow_rate == pytest.approx(q_out, rel=1e-11, abs=0)
    assert f.inlet_flow_rate == pytest.approx(q_out, rel=1e-11, abs=0)
