"""Two bodies and the patch (leakpath.seal._bodies): independent oracles only.

Closed forms are written out here (not taken from the module); statistical checks derive their
tolerance from the number of Fourier modes (docs/seal-bodies.md).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate

import leakpath
from leakpath.errors import InvalidArgumentError
from leakpath.seal._bodies import (
    Material,
    Patch,
    Roughness,
    available_realisations,
    choose_patch,
    composite_psd,
    composite_rms_height,
    composite_rms_slope,
    composite_surface,
    contact_modulus_pair,
    validity_warnings,
)

STEEL = Material(E=210e9, nu=0.3)
RUBBER = Material(E=10e6, nu=0.5)

# Two different rough bodies (lengths in m); 64² patch of side 4 roll-offs of the upper body.
UPPER = Roughness(hurst=0.8, rms_height=1e-6, rolloff_wavelength=100e-6,
                  short_wavelength=25e-6, name="surface.upper")
LOWER = Roughness(hurst=0.5, rms_slope=0.02, rolloff_wavelength=50e-6,
                  short_wavelength=20e-6, name="surface.lower")
PATCH = Patch(n=64, length=400e-6, dx=400e-6 / 64, rule="test")


def psd_rolloff(q, c0, q_r, q_s, hurst):
    """Persson's self-affine spectrum with roll-off, written out independently."""
    q = np.asarray(q, dtype=float)
    out = np.where(q < q_r, c0, c0 * (np.maximum(q, q_r) / q_r) ** (-2 * (1 + hurst)))
    return np.where((q > 0) & (q <= q_s * (1 + 1e-12)), out, 0.0)


def m0_rolloff(c0, q_r, q_s, hurst):
    """2π∫ q C dq in closed form."""
    return 2 * math.pi * c0 * (q_r**2 / 2 + q_r ** (2 + 2 * hurst)
                               * (q_r ** (-2 * hurst) - q_s ** (-2 * hurst)) / (2 * hurst))


def slope2_rolloff(c0, q_r, q_s, hurst):
    """2π∫ q³ C dq in closed form."""
    return 2 * math.pi * c0 * (q_r**4 / 4 + q_r ** (2 + 2 * hurst)
                               * (q_s ** (2 - 2 * hurst) - q_r ** (2 - 2 * hurst))
                               / (2 - 2 * hurst))


def spectral_stats(h, dx):
    """(m0, ⟨|∇h|²⟩) of a periodic sample from its DFT (spectral derivative)."""
    ny, nx = h.shape
    f = np.fft.fft2(h - h.mean())
    p = np.abs(f) ** 2 / (ny * nx) ** 2
    qy = 2 * np.pi * np.fft.fftfreq(ny, dx)
    qx = 2 * np.pi * np.fft.fftfreq(nx, dx)
    q2 = qy[:, None] ** 2 + qx[None, :] ** 2
    return float(p.sum()), float((q2 * p).sum())


# ============================================================================ materials
def test_contact_modulus_steel_rubber_by_hand():
    by_hand = 1.0 / ((1 - 0.3**2) / 210e9 + (1 - 0.5**2) / 10e6)
    assert contact_modulus_pair(STEEL, RUBBER) == pytest.approx(by_hand, rel=1e-14)
    assert contact_modulus_pair(RUBBER, STEEL) == contact_modulus_pair(STEEL, RUBBER)
    # rubber on rigid steel: E/(1 − ν²) = 4E/3
    rigid = Material(E=math.inf, nu=0.3)
    assert contact_modulus_pair(rigid, RUBBER) == pytest.approx(4 * 10e6 / 3, rel=1e-14)
    # steel on steel: half the single-body modulus
    assert contact_modulus_pair(STEEL, STEEL) == pytest.approx(210e9 / 0.91 / 2, rel=1e-14)


def test_both_rigid_refused():
    rigid = Material(E=math.inf, nu=0.0)
    with pytest.raises(InvalidArgumentError) as e:
        contact_modulus_pair(rigid, rigid)
    assert e.value.argument == "material"


