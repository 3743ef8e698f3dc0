"""Elastic–perfectly-plastic contact (hardness cap ``p ≤ H``) against independent oracles:
the bound-constrained quadratic programme solved with scipy on the dense influence matrix,
the flat punch, the uniform-pressure limit, the elastic limit and unloading."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.optimize import brentq, minimize

from leakpath import _core
from leakpath.contact import ContactProblem, solve
from leakpath.errors import InvalidArgumentError, SlopeWarning
from leakpath.surfaces import Surface

DX = 0.1


def rough(n: int, seed: int) -> np.ndarray:
    """A smooth random surface (low-pass filtered noise)."""
    rng = np.random.default_rng(seed)
    w = rng.standard_normal((n, n))
    k = np.fft.fftfreq(n)
    filt = 1.0 / (1.0 + (np.hypot(*np.meshgrid(k, k, indexing="ij")) * n / 3.0) ** 2)
    h = np.real(np.fft.ifft2(np.fft.fft2(w) * filt))
    return h / h.std()


def dense(problem: ContactProblem) -> np.ndarray:
    n = problem.surface.heights.size
    return problem._core.block(np.arange(n, dtype=np.int64))


def box_qp(c: np.ndarray, b: np.ndarray, cap: float) -> np.ndarray:
    """min ½pᵀCp − bᵀp over 0 ≤ p ≤ H: L-BFGS-B finds the sets, then the free set's linear
    system is solved exactly and the sets corrected until the KKT conditions hold."""
    n = b.size
    res = minimize(
        lambda p: (0.5 * p @ c @ p - b @ p, c @ p - b),
        np.zeros(n),
        jac=True,
        method="L-BFGS-B",
        bounds=[(0.0, cap)] * n,
        options={"ftol": 1e-15, "gtol": 1e-12, "maxiter": 50000, "maxcor": 50},
    )
    p = res.x
    tol = 1e-6 * cap
    lower = p <= tol
    upper = p >= cap - tol
    for _ in range(50):
        free = ~(lower | upper)
        q = np.where(upper, cap, 0.0)
        if free.any():
            rhs = b[free] - c[np.ix_(free, upper)] @ q[upper]
            q[free] = np.linalg.solve(c[np.ix_(free, free)], rhs)
        g = c @ q - b
        bad_lo = free & (q < 0)
        bad_hi = free & (q > cap)
        leave_lo = lower & (g < -1e-13)
        leave_hi = upper & (g > 1e-13)
        if not (bad_lo.any() or bad_hi.any() or leave_lo.any() or leave_hi.any()):
            return q
        lower = (lower & ~leave_lo) | bad_lo
        upper = (upper & ~leave_hi) | bad_hi
    raise AssertionError("the active-set refinement of the oracle did not settle")


@pytest.mark.parametrize("boundary", ["free", "periodic"])
@pytest.mark.parametrize("n", [12, 16])
def test_displacement_control_matches_the_box_qp(boundary: str, n: int) -> None:
    h = rough(n, n)
    problem = ContactProblem(Surface(h, DX), boundary=boundary)  # type: ignore[arg-type]
    c = dense(problem)
    delta = 0.5 * (h.max() - h.mean())
    elastic = problem.solve(delta, solver="polonsky-keer")
    cap = 0.4 * float(elastic.pressure.max())
    capped = ContactProblem(Surface(h, DX), boundary=boundary, hardness=cap)  # type: ignore[arg-type]
    state = capped.solve(delta)
    b = delta - (h.max() - h).ravel()
    want = box_qp(c, b, cap)
    got = state.pressure.ravel()
    assert np.max(np.abs(got - want)) <= 1e-9 * cap
    assert np.array_equal(got >= cap, want >= cap)
    assert np.array_equal(got > 0, want > 0)
    assert state.yielding.sum() > 0
    assert state.kkt <= 1e-12
    # The plastic displacement is the interpenetration at the yielding points.
    g_raw = (c @ want - b).reshape(n, n)
    w = np.where(want.reshape(n, n) >= cap, -g_raw, 0.0)
    assert np.max(np.abs(state.plastic_displacement - w)) <= 1e-8 * h.std()
    assert np.all(state.plastic_displacement >= 0)


@pytest.mark.parametrize("boundary", ["free", "periodic"])
def test_load_control_matches_the_box_qp_at_the_load(boundary: str) -> None:
    n = 12
    h = rough(n, 3)
    problem = ContactProblem(Surface(h, DX), boundary=boundary)  # type: ignore[arg-type]
    c = dense(problem)
    pbar = 0.05
    elastic = problem.solve(mean_pressure=pbar)
    cap = 0.5 * float(elastic.pressure.max())

    def excess(delta: float) -> float:
        return box_qp(c, delta - (h.max() - h).ravel(), cap).mean() - pbar

    d_star = brentq(excess, 0.0, 20 * (h.max() - h.min()), xtol=1e-14, rtol=1e-14)
    want = box_qp(c, d_star - (h.max() - h).ravel(), cap)
    state = ContactProblem(
        Surface(h, DX), boundary=boundary, hardness=cap  # type: ignore[arg-type]
    ).solve(mean_pressure=pbar)
    assert abs(state.mean_pressure - pbar) <= 1e-9 * pbar
    assert np.max(np.abs(state.pressure.ravel() - want)) <= 1e-7 * cap
    assert np.array_equal(state.pressure.ravel() >= cap, want >= cap)
    assert abs(state.approach - d_star) <= 1e-7 * (h.max() - h.min())


def test_flat_punch_edges_saturate_first() -> None:
    # A flat square punch (height 1) on a low base: the elastic pressure under a flat punch
    # is singular at its edges, so with a cap between the centre and edge pressures the
    # rim yields and the centre stays elastic.
    n, a = 24, 8
    h = np.zeros((n, n))
    lo = (n - a) // 2
    h[lo : lo + a, lo : lo + a] = 1.0
    delta = 0.01
    elastic = ContactProblem(Surface(h, DX)).solve(delta, solver="polonsky-keer")
    punch = elastic.pressure[lo : lo + a, lo : lo + a]
    assert np.all(punch > 0) and elastic.contact.sum() == a * a
    centre, corner = punch[a // 2, a // 2], punch[0, 0]
    cap = 0.5 * (centre + corner)
    s = ContactProblem(Surface(h, DX), hardness=cap).solve(delta)
    yielding = s.yielding[lo : lo + a, lo : lo + a]
    assert yielding[0, 0] and yielding[-1, -1] and yielding[0, -1] and yielding[-1, 0]
    assert not yielding[a // 2, a // 2]
    assert s.yielding.sum() == yielding.sum()  # nothing outside the punch
    # The box QP agrees.
    c = dense(ContactProblem(Surface(h, DX)))
    want = box_qp(c, delta - (h.max() - h).ravel(), cap)
    assert np.max(np.abs(s.pressure.ravel() - want)) <= 1e-9 * cap
    # Pressed harder, the whole punch face reaches the hardness.
    full = ContactProblem(Surface(h, DX), hardness=cap).solve(mean_pressure=cap * a * a / n**2)
    face = full.pressure[lo : lo + a, lo : lo + a]
    assert np.all(np.abs(face - cap) <= 1e-8 * cap)
    assert full.pressure.sum() - face.sum() <= 1e-8 * cap


@pytest.mark.parametrize("boundary", ["free", "periodic"])
def test_uniform_pressure_limit(boundary: str) -> None:
    h = rough(16, 5)
    cap = 0.2
    problem = ContactProblem(Surface(h, DX), boundary=boundary, hardness=cap)  # type: ignore[arg-type]
    s = problem.solve(mean_pressure=cap)
    assert np.all(s.pressure == cap)
    assert s.plastic_fraction > 0.99
    assert np.all(s.gap >= 0)
    near = problem.solve(mean_pressure=cap * (1 - 1e-3))
    assert near.contact_fraction == 1.0
    assert np.count_nonzero(near.yielding) / near.n_points > 0.9


def test_infinite_hardness_is_the_elastic_solution_bit_for_bit() -> None:
    h = rough(40, 7)
    s = Surface(h, DX)
    for kw in ({"approach": 1.0}, {"mean_pressure": 0.05}):
        a = ContactProblem(s).solve(**kw, solver="polonsky-keer")  # type: ignore[arg-type]
        b = ContactProblem(s, hardness=float("inf")).solve(**kw, solver="polonsky-keer")  # type: ignore[arg-type]
        assert np.array_equal(a.pressure, b.pressure)
        assert np.array_equal(a.gap, b.gap)
        assert a.approach == b.approach and a.iterations == b.iterations
        assert b.hardness is None and b.plastic_volume == 0.0
        # A hardness above every elastic pressure: the elastic solution (another
        # iteration, so to the tolerance) with the same contact set.
        big = 10.0 * float(a.pressure.max())
        c = ContactProblem(s, hardness=big).solve(**kw)  # type: ignore[arg-type]
        assert np.array_equal(c.contact, a.contact)
        assert np.max(np.abs(c.pressure - a.pressure)) <= 1e-8 * float(a.pressure.max())
        assert c.plastic_fraction == 0.0
    # The binding directly: inf is the elastic solve.
    core = _core.ContactProblem(h, DX, 1.0)
    r1 = core.solve(approach=1.0, solver="polonsky-keer")
    r2 = core.solve(approach=1.0, solver="polonsky-keer", hardness=float("inf"))
    assert np.array_equal(r1.pressure, r2.pressure)


@pytest.mark.parametrize("boundary", ["free", "periodic"])
def test_unloading_is_the_elastic_solve_on_the_deformed_surface(boundary: str) -> None:
    h = rough(32, 9)
    cap = 0.1
    problem = ContactProblem(Surface(h, DX), boundary=boundary, hardness=cap)  # type: ignore[arg-type]
    top = problem.solve(mean_pressure=0.04)
    assert top.plastic_volume > 0
    unload = problem.unloading(top)
    low = unload.solve(mean_pressure=0.01)
    perm = top.permanent_surface
    ref = ContactProblem(Surface(perm, DX), boundary=boundary).solve(  # type: ignore[arg-type]
        mean_pressure=0.01, solver="polonsky-keer"
    )
    assert np.max(np.abs(low.pressure - ref.pressure)) <= 1e-8 * cap
    assert np.array_equal(low.contact, ref.contact)
    # Approaches are referenced to the original surface's highest point.
    assert low.approach == pytest.approx(ref.approach + (h.max() - perm.max()), abs=1e-9)
    # The plastic part does not recover; the gap is that of the deformed interface.
    assert np.array_equal(low.plastic_displacement, top.plastic_displacement)
    assert np.allclose(low.gap, ref.gap, atol=1e-9)
    # Displacement control on the unloading problem: the same state at the same approach.
    again = unload.solve(low.approach)
    assert np.max(np.abs(again.pressure - low.pressure)) <= 1e-7 * cap
    # Less load after unloading at the same approach as on loading (the flattened tops).
    reload_top = unload.solve(mean_pressure=0.04)
    assert reload_top.yielding.sum() <= top.yielding.sum()


def test_threads_do_not_change_the_capped_result() -> None:
    h = rough(80, 11)
    problem = ContactProblem(Surface(h, DX), hardness=0.05)
    a = problem.solve(mean_pressure=0.01, threads=1)
    b = problem.solve(mean_pressure=0.01, threads=2)
    assert np.array_equal(a.pressure, b.pressure)
    assert a.approach == b.approach


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), "hard", True, float("-inf")])
def test_bad_hardness_is_refused_naming_it(bad: object) -> None:
    with pytest.raises(InvalidArgumentError) as e:
        ContactProblem(Surface(rough(8, 1), DX), hardness=bad)  # type: ignore[arg-type]
    assert e.value.argument == "hardness"
    with pytest.raises(ValueError, match="hardness"):
        _core.ContactProblem(rough(8, 1), DX, 1.0).solve(approach=1.0, hardness=-1.0)


def test_load_above_hardness_and_exact_solvers_are_refused() -> None:
    problem = ContactProblem(Surface(rough(12, 2), DX), hardness=0.1)
    with pytest.raises(InvalidArgumentError) as e:
        problem.solve(mean_pressure=0.2)
    assert e.value.argument == "mean_pressure"
    for solver in ("active-set", "lawson-hanson"):
        with pytest.raises(InvalidArgumentError) as e:
            problem.solve(1.0, solver=solver)  # type: ignore[arg-type]
        assert e.value.argument == "solver"
    # auto resolves to Polonsky–Keer even on a small grid.
    assert problem.solve(1.0).solver == "polonsky-keer"
    core = _core.ContactProblem(rough(8, 1), DX, 1.0)
    assert core.solve(approach=1.0, hardness=0.1).solver == "polonsky-keer"
    with pytest.raises(ValueError, match="mean_pressure"):
        core.solve(mean_pressure=0.5, hardness=0.1)
    # The module-level solve takes the hardness too.
    s = solve(Surface(rough(12, 2), DX), mean_pressure=0.05, hardness=0.1)
    assert s.hardness == 0.1 and s.pressure.max() <= 0.1


def test_periodic_load_control_where_preconditioned_steps_stall() -> None:
    """A periodic 128² load-controlled capped solve (H = 0.25 of the elastic maximum) on which
    the preconditioned capped steps stall: the solve must still converge, to the same
    minimiser as the plain capped iteration (same contact and plastic sets)."""
    n, hurst = 128, 0.8
    rng = np.random.default_rng(1)
    k = np.hypot(*np.meshgrid(np.fft.fftfreq(n), np.fft.fftfreq(n), indexing="ij"))
    k[0, 0] = 1.0
    filt = k ** (-(1.0 + hurst))
    filt[k < 4.0 / n] = (4.0 / n) ** (-(1.0 + hurst))
    filt[0, 0] = 0.0
    h = np.real(np.fft.ifft2(np.fft.fft2(rng.standard_normal((n, n))) * filt))
    h /= h.std()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SlopeWarning)
        elastic = ContactProblem(Surface(h, 1.0), boundary="periodic").solve(mean_pressure=0.05)
    cap = 0.25 * float(elastic.pressure.max())
    core = _core.ContactProblem(h, 1.0, 1.0, "periodic")
    pre = core.solve(mean_pressure=0.05, hardness=cap, solver="polonsky-keer")
    plain = core.solve(mean_pressure=0.05, hardness=cap, solver="polonsky-keer", precondition=False)
    assert pre.kkt <= 1e-10 and plain.kkt <= 1e-10
    assert pre.preconditioner_products > 0
    assert np.array_equal(pre.pressure > 0, plain.pressure > 0)
    assert np.array_equal(pre.pressure >= cap, plain.pressure >= cap)
    assert np.max(np.abs(pre.pressure - plain.pressure)) <= 1e-8 * cap
    assert abs(pre.mean_pressure - 0.05) <= 1e-9 * 0.05


@pytest.mark.parametrize(("seed", "fraction"), [(0, 0.75), (1, 0.25), (5, 0.5)])
def test_load_control_at_a_loose_tolerance_meets_its_load(seed: int, fraction: float) -> None:
    """At ``tol = 1e-8`` the warm-started solves of the load root search can meet their KKT
    tolerance without moving, while their load is still a few ``tol`` off: the search must
    tighten them rather than collapse its bracket and give up. The answer is checked against
    the bound-constrained QP (scipy) at the approach it reports."""
    from leakpath.generators import rmd

    s = rmd(6, 2.2, seed=seed)
    elastic = ContactProblem(s, boundary="periodic")
    h = s.heights
    ref = elastic.solve(0.3 * (h.max() - h.mean()), tol=1e-8)
    cap = fraction * float(ref.pressure.max())
    problem = ContactProblem(s, boundary="periodic", hardness=cap)
    state = problem.solve(mean_pressure=ref.mean_pressure, tol=1e-8, warm_start=False)
    assert abs(state.mean_pressure - ref.mean_pressure) <= 1e-8 * ref.mean_pressure
    c = dense(problem)
    want = box_qp(c, state.approach - (h.max() - h).ravel(), cap)
    assert np.max(np.abs(state.pressure.ravel() - want)) <= 1e-6 * cap
    assert np.array_equal(state.pressure.ravel() >= cap, want >= cap)
