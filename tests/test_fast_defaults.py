"""The default (``solver="auto"``) paths: the same minimiser as the exact solver, warm starts,
load control, and checkpoints that are bound to their run.

Oracles: the exact block active set (Lawson–Hanson with Cholesky updates) for contact sets,
a displacement-controlled solve at the returned approach for load control, and
``scipy.ndimage.label`` for spanning.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from scipy import ndimage

import leakpath
from leakpath import sweep
from leakpath._sweep import KKT_ACCEPT, SOLVE_TOL
from leakpath.contact import AUTO_ACTIVE_SET_MAX_POINTS, DEFAULT_TOL, ContactProblem, solve

LEVELS = 10


@pytest.fixture(scope="module")
def surface():
    # 65² > AUTO_ACTIVE_SET_MAX_POINTS, so "auto" runs Polonsky–Keer here.
    s = leakpath.spectral(65, 0.9, seed=2, rms_height=1.0)
    assert s.heights.size > AUTO_ACTIVE_SET_MAX_POINTS
    return s


@pytest.fixture(scope="module")
def default_sweep(surface):
    return sweep(surface, levels=LEVELS, keep_fields=True)


def spans_axis(free: np.ndarray, axis: int) -> bool:
    labels, _ = ndimage.label(free)
    first = np.take(labels, 0, axis=axis)
    last = np.take(labels, -1, axis=axis)
    return bool(set(first[first > 0]) & set(last[last > 0]))


def test_default_solver_is_polonsky_keer_with_a_tight_certificate(surface):
    st = solve(surface, 0.5 * surface.height_range)
    assert st.solver == "polonsky-keer"
    assert st.kkt <= 1e-12
    small = leakpath.rmd(4, 2.2, seed=0)
    assert solve(small, 0.5 * small.height_range).solver == "active-set"


def assert_within_certificate(prob, result, surface):
    """Every row of a Polonsky–Keer sweep against the exact solver (block active set), within
    what its KKT certificate bounds (``docs/conventions.md``, "Warm starts"): with
    ``ε = kkt·max(h_s, Δ)`` the level is the exact solution for heights moved by at most ``ε``
    at each point, so its gaps lie within ``ε`` of the exact gaps at ``Δ + ε`` and ``Δ − ε``,
    its free volume within ``ε·A0`` of the exact free volumes there (and within ``2ε·A0`` of
    the exact one at ``Δ``), its load between the exact loads. The contact set is the exact
    solver's."""
    hs, area = surface.height_range, surface.nominal_area
    mask = None
    for k, row in enumerate(result.rows):
        if k == 0:
            continue
        delta = row["approach"]
        eps = row["kkt"] * max(hs, delta)
        slack = 1e-13 * hs  # round-off of the exact solves
        exact = prob.solve(delta, solver="active-set", warm_start=mask)
        near = prob.solve(delta - eps, solver="active-set", warm_start=exact.contact)
        far = prob.solve(delta + eps, solver="active-set", warm_start=exact.contact)
        mask = exact.contact
        assert np.array_equal(result.contact_mask(k), exact.contact), k
        g = result.fields["gap"][k]
        assert np.all(g >= far.gap - eps - slack), k
        assert np.all(g <= near.gap + eps + slack), k
        v = row["free_volume"]
        assert far.free_volume - (eps + slack) * area <= v, k
        assert v <= near.free_volume + (eps + slack) * area, k
        assert abs(v - exact.free_volume) <= 2 * (eps + slack) * area, k
        assert near.load * (1 - 1e-12) <= row["load"] <= far.load * (1 + 1e-12), k
        assert row["solver"] == "polonsky-keer"
        assert row["kkt"] <= SOLVE_TOL  # the sweep's tolerance, below its acceptance


def test_default_sweep_has_the_exact_contact_sets(surface, default_sweep):
    """Every level of the default (warm, Polonsky–Keer) sweep has the exact solver's contact
    set, and its gaps, free volume and load are as close to the exact solver's as its KKT
    certificate guarantees; also a level past the height range."""
    prob = ContactProblem(surface)
    assert_within_certificate(prob, default_sweep, surface)
    assert default_sweep.parameters["solve_tol"] == SOLVE_TOL < KKT_ACCEPT
    deep = solve(surface, 1.3 * surface.height_range)
    exact = prob.solve(1.3 * surface.height_range, solver="active-set")
    assert np.array_equal(deep.contact, exact.contact)


def test_paper_sweep_has_the_exact_contact_sets():
    """The paper's 129² surface and 20 levels: the sweep's contact sets are the exact
    solver's at every level, the other columns within the certificate's bound."""
    from leakpath.experiments import paper_surface

    surface = paper_surface(0)
    result = sweep(surface, levels=20, flow=False, keep_fields=True)
    assert_within_certificate(ContactProblem(surface), result, surface)


