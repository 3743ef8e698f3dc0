"""Reynolds flow over the whole range of finite gaps: exact rational references, contact-state
gaps, and quantities beyond the range of a double.

The reference solves the finite-volume system of docs/flow.md in exact rational arithmetic
(``fractions.Fraction``: every float gap is a rational, so ``g³``, the harmonic face means and
Gaussian elimination are exact), on the cells a plain breadth-first search finds joined to
both reservoirs. Every cell with ``g > 0`` is open (the rule :func:`leakpath.percolation`
shares).

Tolerance: with the conductances ``g³`` spanning up to 45 decades, leakpath either keeps its
Cholesky answer when the first-order error of each rate (from exact residuals) is at most
1e-12, or eliminates without cancellation, where each rate is a sum of positive terms with a
relative error of a few ``n ε`` (n ≤ 36 here), then refines the pressures carried as two
doubles (measured: within 2e-12 of the exact rate). 1e-11 covers both. Rates are compared
relatively only (``abs=0``): under ``pytest.approx``'s default absolute tolerance of 1e-12 any
two of these rates (1e-13 to 1e-48) would compare equal.
"""

from __future__ import annotations

from collections import deque
from fractions import Fraction

import numpy as np
import pytest
from test_flow import _reference

import leakpath
from leakpath import _core
from leakpath._flow import GAP_FLOOR, ROUND_OFF, _prepare_gaps
from leakpath.errors import InvalidArgumentError, NotConvergedError

REL = 1e-11


def _exact_flow(gap: np.ndarray, closed: np.ndarray, periodic: bool = False) -> Fraction:
    """Exact outlet rate ``Q`` at ``η = Δp = dx = 1`` (flow along axis 0)."""
    ny, nx = gap.shape
    c = {
        (i, j): Fraction(float(gap[i, j])) ** 3
        for i in range(ny)
        for j in range(nx)
        if not closed[i, j]
    }

    def neighbours(i: int, j: int) -> list[tuple[int, int]]:
        out = [(i - 1, j), (i + 1, j)]
        if j > 0 or periodic:
            out.append((i, (j - 1) % nx))
        if j < nx - 1 or periodic:
            out.append((i, (j + 1) % nx))
        return [q for q in dict.fromkeys(out) if q in c and q != (i, j)]

    def reached(row: int) -> set[tuple[int, int]]:
        seen = {(row, j) for j in range(nx) if (row, j) in c}
        todo = deque(seen)
        while todo:
            for q in neighbours(*todo.popleft()):
                if q not in seen:
                    seen.add(q)
                    todo.append(q)
        return seen

    cells = sorted(reached(0) & reached(ny - 1))
    if not cells:
        return Fraction(0)
    idx = {k: t for t, k in enumerate(cells)}
    m = len(cells)
    a: list[dict[int, Fraction]] = [{} for _ in range(m)]
    b = [Fraction(0)] * m
    for (i, j), t in idx.items():
        diag = Fraction(0)
        for q in neighbours(i, j):
            cf = 2 * c[i, j] * c[q] / (c[i, j] + c[q])
            diag += cf
            a[t][idx[q]] = a[t].get(idx[q], Fraction(0)) - cf
        if i == 0:
            diag += 2 * c[i, j]
            b[t] += 2 * c[i, j]
        if i == ny - 1:
            diag += 2 * c[i, j]
        a[t][t] = a[t].get(t, Fraction(0)) + diag
    for p in range(m):  # symmetric positive definite: no pivoting
        for r in [r for r in a[p] if r > p]:
            f = a[r][p] / a[p][p]
            for col, v in a[p].items():
                if col >= p:
                    a[r][col] = a[r].get(col, Fraction(0)) - f * v
            b[r] -= f * b[p]
    x = [Fraction(0)] * m
    for p in reversed(range(m)):
        x[p] = (b[p] - sum(v * x[col] for col, v in a[p].items() if col > p)) / a[p][p]
    return sum(2 * c[k] * x[idx[k]] for k in cells if k[0] == ny - 1) / 12


