"""Leak-rate columns of sweeps (leakpath.leakage): Q, K, K* against independent oracles.

Oracles: the parallel-channel permeability of a gap that varies only across the flow,
written out here with numpy; leakpath.flow called on each level's own fields; the
percolation threshold found by the same bisection on a plain breadth-first search.
"""

from __future__ import annotations

import json
import math
from collections import deque

import numpy as np
import pytest

import leakpath
from leakpath import CheckpointMismatch, leakage, sweep
from leakpath._table import COLUMNS
from leakpath.contact import ContactProblem
from leakpath.errors import InvalidArgumentError
from leakpath.leakage import FLOW_TOL
from leakpath.surfaces import Surface


def _grooves(ny=24, nx=20, seed=5):
    """Heights that vary only across axis 0 (along axis 1): channels along axis 0."""
    rng = np.random.default_rng(seed)
    row = rng.normal(size=nx)
    return Surface(np.tile(row, (ny, 1)), dx=0.5)


def test_columns_present_and_undeformed_permeability_is_the_parallel_channels():
    s = _grooves()
    r = sweep(s, levels=4, solver="active-set", boundary="periodic", flow_axis=0)
    for c in ("Q", "K", "K_star"):
        assert c in COLUMNS
    g = s.heights.max() - s.heights  # the undeformed gap
    # Each column of cells along the flow is a series of equal resistances 12η/g³; the
    # columns are in parallel, so K = Q η L/(W Δp) = mean over the columns of g³/12.
    k_channels = float(np.mean(g[0] ** 3 / 12.0))
    ny, nx = s.shape
    assert r.rows[0]["K"] == pytest.approx(k_channels, rel=1e-12, abs=0)
    assert r.rows[0]["Q"] == pytest.approx(k_channels * nx / ny, rel=1e-12, abs=0)
    assert r.reference["K"] == pytest.approx(k_channels, rel=1e-12, abs=0)
    # K* divides every level by that same undeformed K (not by its own row 0 alone).
    for row in r.rows:
        assert row["K_star"] == pytest.approx(row["K"] / k_channels, rel=1e-13, abs=0) or (
            row["K"] == 0 and row["K_star"] == 0
        )
    # Pressing the grooves closes them: the leak rate falls to nothing at full contact.
    ks = [row["K"] for row in r.rows]
    assert all(a >= b for a, b in zip(ks, ks[1:], strict=False))
    assert ks[-1] < 1e-12 * ks[0]


def test_columns_equal_flow_on_each_levels_own_fields():
    s = leakpath.spectral(48, 0.8, seed=2, rms_height=1.0)
    r = sweep(s, levels=8, boundary="periodic", keep_fields=True, flow_axis=1, axis=0)
    assert r.parameters["flow"] is True and r.parameters["flow_axis"] == 1
    for k, row in enumerate(r.rows):
        p, g = r.fields["pressure"][k], r.fields["gap"][k]
        f = leakpath.flow(
            np.maximum(g, 0.0), dx=s.dx, contact=p > 0, axis=1, periodic=True, tol=FLOW_TOL
        )
        assert r.parameters["flow_tol"] == FLOW_TOL
        assert row["Q"] == f.flow_rate
        assert row["K"] == f.permeability
        # Q > 0 exactly when the open region spans axis 1 (same 4-connectivity).
        spans = leakpath.percolation(g, dx=s.dx, contact=p > 0, axis=1, periodic=True)
        assert (row["Q"] > 0) == spans.percolates
    ref = leakpath.flow(np.max(s.heights) - s.heights, dx=s.dx, axis=1, periodic=True)
    assert r.reference["K"] == ref.permeability


def test_flow_switch_and_axis_validation():
    s = leakpath.spectral(24, 0.8, seed=1, rms_height=1.0)
    r = sweep(s, levels=3, flow=False)
    assert all(math.isnan(row[c]) for row in r.rows for c in ("Q", "K", "K_star"))
    assert "Q,K,K_star" in r.csv_text().splitlines()[0]
    assert leakage.flow_enabled(None, (129, 129))
    assert not leakage.flow_enabled(None, (1025, 1025))
    assert leakage.flow_enabled(True, (4097, 4097))
    with pytest.raises(InvalidArgumentError, match="flow:"):
        sweep(s, levels=3, flow="yes")
    with pytest.raises(InvalidArgumentError, match="flow_axis:"):
        sweep(s, levels=3, flow_axis="both")
    # The default flow axis follows a numeric percolation axis.
    assert sweep(s, levels=2, axis=1).parameters["flow_axis"] == 1
    assert sweep(s, levels=2, axis="either").parameters["flow_axis"] == 0


