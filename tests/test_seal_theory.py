"""Seal theory and upscaling (leakpath.seal._theory, leakpath.seal._estimate).

Oracles are independent of the code under test: SciPy quadrature of the PSD and of Persson's
stress distribution, SciPy root finding on the effective-medium condition, exact closed forms
(parallel plates, Dykhne's √(k₁k₂), log-symmetric samples), SciPy's means, and leakpath's
finite-volume flow solver for the leak rates.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, optimize, special, stats

import leakpath
from leakpath.errors import InvalidArgumentError
from leakpath.seal._estimate import (
    BOOTSTRAP_RESAMPLES,
    PermeabilityEstimate,
    effective_permeability,
    gas_mass_flow,
    liquid_leak_rate,
)
from leakpath.seal._theory import bruggeman_permeability, persson_contact_fraction

R_AIR = 287.05  # J/(kg K)


# --------------------------------------------------------------------------- Persson


def _psd(q0: float, qr: float, q1: float, hurst: float, c0: float):
    """Self-affine isotropic PSD with a roll-off: C0 below q_r, C0 (q/q_r)^(−2(1+H)) above."""

    def c(q: float) -> float:
        if q < q0 or q > q1:
            return 0.0
        return c0 if q < qr else c0 * (q / qr) ** (-2.0 * (1.0 + hurst))

    return c


@pytest.mark.parametrize("hurst", [0.3, 0.8])
@pytest.mark.parametrize("p_over", [0.01, 0.1, 0.5])
def test_persson_area_equals_the_stress_distribution_integrated_over_the_psd(hurst, p_over):
    # Persson's G from the PSD by quadrature, G = (π/4)(E*/p)² ∫ q³ C dq; the area is the
    # integral over σ > 0 of the image solution P(σ) of the stress diffusion, also by
    # quadrature. The function only sees h'_rms = sqrt(2π ∫ q³ C dq).
    q0, qr, q1 = 2 * np.pi / 1e-3, 2 * np.pi / 2.5e-4, 2 * np.pi / 1e-6  # rad/m
    c = _psd(q0, qr, q1, hurst, 1e-30)  # m^4
    moment = integrate.quad(lambda q: q**3 * c(q), q0, q1, points=[qr], limit=400, epsabs=0)[0]
    slope = math.sqrt(2 * np.pi * moment)
    e_star = 2.1e6
    p = p_over * e_star * slope
    g = (np.pi / 4) * (e_star / p) ** 2 * moment
    width = math.sqrt(4 * g) * p

    def density(s: float) -> float:
        return (math.exp(-((s - p) ** 2) / width**2) - math.exp(-((s + p) ** 2) / width**2)) / (
            width * math.sqrt(np.pi)
        )

    area = integrate.quad(density, 0, p + 40 * width, points=[p], limit=400, epsabs=0)[0]
    got = persson_contact_fraction(p, e_star, slope)
    assert isinstance(got, float)
    assert got == pytest.approx(area, rel=1e-8)
    assert got == pytest.approx(special.erf(1 / (2 * math.sqrt(g))), rel=1e-12, abs=0)


def test_persson_small_load_constant_is_sqrt_8_over_pi():
    e_star, slope = 1e7, 0.2
    p = 1e-7 * e_star * slope
    kappa = persson_contact_fraction(p, e_star, slope) / (p / (e_star * slope))
    assert kappa == pytest.approx(math.sqrt(8 / math.pi), rel=1e-12)
    assert kappa == pytest.approx(1.5958, abs=1e-4)


def test_persson_limits_and_broadcasting():
    p = np.array([0.0, 1e3, 1e5, 1e7, 1e12])
    a = persson_contact_fraction(p, 1e7, 0.1)
    assert isinstance(a, np.ndarray) and a.shape == p.shape
    assert a[0] == 0.0 and a[-1] == 1.0
    assert np.all(np.diff(a[:-1]) > 0) and a[-2] <= a[-1]
    # A smooth pair is in full contact at any load; none at zero load.
    np.testing.assert_array_equal(persson_contact_fraction([0.0, 1.0], 1e7, 0.0), [0.0, 1.0])
    # Doubling E* halves the argument: same area at double the pressure.
    assert persson_contact_fraction(2e4, 2e7, 0.1) == persson_contact_fraction(1e4, 1e7, 0.1)


def test_simulated_area_exceeds_persson_at_small_loads():
    # Where theory and simulation part: boundary elements give A/A0 = κ p̄/(E* h'_rms) with
    # κ ≈ 2 (and more on a coarse grid), Persson κ = √(8/π) ≈ 1.6.
    s = leakpath.spectral(
        (128, 128), 0.8, seed=0, length=1e-3, rms_slope=0.1,
        long_cutoff=2.5e-4, short_cutoff=1.25e-4,
    )
    problem = leakpath.ContactProblem(s, E=1e7, nu=0.0, boundary="periodic")
    slope = leakpath.rms_slope(s)
    for p in (5e3, 2e4, 1e5):
        ratio = problem.solve(mean_pressure=p).contact_fraction / persson_contact_fraction(
            p, 1e7, slope
        )
        assert 1.1 < ratio < 2.0


@pytest.mark.parametrize(
    ("kwargs", "argument"),
    [
        ({"mean_pressure": -1.0}, "mean_pressure"),
        ({"mean_pressure": [1.0, math.nan]}, "mean_pressure"),
        ({"E_star": 0.0}, "E_star"),
        ({"E_star": math.inf}, "E_star"),
        ({"rms_slope": -0.1}, "rms_slope"),
        ({"rms_slope": "steep"}, "rms_slope"),
    ],
)
def test_persson_refuses_bad_inputs_by_name(kwargs, argument):
    args = {"mean_pressure": 1e5, "E_star": 1e7, "rms_slope": 0.1} | kwargs
    with pytest.raises(InvalidArgumentError) as err:
        persson_contact_fraction(**args)
    assert err.value.argument == argument
    assert str(err.value).startswith(argument + ":")


# --------------------------------------------------------------------------- Bruggeman


def _ema_root(k: np.ndarray) -> float:
    """Oracle: Brent's method on Σ (k − x)/(k + x) = 0 between its sign changes."""
    k = np.asarray(k, float).ravel()
    if np.count_nonzero(k == 0) * 2 >= k.size:
        return 0.0

    def f(t: float) -> float:
        x = math.exp(t)
        return float(np.sum((k - x) / (k + x)))

    kp = k[k > 0]
    return math.exp(
        optimize.brentq(f, math.log(kp.min()) - 80, math.log(kp.max()), xtol=1e-14, rtol=1e-15)
    )