def _closed(gap: np.ndarray) -> np.ndarray:
    return gap <= 0


# Fields on which the Cholesky factor of the assembled matrix alone was off by 2 %, 22 %
# and 55 %, or met a non-positive pivot.
@pytest.mark.parametrize("seed", [122, 128, 147, 139])
def test_gaps_spanning_nine_decades_match_the_exact_rational_flow(seed):
    # Every cell open, g³ over 27 decades.
    rng = np.random.default_rng(seed)
    gap = 10.0 ** rng.uniform(-8.9, 0.0, size=(6, 6))
    exact = _exact_flow(gap, _closed(gap))
    assert exact > 0
    rates = []
    for g in (gap, np.ascontiguousarray(gap[::-1])):  # mirrored: the same flow, reversed
        f = leakpath.flow(g, dx=1.0)
        assert f.percolates and f.flow_rate > 0 and f.inlet_flow_rate > 0
        assert f.flow_rate == pytest.approx(float(exact), rel=REL, abs=0)
        assert f.inlet_flow_rate == pytest.approx(float(exact), rel=REL, abs=0)
        assert f.conservation <= 1e-6
        rates.append(f.flow_rate)
    assert rates[1] == pytest.approx(rates[0], rel=REL, abs=0)


@pytest.mark.parametrize("seed", [300, 303, 304, 307])
def test_gaps_spanning_fifteen_decades_match_the_exact_rational_flow(seed):
    # g³ over 45 decades, every cell open.
    rng = np.random.default_rng(seed)
    gap = 10.0 ** rng.uniform(-15.0, 0.0, size=(6, 6))
    exact = _exact_flow(gap, _closed(gap))
    assert exact > 0
    for g in (gap, np.ascontiguousarray(gap[::-1])):
        f = leakpath.flow(g, dx=1.0)
        assert f.percolates and f.flow_rate > 0
        assert f.flow_rate == pytest.approx(float(exact), rel=REL, abs=0)
        assert f.inlet_flow_rate == pytest.approx(float(exact), rel=REL, abs=0)
        assert f.conservation <= 1e-6


def test_a_twenty_decade_field_whose_fluxes_cannot_balance_is_refused():
    rng = np.random.default_rng(309)
    gap = 10.0 ** rng.uniform(-20.0, 0.0, size=(6, 6))
    for g in (gap, np.ascontiguousarray(gap[::-1])):
        with pytest.raises(NotConvergedError, match="balance"):
            leakpath.flow(g, dx=1.0)


@pytest.mark.parametrize(("decades", "seeds"), [(15.0, range(309, 310)), (25.0, range(300, 306))])
def test_fields_over_many_decades_are_exact_or_refused(decades, seeds):
    # g³ over 45 and 75 decades, every cell open: each answer returned (in both directions)
    # has both rates within 1e-8 of the exact rational flow and balanced fluxes; the rest
    # are refused. (Residuals that summed `c x_l` and `c x_k` apart, each product exact,
    # returned rates 1e-6 off at 25 decades: the sum's second-order error scaled with
    # `c x`, not with the flux `c (x_l − x_k)`.)
    returned = 0
    for seed in seeds:
        rng = np.random.default_rng(seed)
        gap = 10.0 ** rng.uniform(-decades, 0.0, size=(6, 6))
        for g in (gap, np.ascontiguousarray(gap[::-1])):
            exact = float(_exact_flow(g, _closed(g)))
            try:
                f = leakpath.flow(g, dx=1.0)
            except NotConvergedError as e:
                assert "balance" in str(e)
                continue
            returned += 1
            assert f.flow_rate == pytest.approx(exact, rel=1e-8, abs=0)
            assert f.inlet_flow_rate == pytest.approx(exact, rel=1e-8, abs=0)
            assert f.conservation <= 1e-6
    assert returned >= len(seeds)


