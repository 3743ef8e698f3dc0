"""Contact solvers against independent oracles: dense Love products, scipy's NNLS, Hertz."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import nnls

import leakpath
from leakpath import _core
from leakpath.contact import ContactProblem, solve
from leakpath.errors import InvalidArgumentError

EXACT_SOLVERS = ["lawson-hanson", "active-set"]


def love_matrix(ny: int, nx: int, dx: float, e_star: float) -> np.ndarray:
    """Dense influence matrix from Love's closed form, written out here independently."""

    def f(x, y):
        # x ln(y + r) + y ln(x + r), the corner function of Johnson eq. 3.25 (log form).
        r = np.hypot(x, y)
        return x * np.log(y + r) + y * np.log(x + r)

    a = dx / 2
    yy, xx = np.meshgrid(np.arange(ny) * dx, np.arange(nx) * dx, indexing="ij")
    y, x = yy.ravel(), xx.ravel()
    X = np.abs(x[:, None] - x[None, :])
    Y = np.abs(y[:, None] - y[None, :])
    u = f(X + a, Y + a) - f(X + a, Y - a) - f(X - a, Y + a) + f(X - a, Y - a)
    return u / (np.pi * e_star)


@pytest.mark.parametrize("shape", [(9, 9), (8, 8), (7, 12), (13, 6)])
def test_free_operator_equals_dense_love_product(shape):
    rng = np.random.default_rng(1)
    dx, e_star = 0.37, 2.5
    h = rng.random(shape)
    prob = _core.ContactProblem(h, dx, e_star, "free")
    C = love_matrix(*shape, dx, e_star)
    for _ in range(3):
        p = rng.random(shape)
        u = prob.apply(p)
        ref = (C @ p.ravel()).reshape(shape)
        assert np.max(np.abs(u - ref)) <= 1e-12 * np.max(np.abs(ref))
    # The blocks used by Lawson–Hanson are the same matrix.
    idx = np.array([0, 3, 5, shape[0] * shape[1] - 1])
    np.testing.assert_allclose(prob.block(idx), C[np.ix_(idx, idx)], rtol=0, atol=1e-12 * C.max())


@pytest.mark.parametrize("shape", [(16, 16), (9, 9), (10, 15)])
def test_periodic_operator_equals_dense_circulant(shape):
    rng = np.random.default_rng(2)
    ny, nx = shape
    dx, e_star = 0.5, 1.3
    qy = 2 * np.pi * np.fft.fftfreq(ny, dx)
    qx = 2 * np.pi * np.fft.fftfreq(nx, dx)
    q = np.hypot(qy[:, None], qx[None, :])
    stiff = np.zeros_like(q)
    stiff[q > 0] = 2.0 / (e_star * q[q > 0])
    # Dense circulant: column j is the response to a unit pressure at j.
    C = np.empty((ny * nx, ny * nx))
    for j in range(ny * nx):
        e = np.zeros(ny * nx)
        e[j] = 1.0
        C[:, j] = np.real(np.fft.ifft2(np.fft.fft2(e.reshape(shape)) * stiff)).ravel()
    prob = _core.ContactProblem(rng.random(shape), dx, e_star, "periodic")
    for _ in range(3):
        p = rng.random(shape)
        ref = (C @ p.ravel()).reshape(shape)
        u = prob.apply(p)
        assert np.max(np.abs(u - ref)) <= 1e-12 * np.max(np.abs(ref))


def nnls_reference(h: np.ndarray, dx: float, approach: float) -> np.ndarray:
    """min ½pᵀCp − bᵀp, p ≥ 0  ⇔  min ‖R p − R⁻ᵀ b‖, C = RᵀR, by scipy's NNLS."""
    C = love_matrix(*h.shape, dx, 1.0)
    b = approach - (h.max() - h.ravel())
    R = np.linalg.cholesky(C).T
    d = np.linalg.solve(R.T, b)
    p, _ = nnls(R, d, maxiter=50 * len(b))
    return p.reshape(h.shape)