@pytest.mark.parametrize(
    "kwargs, argument",
    [
        (dict(E=0.0, nu=0.3), "material.upper.E"),
        (dict(E=-1e9, nu=0.3), "material.upper.E"),
        (dict(E=math.nan, nu=0.3), "material.upper.E"),
        (dict(E="2e11", nu=0.3), "material.upper.E"),
        (dict(E=1e9, nu=0.51), "material.upper.nu"),
        (dict(E=1e9, nu=-1.0), "material.upper.nu"),
    ],
)
def test_bad_material_refused_by_name(kwargs, argument):
    with pytest.raises(InvalidArgumentError) as e:
        Material(**kwargs, name="material.upper")
    assert e.value.argument == argument
    assert str(e.value).startswith(argument + ":")


# ============================================================================ pair = composite
def test_pair_equals_composite_against_combined_modulus():
    """Each body generated alone (the other smooth) and summed by hand equals the composite;
    a contact solve of that sum with the pair's E* equals the solve of the composite."""
    flat = Roughness.smooth()
    h_u = composite_surface(UPPER, flat, PATCH, realisation=3, seed=11).heights
    h_l = composite_surface(flat, LOWER, PATCH, realisation=3, seed=11).heights
    comp = composite_surface(UPPER, LOWER, PATCH, realisation=3, seed=11)
    np.testing.assert_allclose(comp.heights, h_u + h_l, rtol=0, atol=1e-15 * np.ptp(h_u + h_l))
    assert comp.dx == PATCH.dx and comp.shape == (64, 64)

    e_star = contact_modulus_pair(STEEL, RUBBER)
    slope = composite_rms_slope(UPPER, LOWER)
    p_mean = 0.1 * e_star * slope / 2  # about 10 % contact (Persson: A/A0 ≈ 2p̄/(E* slope))
    a = leakpath.ContactProblem(leakpath.Surface(h_u + h_l, PATCH.dx), E=e_star, nu=0.0,
                                boundary="periodic").solve(mean_pressure=p_mean)
    b = leakpath.ContactProblem(comp, E=e_star, nu=0.0,
                                boundary="periodic").solve(mean_pressure=p_mean)
    frac = np.mean(a.pressure > 0)
    assert 0.02 < frac < 0.5
    np.testing.assert_array_equal(a.pressure > 0, b.pressure > 0)
    np.testing.assert_allclose(b.pressure, a.pressure, rtol=0, atol=1e-9 * a.pressure.max())
    np.testing.assert_allclose(b.gap, a.gap, rtol=0, atol=1e-9 * np.ptp(comp.heights))
    # the same E* from a rubber body's own (E, ν) against a rigid flat
    rubber_alone = leakpath.ContactProblem(comp, E=10e6, nu=0.5, boundary="periodic")
    assert rubber_alone.e_star == pytest.approx(
        contact_modulus_pair(Material(math.inf, 0.3), RUBBER), rel=1e-14
    )


def test_swapping_bodies_changes_nothing():
    a = composite_surface(UPPER, LOWER, PATCH, realisation=1, seed=5)
    b = composite_surface(LOWER, UPPER, PATCH, realisation=1, seed=5)
    np.testing.assert_array_equal(a.heights, b.heights)
    assert contact_modulus_pair(STEEL, RUBBER) == contact_modulus_pair(RUBBER, STEEL)
    assert composite_rms_slope(UPPER, LOWER) == composite_rms_slope(LOWER, UPPER)
    assert composite_rms_height(UPPER, LOWER) == composite_rms_height(LOWER, UPPER)
    q = np.geomspace(1e3, 1e6, 50)
    np.testing.assert_array_equal(composite_psd(UPPER, LOWER)(q), composite_psd(LOWER, UPPER)(q))


def test_identical_bodies_are_independent():
    """Two bodies with the same description get independent noise: the composite of two
    equal bodies is not 2·h (variance 2m0, not 4m0)."""
    body = Roughness(hurst=0.7, rms_height=1.0, rolloff_wavelength=0.25, short_wavelength=1 / 16)
    patch = Patch(n=64, length=1.0, dx=1 / 64, rule="test")
    single = composite_surface(body, Roughness.smooth(), patch, realisation=0, seed=0).heights
    pair = composite_surface(body, body, patch, realisation=0, seed=0).heights
    other = pair - single
    corr = np.sum(single * other) / math.sqrt(np.sum(single**2) * np.sum(other**2))
    assert abs(corr) < 0.35  # ≈ 70 independent roll-off modes: |r| ≲ 4/√70 ≈ 0.5 at worst
    assert not np.allclose(other, single)