@pytest.mark.parametrize("neck", [1e-3, 1e-15, 1e-40])
def test_a_neck_in_series_at_any_depth(neck):
    # A column of unit gaps with one neck: the exact series resistance, g³ down to 1e-120.
    gap = np.ones((7, 1))
    gap[3, 0] = neck
    c = [Fraction(float(g)) ** 3 for g in gap[:, 0]]
    faces = sum((a + b) / (2 * a * b) for a, b in zip(c[:-1], c[1:], strict=True))
    exact = 1 / (1 / (2 * c[0]) + faces + 1 / (2 * c[-1])) / 12
    assert exact == _exact_flow(gap, _closed(gap))
    f = leakpath.flow(gap, dx=1.0)
    assert f.percolates and f.flow_rate == pytest.approx(float(exact), rel=REL, abs=0)
    assert f.inlet_flow_rate == pytest.approx(float(exact), rel=REL, abs=0)


def test_wide_regions_between_two_necks():
    # Wide cells between two necks sit at an intermediate pressure: the face fluxes inside
    # must balance to ~Q/c of the wide cells. Resolved down to necks of g³ ~ 1e-15 ...
    gap = np.ones((9, 3))
    gap[3, :] = gap[6, :] = 1e-5
    f = leakpath.flow(gap, dx=1.0)
    assert f.flow_rate == pytest.approx(float(_exact_flow(gap, _closed(gap))), rel=REL, abs=0)
    assert f.conservation <= 1e-6
    # ... and refused, not returned unbalanced, when g³ is 1e-24 of the wide cells.
    gap[3, :] = gap[6, :] = 1e-8
    with pytest.raises(NotConvergedError, match="balance"):
        leakpath.flow(gap, dx=1.0)


@pytest.mark.parametrize("boundary", ["free", "periodic"])
def test_a_contact_states_gap_clipped_or_with_its_round_off(boundary):
    s = leakpath.spectral(64, 0.8, seed=7, rms_height=1.0)
    st = leakpath.solve(s, 0.35 * (s.heights.max() - s.heights.min()), boundary=boundary)
    on_contact = st.gap[st.contact]
    # A contact solve leaves round-off of either sign on its contact cells.
    assert (on_contact < 0).any() and (on_contact > 0).any()
    assert np.abs(on_contact).max() <= ROUND_OFF * st.gap.max()
    periodic = boundary == "periodic"
    # scipy's sparse solve of an independent assembly on the state's own contact mask.
    _, reference = _reference(np.maximum(st.gap, 0.0), st.contact, 1.0, 1.0, periodic)
    assert reference > 0
    # The clipped gap opens the contact cells with round-off above 0 (g³ ~ 1e-35 of the
    # free cells'); the raw gap closes those below. Neither changes the rate beyond 1e-10.
    for g in (np.clip(st.gap, 0, None), st.gap):
        f = leakpath.flow(g, dx=st.dx, periodic=periodic)
        assert f.flow_rate == pytest.approx(reference, rel=1e-10, abs=0)
        assert f.inlet_flow_rate == pytest.approx(reference, rel=1e-10, abs=0)


def test_clearly_negative_gaps_are_still_refused():
    gap = np.ones((4, 4))
    gap[1, 2] = -1e-6
    with pytest.raises(InvalidArgumentError, match="negative on a free cell") as e:
        leakpath.flow(gap, dx=1.0)
    assert e.value.argument == "gap"
    gap[1, 2] = -1e-12  # within the round-off band: contact
    f = leakpath.flow(gap, dx=1.0)
    assert np.isnan(f.pressure[1, 2]) and f.flow_rate > 0


@pytest.mark.parametrize("cells", [[(299, 299), (250, 10)], [(0, 5), (299, 0)],
                                   [(218, 160), (218, 161), (218, 159)]])
def test_the_first_non_finite_gap_in_row_major_order_is_named(cells):
    # 300² = 90,000 cells: more than one block of the core's parallel search (65,536 cells),
    # with the bad values in different blocks and (last case) on both sides of a block edge
    # at cell 65,536 = (218, 136) … (218, 161).
    gap = np.ones((300, 300))
    for k, c in enumerate(cells):
        gap[c] = [np.nan, np.inf, -np.inf][k % 3]
    first = min(cells)
    with pytest.raises(InvalidArgumentError, match="not finite") as e:
        leakpath.flow(gap, dx=1.0)
    assert e.value.argument == "gap"
    assert f"at ({first[0]}, {first[1]})" in str(e.value)


