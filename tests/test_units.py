"""Length units: default sizes within the small-slope model, the unit carried from the
surface into tables, metadata and files, and the slope warning."""

from __future__ import annotations

import csv
import warnings

import numpy as np
import pytest

import leakpath
from leakpath.errors import InvalidArgumentError, LeakpathWarning, SlopeWarning
from leakpath.surfaces import DEFAULT_UNIT, MAX_RMS_SLOPE


def _rms_slope(h: np.ndarray, dx: float) -> float:
    """Forward-difference rms gradient, written out independently of leakpath.moments."""
    sx = (h[:, 1:] - h[:, :-1]) / dx
    sy = (h[1:, :] - h[:-1, :]) / dx
    return float(np.sqrt(np.mean(sx**2) + np.mean(sy**2)))


@pytest.mark.parametrize(
    "make",
    [
        lambda: leakpath.rmd(7, 2.1, seed=0),
        lambda: leakpath.rmd(8, 2.3, seed=4),
        lambda: leakpath.spectral(128, 0.8, seed=0),
        lambda: leakpath.spectral((64, 96), 0.7, seed=1),
    ],
)
def test_default_surfaces_are_in_micrometres_with_small_slopes(make) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error", LeakpathWarning)
        s = make()
    assert s.unit == DEFAULT_UNIT == "µm" and s.metadata["unit"] == "µm"
    assert s.metadata["length"] == 500.0  # rmd: 2^m·dx; spectral: nx·dx
    slope = _rms_slope(s.heights, s.dx)
    assert slope <= 0.1
    assert s.rms_slope == pytest.approx(slope, rel=1e-12, abs=0)


def test_steep_surfaces_warn_once_with_a_leakpath_warning() -> None:
    with pytest.warns(SlopeWarning, match=r"rms slope .* exceeds 0\.3") as record:
        s = leakpath.rmd(5, 2.1, seed=0, length=1.0)  # the old default: slope ~14
    assert len(record) == 1 and issubclass(SlopeWarning, UserWarning)
    assert _rms_slope(s.heights, s.dx) > MAX_RMS_SLOPE
    with warnings.catch_warnings():  # once per surface: not again for its contact problem
        warnings.simplefilter("error", SlopeWarning)
        leakpath.ContactProblem(s)
    # A surface built by hand warns when it enters the contact model.
    steep = leakpath.Surface(s.heights, s.dx)
    with pytest.warns(SlopeWarning) as record:
        leakpath.ContactProblem(steep)
    # Warnings point at the user's line, also from inside a sweep.
    assert record[0].filename == __file__
    with pytest.warns(SlopeWarning) as record:
        leakpath.sweep(leakpath.Surface(s.heights, s.dx), levels=1, flow=False)
    assert record[0].filename == __file__


def test_the_unit_travels_with_the_surface(tmp_path) -> None:
    s = leakpath.rmd(5, 2.1, seed=0, length=5e-4, sigma0=3e-6, unit="m")
    assert s.unit == "m"
    back = leakpath.load(s.save(tmp_path / "s.npz"))
    assert back.unit == "m" and np.array_equal(back.heights, s.heights)
    with pytest.raises(InvalidArgumentError, match=r"^unit: 'µm' differs"):
        leakpath.load(tmp_path / "s.npz", unit="µm")
    np.save(tmp_path / "h.npy", s.heights)
    assert leakpath.load(tmp_path / "h.npy", dx=s.dx).unit == "µm"  # the documented default
    assert leakpath.load(tmp_path / "h.npy", dx=s.dx, unit="m").unit == "m"
    # Given, from the metadata, or the default; set later with a check.
    assert leakpath.Surface(np.zeros((3, 3)), 1.0, {"unit": "nm"}).unit == "nm"
    t = leakpath.Surface(np.zeros((3, 3)), 1.0, unit="mm")
    assert t.unit == "mm" and t.metadata["unit"] == "mm"
    t.unit = "m"
    assert t.metadata["unit"] == "m" and "unit='m'" in repr(t)
    for bad in ("", "   ", 3, None, "a\nb", "x" * 40):
        with pytest.raises(InvalidArgumentError, match=r"^unit"):
            t.unit = bad


def test_sweep_tables_carry_the_unit(tmp_path) -> None:
    s = leakpath.rmd(4, 2.2, seed=2, length=5e-4, sigma0=3e-6, unit="m")
    result = leakpath.sweep(s, levels=3, flow=False)
    units = result.units
    assert units["approach"] == "m" and units["free_volume"] == "m^3"
    assert units["contact_area"] == "m^2" and units["V_pg_star"] == "1"
    assert result.metadata()["units"] == units and result.metadata()["surface"]["unit"] == "m"
    plain = result.to_csv(tmp_path / "plain.csv")
    with_units = result.to_csv(tmp_path / "units.csv", units=True)
    rows_plain = list(csv.reader(plain.open(encoding="utf-8")))
    rows_units = list(csv.reader(with_units.open(encoding="utf-8")))
    assert rows_plain[1:] == rows_units[1:]
    header = dict(zip(rows_plain[0], rows_units[0], strict=True))
    assert header["approach"] == "approach [m]" and header["solver"] == "solver"
    assert header["V_pg"] == "V_pg [m^3]" and header["K_star"] == "K_star [1]"
    assert "m" in repr(result).split("approach", 1)[1]


def test_percolation_areas_are_in_unit_squared() -> None:
    s = leakpath.rmd(5, 2.1, seed=1)
    state = leakpath.ContactProblem(s).solve(0.4 * s.height_range)
    p = state.percolation(axis=0)
    open_cells = ~state.contact & (state.gap > 0)
    assert p.free_cells == int(open_cells.sum())
    assert p.free_area == pytest.approx(open_cells.sum() * s.dx**2, rel=1e-15)
    assert p.spanning_area == pytest.approx(p.spanning_cells * s.dx**2, rel=1e-15)
    np.testing.assert_allclose(p.areas, p.cell_counts * s.dx**2, rtol=1e-15)
