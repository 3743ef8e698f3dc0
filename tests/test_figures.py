"""Saving a figure in several formats (leakpath.plotting.save_figure): the layout is computed
once and reused, so every format must show the axes where matplotlib's constrained layout
puts them for that format alone."""

from __future__ import annotations

import io

import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.layout_engine import ConstrainedLayoutEngine

from leakpath.plotting import save_figure


def _figure() -> Figure:
    fig = Figure(figsize=(8.0, 3.6), layout="constrained")
    ax_a, ax_b = fig.subplots(1, 2)
    x = np.logspace(-7, 0, 50)
    ax_a.loglog(x, x**1.5, label="K* [1]")
    ax_a.set_xlabel("contact fraction a [1]")
    ax_a.set_ylabel(r"$K^* = K / K(\Delta = 0)$ [1]")
    ax_a.grid(True, which="both")
    ax_a.legend()
    im = ax_b.imshow(np.arange(64.0).reshape(8, 8), extent=(0.0, 1.0, 0.0, 1.0))
    fig.colorbar(im, ax=ax_b, label=r"$|q|/dx$ [µm$^2$/s]")
    ax_b.set_xlabel("x [µm]")
    ax_b.set_ylabel("y [µm]")
    fig.suptitle("a figure with a colour bar and a title")
    return fig


def _positions(fig: Figure) -> np.ndarray:
    return np.array([ax.get_position().bounds for ax in fig.axes])


@pytest.mark.parametrize("formats", [("png", "pdf"), ("pdf", "png", "svg")])
def test_every_format_has_its_own_formats_layout(tmp_path, formats):
    fig = _figure()
    paths = save_figure(fig, tmp_path / "f", formats, dpi=100)
    assert [p.name for p in paths] == [f"f.{fmt}" for fmt in formats]
    heads = {"png": b"\x89PNG", "pdf": b"%PDF", "svg": b"<?xml"}
    for p, fmt in zip(paths, formats, strict=True):
        assert p.read_bytes().startswith(heads[fmt])
    # The engine is back on the figure, so later changes are laid out again.
    assert isinstance(fig.get_layout_engine(), ConstrainedLayoutEngine)
    # Oracle: a twin figure drawn by matplotlib alone in each format, its layout its own.
    reused = _positions(fig)
    for fmt in formats:
        twin = _figure()
        twin.savefig(io.BytesIO(), format=fmt, dpi=100)
        np.testing.assert_allclose(reused, _positions(twin), atol=0.01)


def test_a_figure_without_a_layout_engine_is_saved_as_it_is(tmp_path):
    fig = Figure(figsize=(4.0, 3.0))
    ax = fig.add_subplot()
    ax.plot([0.0, 1.0], [0.0, 1.0])
    before = _positions(fig)
    paths = save_figure(fig, tmp_path / "g", ("png", "pdf"))
    assert [p.name for p in paths] == ["g.png", "g.pdf"]
    assert fig.get_layout_engine() is None
    np.testing.assert_array_equal(_positions(fig), before)