def test_resume_carries_the_columns_byte_identical(tmp_path):
    s = leakpath.spectral(40, 0.8, seed=4, rms_height=1.0)
    full = sweep(s, levels=6, boundary="periodic", checkpoint_dir=tmp_path / "a")
    assert any(row["Q"] > 0 for row in full.rows)
    for k in (3, 4, 6):
        (tmp_path / "a" / f"level_{k:04d}.json").unlink()
    resumed = sweep(s, levels=6, boundary="periodic", checkpoint_dir=tmp_path / "a")
    assert resumed.resumed == [0, 1, 2, 5]
    assert resumed.csv_text() == full.csv_text()
    rec = json.loads((tmp_path / "a" / "level_0002.json").read_text())
    assert rec["row"]["Q"] == full.rows[2]["Q"]
    # A checkpoint of the previous format (no Q, K) is refused, naming the format.
    man = tmp_path / "a" / "manifest.json"
    data = json.loads(man.read_text())
    data["format"] = 2
    man.write_text(json.dumps(data))
    with pytest.raises(CheckpointMismatch, match="checkpoint format 2"):
        sweep(s, levels=6, boundary="periodic", checkpoint_dir=tmp_path / "a")


def test_a_free_cell_with_zero_gap_is_closed_for_both():
    """A corridor of open cells whose only link is a free cell with g = 0."""
    gap = np.zeros((5, 5))
    contact = np.ones((5, 5), dtype=bool)
    contact[:, 2] = False
    gap[:, 2] = 1.0
    gap[2, 2] = 0.0  # free (p = 0) but closed
    perc = leakpath.percolation(gap, dx=1.0, contact=contact, axis=0)
    f = leakpath.flow(gap, dx=1.0, contact=contact, axis=0)
    assert not perc.percolates and f.flow_rate == 0.0
    gap[2, 2] = 1e-3
    perc = leakpath.percolation(gap, dx=1.0, contact=contact, axis=0)
    f = leakpath.flow(gap, dx=1.0, contact=contact, axis=0)
    assert perc.percolates and f.flow_rate > 0.0


@pytest.mark.parametrize("neck", [1e-60, 1e-120, 1e-200, 5e-324])
def test_an_open_neck_whose_cube_underflows_still_conducts(neck):
    """g > 0 is open for both, even when (g/g_max)³ or a face's product underflows."""
    gap = np.zeros((6, 5))
    gap[:, 2] = 1.0
    gap[3, 2] = neck
    perc = leakpath.percolation(gap, dx=1.0, axis=0)
    f = leakpath.flow(gap, dx=1.0, axis=0)
    assert perc.percolates
    assert f.flow_rate > 0.0 and f.percolates
    assert np.array_equal(np.isfinite(f.pressure), gap > 0)


def _bfs_spans(open_: np.ndarray, periodic: bool) -> bool:
    """Plain breadth-first search: does an open 4-connected path join row 0 to the last row?"""
    ny, nx = open_.shape
    seen = np.zeros_like(open_)
    todo = deque((0, j) for j in range(nx) if open_[0, j])
    for c in todo:
        seen[c] = True
    while todo:
        i, j = todo.popleft()
        if i == ny - 1:
            return True
        for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            a, b = i + di, j + dj
            if periodic:
                b %= nx
            if 0 <= a < ny and 0 <= b < nx and open_[a, b] and not seen[a, b]:
                seen[a, b] = True
                todo.append((a, b))
    return False


@pytest.mark.parametrize("seed", [0, 3, 7, 11])
def test_leak_stops_at_the_percolation_threshold(seed):
    """Bisection on Q > 0 with percolation_threshold's bracket and warm starts gives the same
    threshold; every state's Q > 0 agrees with a plain BFS on its open cells."""
    s = leakpath.spectral(48, 0.8, seed=seed, rms_height=1.0)
    pt = leakpath.percolation_threshold(s, boundary="periodic", solver="polonsky-keer")
    prob = ContactProblem(s, boundary="periodic")
    tol = 1e-4 * s.height_range

    def leaks(st):
        q = st.flow().flow_rate
        open_ = (st.pressure <= 0) & (np.maximum(st.gap, 0.0) > 0)
        assert (q > 0) == _bfs_spans(open_, periodic=True)
        return q > 0

    def solve(a, lo_state, hi_state):
        # percolation_threshold's starts: the pressure interpolated between the bracketing
        # states (the state below while nothing above is solved); its KKT tolerance 1e-6.
        start = lo_state if lo_state.approach > 0 else None
        if start is not None and hi_state is not None:
            t = (a - lo_state.approach) / (hi_state.approach - lo_state.approach)
            start = (1 - t) * lo_state.pressure + t * hi_state.pressure
        return prob.solve(a, solver="polonsky-keer", warm_start=start, tol=1e-6)

    lo_state = prob.solve(0.0, solver="polonsky-keer")
    assert leaks(lo_state)
    lo, hi, hi_state = 0.0, prob.max_approach, None
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        st = solve(mid, lo_state, hi_state)
        if leaks(st):
            lo, lo_state = mid, st
        else:
            hi, hi_state = mid, st
    assert hi == pt.approach
    assert hi_state is not None and hi_state.contact_fraction == pt.contact_fraction