@pytest.mark.parametrize("g", [1e-9, 3.7e-6, 2.0])
def test_bruggeman_uniform_gap_is_parallel_plates_exactly(g):
    assert bruggeman_permeability(np.full((9, 13), g), 1e-6) == g**3 / 12


def test_bruggeman_two_values_half_each_is_dykhnes_geometric_mean():
    rng = np.random.default_rng(3)
    cells = np.zeros(64 * 64, bool)
    cells[: cells.size // 2] = True
    rng.shuffle(cells)
    g1, g2 = 1e-6, 7e-6
    gap = np.where(cells.reshape(64, 64), g1, g2)
    want = math.sqrt((g1**3 / 12) * (g2**3 / 12))
    assert bruggeman_permeability(gap, 1e-5) == pytest.approx(want, rel=1e-13, abs=0)


def test_bruggeman_is_zero_from_half_of_the_cells_closed():
    rng = np.random.default_rng(4)
    gap = 1e-6 * np.exp(rng.normal(0, 0.5, (40, 40)))
    order = rng.permutation(gap.size)
    for n_closed, positive in [(799, True), (800, False), (1200, False)]:
        g = gap.copy().ravel()
        g[order[:n_closed]] = 0.0
        g = g.reshape(40, 40)
        k = bruggeman_permeability(g, 1e-5)
        assert (k > 0) is positive
        assert k == pytest.approx(_ema_root(g**3 / 12), rel=1e-12, abs=0)
        # The same cells closed through a contact mask (gaps there ignored).
        masked = np.where(g == 0, 5e-6, g)
        k_masked = bruggeman_permeability(masked, 1e-5, contact=g == 0)
        assert k_masked == pytest.approx(k, rel=1e-14, abs=0)
    # Fully closed.
    assert bruggeman_permeability(np.zeros((4, 4)), 1.0) == 0.0


@pytest.mark.parametrize("closed", [0.0, 0.3, 0.49])
def test_bruggeman_solves_the_effective_medium_condition(closed):
    rng = np.random.default_rng(5)
    gap = 1e-6 * np.exp(rng.normal(0, 1.0, (50, 50)))
    gap[rng.random(gap.shape) < closed] = -1e-9  # closed (g <= 0, no contact mask)
    k = bruggeman_permeability(gap, 1e-5)
    assert k == pytest.approx(_ema_root(np.clip(gap, 0, None) ** 3 / 12), rel=1e-12, abs=0)


@pytest.mark.parametrize("seed", [0, 1])
def test_bruggeman_between_wiener_bounds_and_near_the_finite_volume_flow(seed):
    rng = np.random.default_rng(seed)
    gap = 1e-6 * np.exp(rng.normal(0, 0.4, (128, 128)))  # lognormal, σ(ln k) = 1.2
    k = gap**3 / 12
    ema = bruggeman_permeability(gap, 1e-5)
    assert stats.hmean(k.ravel()) < ema < k.mean()
    # Log-symmetric cells: the EMA is the geometric mean up to the sample's asymmetry.
    assert ema == pytest.approx(stats.gmean(k.ravel()), rel=0.01, abs=0)
    for axis in (0, 1):
        fv = leakpath.flow(gap, dx=1e-5, axis=axis, periodic=True).permeability
        assert stats.hmean(k.ravel()) < fv < k.mean()
        # Stated accuracy of the EMA on such fields: within a factor 1.5 of the exact flow.
        assert 1 / 1.5 < fv / ema < 1.5


def test_bruggeman_does_not_depend_on_axis_dx_or_orientation():
    rng = np.random.default_rng(6)
    gap = np.clip(rng.normal(1e-6, 1e-6, (30, 20)), 0, None)
    k = bruggeman_permeability(gap, 1e-5)
    assert bruggeman_permeability(gap, 3.0, axis=1) == k
    assert bruggeman_permeability(gap.T, 1e-5) == k


@pytest.mark.parametrize(
    ("gap", "kwargs", "argument"),
    [
        (np.ones(5), {}, "gap"),
        (np.full((3, 3), math.nan), {}, "gap"),
        (np.ones((3, 3)), {"dx": 0.0}, "dx"),
        (np.ones((3, 3)), {"dx": math.inf}, "dx"),
        (np.ones((3, 3)), {"axis": 2}, "axis"),
        (np.ones((3, 3)), {"contact": np.zeros((2, 2), bool)}, "contact"),
        (-np.ones((3, 3)), {"contact": np.zeros((3, 3), bool)}, "gap"),
    ],
)
def test_bruggeman_refuses_bad_inputs_by_name(gap, kwargs, argument):
    args = {"dx": 1.0} | kwargs
    dx = args.pop("dx")
    with pytest.raises(InvalidArgumentError) as err:
        bruggeman_permeability(gap, dx, **args)
    assert err.value.argument == argument


# --------------------------------------------------------------------------- estimator


def test_estimate_of_a_log_symmetric_sample_is_its_geometric_mean():
    # k = K e^{±u}: every pair contributes tanh(u/2) − tanh(u/2) = 0 at K, exactly.
    u = np.array([0.1, 0.7, 2.0, 3.5, 5.0])
    k = 3e-18 * np.exp(np.concatenate([u, -u, [0.0]]))
    est = effective_permeability(k)
    assert est.value == pytest.approx(3e-18, rel=1e-12, abs=0)
    assert est.geometric == pytest.approx(stats.gmean(k), rel=1e-12, abs=0)
    assert est.value == pytest.approx(est.geometric, rel=1e-12, abs=0)


def test_estimate_of_lognormal_samples_is_close_to_the_geometric_mean():
    k = 1e-17 * np.exp(np.random.default_rng(7).normal(0, 2.0, 1000))
    est = effective_permeability(k)
    assert est.value == pytest.approx(stats.gmean(k), rel=0.05, abs=0)
    assert est.value == pytest.approx(1e-17, rel=0.25, abs=0)  # the population's geometric mean


@pytest.mark.parametrize("seed", range(5))
def test_estimate_ordering_and_means_against_scipy(seed):
    rng = np.random.default_rng(seed)
    k = 1e-18 * rng.gamma(0.5 + seed, size=12)
    est = effective_permeability(k)
    assert isinstance(est, PermeabilityEstimate)
    assert est.arithmetic == pytest.approx(np.mean(k), rel=1e-14, abs=0)
    assert est.harmonic == pytest.approx(stats.hmean(k), rel=1e-12, abs=0)
    assert est.geometric == pytest.approx(stats.gmean(k), rel=1e-12, abs=0)
    assert est.harmonic <= est.geometric <= est.arithmetic
    assert est.harmonic <= est.value <= est.arithmetic
    assert est.value == pytest.approx(_ema_root(k), rel=1e-12, abs=0)
    assert est.low <= est.value <= est.high
    assert (est.n, est.n_leaking, est.leak_fraction) == (12, 12, 1.0)
    assert "bruggeman" in est.method and str(BOOTSTRAP_RESAMPLES) in est.method


def test_estimate_with_closed_patches():
    k = np.array([0.0, 0.0, 0.0, 1e-18, 4e-18, 2e-18, 9e-18])
    est = effective_permeability(k)
    assert est.harmonic == 0.0 and est.geometric == 0.0
    assert est.value == pytest.approx(_ema_root(k), rel=1e-12, abs=0) and est.value > 0
    assert est.leak_fraction == pytest.approx(4 / 7) and est.n_leaking == 4
    # Half or more closed: the 2-D effective-medium threshold.
    half = effective_permeability(np.array([0.0, 0.0, 1e-18, 5e-18]))
    assert half.value == 0.0 and half.arithmetic > 0
    none = effective_permeability(np.zeros(16))
    assert (none.value, none.low, none.high, none.leak_fraction, none.n_leaking) == (
        0.0, 0.0, 0.0, 0.0, 0,
    )


@pytest.mark.filterwarnings("error")
def test_estimate_over_three_hundred_decades():
    # 2(ε − K)/(ε + K) + (1 − K)/(1 + K) = 0 has K = 3ε (1 + O(ε)): no underflow on the way.
    k = np.array([1e-300, 1e-300, 1.0])
    est = effective_permeability(k)
    assert est.value == pytest.approx(3e-300, rel=1e-12, abs=0)
    assert est.harmonic == pytest.approx(1.5e-300, rel=1e-12, abs=0)
    assert est.geometric == pytest.approx(1e-200, rel=1e-12, abs=0)
    assert 0 < est.low <= est.value <= est.high <= 1.0


def test_estimate_from_one_realisation_has_no_interval():
    est = effective_permeability([2e-18])
    assert est.value == 2e-18 and math.isnan(est.low) and math.isnan(est.high)
    assert "no interval" in est.method


def test_bootstrap_is_deterministic_in_the_seed():
    k = 1e-18 * np.exp(np.random.default_rng(8).normal(0, 1.5, 16))
    a, b = effective_permeability(k, seed=11), effective_permeability(k, seed=11)
    assert a == b
    c = effective_permeability(k, seed=12)
    assert c.value == a.value and (c.low, c.high) != (a.low, a.high)
    # A wider confidence level gives a wider interval from the same resamples.
    d = effective_permeability(k, seed=11, confidence=0.99)
    assert d.low <= a.low and d.high >= a.high


def test_groups_resample_whole_realisations():
    k = 1e-18 * np.exp(np.random.default_rng(9).normal(0, 1.5, 10))
    single = effective_permeability(k, seed=3)
    # Each realisation twice (two flow directions with the same k): resampling whole groups
    # draws the same realisations as resampling the singles.
    paired = effective_permeability(np.repeat(k, 2), seed=3, groups=np.repeat(np.arange(10), 2))
    assert paired.value == pytest.approx(single.value, rel=1e-12, abs=0)
    assert paired.low == pytest.approx(single.low, rel=1e-12, abs=0)
    assert paired.high == pytest.approx(single.high, rel=1e-12, abs=0)
    # Treated as 20 independent values the interval would be narrower.
    naive = effective_permeability(np.repeat(k, 2), seed=3)
    assert naive.high / naive.low < paired.high / paired.low


def _population_root(sigma: float, closed: float) -> float:
    """Bruggeman K of the population: (1 − c) E[tanh((ln k − ln K)/2)] − c = 0, k ~ LN(0, σ)."""

    def f(t: float) -> float:
        mean = integrate.quad(
            lambda z: math.tanh((sigma * z - t) / 2) * stats.norm.pdf(z), -12, 12, epsabs=1e-14
        )[0]
        return (1 - closed) * mean - closed

    return math.exp(optimize.brentq(f, -30, 30, xtol=1e-13))


@pytest.mark.parametrize(("sigma", "closed"), [(2.0, 0.0), (2.0, 0.25)])
def test_interval_covers_the_true_effective_permeability(sigma, closed):
    # 200 synthetic experiments of 16 realisations with deterministic seeds; the 95 % interval
    # must cover the population's K_eff in at least 85 % of them (a percentile bootstrap from
    # 16 values covers somewhat less than nominal).
    true = 1e-18 * _population_root(sigma, closed)
    if closed == 0:
        assert true == pytest.approx(1e-18, rel=1e-9, abs=0)  # log-symmetric: the median
    hits = 0
    for experiment in range(200):
        rng = np.random.default_rng(10_000 + experiment)
        k = 1e-18 * np.exp(rng.normal(0, sigma, 16))
        k[rng.random(16) < closed] = 0.0
        est = effective_permeability(k, seed=experiment)
        hits += est.low <= true <= est.high
    assert hits >= 170
    assert hits < 200  # an interval that always covers would be too wide to be informative


@pytest.mark.parametrize(
    ("k", "kwargs", "argument"),
    [
        ([], {}, "k"),
        ([[1e-18, 2e-18]], {}, "k"),
        ([1e-18, -1e-20], {}, "k"),
        ([1e-18, math.nan], {}, "k"),
        ([1e-18, math.inf], {}, "k"),
        (["a"], {}, "k"),
        ([1e-18, 2e-18], {"confidence": 1.0}, "confidence"),
        ([1e-18, 2e-18], {"confidence": 0.0}, "confidence"),
        ([1e-18, 2e-18], {"seed": -1}, "seed"),
        ([1e-18, 2e-18], {"seed": 1.5}, "seed"),
        ([1e-18, 2e-18], {"groups": [0]}, "groups"),
    ],
)
def test_estimate_refuses_bad_inputs_by_name(k, kwargs, argument):
    with pytest.raises(InvalidArgumentError) as err:
        effective_permeability(k, **kwargs)
    assert err.value.argument == argument


# --------------------------------------------------------------------------- leak rates


@pytest.mark.parametrize("axis", [0, 1])
def test_liquid_leak_rate_matches_the_flow_solver_on_parallel_plates(axis):
    ny, nx, g, dx = 24, 15, 3e-6, 2e-5
    eta, dp = 1.0e-3, 1e5
    f = leakpath.flow(np.full((ny, nx), g), dx=dx, axis=axis, viscosity=eta, pressure_drop=dp)
    n_along, n_across = (ny, nx) if axis == 0 else (nx, ny)
    q = liquid_leak_rate(
        g**3 / 12, width=n_across * dx, length=n_along * dx, viscosity=eta, pressure_drop=dp
    )
    assert q == pytest.approx(f.flow_rate, rel=1e-11, abs=0)
    assert q == pytest.approx(n_across * g**3 * dp / (12 * eta * n_along), rel=1e-14, abs=0)


@pytest.mark.parametrize("axis", [0, 1])
def test_gas_mass_flow_matches_the_flow_solver_on_parallel_plates(axis):
    ny, nx, g, dx = 30, 17, 2e-6, 1e-5
    eta, t, p_in, p_out = 1.8e-5, 293.15, 3e5, 1e5
    f = leakpath.flow(
        np.full((ny, nx), g), dx=dx, axis=axis, viscosity=eta, gas=True,
        inlet_pressure=p_in, outlet_pressure=p_out, gas_constant=R_AIR, temperature=t,
    )
    n_along, n_across = (ny, nx) if axis == 0 else (nx, ny)
    m = gas_mass_flow(
        g**3 / 12, width=n_across * dx, length=n_along * dx, viscosity=eta,
        inlet_pressure=p_in, outlet_pressure=p_out, gas_constant=R_AIR, temperature=t,
    )
    assert m == pytest.approx(f.mass_flow_rate, rel=1e-11, abs=0)
    assert m == pytest.approx(
        n_across * g**3 * (p_in**2 - p_out**2) / (24 * eta * R_AIR * t * n_along), rel=1e-14, abs=0
    )


def test_leak_rates_broadcast_and_pass_nan_through():
    q = liquid_leak_rate(
        np.array([1e-18, math.nan, 0.0]), width=0.1, length=2e-3, viscosity=1e-3,
        pressure_drop=1e5,
    )
    assert q[0] == pytest.approx(1e-18 * 50 * 1e8, rel=1e-14, abs=0)
    assert math.isnan(q[1]) and q[2] == 0.0


@pytest.mark.parametrize(
    ("kwargs", "argument"),
    [
        ({"k_eff": -1e-18}, "k_eff"),
        ({"k_eff": math.inf}, "k_eff"),
        ({"width": 0.0}, "width"),
        ({"length": -1.0}, "length"),
        ({"viscosity": math.nan}, "viscosity"),
        ({"pressure_drop": math.inf}, "pressure_drop"),
    ],
)
def test_liquid_leak_rate_refuses_bad_inputs_by_name(kwargs, argument):
    args = {
        "k_eff": 1e-18, "width": 0.1, "length": 2e-3, "viscosity": 1e-3, "pressure_drop": 1e5,
    } | kwargs
    k = args.pop("k_eff")
    with pytest.raises(InvalidArgumentError) as err:
        liquid_leak_rate(k, **args)
    assert err.value.argument == argument


@pytest.mark.parametrize(
    ("kwargs", "argument"),
    [
        ({"inlet_pressure": -1.0}, "inlet_pressure"),
        ({"outlet_pressure": math.nan}, "outlet_pressure"),
        ({"gas_constant": 0.0}, "gas_constant"),
        ({"temperature": -5.0}, "temperature"),
    ],
)
def test_gas_mass_flow_refuses_bad_inputs_by_name(kwargs, argument):
    args = {
        "width": 0.1, "length": 2e-3, "viscosity": 1.8e-5, "inlet_pressure": 2e5,
        "outlet_pressure": 1e5, "gas_constant": R_AIR, "temperature": 293.15,
    } | kwargs
    with pytest.raises(InvalidArgumentError) as err:
        gas_mass_flow(1e-18, **args)
    assert err.value.argument == argument
