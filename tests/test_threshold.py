"""The percolation threshold search, checked with scipy.ndimage.label on the bracketing states."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

import leakpath
from leakpath.contact import ContactProblem


def spans_axis(free: np.ndarray, axis: int) -> bool:
    labels, _ = ndimage.label(free)  # 4-connectivity
    first = np.take(labels, 0, axis=axis)
    last = np.take(labels, -1, axis=axis)
    common = set(first[first > 0]) & set(last[last > 0])
    return bool(common)


@pytest.mark.parametrize("axis", [0, 1])
def test_threshold_brackets_the_loss_of_spanning(axis):
    s = leakpath.rmd(5, 2.1, seed=1)
    hs = s.height_range
    res = leakpath.percolation_threshold(s, axis=axis, atol=1e-3 * hs)
    assert res.found
    assert spans_axis(~res.below.contact, axis)
    assert not spans_axis(~res.above.contact, axis)
    assert res.above.approach - res.below.approach <= 1e-3 * hs
    assert res.approach == res.above.approach
    assert res.contact_fraction == res.above.contact_fraction
    # An independent coarse scan agrees on where spanning is lost.
    prob = ContactProblem(s)
    grid = np.linspace(0, hs, 41)
    first_blocked = next(
        a for a in grid if not spans_axis(~prob.solve(a, solver="active-set").contact, axis)
    )
    assert res.approach <= first_blocked + 1e-12
    assert res.approach > first_blocked - hs / 40 - 1e-3 * hs


def test_threshold_arguments():
    s = leakpath.rmd(4, 2.5, seed=0)
    with pytest.raises(ValueError, match="atol"):
        leakpath.percolation_threshold(s, atol=-1.0)
    with pytest.raises(ValueError, match="max_solves"):
        leakpath.percolation_threshold(s, max_solves=1)


def spans_periodic(open_: np.ndarray, axis: int) -> bool:
    """Does an open 4-connected path join the two sides along ``axis``, the other axis
    wrapping? scipy's labelling, with the labels across the wrap merged by a union–find."""
    cells = open_ if axis == 0 else open_.T
    labels, _ = ndimage.label(cells)
    parent: dict[int, int] = {}

    def root(x: int) -> int:
        while parent.get(x, x) != x:
            x = parent[x]
        return x

    for a, b in zip(labels[:, 0], labels[:, -1], strict=True):
        if a and b:
            parent[root(a)] = root(b)
    first = {root(x) for x in labels[0] if x}
    last = {root(x) for x in labels[-1] if x}
    return bool(first & last)


def open_cells(state) -> np.ndarray:
    return (state.pressure <= 0) & (state.gap > 0)


@pytest.mark.parametrize("seed", [0, 4])
def test_both_axes_share_solves_and_bracket_the_loss_of_spanning(seed):
    s = leakpath.spectral(64, 0.8, seed=seed, rms_height=1.0, rolloff=125.0)
    hs = s.height_range
    both = leakpath.percolation_thresholds(s, axes=(0, 1), boundary="periodic")
    assert [r.axis for r in both] == [0, 1]
    for r in both:
        assert r.found
        assert spans_periodic(open_cells(r.below), r.axis)
        assert not spans_periodic(open_cells(r.above), r.axis)
        assert r.above.approach - r.below.approach <= 1e-4 * hs
        assert r.approach == r.above.approach
        # A separate search (cold starts, solves to 1e-12) finds the same threshold
        # within the bisection tolerance.
        alone = leakpath.percolation_threshold(
            s, axis=r.axis, boundary="periodic", tol=1e-12, warm_start=False
        )
        assert abs(alone.approach - r.approach) <= 1e-4 * hs
    # The second axis starts from the states of the first: fewer new solves.
    assert both[1].solves < both[0].solves


def test_default_solve_tolerance_follows_atol():
    """The default KKT tolerance of the solves is 1e-2·atol/h_s (at most 1e-6)."""
    s = leakpath.spectral(48, 0.8, seed=2, rms_height=1.0)
    hs = s.height_range
    for atol, expected in ((None, 1e-6), (1e-6 * hs, 1e-8), (1e-12 * hs, 1e-12)):
        r = leakpath.percolation_threshold(s, boundary="periodic", atol=atol)
        kkt = [st.kkt for st in (r.below, r.above) if st.approach > 0]
        assert max(kkt) <= expected
        assert spans_periodic(open_cells(r.below), 0)
        assert not spans_periodic(open_cells(r.above), 0)


def test_thresholds_arguments():
    s = leakpath.rmd(4, 2.5, seed=0)
    with pytest.raises(ValueError, match="tol"):
        leakpath.percolation_threshold(s, tol=0.0)
    for axes in ((), "0", 0, (0, 2)):
        with pytest.raises(ValueError, match="axes"):
            leakpath.percolation_thresholds(s, axes=axes)