@pytest.mark.parametrize("solver", EXACT_SOLVERS)
@pytest.mark.parametrize("n,seed", [(5, 0), (9, 1), (12, 2), (17, 3)])
def test_lawson_hanson_equals_scipy_nnls(solver, n, seed):
    rng = np.random.default_rng(seed)
    h = rng.standard_normal((n, n))
    dx = 0.1
    prob = ContactProblem(h, dx=dx)
    hs = h.max() - h.min()
    for frac in (0.05, 0.3, 0.7, 1.0):
        state = prob.solve(frac * hs, solver=solver)
        ref = nnls_reference(h, dx, frac * hs)
        scale = np.abs(ref).max()
        assert np.max(np.abs(state.pressure - ref)) <= 1e-10 * scale
        np.testing.assert_array_equal(state.contact, ref > 1e-12 * scale)
        # KKT: gap ≥ 0, zero gap on contact, complementarity — checked from the fields.
        g = state.gap
        assert g.min() >= -1e-12 * hs
        assert np.abs(g[state.contact]).max() <= 1e-12 * hs
        assert state.kkt <= 1e-11


@pytest.mark.parametrize("solver", EXACT_SOLVERS)
def test_warm_start_equals_cold(solver):
    s = leakpath.rmd(5, 2.3, seed=4)
    prob = ContactProblem(s)
    cold_prob = ContactProblem(s)
    hs = s.height_range
    for k in range(1, 11):
        a = k * hs / 10
        warm = prob.solve(a, solver=solver, warm_start=True)
        cold = cold_prob.solve(a, solver=solver, warm_start=False)
        scale = np.abs(cold.pressure).max()
        assert np.max(np.abs(warm.pressure - cold.pressure)) <= 1e-10 * scale
        np.testing.assert_array_equal(warm.contact, cold.contact)
    # Warm start from a given state's contact set (e.g. a deeper level) also lands there.
    deep = cold_prob.solve(hs, solver=solver)
    shallow = prob.solve(0.5 * hs, solver=solver, warm_start=deep)
    ref = cold_prob.solve(0.5 * hs, solver=solver)
    assert np.max(np.abs(shallow.pressure - ref.pressure)) <= 1e-10 * np.abs(ref.pressure).max()


def test_hertz_paraboloid():
    n, R, e_star = 161, 1.0, 1.0
    L = 0.5
    dx = L / n
    c = (n - 1) / 2
    y, x = (np.mgrid[0:n, 0:n] - c) * dx
    h = -(x**2 + y**2) / (2 * R)
    a_target = 60 * dx / 2  # contact radius ≈ 30 elements
    delta = a_target**2 / R
    state = solve(h, delta, dx=dx, E=e_star, solver="active-set")
    a_hertz = np.sqrt(R * delta)
    p0 = 2 * e_star * a_hertz / (np.pi * R)
    F = 4 / 3 * e_star * np.sqrt(R) * delta**1.5
    a_num = np.sqrt(state.contact_area / np.pi)
    assert abs(a_num / a_hertz - 1) < 0.02
    assert abs(state.pressure[int(c), int(c)] / p0 - 1) < 0.02
    assert abs(state.load / F - 1) < 0.02
    # Load–approach relation at a second approach: F ∝ δ^{3/2}.
    state2 = solve(h, 0.5 * delta, dx=dx, E=e_star, solver="active-set")
    assert abs(state2.load / (4 / 3 * e_star * np.sqrt(R) * (0.5 * delta) ** 1.5) - 1) < 0.02


def test_state_quantities_are_consistent():
    s = leakpath.rmd(4, 2.2, seed=1, length=2.0)
    st = solve(s, 0.4 * s.height_range, E=3.0, nu=0.3, solver="active-set")
    dx = s.dx
    assert st.e_star == pytest.approx(3.0 / (1 - 0.09))
    np.testing.assert_allclose(st.deformed, s.heights - st.displacement)
    expected_gap = s.heights.max() - st.approach - s.heights + st.displacement
    np.testing.assert_allclose(st.gap, expected_gap, atol=1e-14 * s.height_range)
    assert st.load == pytest.approx(dx**2 * st.pressure.sum())
    assert st.free_volume == pytest.approx(dx**2 * st.gap.sum())
    assert st.mean_gap == pytest.approx(st.free_volume / (s.heights.size * dx**2))
    assert st.contact_fraction == np.count_nonzero(st.pressure > 0) / s.heights.size


def test_zero_approach_is_zero_pressure():
    s = leakpath.rmd(4, 2.5, seed=2)
    st = solve(s, 0.0)
    assert np.all(st.pressure == 0)
    assert st.load == 0
    assert st.free_volume == pytest.approx(s.dx**2 * np.sum(s.heights.max() - s.heights))