def test_cold_replay_gives_the_same_table_to_round_off(surface, default_sweep):
    cold = sweep(surface, levels=LEVELS, warm_start=False)
    assert list(cold.column("n_contact")) == list(default_sweep.column("n_contact"))
    # Each free volume is within 2·kkt·h_s·A0 of the exact one (docs/conventions.md).
    bound = 2 * (cold.column("kkt") + default_sweep.column("kkt")) * surface.height_range
    diff = np.abs(cold.column("free_volume") - default_sweep.column("free_volume"))
    assert np.all(diff <= bound * surface.nominal_area * (1 + 1e-9))


def test_warm_start_from_a_state_or_pressure_field(surface):
    prob = ContactProblem(surface)
    hs = surface.height_range
    # One level of a 20-level sweep below.
    first = prob.solve(0.45 * hs)
    cold = prob.solve(0.5 * hs)
    from_state = prob.solve(0.5 * hs, warm_start=first)
    from_field = prob.solve(0.5 * hs, warm_start=first.pressure)
    assert np.array_equal(from_state.pressure, from_field.pressure)
    assert np.array_equal(from_state.contact, cold.contact)
    # A cold solve starts from the coarse-grid solution; against a start from p = 0 the warm
    # start must save FFT products (the work: a chord step is an iteration of one product, a
    # regular one with a wholesale set change two). On a grid this small the gain is a few
    # products and depends on the surface; the sweep benchmarks measure it at scale.
    from_zero = prob._core.solve(
        approach=0.5 * hs, solver="polonsky-keer", tol=DEFAULT_TOL, coarse_start=False
    )
    assert from_state.fft_products < from_zero.fft_products
    assert np.array_equal(from_zero.pressure > 0, cold.contact)
    with pytest.raises(ValueError, match="^warm_start"):
        prob.solve(0.5 * hs, warm_start=np.ones((3, 3), dtype=bool))
    with pytest.raises(ValueError, match="^warm_start"):
        prob.solve(0.5 * hs, warm_start=np.full(surface.shape, np.nan))


@pytest.mark.parametrize("boundary", ["free", "periodic"])
def test_load_control_reaches_the_displacement_solution(surface, boundary):
    prob = ContactProblem(surface, E=2.0, nu=0.3, boundary=boundary)
    pbar = 0.02 * prob.e_star * surface.height_range / surface.length[0]
    st = prob.solve(mean_pressure=pbar)
    assert st.mean_pressure == pytest.approx(pbar, rel=1e-12, abs=0)
    # The exact solver at the approach the load-controlled solve found.
    exact = prob.solve(st.approach, solver="active-set")
    assert np.array_equal(st.contact, exact.contact)
    assert exact.mean_pressure == pytest.approx(pbar, rel=1e-8)


def test_load_control_arguments(surface):
    prob = ContactProblem(surface)
    with pytest.raises(ValueError, match="^approach"):
        prob.solve(0.1, mean_pressure=0.1)
    with pytest.raises(ValueError, match="^approach"):
        prob.solve()
    with pytest.raises(ValueError, match="^mean_pressure"):
        prob.solve(mean_pressure=-1.0)
    with pytest.raises(ValueError, match="^solver"):
        prob.solve(mean_pressure=0.1, solver="active-set")


def test_sweep_over_mean_pressures(surface):
    e_star = 1.0 / (1 - 0.25**2)
    pressures = np.array([0.005, 0.01, 0.02, 0.04]) * e_star
    res = sweep(surface, mean_pressures=pressures, nu=0.25)
    np.testing.assert_allclose(res.column("mean_pressure"), pressures, rtol=1e-12)
    np.testing.assert_allclose(res.column("mean_pressure_star"), pressures / e_star, rtol=1e-12)
    assert np.all(np.diff(res.column("approach")) > 0)
    assert np.all(np.diff(res.column("contact_fraction")) > 0)
    with pytest.raises(ValueError, match="^mean_pressures"):
        sweep(surface, mean_pressures=[0.1, 0.05])
    with pytest.raises(ValueError, match="^mean_pressures"):
        sweep(surface, approaches=[0.0, 0.1], mean_pressures=[0.1])


def test_warm_sweep_resumes_byte_identically(tmp_path, surface, default_sweep):
    ck = tmp_path / "ck"
    full = sweep(surface, levels=LEVELS, checkpoint_dir=ck)
    assert full.csv_text() == default_sweep.csv_text()
    for k in range(4, LEVELS + 1):
        (ck / f"level_{k:04d}.json").unlink()
    again = sweep(surface, levels=LEVELS, checkpoint_dir=ck)
    assert again.resumed == [0, 1, 2, 3]
    assert again.csv_text() == full.csv_text()