def test_flow_figures_and_cli_columns(tmp_path):
    import subprocess
    import sys

    from leakpath.plotting.flow import flux_magnitude, level_flow, save_flow_figures

    s = leakpath.spectral(32, 0.8, seed=6, rms_height=1.0)
    r = sweep(s, levels=6, boundary="periodic", keep_fields=True)
    paths = save_flow_figures(r, tmp_path / "f", formats=("png",), flux_levels=[2, 6])
    assert sorted(p.name for p in paths) == ["fig4_leak_rate.png", "flux_k02.png", "flux_k06.png"]
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # The mapped flux is that level's flow: the outlet row of |q_y| sums to Q/dx.
    f = level_flow(r, 2)
    assert f.flow_rate == r.rows[2]["Q"]
    mag = flux_magnitude(f)
    assert mag.shape == s.shape and np.nanmax(mag) > 0
    # Re-solving without kept fields gives the same leak to the solver's tolerance.
    r2 = sweep(s, levels=6, boundary="periodic")
    assert level_flow(r2, 2).flow_rate == pytest.approx(r.rows[2]["Q"], rel=1e-6, abs=0)
    with pytest.raises(InvalidArgumentError, match="flux_levels"):
        save_flow_figures(r, tmp_path / "g", flux_levels=[7])

    out = tmp_path / "cli"
    run = subprocess.run(
        [sys.executable, "-m", "leakpath", "sweep", "spectral:n=32,hurst=0.8,seed=6,rms_height=1",
         "--levels", "6", "--boundary", "periodic", "--flow-axis", "1", "--flux-maps", "3",
         "--out", str(out), "--json"],
        capture_output=True, text=True, check=False,
    )
    assert run.returncode == 0, run.stderr
    header = (out / "table.csv").read_text().splitlines()[0].split(",")
    assert header[-3:] == ["Q", "K", "K_star"]
    assert (out / "figures" / "flux_k03.png").exists()
    assert (out / "figures" / "fig4_leak_rate.pdf").exists()
    summary = json.loads(run.stdout)["summary"]
    assert summary[0]["K_star"] == 1.0
    lib = sweep(s, levels=6, boundary="periodic", flow_axis=1)
    assert [row["K_star"] for row in summary] == [row["K_star"] for row in lib.rows]
    off = subprocess.run(
        [sys.executable, "-m", "leakpath", "sweep", "spectral:n=32,hurst=0.8,seed=6,rms_height=1",
         "--levels", "2", "--no-flow", "--out", str(tmp_path / "off"), "--json"],
        capture_output=True, text=True, check=False,
    )
    assert off.returncode == 0, off.stderr
    assert not list((tmp_path / "off" / "figures").glob("fig4*"))


# ------------------------------------------------------------ flows beside the contact solves
def _states(n=5, size=33, seed=3):
    s = leakpath.spectral(size, 0.8, seed=seed, rms_height=1.0)
    problem = ContactProblem(s)
    approaches = np.linspace(0.0, 0.6, n) * s.height_range
    return [problem.solve(float(a)) for a in approaches]


def _direct(state, axis=0):
    f = leakpath.flow(state, axis=axis)
    return {"Q": f.flow_rate, "K": f.permeability}


@pytest.mark.parametrize("background", [True, False])
def test_level_flows_equal_each_flow_computed_alone(background):
    states = _states()
    flows = leakage.LevelFlows(0, True, background=background)
    try:
        for k, st in enumerate(states):
            flows.submit(k, st)
        flows.submit("again", states[0])  # an identical state: solved once, same numbers
        got = flows.finished() + flows.finish()
    finally:
        flows.close()
    assert [key for key, _, _, _ in got] == [0, 1, 2, 3, 4, "again"]
    for key, work, cols, seconds in got:
        want = _direct(states[0 if key == "again" else key])
        assert cols == want  # the same bits: the solver's result ignores its thread count
        assert work is None and seconds >= 0
    assert got[-1][3] == 0.0  # the identical state was not solved again
    assert any(cols["Q"] > 0 for _, _, cols, _ in got)