def _prepared_by_definition(gap, contact):
    """docs/flow.md "Supported range of gaps", cell by cell: the largest free gap ``g_max``
    (0 when none is positive); a free gap below ``−ROUND_OFF·g_max`` refused (``None``); free
    gaps in ``[−ROUND_OFF·g_max, 0)`` set to 0, free gaps in ``(0, GAP_FLOOR·g_max)`` raised
    to ``GAP_FLOOR·g_max``; contact cells as given."""
    free = [(i, j) for i in range(gap.shape[0]) for j in range(gap.shape[1])
            if contact is None or not contact[i, j]]
    gmax = max([0.0] + [float(gap[c]) for c in free])
    out = gap.copy()
    for c in free:
        v = float(gap[c])
        if v < -ROUND_OFF * gmax:
            return None
        if v < 0:
            out[c] = 0.0
        elif 0 < v < GAP_FLOOR * gmax:
            out[c] = GAP_FLOOR * gmax
    return out


@pytest.mark.parametrize("seed", range(40))
def test_gap_preparation_follows_its_definition(seed):
    # Random fields mixing contact cells (of any gap), zeros, the round-off band on both
    # sides of its edge, gaps below the floor, and ordinary gaps.
    rng = np.random.default_rng(seed)
    shape = (int(rng.integers(1, 7)), int(rng.integers(1, 7)))
    gap = rng.choice([0.0, 1.0, 2.5, -5e-10, -2e-9, 1e-60, 3e-51, -0.5], size=shape)
    gap = gap * rng.uniform(0.5, 2.0)
    contact = None if seed % 3 == 0 else rng.random(shape) < 0.4
    want = _prepared_by_definition(gap, contact)
    if want is None:
        with pytest.raises(InvalidArgumentError, match="negative on a free cell") as e:
            _prepare_gaps(gap, contact)
        assert e.value.argument == "gap"
    else:
        got = _prepare_gaps(gap, contact)
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("seed", range(8))
def test_the_free_gaps_extremes_are_numpys_masked_reductions(seed):
    # The core's one pass against numpy's reductions with a `where=` mask, on grids of one
    # cell to several of the core's chunks, masks with no, some and every cell in contact,
    # and a transposed (not C-contiguous) gap.
    rng = np.random.default_rng(seed)
    shape = [(1, 1), (3, 7), (300, 700), (257, 1031)][seed % 4]
    gap = rng.normal(size=shape)
    if seed % 2:
        gap = np.ascontiguousarray(gap.T).T
    for frac in (0.0, 0.4, 1.0):
        contact = rng.random(shape) < frac
        want = (
            float(np.min(gap, where=~contact, initial=np.inf)),
            float(np.max(gap, where=~contact, initial=-np.inf)),
        )
        assert _core.free_gap_extremes(gap, contact) == want
    assert _core.free_gap_extremes(gap) == (float(gap.min()), float(gap.max()))
    with pytest.raises(InvalidArgumentError, match="shape") as e:
        _core.free_gap_extremes(gap, np.zeros((shape[0] + 1, shape[1]), dtype=bool))
    assert e.value.argument == "contact"


def _plates(ny: int, nx: int, g: float, eta: float, dp: float) -> float:
    """``Q = W g³ Δp/(12 η L)`` in exact rationals, flow along axis 0."""
    q = nx * Fraction(g) ** 3 * Fraction(dp) / (12 * Fraction(eta) * ny)
    return float(q)