# ============================================================================ spectra
def test_psd_and_integrals_against_closed_forms():
    q_r, q_s = 2 * math.pi / 100e-6, 2 * math.pi / 25e-6
    c0 = 1e-6**2 / m0_rolloff(1.0, q_r, q_s, 0.8)  # rms height 1 µm
    q = np.geomspace(q_r / 10, q_s * 2, 400)
    up = composite_psd(UPPER, Roughness.smooth())(q)
    np.testing.assert_allclose(up, psd_rolloff(q, c0, q_r, q_s, 0.8), rtol=1e-12, atol=0)
    # LOWER given by its rms slope
    q_r2, q_s2 = 2 * math.pi / 50e-6, 2 * math.pi / 20e-6
    c0_l = 0.02**2 / slope2_rolloff(1.0, q_r2, q_s2, 0.5)
    np.testing.assert_allclose(composite_psd(UPPER, LOWER)(q),
                               up + psd_rolloff(q, c0_l, q_r2, q_s2, 0.5), rtol=1e-12)
    m0 = 1e-12 + m0_rolloff(c0_l, q_r2, q_s2, 0.5)
    s2 = slope2_rolloff(c0, q_r, q_s, 0.8) + 0.02**2
    assert composite_rms_height(UPPER, LOWER) == pytest.approx(math.sqrt(m0), rel=1e-12, abs=0)
    assert composite_rms_slope(UPPER, LOWER) == pytest.approx(math.sqrt(s2), rel=1e-12, abs=0)
    # and by quadrature of the returned C(q)
    c = composite_psd(UPPER, LOWER)
    # up to the larger cutoff (LOWER's, q_s2 > q_s): above it C(q) = 0
    *pts, q_top = sorted([q_r, q_r2, q_s2, q_s])
    m0_quad = integrate.quad(lambda x: 2 * np.pi * x * c(x), 0, q_top, points=pts, limit=200)[0]
    assert m0_quad == pytest.approx(m0, rel=1e-8, abs=0)


def test_tabulated_psd_and_no_rolloff():
    """A two-point table is the same power law (log-log interpolation), flat below; a body
    without roll-off starts at the patch's lowest mode 2π/L and needs L."""
    q_r, q_s, h = 2 * math.pi / 1e-3, 2 * math.pi / 1e-4, 0.6
    table = (np.array([q_r, q_s]), np.array([1e-20, 1e-20 * (q_s / q_r) ** (-2 * (1 + h))]))
    tab = Roughness(psd=table)
    q = np.geomspace(q_r / 3, q_s * 1.5, 100)
    np.testing.assert_allclose(composite_psd(tab, Roughness.smooth())(q),
                               psd_rolloff(q, 1e-20, q_r, q_s, h), rtol=1e-12)
    assert composite_rms_height(tab, Roughness.smooth()) == pytest.approx(
        math.sqrt(m0_rolloff(1e-20, q_r, q_s, h)), rel=1e-12, abs=0)
    # rescaled table
    tab2 = Roughness(psd=table, rms_slope=0.1)
    assert composite_rms_slope(tab2, tab2) == pytest.approx(0.1 * math.sqrt(2), rel=1e-12, abs=0)

    sa = Roughness(hurst=h, rms_height=2e-6, short_wavelength=1e-4)
    with pytest.raises(InvalidArgumentError) as e:
        composite_rms_height(sa, Roughness.smooth())
    assert e.value.argument == "length"
    length = 2e-3
    q_l = 2 * math.pi / length
    assert composite_rms_height(sa, Roughness.smooth(), length=length) == pytest.approx(2e-6)
    # C0 (q/q_L)^(−2(1+H)) on [q_L, q_s], zero below
    c0 = (2e-6) ** 2 / (2 * math.pi * q_l ** (2 + 2 * h) * (q_l ** (-2 * h) - q_s ** (-2 * h))
                        / (2 * h))
    cq = composite_psd(sa, Roughness.smooth(), length=length)
    assert cq(np.array([q_l / 2]))[0] == 0.0
    assert cq(np.array([2 * q_l]))[0] == pytest.approx(c0 * 2 ** (-2 * (1 + h)), rel=1e-12, abs=0)


