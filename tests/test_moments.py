"""Tests for leakpath.moments against closed forms for sampled sines.

For ``s_j = A sin(k x_j + φ)``, ``x_j = j·dx`` (any k, not only whole periods):

* forward difference: ``s_{j+1} − s_j = 2A sin(k dx/2) cos(k x_j + k dx/2 + φ)``;
* central second difference: ``s_{j+1} − 2 s_j + s_{j−1} = −4 sin²(k dx/2) s_j``;
* the sample means of ``cos²`` / ``sin²`` follow from Lagrange's sum
  ``Σ_{j=0}^{M−1} cos(a + j b) = sin(M b/2)/sin(b/2) · cos(a + (M−1) b/2)``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from leakpath import moments as mom
from leakpath.generators import rmd, spectral
from leakpath.moments import Moments, nayak_moments, rms_curvature, rms_height, rms_slope


def lagrange_cos_sum(a: float, b: float, count: int) -> float:
    """``Σ_{j=0}^{count−1} cos(a + j b)`` in closed form."""
    if abs(math.sin(b / 2)) < 1e-300:
        return count * math.cos(a)
    return math.sin(count * b / 2) / math.sin(b / 2) * math.cos(a + (count - 1) * b / 2)


def lagrange_sin_sum(a: float, b: float, count: int) -> float:
    """``Σ_{j=0}^{count−1} sin(a + j b)`` in closed form."""
    return math.sin(count * b / 2) / math.sin(b / 2) * math.sin(a + (count - 1) * b / 2)


def sine_expectations(amp: float, k: float, phi: float, n: int, dx: float):
    """Exact (m0, ⟨s_x²⟩, ⟨s_xx²⟩) of the 1-D sample s_j = amp·sin(k j dx + φ), j < n."""
    b = k * dx
    mean = amp * lagrange_sin_sum(phi, b, n) / n
    mean_sq = amp**2 / 2 * (1 - lagrange_cos_sum(2 * phi, 2 * b, n) / n)
    m0 = mean_sq - mean**2
    # forward differences j = 0 … n−2:  cos²(θ_j), θ_j = b j + b/2 + φ
    cos2 = 0.5 * (1 + lagrange_cos_sum(b + 2 * phi, 2 * b, n - 1) / (n - 1))
    sx2 = (2 * amp * math.sin(b / 2) / dx) ** 2 * cos2
    # central second differences at j = 1 … n−2:  sin²(b j + φ)
    sin2 = 0.5 * (1 - lagrange_cos_sum(2 * (b + phi), 2 * b, n - 2) / (n - 2))
    sxx2 = (4 * math.sin(b / 2) ** 2 / dx**2) ** 2 * amp**2 * sin2
    return m0, sx2, sxx2


CASES = [
    # amp, k (rad/length), phi, n, dx
    (1.0, 0.37, 0.0, 17, 0.5),
    (2.5, 3.1, 0.7, 40, 0.1),
    (0.01, 1.9, -1.2, 9, 1.3),
    (7.0, 2 * np.pi * 3 / (64 * 0.25), 0.3, 64, 0.25),  # whole periods
]


class TestClosedForms:
    @pytest.mark.parametrize("amp, k, phi, n, dx", CASES)
    def test_sine_along_axis1(self, amp, k, phi, n, dx):
        ny = 5
        x = np.arange(n) * dx
        s = np.tile(amp * np.sin(k * x + phi), (ny, 1))  # varies along axis 1 (x) only
        m0, sx2, sxx2 = sine_expectations(amp, k, phi, n, dx)
        got = nayak_moments(s, dx)
        assert got.m0 == pytest.approx(m0, rel=1e-12, abs=1e-15 * amp**2)
        assert got.m2 == pytest.approx(0.5 * sx2, rel=1e-12, abs=0)
        assert got.m4 == pytest.approx(0.5 * sxx2, rel=1e-12, abs=0)
        assert got.alpha == pytest.approx(got.m0 * got.m4 / got.m2**2, rel=1e-14, abs=0)
        assert rms_slope(s, dx) == pytest.approx(math.sqrt(sx2), rel=1e-12, abs=0)
        assert rms_curvature(s, dx) == pytest.approx(math.sqrt(sxx2), rel=1e-12, abs=0)

    @pytest.mark.parametrize("amp, k, phi, n, dx", CASES)
    def test_sine_along_axis0(self, amp, k, phi, n, dx):
        nx = 6
        y = np.arange(n) * dx
        s = np.tile(amp * np.sin(k * y + phi)[:, None], (1, nx))  # varies along axis 0 (y)
        m0, sy2, syy2 = sine_expectations(amp, k, phi, n, dx)
        got = nayak_moments(s, dx)
        assert got.m0 == pytest.approx(m0, rel=1e-12, abs=1e-15 * amp**2)
        assert got.m2 == pytest.approx(0.5 * sy2, rel=1e-12, abs=0)
        assert got.m4 == pytest.approx(0.5 * syy2, rel=1e-12, abs=0)

    def test_sum_of_sines_on_both_axes(self):
        """m2, m4 add the x and y parts (the cross terms vanish for separable sums)."""
        ny, nx, dx = 23, 31, 0.2
        ky, kx = 1.7, 2.9
        y = np.arange(ny)[:, None] * dx
        x = np.arange(nx)[None, :] * dx
        s = np.sin(ky * y + 0.2) + 0.5 * np.sin(kx * x - 0.4)
        _, sy2, syy2 = sine_expectations(1.0, ky, 0.2, ny, dx)
        _, sx2, sxx2 = sine_expectations(0.5, kx, -0.4, nx, dx)
        got = nayak_moments(s, dx)
        assert got.m2 == pytest.approx(0.5 * (sx2 + sy2), rel=1e-12)
        assert got.m4 == pytest.approx(0.5 * (sxx2 + syy2), rel=1e-12)
        assert got.m0 == pytest.approx(np.var(s), rel=1e-12, abs=0)

    def test_plane_and_paraboloid(self):
        """Exact polynomial cases: a tilted plane has m4 = 0; x² has s_xx = 2."""
        ny, nx, dx = 7, 9, 0.5
        y = np.arange(ny)[:, None] * dx
        x = np.arange(nx)[None, :] * dx
        plane = 0.3 * x - 0.2 * y + np.zeros((ny, nx))
        got = nayak_moments(plane, dx)
        assert got.m2 == pytest.approx(0.5 * (0.3**2 + 0.2**2), rel=1e-12, abs=0)
        assert got.m4 == pytest.approx(0.0, abs=1e-20)
        para = x**2 + np.zeros((ny, nx))
        got = nayak_moments(para, dx)
        assert got.m4 == pytest.approx(0.5 * 4.0, rel=1e-12)
        # forward differences of x²: (2 x_j + dx), j = 0 … nx−2
        fd = 2 * np.arange(nx - 1) * dx + dx
        assert got.m2 == pytest.approx(0.5 * np.mean(fd**2), rel=1e-12)

    @pytest.mark.parametrize("axis", [0, 1])
    def test_spectral_periodic_sine(self, axis):
        n, dx, c, amp = 64, 0.3, 5, 1.7
        k = 2 * np.pi * c / (n * dx)
        line = amp * np.cos(k * np.arange(n) * dx + 0.4)
        s = np.tile(line, (n, 1)) if axis == 1 else np.tile(line[:, None], (1, n))
        got = nayak_moments(s, dx, method="spectral")
        assert got.m0 == pytest.approx(amp**2 / 2, rel=1e-12)
        assert got.m2 == pytest.approx(0.5 * k**2 * amp**2 / 2, rel=1e-12)
        assert got.m4 == pytest.approx(0.5 * k**4 * amp**2 / 2, rel=1e-12)

    def test_spectral_nyquist_weight(self):
        """A sampled Nyquist mode a·(−1)^j counts with half weight (band-limited cosine)."""
        n, dx, amp = 16, 0.5, 2.0
        s = np.tile(amp * (-1.0) ** np.arange(n), (n, 1))
        got = nayak_moments(s, dx, method="spectral")
        q_n = np.pi / dx
        assert got.m0 == pytest.approx(amp**2, rel=1e-12)
        assert got.m2 == pytest.approx(0.5 * 0.5 * q_n**2 * amp**2, rel=1e-12)
        assert got.m4 == pytest.approx(0.5 * 0.5 * q_n**4 * amp**2, rel=1e-12)


class TestEstimators:
    @pytest.mark.parametrize("seed", [0, 1, 2])
    @pytest.mark.parametrize("hurst", [0.3, 0.8])
    def test_fd_and_spectral_agree(self, seed, hurst):
        s = spectral(256, hurst, seed=seed, length=500.0, short_cutoff=16 * 500.0 / 256)
        fd = nayak_moments(s)
        sp = nayak_moments(s, method="spectral")
        assert fd.m0 == pytest.approx(sp.m0, rel=1e-12, abs=0)
        assert fd.m2 == pytest.approx(sp.m2, rel=0.02)
        assert fd.m4 == pytest.approx(sp.m4, rel=0.02)
        assert fd.alpha == pytest.approx(sp.alpha, rel=0.02)

    @pytest.mark.parametrize("seed", range(4))
    def test_alpha_at_least_1p5_gaussian(self, seed):
        for s in (
            spectral(128, 0.7, seed=seed),
            spectral(128, 0.2, seed=seed),
            rmd(7, 2.2, seed=seed),
        ):
            for method in ("fd", "spectral"):
                assert nayak_moments(s, method=method).alpha >= 1.5

    def test_alpha_narrow_isotropic_ring(self):
        """Isotropic ring spectrum: alpha → 3/2 (Nayak's lower bound)."""
        L, n = 1.0, 256  # noqa: N806
        s = spectral(n, 0.5, seed=3, length=L, long_cutoff=L / 30, short_cutoff=L / 32)
        assert nayak_moments(s, method="spectral").alpha == pytest.approx(1.5, rel=0.05)

    def test_rms_helpers_consistent(self):
        s = rmd(6, 2.4, seed=1)
        mo = nayak_moments(s)
        assert rms_height(s) == pytest.approx(math.sqrt(mo.m0), rel=1e-14, abs=0)
        assert rms_height(s.heights) == pytest.approx(np.std(s.heights), rel=1e-14, abs=0)
        assert rms_slope(s) == pytest.approx(math.sqrt(2 * mo.m2), rel=1e-14, abs=0)
        assert rms_curvature(s) == pytest.approx(math.sqrt(2 * mo.m4), rel=1e-14, abs=0)

    def test_surface_argument(self):
        s = rmd(5, 2.2, seed=0, length=3.0)
        a = nayak_moments(s)
        b = nayak_moments(s.heights, s.dx)
        assert a == b
        assert s.moments() == a
        assert nayak_moments(s, s.dx) == a
        with pytest.raises(ValueError, match=r"\bdx\b"):
            nayak_moments(s, 2 * s.dx)

    def test_result_type(self):
        r = nayak_moments(np.arange(16.0).reshape(4, 4) ** 2, 1.0)
        assert isinstance(r, Moments)
        assert set(r.as_dict()) == {"m0", "m2", "m4", "alpha"}
        with pytest.raises(AttributeError):
            r.m0 = 1.0  # type: ignore[misc]

    def test_flat_alpha_nan(self):
        r = nayak_moments(np.full((4, 5), 3.0), 1.0)
        assert r.m0 == 0 and r.m2 == 0 and r.m4 == 0 and math.isnan(r.alpha)

    def test_scaling_units(self):
        """Scaling heights by c and dx by l: m0 ∝ c², m2 ∝ (c/l)², m4 ∝ (c/l²)²."""
        h = rmd(5, 2.3, seed=4).heights
        a = nayak_moments(h, 0.1)
        b = nayak_moments(3.0 * h, 0.2)
        assert b.m0 == pytest.approx(9 * a.m0, rel=1e-12)
        assert b.m2 == pytest.approx(9 / 4 * a.m2, rel=1e-12)
        assert b.m4 == pytest.approx(9 / 16 * a.m4, rel=1e-12)
        assert b.alpha == pytest.approx(a.alpha, rel=1e-12)


class TestValidation:
    @pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
    @pytest.mark.parametrize("method", ["fd", "spectral"])
    def test_non_finite(self, bad, method):
        h = np.zeros((5, 5))
        h[1, 3] = bad
        with pytest.raises(ValueError, match=r"\bheights\b"):
            nayak_moments(h, 1.0, method=method)

    @pytest.mark.parametrize("h", [np.zeros(10), np.zeros((3, 3, 3)), np.float64(1.0)])
    def test_not_2d(self, h):
        with pytest.raises(ValueError, match="2-D"):
            nayak_moments(h, 1.0)

    @pytest.mark.parametrize("shape", [(2, 10), (10, 2), (1, 1), (0, 5)])
    def test_too_few_points(self, shape):
        with pytest.raises(ValueError, match="at least 3"):
            nayak_moments(np.zeros(shape), 1.0)

    @pytest.mark.parametrize("dx", [0.0, -1.0, np.nan, np.inf, None, True, "1"])
    def test_bad_dx(self, dx):
        with pytest.raises(ValueError, match=r"\bdx\b"):
            nayak_moments(np.zeros((4, 4)), dx)

    def test_bad_method(self):
        with pytest.raises(ValueError, match=r"\bmethod\b"):
            nayak_moments(np.zeros((4, 4)), 1.0, method="fft")  # type: ignore[arg-type]

    def test_rms_slope_needs_two_points(self):
        assert rms_slope(np.zeros((2, 2)), 1.0) == 0.0
        with pytest.raises(ValueError, match="at least 2"):
            rms_slope(np.zeros((1, 4)), 1.0)


def test_module_exports():
    assert set(mom.__all__) >= {"Moments", "nayak_moments", "rms_height", "rms_slope"}