@pytest.mark.parametrize(
    "kwargs,name",
    [
        ({"approach": -0.1}, "approach"),
        ({"approach": float("nan")}, "approach"),
        ({"approach": 10.0, "boundary": "periodic"}, "approach"),
        ({"E": 0.0}, "E"),
        ({"E": -1.0}, "E"),
        ({"nu": 0.6}, "nu"),
        ({"nu": -1.0}, "nu"),
        ({"solver": "simplex"}, "solver"),
        ({"boundary": "open"}, "boundary"),
        ({"tol": -1.0}, "tol"),
    ],
)
def test_bad_arguments_name_themselves(kwargs, name):
    s = leakpath.rmd(3, 2.5, seed=0)
    args = {"approach": 0.1 * s.height_range}
    args.update(kwargs)
    approach = args.pop("approach")
    with pytest.raises(ValueError, match=rf"^{name}\b"):
        solve(s, approach, **args)


def test_free_boundary_presses_past_the_height_range():
    """A free patch is only partly in contact at Δ = h_s; deeper approaches keep adding
    contact and are solved exactly (Polonsky–Keer and the active set agree)."""
    s = leakpath.rmd(5, 2.1, seed=1)
    hs = s.height_range
    at_hs = solve(s, hs)
    deeper = solve(s, 1.5 * hs, solver="polonsky-keer")
    exact = solve(s, 1.5 * hs, solver="active-set")
    assert at_hs.contact_fraction < deeper.contact_fraction < 1.0
    assert np.array_equal(deeper.contact, exact.contact)
    assert deeper.kkt <= 1e-12 and exact.kkt <= 1e-12


def test_bad_heights():
    h = np.ones((5, 5))
    h[2, 2] = np.nan
    with pytest.raises(ValueError, match="heights"):
        solve(h, 0.1, dx=1.0)
    with pytest.raises(ValueError, match="heights"):
        solve(np.ones(5), 0.1, dx=1.0)
    with pytest.raises(ValueError, match="dx"):
        solve(np.ones((5, 5)), 0.1)


@pytest.mark.parametrize("cells", [[(299, 299), (250, 10)], [(0, 5), (299, 0)],
                                   [(218, 160), (218, 161), (218, 159)]])
def test_the_first_non_finite_initial_pressure_is_named(cells):
    # 300² values: more than one block of the core's parallel search (65,536), the bad
    # values in different blocks and on both sides of the edge at (218, 136).
    prob = _core.ContactProblem(np.zeros((300, 300)), 1.0 / 300, 1.0, "periodic")
    p0 = np.zeros((300, 300))
    for k, c in enumerate(cells):
        p0[c] = [np.nan, np.inf, -np.inf][k % 3]
    first = min(cells)
    with pytest.raises(ValueError, match="initial_pressure") as e:
        prob.solve(approach=0.1, solver="polonsky-keer", start="pressure", initial_pressure=p0)
    assert f"element ({first[0]}, {first[1]})" in str(e.value)


