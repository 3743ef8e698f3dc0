"""The paper's setup callable from Python, in one unit of length (µm)."""

from __future__ import annotations

import numpy as np

import leakpath
from leakpath.experiments import PAPER, PaperSetup, paper, paper_surface


def test_paper_surface_is_in_micrometres() -> None:
    s = paper_surface(0)
    assert s.shape == (129, 129)
    assert s.metadata["unit"] == "µm"
    assert np.isclose(s.length[0], 129 * s.dx)  # 129 elements of side dx
    assert np.isclose(s.dx, 100.0 / 128)
    # RMD heights with the default σ0: a height range of a few µm, as the paper's 6.72 µm.
    assert 1.0 < s.height_range < 20.0
    # The same seed gives the same heights as the generator called directly.
    direct = leakpath.rmd(PAPER.m, PAPER.D, seed=0, length=PAPER.side)
    np.testing.assert_array_equal(s.heights, direct.heights)


def test_contact_is_scale_free_in_the_plane() -> None:
    """Scaling the side by s at fixed heights leaves the contact set unchanged and divides
    the pressures by s: the dimensionless columns do not depend on the length unit."""
    small = PaperSetup(m=5, side=100.0)
    s_um = paper_surface(1, small)
    s_mm = leakpath.Surface(s_um.heights.copy(), s_um.dx / 1000.0)
    delta = 0.4 * s_um.height_range
    a = leakpath.solve(s_um, delta, solver="active-set")
    b = leakpath.solve(s_mm, delta, solver="active-set")
    np.testing.assert_array_equal(a.contact, b.contact)
    np.testing.assert_allclose(a.pressure * 1000.0, b.pressure, rtol=1e-9, atol=1e-12)


def test_paper_runs_the_sweep_of_the_setup() -> None:
    setup = PaperSetup(m=4, levels=4)
    result = paper(0, setup=setup, flow=False)
    assert len(result.rows) == setup.levels + 1
    assert result.surface.metadata["unit"] == "µm"
    np.testing.assert_allclose(
        result.column("approach_star"), np.linspace(0.0, 1.0, setup.levels + 1), atol=1e-15
    )