def test_checkpoint_of_another_solve_tolerance_is_refused(tmp_path, surface, monkeypatch):
    """A checkpoint written with another sweep tolerance (an older leakpath's 1e-10) is
    refused, naming the parameter, rather than mixed with levels solved to this one."""
    import leakpath._sweep as sweep_module
    from leakpath import CheckpointMismatch

    ck = tmp_path / "ck"
    with monkeypatch.context() as m:
        m.setattr(sweep_module, "SOLVE_TOL", 1e-10)
        old = sweep(surface, levels=2, checkpoint_dir=ck)
    assert old.parameters["solve_tol"] == 1e-10
    with pytest.raises(CheckpointMismatch, match="solve_tol"):
        sweep(surface, levels=2, checkpoint_dir=ck)


def _tamper(path, edit):
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))


@pytest.mark.parametrize(
    "edit",
    [
        lambda d: d["row"].__setitem__("load", d["row"]["load"] * 1.0000001),
        lambda d: d["row"].__setitem__("load", None),
        lambda d: d["row"].__setitem__("n_contact", -5),
        lambda d: d.__setitem__("mask", "garbage"),
        lambda d: d.pop("row"),
    ],
)
def test_corrupt_checkpoints_are_recomputed_not_used(tmp_path, surface, default_sweep, edit):
    ck = tmp_path / "ck"
    sweep(surface, levels=LEVELS, checkpoint_dir=ck)
    _tamper(ck / "level_0005.json", edit)
    with pytest.warns(UserWarning, match="level 5"):
        again = sweep(surface, levels=LEVELS, checkpoint_dir=ck)
    assert 5 in again.recomputed and 5 not in again.resumed
    assert again.csv_text() == default_sweep.csv_text()


def test_truncated_checkpoint_is_recomputed(tmp_path, surface, default_sweep):
    ck = tmp_path / "ck"
    sweep(surface, levels=LEVELS, checkpoint_dir=ck)
    path = ck / "level_0003.json"
    path.write_bytes(path.read_bytes()[:100])
    with pytest.warns(UserWarning, match="level 3"):
        again = sweep(surface, levels=LEVELS, checkpoint_dir=ck)
    assert again.csv_text() == default_sweep.csv_text()


def test_foreign_checkpoints_are_recomputed(tmp_path, surface, default_sweep):
    other = leakpath.spectral(65, 0.9, seed=5, rms_height=1.0)
    a, b = tmp_path / "a", tmp_path / "b"
    sweep(surface, levels=LEVELS, checkpoint_dir=a)
    sweep(other, levels=LEVELS, checkpoint_dir=b)
    for k in range(6, LEVELS + 1):
        name = f"level_{k:04d}.json"
        (a / name).write_bytes((b / name).read_bytes())
    with pytest.warns(UserWarning, match="another run"):
        again = sweep(surface, levels=LEVELS, checkpoint_dir=a)
    assert again.recomputed == list(range(6, LEVELS + 1))
    assert again.csv_text() == default_sweep.csv_text()


def test_intact_checkpoints_resume_without_warnings(tmp_path, surface):
    ck = tmp_path / "ck"
    sweep(surface, levels=LEVELS, checkpoint_dir=ck)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        again = sweep(surface, levels=LEVELS, checkpoint_dir=ck)
    assert again.resumed == list(range(LEVELS + 1)) and again.recomputed == []


def test_threshold_warm_and_cold_agree_and_bracket(surface):
    warm = leakpath.percolation_threshold(surface, axis=1, boundary="periodic")
    cold = leakpath.percolation_threshold(
        surface, axis=1, boundary="periodic", warm_start=False
    )
    assert warm.found and cold.found
    assert abs(warm.approach - cold.approach) <= 1e-4 * surface.height_range
    # Periodic: clusters wrap across axis 0; three copies stacked along it show that.
    periodic_spans = lambda m: spans_axis(np.tile(m, (3, 1)), 1)  # noqa: E731
    assert periodic_spans(~warm.below.contact)
    assert not periodic_spans(~warm.above.contact)


def test_free_threshold_past_the_height_range_is_found():
    """A free patch that still percolates at Δ = h_s: the bracket is doubled until the free
    region stops spanning (checked with scipy labels on the bracketing states)."""
    found = None
    for seed in range(8):
        s = leakpath.rmd(6, 2.1, seed=seed)
        st = solve(s, s.height_range)
        if spans_axis(~st.contact, 0):
            found = s
            break
    assert found is not None, "no surface in the scan percolates at h_s"
    res = leakpath.percolation_threshold(found, axis=0, atol=1e-3 * found.height_range)
    assert res.found
    assert res.approach > found.height_range
    assert spans_axis(~res.below.contact, 0)
    assert not spans_axis(~res.above.contact, 0)
    assert res.above.approach - res.below.approach <= 1e-3 * found.height_range
