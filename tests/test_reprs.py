"""Short reprs: every result object and the contact problem print a few lines of shapes and
scalars, never the contents of their arrays."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import leakpath
from leakpath import ContactProblem, percolation_threshold, rmd, sweep
from leakpath.ensemble import ensemble
from leakpath.moments import nayak_moments
from leakpath.threshold import PercolationThreshold

MAX_LINES = 6
MAX_CHARS = 600


@pytest.fixture(scope="module")
def surface() -> leakpath.Surface:
    return rmd(5, 2.2, seed=1)


@pytest.fixture(scope="module")
def problem(surface: leakpath.Surface) -> ContactProblem:
    return ContactProblem(surface)


@pytest.fixture(scope="module")
def state(problem: ContactProblem) -> leakpath.ContactState:
    return problem.solve(0.3 * problem.max_approach)


def check_short(obj: Any, name: str) -> str:
    text = repr(obj)
    assert type(obj).__name__ == name
    assert text.startswith(f"{name}("), text
    assert len(text.splitlines()) <= MAX_LINES, text
    assert len(text) <= MAX_CHARS, text
    assert "array(" not in text and "[[" not in text, text
    assert " at 0x" not in text, text  # not the default object repr
    # No run of numbers as numpy prints an array: "[0. 0. 0." or "0.1, 0.2, 0.3, 0.4".
    assert not re.search(r"(-?\d[\d.e+-]*,?\s+){6,}", text), text
    return text


def test_surface(surface: leakpath.Surface) -> None:
    text = check_short(surface, "Surface")
    assert "(33, 33)" in text


def test_contact_problem(problem: ContactProblem) -> None:
    text = check_short(problem, "ContactProblem")
    assert "33x33" in text and "boundary='free'" in text
    assert f"max_approach={problem.max_approach:.6g}" in text


def test_contact_state(state: leakpath.ContactState) -> None:
    text = check_short(state, "ContactState")
    assert "33x33" in text
    assert f"approach={state.approach:.6g} µm" in text  # the surface's unit
    assert f"mean_gap={state.mean_gap:.4g} µm" in text and "(unit of E)" in text
    assert f"contact_fraction={state.contact_fraction:.4g}" in text
    assert f"solver={state.solver!r}" in text


@pytest.mark.parametrize(
    ("pressure", "shown"),
    [("abc", "pressure=str"), (np.full((33, 33), "x"), "ndarray of shape (33, 33)"),
     (np.zeros((3, 3)), "3x3 grid")],
)
def test_contact_state_with_malformed_fields(
    state: leakpath.ContactState, pressure: Any, shown: str
) -> None:
    # Error messages describe a refused warm start by its repr: it must not raise.
    import dataclasses

    text = check_short(dataclasses.replace(state, pressure=pressure), "ContactState")
    assert shown in text


def test_percolation(state: leakpath.ContactState) -> None:
    perc = state.percolation()
    text = check_short(perc, "Percolation")
    assert f"clusters={perc.n_clusters}" in text
    assert f"V_pg={perc.spanning_volume:.4g} µm^3" in text


def test_reprs_name_the_surface_unit() -> None:
    """The unit printed is the surface's own, not a default; a bare gap array has none."""
    s = rmd(4, 2.2, seed=2, length=5e-4, sigma0=3e-6, unit="m")
    st = ContactProblem(s).solve(0.4 * s.height_range)
    assert f"approach={st.approach:.6g} m," in repr(st)
    perc = st.percolation()
    assert f"V={perc.free_volume:.4g} m^3)" in repr(perc)
    bare = leakpath.percolation(st.gap, dx=s.dx, contact=st.contact)
    assert f"V={bare.free_volume:.4g} length^3)" in repr(bare)
    t = percolation_threshold(s)
    assert f"approach={t.approach:.6g} m," in repr(t)
    f = st.flow()
    assert f"Q={f.flow_rate:.6g} m^3/t," in repr(f) and f"K={f.permeability:.6g} m^3," in repr(f)
    bare_flow = leakpath.flow(st.gap.clip(0.0), dx=s.dx, contact=st.contact)
    assert f"aperture={bare_flow.hydraulic_aperture:.6g} length," in repr(bare_flow)


def test_flow(state: leakpath.ContactState) -> None:
    f = state.flow()
    text = check_short(f, "Flow")
    assert "grid=33x33" in text


def test_moments(surface: leakpath.Surface) -> None:
    m = nayak_moments(surface)
    text = check_short(m, "Moments")
    assert "alpha=" in text


def test_percolation_threshold(surface: leakpath.Surface) -> None:
    t = percolation_threshold(surface)
    assert t.found
    text = check_short(t, "PercolationThreshold")
    assert "ContactState" not in text  # the bracketing states are not embedded
    assert f"approach={t.approach:.6g} µm" in text and f"solves={t.solves}" in text


def test_percolation_threshold_not_found(state: leakpath.ContactState) -> None:
    # The free region still spans at the largest approach: no state above, NaN threshold.
    t = PercolationThreshold(float("nan"), float("nan"), float("nan"), state, None, 3, 0)
    text = check_short(t, "PercolationThreshold")
    assert "found=False" in text and "None]" in text


@pytest.mark.parametrize("flow", [True, False])
def test_sweep_result(surface: leakpath.Surface, flow: bool) -> None:
    result = sweep(surface, levels=5, flow=flow, keep_fields=True)
    text = check_short(result, "SweepResult")
    assert f"{len(result)} levels on a 33x33 surface" in text
    assert ("K*" in text) is flow and ("no leak-rate columns" in text) is not flow
    assert f"{result.total_seconds:.3g} s" in text


def test_sweep_result_shows_the_length_unit(surface: leakpath.Surface) -> None:
    metres = leakpath.Surface(surface.heights * 1e-6, surface.dx * 1e-3, metadata={"unit": "m"})
    result = sweep(metres, levels=2, flow=False)
    text = check_short(result, "SweepResult")
    assert f"dx={surface.dx * 1e-3:.6g} m," in text


def test_ensemble_result(tmp_path: Path) -> None:
    result = ensemble(params={"m": [3, 4], "D": [2.1, 2.2, 2.3]}, surfaces=1, levels=2,
                      out=tmp_path / "run", executor="serial", progress=False)
    assert len(result.keys) == 6
    text = check_short(result, "EnsembleResult")
    assert "2 more" in text and "surfaces=6" in text


def test_ensemble_result_long_directory(tmp_path: Path) -> None:
    deep = tmp_path.joinpath(*(["a-rather-long-directory-name"] * 20))
    result = ensemble(params={"m": 3, "D": 2.2}, surfaces=1, levels=2, out=deep,
                      executor="serial", progress=False)
    assert len(str(deep)) > MAX_CHARS
    text = check_short(result, "EnsembleResult")
    assert text.count("a-rather-long-directory-name") < 20


def test_reprs_leave_no_field_arrays_in_fixed_objects(state: leakpath.ContactState) -> None:
    # A state with large pressures still prints its scalars only.
    big = leakpath.ContactState(
        approach=1.0, pressure=np.full((64, 64), 1e300), displacement=np.zeros((64, 64)),
        gap=np.zeros((64, 64)), heights=np.zeros((64, 64)), dx=1.0, e_star=1.0,
        boundary="free", solver="active-set", iterations=1, kkt=0.0, seconds=0.0,
    )
    check_short(big, "ContactState")