def _expected_discrete(psd, n, length):
    """Σ_k C(q_k) Δq² and Σ_k q² C Δq² over the modes max(|kx|,|ky|) < n/2 (the spectra used
    here vanish at the Nyquist lines), and the sums of squared weights for the variances."""
    k = np.arange(-(n // 2) + 1, n // 2)
    q = 2 * np.pi / length * np.hypot(k[:, None], k[None, :])
    w = psd(q) * (2 * np.pi / length) ** 2
    w[q == 0] = 0
    return w.sum(), (q**2 * w).sum(), (w**2).sum(), ((q**2 * w) ** 2).sum()


def test_generated_rms_matches_request_statistically():
    """Mean over 8 realisations of m0 and ⟨|∇h|²⟩ (measured by DFT) against Σ_k C Δq² from
    the closed-form C. For a Gaussian field the sampled m0 is Σ over mode pairs of independent
    exponentials: var(m0) = 2 Σ_k w_k² (w_k = C(q_k)Δq², all modes), so the tolerance is
    4 standard errors of the mean; the discrete sum itself is within 6 % of the continuum
    integral for this patch (4 roll-offs, 5 points per short wavelength)."""
    upper = Roughness(hurst=0.8, rms_height=1e-6, rolloff_wavelength=1e-3, short_wavelength=5e-5)
    lower = Roughness(hurst=0.4, rms_slope=0.03, rolloff_wavelength=5e-4, short_wavelength=1e-4)
    patch = choose_patch(upper, lower, points_per_short_wavelength=5, max_n=128)
    assert patch.n == 128 and patch.length == pytest.approx(128e-5)

    q_r, q_s = 2 * math.pi / 1e-3, 2 * math.pi / 5e-5
    c0u = 1e-12 / m0_rolloff(1.0, q_r, q_s, 0.8)
    q_r2, q_s2 = 2 * math.pi / 5e-4, 2 * math.pi / 1e-4
    c0l = 0.03**2 / slope2_rolloff(1.0, q_r2, q_s2, 0.4)

    def psd(q):
        return psd_rolloff(q, c0u, q_r, q_s, 0.8) + psd_rolloff(q, c0l, q_r2, q_s2, 0.4)

    e_m0, e_s2, v_m0, v_s2 = _expected_discrete(psd, patch.n, patch.length)
    seeds = 8
    stats = np.array([spectral_stats(composite_surface(upper, lower, patch, realisation=r,
                                                       seed=2026).heights, patch.dx)
                      for r in range(seeds)])
    se_m0 = math.sqrt(2 * v_m0 / seeds)
    se_s2 = math.sqrt(2 * v_s2 / seeds)
    assert abs(stats[:, 0].mean() - e_m0) < 4 * se_m0
    assert abs(stats[:, 1].mean() - e_s2) < 4 * se_s2
    assert se_s2 / e_s2 < 0.03  # the slope is set by many modes: a tight check
    # the discrete expectation against the continuum (what the user asked for)
    assert e_m0 == pytest.approx(composite_rms_height(upper, lower) ** 2, rel=0.06, abs=0)
    assert e_s2 == pytest.approx(composite_rms_slope(upper, lower) ** 2, rel=0.06)
    # realisations are distinct and uncorrelated
    a = composite_surface(upper, lower, patch, realisation=0, seed=2026).heights
    b = composite_surface(upper, lower, patch, realisation=1, seed=2026).heights
    assert abs(np.corrcoef(a.ravel(), b.ravel())[0, 1]) < 0.5


def test_deterministic_in_seed_and_realisation():
    a = composite_surface(UPPER, LOWER, PATCH, realisation=2, seed=9).heights
    b = composite_surface(UPPER, LOWER, PATCH, realisation=2, seed=9).heights
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, composite_surface(UPPER, LOWER, PATCH, realisation=3,
                                                seed=9).heights)
    assert not np.allclose(a, composite_surface(UPPER, LOWER, PATCH, realisation=2,
                                                seed=10).heights)


# ============================================================================ refine
def _band_limited_restriction(fine, n):
    """Keep the fine surface's modes with max(|kx|,|ky|) ≤ n/2 and sample every other point."""
    m = fine.shape[0]
    k = np.fft.fftfreq(m, 1 / m)
    kk = np.maximum(np.abs(k)[:, None], np.abs(k)[None, :])
    f = np.fft.fft2(fine)
    f[kk > n / 2] = 0
    return np.fft.ifft2(f).real[::2, ::2]


def test_refine_is_the_same_realisation():
    """Coarse grid resolving the short cut-off by 2.5 points: the fine grid adds modes between
    the two Nyquists; the coarse surface is the fine one's band-limited restriction."""
    patch = Patch(n=32, length=400e-6, dx=400e-6 / 32, rule="test")
    coarse = composite_surface(UPPER, LOWER, patch, realisation=4, seed=3)
    fine = composite_surface(UPPER, LOWER, patch, realisation=4, seed=3, refine=2)
    assert fine.shape == (64, 64) and fine.dx == pytest.approx(patch.dx / 2, rel=1e-15, abs=0)
    scale = np.abs(coarse.heights).max()
    restricted = _band_limited_restriction(fine.heights, 32)
    np.testing.assert_allclose(restricted, coarse.heights, rtol=0, atol=1e-12 * scale)
    # the fine grid really added modes beyond the coarse Nyquist (not a trivial pass)
    assert np.abs(fine.heights[::2, ::2] - coarse.heights).max() > 1e-3 * scale


def test_refine_is_exact_fourier_interpolation_when_resolved():
    """No modes between the Nyquists (λ_s = 4 dx): the fine surface is the coarse one
    zero-padded in Fourier space."""
    n = 32
    patch = Patch(n=n, length=400e-6, dx=400e-6 / n, rule="test")
    body = Roughness(hurst=0.7, rms_height=1e-6, rolloff_wavelength=100e-6,
                     short_wavelength=4 * patch.dx)
    coarse = composite_surface(body, Roughness.smooth(), patch, realisation=0, seed=1).heights
    fine = composite_surface(body, Roughness.smooth(), patch, realisation=0, seed=1,
                             refine=2).heights
    f = np.fft.fftshift(np.fft.fft2(coarse))
    padded = np.zeros((2 * n, 2 * n), dtype=complex)
    padded[n // 2 : n // 2 + n, n // 2 : n // 2 + n] = f
    interp = np.fft.ifft2(np.fft.ifftshift(padded)).real * 4
    np.testing.assert_allclose(fine, interp, rtol=0, atol=1e-12 * np.abs(coarse).max())
    np.testing.assert_allclose(fine[::2, ::2], coarse, rtol=0, atol=1e-12 * np.abs(coarse).max())


# ============================================================================ files
def test_files_pair_realisation_by_realisation(tmp_path):
    rng = np.random.default_rng(0)
    dx = 2e-6
    ups = [rng.normal(3e-6, 1e-6, (16, 24)) for _ in range(2)]
    los = [rng.normal(-1e-6, 5e-7, (16, 24)) for _ in range(2)]
    paths_u, paths_l = [], []
    for i in range(2):
        paths_u.append(tmp_path / f"upper{i}.npy")
        paths_l.append(tmp_path / f"lower{i}.npy")
        np.save(paths_u[-1], ups[i])
        np.save(paths_l[-1], los[i])
    upper = Roughness(files=tuple(str(p) for p in paths_u), dx=dx, name="surface.upper")
    lower = Roughness(files=[str(p) for p in paths_l], dx=dx, name="surface.lower")
    patch = choose_patch(upper, lower)
    assert (patch.n, patch.dx) == (24, dx)
    assert available_realisations(upper, lower) == 2
    for k in range(2):
        s = composite_surface(upper, lower, patch, realisation=k, seed=0)
        by_hand = (ups[k] - ups[k].mean()) + (los[k] - los[k].mean())
        np.testing.assert_allclose(s.heights, by_hand, rtol=0, atol=1e-20)
        assert s.dx == dx
    # a smooth partner contributes 0; swapping changes nothing
    s = composite_surface(Roughness.smooth(), lower, patch, realisation=1, seed=0)
    np.testing.assert_allclose(s.heights, los[1] - los[1].mean(), rtol=0, atol=1e-21)
    np.testing.assert_array_equal(
        composite_surface(upper, lower, patch, realisation=0, seed=0).heights,
        composite_surface(lower, upper, patch, realisation=0, seed=0).heights)
    # statistics measured from the data
    m0 = np.mean((ups[0] - ups[0].mean()) ** 2) + np.mean((ups[1] - ups[1].mean()) ** 2)
    rms = composite_rms_height(upper, Roughness.smooth())
    assert rms == pytest.approx(math.sqrt(m0 / 2), abs=0)
    with pytest.raises(InvalidArgumentError) as e:
        composite_surface(upper, lower, patch, realisation=2, seed=0)
    assert e.value.argument == "realisation"
    with pytest.raises(InvalidArgumentError) as e:
        composite_surface(upper, lower, patch, realisation=0, seed=0, refine=2)
    assert e.value.argument == "refine"
    np.save(tmp_path / "odd.npy", np.zeros((16, 20)))
    odd = Roughness(files=(str(tmp_path / "odd.npy"),), dx=dx, name="surface.lower")
    with pytest.raises(InvalidArgumentError) as e:
        composite_surface(upper, odd, patch, realisation=0, seed=0)
    assert e.value.argument == "surface.lower.files"


def test_file_with_statistical_partner(tmp_path):
    """A measured body against a statistical one: generated on the file's grid."""
    rng = np.random.default_rng(1)
    h = rng.normal(0, 1e-6, (32, 32))
    np.save(tmp_path / "u.npy", h)
    upper = Roughness(files=(str(tmp_path / "u.npy"),), dx=1e-5)
    lower = Roughness(hurst=0.7, rms_height=1e-6, rolloff_wavelength=1e-4, short_wavelength=4e-5)
    patch = choose_patch(upper, lower)
    s = composite_surface(upper, lower, patch, realisation=0, seed=0)
    alone = composite_surface(Roughness.smooth(), lower, patch, realisation=0, seed=0)
    np.testing.assert_allclose(s.heights, h - h.mean() + alone.heights, rtol=0, atol=1e-20)


# ============================================================================ patch rules
def test_choose_patch_rules():
    upper = Roughness(hurst=0.8, rms_height=1e-6, rolloff_wavelength=1e-4, short_wavelength=1e-5)
    lower = Roughness(hurst=0.8, rms_height=1e-6, rolloff_wavelength=3e-4, short_wavelength=2e-5)
    p = choose_patch(upper, lower)
    # dx = min λ_s / 4, L ≥ 4 · max λ_r = 1.2 mm → 480 points → 512
    assert p.dx == pytest.approx(1e-5 / 4)
    assert p.n == 512 and p.length == pytest.approx(512 * 2.5e-6)
    assert p.length >= 4 * 3e-4 and p.dx <= 1e-5 / 4
    assert "λ_s" in p.rule and "λ_r" in p.rule
    assert validity_warnings(upper, lower, p) == []
    capped = choose_patch(upper, lower, max_n=128)
    assert capped.n == 128 and capped.dx == pytest.approx(2.5e-6)
    assert "max_n = 128" in capped.rule and "roll-off wavelengths instead of 4" in capped.rule
    over = choose_patch(upper, lower, points_per_short_wavelength=8, rolloffs_per_patch=1)
    assert over.dx == pytest.approx(1e-5 / 8) and over.n == 256  # 3e-4 / 1.25e-6 = 240
    given = choose_patch(upper, lower, length=1e-3)
    assert given.length == 1e-3 and given.n == 512 and given.dx <= 1e-5 / 4
    both = choose_patch(upper, lower, n=64, length=1e-3)
    assert (both.n, both.length, both.dx) == (64, 1e-3, 1e-3 / 64)
    # no roll-off anywhere: the patch side must be given
    sa = Roughness(hurst=0.8, rms_slope=0.1, short_wavelength=1e-5)
    with pytest.raises(InvalidArgumentError) as e:
        choose_patch(sa, Roughness.smooth())
    assert e.value.argument == "length"
    assert choose_patch(sa, Roughness.smooth(), length=1e-3).n == 512
    for kwargs, arg in [(dict(n=100), "n"), (dict(n=2048), "n"), (dict(max_n=1), "max_n"),
                        (dict(points_per_short_wavelength=0), "points_per_short_wavelength"),
                        (dict(length=-1.0), "length")]:
        with pytest.raises(InvalidArgumentError) as e:
            choose_patch(upper, lower, **kwargs)
        assert e.value.argument == arg
    with pytest.raises(InvalidArgumentError) as e:
        choose_patch(Roughness.smooth(), Roughness.smooth())
    assert e.value.argument == "surface"


def test_validity_warnings_fire_at_thresholds():
    def body(slope):
        return Roughness(hurst=0.8, rms_slope=slope, rolloff_wavelength=1e-4,
                         short_wavelength=1e-5, name="surface.upper")

    fine = Patch(n=64, length=64 * 2.5e-6, dx=2.5e-6, rule="test")  # 4 points, 1.6 roll-offs
    smooth = Roughness.smooth()
    # two equal bodies of slope s: composite √2·s
    ok = validity_warnings(body(0.29 / math.sqrt(2)), body(0.29 / math.sqrt(2)),
                           Patch(n=128, length=128 * 2.5e-6, dx=2.5e-6, rule="t"))
    assert ok == []
    steep = validity_warnings(body(0.31 / math.sqrt(2)), body(0.31 / math.sqrt(2)),
                              Patch(n=128, length=128 * 2.5e-6, dx=2.5e-6, rule="t"))
    assert len(steep) == 1 and "rms slope" in steep[0]
    small = validity_warnings(body(0.1), smooth, fine)
    assert len(small) == 1 and "roll-off" in small[0]
    big = Patch(n=80, length=80 * 2.5e-6, dx=2.5e-6, rule="t")  # exactly 2 roll-offs
    assert validity_warnings(body(0.1), smooth, big) == []
    coarse = Patch(n=128, length=128 * 2.6e-6, dx=2.6e-6, rule="t")  # 3.85 points
    w = validity_warnings(body(0.1), smooth, coarse)
    assert len(w) == 1 and "grid points" in w[0]


# ============================================================================ bad input
@pytest.mark.parametrize(
    "kwargs, argument",
    [
        (dict(hurst=0.8, rms_height=1e-6, rms_slope=0.1, short_wavelength=1e-5),
         "surface.upper.rms_height"),
        (dict(hurst=1.0, rms_height=1e-6, short_wavelength=1e-5), "surface.upper.hurst"),
        (dict(rms_height=1e-6, short_wavelength=1e-5), "surface.upper.hurst"),
        (dict(hurst=0.8, short_wavelength=1e-5), "surface.upper.rms_height"),
        (dict(hurst=0.8, rms_height=1e-6), "surface.upper.short_wavelength"),
        (dict(hurst=0.8, rms_height=-1e-6, short_wavelength=1e-5), "surface.upper.rms_height"),
        (dict(hurst=0.8, rms_slope=0.0, short_wavelength=1e-5), "surface.upper.rms_slope"),
        (dict(hurst=0.8, rms_height=1e-6, short_wavelength=1e-5, rolloff_wavelength=1e-5),
         "surface.upper.rolloff_wavelength"),
        (dict(hurst=0.8, rms_height=1e-6, short_wavelength=1e-5, dx=1e-6), "surface.upper.dx"),
        (dict(files=("a.npy",), hurst=0.8), "surface.upper.hurst"),
        (dict(files=()), "surface.upper.files"),
        (dict(flat=True, rms_height=1e-6), "surface.upper.rms_height"),
        (dict(flat="yes"), "surface.upper.flat"),
        (dict(psd=(np.array([1.0, 2.0]), np.array([1.0, 0.0]))), "surface.upper.psd"),
        (dict(psd=(np.array([2.0, 1.0]), np.array([1.0, 1.0]))), "surface.upper.psd"),
        (dict(psd=(np.array([1.0, 2.0]), np.array([1.0, 1.0])), hurst=0.5),
         "surface.upper.hurst"),
        (dict(), "surface.upper"),
    ],
)
def test_bad_roughness_refused_by_name(kwargs, argument):
    with pytest.raises(InvalidArgumentError) as e:
        Roughness(**kwargs, name="surface.upper")
    assert e.value.argument == argument
    assert str(e.value).startswith(argument + ":")


def test_bad_surface_arguments_refused_by_name():
    for kwargs, arg in [(dict(realisation=-1, seed=0), "realisation"),
                        (dict(realisation=0, seed=-1), "seed"),
                        (dict(realisation=0, seed=0, refine=3), "refine"),
                        (dict(realisation=0, seed=0, refine=0), "refine"),
                        (dict(realisation=1.0, seed=0), "realisation")]:
        with pytest.raises(InvalidArgumentError) as e:
            composite_surface(UPPER, LOWER, PATCH, **kwargs)
        assert e.value.argument == arg
    with pytest.raises(InvalidArgumentError) as e:
        composite_surface(UPPER, "rough", PATCH, realisation=0, seed=0)
    assert e.value.argument == "surface.lower"


def test_measured_psd_of_a_spectral_surface(tmp_path):
    """The PSD estimated from a file holding a leakpath.spectral surface (C ∝ q^(−2(1+H)),
    q = 2π/λ rad/m) integrates to its measured m0 and has its exponent; the file body's rms
    values are the data's (rms height; forward-difference slope as leakpath.rms_slope)."""
    hurst, n, dx = 0.7, 128, 1e-6
    s = leakpath.spectral(n, hurst, seed=4, length=n * dx, rms_height=1e-6,
                          short_cutoff=8 * dx)
    np.save(tmp_path / "s.npy", s.heights)
    body = Roughness(files=(str(tmp_path / "s.npy"),), dx=dx)
    flat = Roughness.smooth()
    assert composite_rms_height(body, flat) == pytest.approx(1e-6, rel=1e-12, abs=0)
    assert composite_rms_slope(body, flat) == pytest.approx(leakpath.rms_slope(s), rel=1e-12, abs=0)
    c = composite_psd(body, flat)
    dq = 2 * np.pi / (n * dx)
    m0 = integrate.quad(lambda x: 2 * np.pi * x * c(x), 0, 2 * np.pi / (4 * dx),
                        points=dq * np.arange(1, 40), limit=400)[0]
    # Annulus-normalised bins integrate to m0; the log-log interpolation between the few
    # steep lowest bins (this spectrum has no roll-off: 4 modes carry most of m0) loses ~12 %.
    assert m0 == pytest.approx(1e-12, rel=0.2, abs=0)
    band = np.geomspace(2 * np.pi / (n * dx) * 4, 2 * np.pi / (8 * dx) * 0.8, 20)
    exponent = np.polyfit(np.log(band), np.log(c(band)), 1)[0]
    assert exponent == pytest.approx(-2 * (1 + hurst), abs=0.25)
    assert c(np.array([2 * np.pi / (4 * dx)]))[0] < 1e-6 * c(band[:1])[0]  # beyond the cut-off


def test_patch_is_validated():
    with pytest.raises(InvalidArgumentError) as e:
        Patch(n=64, length=1e-3, dx=1e-5, rule="x")
    assert e.value.argument == "patch.dx"
    with pytest.raises(InvalidArgumentError) as e:
        Patch(n=1, length=1e-3, dx=1e-3, rule="x")
    assert e.value.argument == "patch.n"
    with pytest.raises(InvalidArgumentError) as e:
        Patch(n=64, length=0.0, dx=0.0, rule="x")
    assert e.value.argument == "patch.length"
