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
