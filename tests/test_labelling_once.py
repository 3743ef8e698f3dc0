"""A contact state's open cells are labelled once: its percolation classes along every axis,
its class volumes and its flow all read the same labelling."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

import leakpath
from leakpath import _core, _percolation


@pytest.fixture
def calls(monkeypatch):
    """Counts the labellings (the private entry point) and the flow solves that label."""
    seen = {"label": 0, "flow_labelled": 0, "classify": 0}
    label = _percolation._label_open
    solve = _core.solve_reynolds_flow
    classify = _core.classify

    def counted_classify(*args, **kwargs):
        seen["classify"] += 1
        return classify(*args, **kwargs)

    def counted_label(*args, **kwargs):
        seen["label"] += 1
        return label(*args, **kwargs)

    def counted_solve(*args, **kwargs):
        res = solve(*args, **kwargs)
        seen["flow_labelled"] += int(res.labelled)
        return res

    monkeypatch.setattr(_percolation, "_label_open", counted_label)
    monkeypatch.setattr(_core, "solve_reynolds_flow", counted_solve)
    monkeypatch.setattr(_core, "classify", counted_classify)
    return seen


@pytest.mark.parametrize("axis", [0, 1, "either", "both"])
def test_a_sweep_level_labels_once(calls, axis) -> None:
    surface = leakpath.rmd(5, 2.1, seed=3)
    result = leakpath.sweep(surface, levels=6, axis=axis, flow=True)
    rows = len(result.rows)
    # One labelling per level, one for the reference state (Δ = 0, nothing in contact);
    # one classification call per labelling covers both axes and `axis`; the flow solves
    # reuse the labellings.
    assert calls["label"] == rows + 1
    assert calls["classify"] == rows + 1
    assert calls["flow_labelled"] == 0


def test_one_labelling_serves_every_axis_and_the_flow(calls) -> None:
    surface = leakpath.rmd(5, 2.1, seed=1)
    state = leakpath.ContactProblem(surface).solve(0.4 * surface.height_range)
    perc = {a: state.percolation(axis=a) for a in (0, 1, "either", "both")}
    f = state.flow(axis=1)
    assert calls["label"] == 1 and calls["flow_labelled"] == 0
    # The shared labels against an independent labelling of the open cells.
    open_cells = ~state.contact & (state.gap > 0)
    ref, n = ndimage.label(open_cells)
    assert perc[0].n_clusters == n
    assert np.array_equal(perc[1].labels, ref)
    assert perc["either"].labels is perc[0].labels
    # The flow with the shared labelling equals one that labels by itself (a gap array).
    g = np.where(state.contact, 0.0, np.maximum(state.gap, 0.0))
    alone = leakpath.flow(g, dx=state.dx, contact=state.contact, axis=1)
    assert calls["flow_labelled"] == 1
    assert f.flow_rate == alone.flow_rate and f.permeability == alone.permeability


def test_periodic_states_label_once_per_wrap(calls) -> None:
    surface = leakpath.spectral((32, 32), seed=2, hurst=0.8, rms_height=0.5)
    state = leakpath.ContactProblem(surface, boundary="periodic").solve(0.5)
    for a in (0, 1, "either", 0, 1):
        state.percolation(axis=a)
    state.flow(axis=0)
    state.flow(axis=1)
    # Wrap across axis 1 (flow along 0), across axis 0 (along 1), and none (either).
    assert calls["label"] == 3 and calls["flow_labelled"] == 0