@pytest.mark.parametrize(("g", "eta", "dp"), [
    (1e100, 1e300, 1.0),  # g³ = 1e300 alone is still a double; with η it is not needed
    (1e102, 1e10, 1.0),  # g³ ≈ 1e306: the permeability g³/12 is near the top of the range
    (1e-10, 1e-320, 1.0),  # subnormal viscosity: 1/η overflows, Q does not
    (1e-100, 1e-10, 1e10),  # g³ = 1e-300
    (1.0, 1.0, 1e308),  # the largest pressure drops
])
def test_extreme_but_representable_inputs_are_right(g, eta, dp):
    ny, nx = 6, 4
    f = leakpath.flow(np.full((ny, nx), g), dx=1.0, viscosity=eta, pressure_drop=dp)
    q = _plates(ny, nx, g, eta, dp)
    assert f.flow_rate == pytest.approx(q, rel=1e-13, abs=0)
    assert f.inlet_flow_rate == pytest.approx(q, rel=1e-13, abs=0)
    assert f.hydraulic_aperture == pytest.approx(g, rel=1e-13, abs=0)


@pytest.mark.parametrize(("kwargs", "argument"), [
    ({"g": 1e120}, "gap"),  # g³ overflows
    ({"g": 1e-120}, "gap"),  # g³ underflows: Q would be 0 although the plates percolate
    ({"eta": 1e-320}, "viscosity"),
    ({"g": 10.0, "dp": 1e308}, "pressure_drop"),
])
def test_quantities_beyond_a_double_are_refused(kwargs, argument):
    g, eta, dp = kwargs.get("g", 1.0), kwargs.get("eta", 1.0), kwargs.get("dp", 1.0)
    with pytest.raises(InvalidArgumentError, match="range of a double") as e:
        leakpath.flow(np.full((6, 8), g), dx=1.0, viscosity=eta, pressure_drop=dp)
    assert e.value.argument == argument


def test_gas_at_tiny_pressures():
    ny, nx, g = 6, 4, 1.0
    kw = {"dx": 1.0, "gas": True, "temperature": 1.0}
    # p_in² = 9e-320 is subnormal, the mass flow ~4e-220 is not.
    p_in, p_out, r_s = 3e-160, 1e-160, 1e-100
    f = leakpath.flow(
        np.full((ny, nx), g), inlet_pressure=p_in, outlet_pressure=p_out, gas_constant=r_s, **kw
    )
    mdot = nx * Fraction(g) ** 3 * (Fraction(p_in) ** 2 - Fraction(p_out) ** 2) / (
        24 * Fraction(r_s) * ny
    )
    assert f.mass_flow_rate == pytest.approx(float(mdot), rel=1e-13, abs=0)
    x = (np.arange(ny) + 0.5) / ny
    # p = √(p_in² − (p_in² − p_out²) x), with p_in taken out (p_in² is subnormal).
    p_exact = p_in * np.sqrt(1 - (1 - (p_out / p_in) ** 2) * x)
    np.testing.assert_allclose(f.pressure[:, 0], p_exact, rtol=1e-12)
    # The mass flow ~1e-405 itself is below the range: refused, not returned as 0.
    with pytest.raises(InvalidArgumentError, match="range of a double") as e:
        leakpath.flow(
            np.full((ny, nx), g),
            inlet_pressure=3e-200,
            outlet_pressure=1e-200,
            gas_constant=287.05,
            **kw,
        )
    assert e.value.argument == "inlet_pressure"


@pytest.mark.parametrize("name", [
    "viscosity", "pressure_drop", "dx", "tol", "max_iter", "memory_limit",
])
def test_huge_integers_name_the_argument(name):
    with pytest.raises(InvalidArgumentError) as e:
        leakpath.flow(np.ones((4, 4)), **{"dx": 1.0, name: 10**400})
    assert e.value.argument == name


@pytest.mark.parametrize("name", ["inlet_pressure", "outlet_pressure", "gas_constant",
                                  "temperature"])
def test_huge_integer_gas_inputs_name_the_argument(name):
    kw = {"inlet_pressure": 2.0, "outlet_pressure": 1.0, "gas_constant": 1.0, "temperature": 1.0}
    kw[name] = 10**400
    with pytest.raises(InvalidArgumentError) as e:
        leakpath.flow(np.ones((4, 4)), dx=1.0, gas=True, **kw)
    assert e.value.argument == name