def test_level_flows_switched_off_give_nan_without_solving(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("no flow may be solved with the columns switched off")

    monkeypatch.setattr(leakage, "flow", refuse)
    flows = leakage.LevelFlows(0, False)
    flows.submit(0, _states(n=1)[0])
    [(key, work, cols, seconds)] = flows.finish()
    assert key == 0 and work is None and seconds == 0.0
    assert math.isnan(cols["Q"]) and math.isnan(cols["K"])


def test_queued_flows_are_helped_by_the_submitting_thread(monkeypatch):
    import threading
    import time

    states = _states(n=6)
    where = []
    real = leakage.flow

    def slow(state, **kwargs):
        where.append(threading.current_thread().name)
        time.sleep(0.05)  # slower than submitting: the queue fills up
        return real(state, **kwargs)

    monkeypatch.setattr(leakage, "flow", slow)
    monkeypatch.setattr(leakage, "MAX_PENDING", 1)
    flows = leakage.LevelFlows(0, True, background=True)
    try:
        for k, st in enumerate(states):
            # The work runs first in the same job, with the job's thread count.
            flows.submit(k, st, lambda threads, k=k: (k, threads, threading.current_thread().name))
        got = flows.finish()
    finally:
        flows.close()
    assert [k for k, _, _, _ in got] == list(range(6))
    assert threading.current_thread().name in where
    assert any(name.startswith("leakpath-flow") for name in where)
    for k, work, cols, _ in got:
        assert cols == _direct(states[k])
        assert work[0] == k
        # One thread on the background thread, all solver threads where it was helped.
        assert work[1] == (1 if work[2].startswith("leakpath-flow") else None)


def test_flows_sharing_the_analysis_run_in_order_with_the_same_bits(monkeypatch):
    """On grids where the levels pass the factor's analysis on (here every grid), no flow is
    taken over by the submitting thread, and the rates are the same bits as in turn on one
    thread; each within 1e-10 of a fresh analysis."""
    import threading
    import time

    s = leakpath.spectral(65, 0.8, seed=3, rms_height=1.0)
    problem = ContactProblem(s)
    states = [problem.solve(float(a) * s.height_range) for a in np.linspace(0.0, 0.1, 6)]
    real = leakage.flow
    where = []

    def slow(state, **kwargs):
        where.append(threading.current_thread().name)
        time.sleep(0.05)
        return real(state, **kwargs)

    monkeypatch.setattr(leakage, "flow", slow)
    monkeypatch.setattr(leakage, "MAX_PENDING", 1)
    monkeypatch.setattr(leakage, "ANALYSIS_MIN_CELLS", 0)
    runs = []
    for background in (True, False):
        flows = leakage.LevelFlows(0, True, background=background)
        try:
            for k, st in enumerate(states):
                flows.submit(k, st)
            got = flows.finish()
            assert flows.analysis is not None and flows.analysis.reuses >= 1
        finally:
            flows.close()
        assert flows.analysis.unknowns == 0  # dropped on close
        runs.append([cols for _, _, cols, _ in got])
        if background:
            assert all(name.startswith("leakpath-flow") for name in where)
    assert runs[0] == runs[1]
    for st, cols in zip(states, runs[0], strict=True):
        fresh = _direct(st)
        assert abs(cols["Q"] - fresh["Q"]) <= 1e-10 * abs(fresh["Q"])


def test_a_failing_flow_stops_the_sweep_and_its_level_is_not_saved(tmp_path, monkeypatch):
    s = leakpath.spectral(32, 0.8, seed=6, rms_height=1.0)
    fresh = sweep(s, levels=5)
    real = leakage.flow
    calls = []

    def failing(state, **kwargs):
        calls.append(1)
        if len(calls) == 4:  # the reference, then levels 0 (shared), 1, 2: level 3 fails
            raise leakpath.errors.NotConvergedError("flow: injected failure")
        return real(state, **kwargs)

    monkeypatch.setattr(leakage, "flow", failing)
    with pytest.raises(leakpath.errors.NotConvergedError, match="injected"):
        sweep(s, levels=5, checkpoint_dir=tmp_path)
    saved = sorted(p.name for p in tmp_path.glob("level_*.json"))
    assert "level_0003.json" not in saved
    monkeypatch.setattr(leakage, "flow", real)
    resumed = sweep(s, levels=5, checkpoint_dir=tmp_path)
    assert 3 not in resumed.resumed
    assert resumed.csv_text() == fresh.csv_text()


def test_flow_threads_argument():
    st = _states(n=3)[2]
    one = leakpath.flow(st, threads=1)
    every = leakpath.flow(st)
    assert one.flow_rate == every.flow_rate
    np.testing.assert_array_equal(one.pressure, every.pressure)
    for bad in (0, -1, 2.5, True, "2"):
        with pytest.raises(InvalidArgumentError, match="threads"):
            leakpath.flow(st, threads=bad)
    assert leakpath._core.solver_threads() >= 1