def test_too_large_is_refused_with_an_estimate():
    s = leakpath.rmd(5, 2.3, seed=0)
    prob = ContactProblem(s, memory_limit=200 * 1024 * 1024 // 100)  # 2 MiB
    with pytest.raises(MemoryError, match=r"limit of 2 MiB"):
        prob.solve(s.height_range, solver="active-set")
    with pytest.raises(MemoryError, match=r"limit of 1 MiB"):
        ContactProblem(leakpath.rmd(8, 2.3, seed=0), memory_limit=1 << 20)


def test_periodic_full_contact_limit():
    s = leakpath.spectral(32, 0.8, seed=1, rms_height=1.0)
    prob = ContactProblem(s, boundary="periodic")
    limit = s.heights.max() - s.heights.mean()
    assert prob.max_approach == pytest.approx(limit)
    with pytest.raises(ValueError, match="approach"):
        prob.solve(1.01 * limit)
    st = prob.solve(0.5 * limit, solver="active-set")
    # u has zero mean, so the mean gap is fixed by the approach alone.
    assert st.displacement.mean() == pytest.approx(0.0, abs=1e-12 * s.height_range)
    assert st.mean_gap == pytest.approx(limit - 0.5 * limit, rel=1e-10)


def periodic_matrix(ny: int, nx: int, dx: float, e_star: float) -> np.ndarray:
    """Dense circulant of the periodic half-space, ``û_q = 2 p̂_q/(E*|q|)``, by numpy FFTs."""
    qy = 2 * np.pi * np.fft.fftfreq(ny, dx)
    qx = 2 * np.pi * np.fft.fftfreq(nx, dx)
    q = np.hypot(qy[:, None], qx[None, :])
    stiff = np.zeros_like(q)
    stiff[q > 0] = 2.0 / (e_star * q[q > 0])
    eye = np.eye(ny * nx).reshape(ny * nx, ny, nx)
    cols = np.real(np.fft.ifft2(np.fft.fft2(eye, axes=(1, 2)) * stiff, axes=(1, 2)))
    return cols.reshape(ny * nx, ny * nx).T


def qp_reference(C: np.ndarray, b: np.ndarray) -> np.ndarray:
    """min ½pᵀCp − bᵀp, p ≥ 0 for a semidefinite C: projected Gauss–Seidel to find the
    support, then an exact solve on it (numpy), verified against the KKT conditions."""
    n = b.size
    p = np.zeros(n)
    for _ in range(3000):
        for i in range(n):
            r = b[i] - C[i] @ p + C[i, i] * p[i]
            p[i] = max(r / C[i, i], 0.0)
    support = p > 1e-8 * max(p.max(), 1e-300)
    exact = np.zeros(n)
    exact[support] = np.linalg.solve(C[np.ix_(support, support)], b[support])
    g = C @ exact - b
    assert exact.min() >= 0 and g.min() >= -1e-10 * np.abs(b).max(), "reference failed"
    return exact


@pytest.mark.parametrize("solver", EXACT_SOLVERS)
@pytest.mark.parametrize("shape,seed", [((8, 8), 0), ((12, 9), 1), ((10, 10), 2)])
def test_periodic_exact_solvers_equal_reference(solver, shape, seed):
    rng = np.random.default_rng(seed)
    h = rng.standard_normal(shape)
    dx = 0.2
    C = periodic_matrix(*shape, dx, 1.0)
    prob = ContactProblem(h, dx=dx, boundary="periodic")
    limit = h.max() - h.mean()
    for frac in (0.1, 0.4, 0.8):
        a = frac * limit
        b = a - (h.max() - h.ravel())
        p_ref = qp_reference(C, b)
        st = prob.solve(a, solver=solver)
        scale = np.abs(p_ref).max()
        assert np.max(np.abs(st.pressure.ravel() - p_ref)) <= 1e-9 * scale
        assert st.kkt <= 1e-10
        assert st.gap.min() >= -1e-11 * limit


def full_contact_reference(C: np.ndarray, h: np.ndarray, mean_pressure: float):
    """Full contact under load control is linear: ``C p − Δ 1 = h − max h``, ``Σ p = p̄ N``
    (a bordered system solved densely by numpy); returns ``(p, Δ)``."""
    n = h.size
    a = np.zeros((n + 1, n + 1))
    a[:n, :n] = C
    a[:n, n] = -1.0
    a[n, :n] = 1.0
    rhs = np.append(h.ravel() - h.max(), mean_pressure * n)
    x = np.linalg.solve(a, rhs)
    return x[:n], x[n]


@pytest.mark.parametrize("boundary", ["free", "periodic"])
@pytest.mark.parametrize("mean_pressure", [1e4, 1e6])
def test_load_control_far_past_full_contact(boundary, mean_pressure):
    """p̄ ≫ E*: the whole patch is in contact and the answer is the linear full-contact
    solution. The certificate is relative to max(h_s, |Δ|, p̄·C_00) (round-off of u and Δ
    is relative to them), so such loads converge instead of stalling at ~1e-12 h_s."""
    s = leakpath.rmd(5, 2.2, seed=1)
    dx = s.dx
    if boundary == "free":
        C = love_matrix(*s.shape, dx, 1.0)
    else:
        C = periodic_matrix(*s.shape, dx, 1.0)
    p_ref, delta_ref = full_contact_reference(C, s.heights, mean_pressure)
    assert p_ref.min() > 0  # the reference is a contact solution: p > 0 everywhere
    st = ContactProblem(s, boundary=boundary).solve(mean_pressure=mean_pressure)
    assert st.contact_fraction == 1.0
    assert st.kkt <= 1e-12
    assert np.max(np.abs(st.pressure.ravel() - p_ref)) <= 1e-9 * p_ref.max()
    assert st.approach == pytest.approx(delta_ref, rel=1e-9, abs=1e-9 * s.height_range)
    assert st.mean_pressure == pytest.approx(mean_pressure, rel=1e-12)


def test_load_control_refuses_loads_beyond_the_floating_point_range():
    s = leakpath.rmd(3, 2.2, seed=1)
    for bad in (1e200, 1e-200):
        with pytest.raises(InvalidArgumentError, match=r"^mean_pressure: .*1e±250") as info:
            solve(s, mean_pressure=bad)
        assert info.value.argument == "mean_pressure"


def test_solution_pressures_respect_the_warm_start_bound():
    """Free boundary: at a contact point C_00 p_i ≤ (C p)_i = Δ − (max h − h_i) ≤ Δ, all
    C_ij > 0, so p ≤ max(h_s, Δ)/C_00 — the scale against which warm starts are checked."""
    s = leakpath.rmd(5, 2.3, seed=2)
    c00 = love_matrix(1, 1, s.dx, 1.0)[0, 0]
    for frac in (0.2, 1.0, 3.0):
        a = frac * s.height_range
        st = solve(s, a, solver="active-set")
        assert 0 < st.pressure.max() <= a / c00 * (1 + 1e-12)


class _Duck:
    pressure = "1.0"
    contact = "yes"
    shape = (33, 33)


@pytest.mark.parametrize(
    "make",
    [
        lambda h: np.full(h.shape, 1e300),  # absurd magnitude: C p overflows
        lambda h: np.full(h.shape, -1.0),  # negative pressures
        lambda h: np.where(h > 0, np.nan, 0.0),  # NaN
        lambda h: np.ones((h.shape[0], h.shape[1] + 1)),  # wrong shape
        lambda h: [[1.0, 2.0], [3.0]],  # ragged
        lambda h: "pressure",  # a string
        lambda h: _Duck(),  # duck-typed state with string attributes
        lambda h: np.full(h.shape, "1.0"),  # an array of strings
    ],
    ids=["1e300", "negative", "nan", "shape", "ragged", "string", "duck", "str-array"],
)
def test_bad_warm_starts_are_refused_by_name(make):
    s = leakpath.rmd(5, 2.2, seed=1)
    prob = ContactProblem(s)
    with pytest.raises(InvalidArgumentError, match=r"^warm_start: ") as info:
        prob.solve(0.3 * s.height_range, warm_start=make(s.heights))
    assert info.value.argument == "warm_start"


def test_state_with_bad_fields_is_refused_as_warm_start():
    import dataclasses

    s = leakpath.rmd(5, 2.2, seed=1)
    prob = ContactProblem(s)
    good = prob.solve(0.3 * s.height_range)
    for pressure in ("abc", np.full(s.shape, "x"), np.full(s.shape, np.inf), np.zeros((3, 3))):
        bad = dataclasses.replace(good, pressure=pressure)
        with pytest.raises(InvalidArgumentError, match=r"^warm_start: "):
            prob.solve(0.3 * s.height_range, warm_start=bad)


def test_load_control_rescales_a_large_warm_start():
    """Load control rescales a start to the load, so any finite magnitude is a valid start:
    a 1e300 field lands on the cold solution; one whose sum overflows is refused."""
    s = leakpath.rmd(5, 2.2, seed=1)
    prob = ContactProblem(s)
    cold = prob.solve(mean_pressure=0.5, solver="polonsky-keer")
    warm = prob.solve(
        mean_pressure=0.5, solver="polonsky-keer", warm_start=np.full(s.shape, 1e300)
    )
    assert warm.kkt <= 1e-12
    np.testing.assert_array_equal(warm.contact, cold.contact)
    assert np.max(np.abs(warm.pressure - cold.pressure)) <= 1e-9 * cold.pressure.max()
    with pytest.raises(InvalidArgumentError, match=r"^warm_start: .*sums to inf"):
        prob.solve(mean_pressure=0.5, warm_start=np.full(s.shape, 1e306))


def test_single_precision_early_products_give_the_double_precision_minimiser():
    # Oracle: the same solve in double precision throughout (single_precision_above=0).
    s = leakpath.rmd(7, 2.2, seed=3)
    h = np.ascontiguousarray(s.heights)
    hs = float(h.max() - h.min())
    prob = _core.ContactProblem(h, s.dx, 1.0, "free")
    a = prob.solve(approach=0.3 * hs, solver="polonsky-keer", tol=1e-10)
    b = prob.solve(
        approach=0.3 * hs, solver="polonsky-keer", tol=1e-10, single_precision_above=0.0
    )
    assert a.single_products > 0 and b.single_products == 0
    assert a.kkt <= 1e-10 and b.kkt <= 1e-10
    np.testing.assert_array_equal(a.pressure > 0, b.pressure > 0)
    assert abs(a.load - b.load) <= 1e-6 * b.load
    for bad in (-1.0, float("nan")):
        with pytest.raises(ValueError, match=r"^single_precision_above\b"):
            prob.solve(approach=0.3 * hs, solver="polonsky-keer", single_precision_above=bad)
