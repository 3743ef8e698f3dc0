"""Tests for leakpath.surfaces: Surface container, RMD and spectral generators, file I/O.

Oracles are independent of the code under test: a scalar hand computation of the 3×3 RMD
case, a plain-loop re-implementation of Saupe's MidPointFM2D, the Hurst exponent measured
from height increments, the PSD slope measured from an FFT, and numpy re-computations of
rms height and slope.
"""

from __future__ import annotations

import json
import math
import os
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from leakpath import surfaces
from leakpath.errors import InvalidArgumentError, ProblemTooLargeError
from leakpath.generators import rmd, spectral
from leakpath.surfaces import Surface, load

SIGMA0 = 1.0 / math.sqrt(0.09)


# ---------------------------------------------------------------------------- oracles
def rmd_reference(m: int, D: float, seed: int, sigma0: float = SIGMA0) -> np.ndarray:  # noqa: N803
    """Plain-loop MidPointFM2D (Saupe, no addition) with the documented draw order."""
    hurst = 3.0 - D
    n = 2**m
    rng = np.random.default_rng(seed)
    x = [[0.0] * (n + 1) for _ in range(n + 1)]
    g = rng.standard_normal(4)
    x[0][0] = sigma0 * g[0]
    x[0][n] = sigma0 * g[1]
    x[n][0] = sigma0 * g[2]
    x[n][n] = sigma0 * g[3]
    f = 2.0 ** (-0.5 * hurst)
    delta = sigma0
    big, d = n, n // 2
    for level in range(1, m + 1):
        k = 2 ** (level - 1)
        delta = delta * f
        gc = rng.standard_normal((k, k))
        for a, i in enumerate(range(d, n, big)):
            for b, j in enumerate(range(d, n, big)):
                corners = x[i - d][j - d] + x[i - d][j + d] + x[i + d][j - d] + x[i + d][j + d]
                x[i][j] = corners / 4.0 + delta * gc[a][b]
        delta = delta * f
        ge = iter(rng.standard_normal(2 * k * (k + 1)))
        for i in range(0, n + 1, big):  # midpoints on grid rows
            for j in range(d, n, big):
                total, count = x[i][j - d] + x[i][j + d], 2
                if i > 0:
                    total, count = total + x[i - d][j], count + 1
                if i < n:
                    total, count = total + x[i + d][j], count + 1
                x[i][j] = total / count + delta * next(ge)
        for i in range(d, n, big):  # midpoints on grid columns
            for j in range(0, n + 1, big):
                total, count = x[i - d][j] + x[i + d][j], 2
                if j > 0:
                    total, count = total + x[i][j - d], count + 1
                if j < n:
                    total, count = total + x[i][j + d], count + 1
                x[i][j] = total / count + delta * next(ge)
        big, d = big // 2, d // 2
    h = np.array(x)
    return h - h.min()


def hurst_from_increments(h: np.ndarray, lags=(2, 4, 8, 16, 32)) -> float:
    """Fit log⟨(h(x+l) − h(x))²⟩ = 2H log l + c over the lags, both axes pooled."""
    msi = []
    for lag in lags:
        ax1 = np.mean((h[:, lag:] - h[:, :-lag]) ** 2)
        ax0 = np.mean((h[lag:, :] - h[:-lag, :]) ** 2)
        msi.append(0.5 * (ax0 + ax1))
    slope = np.polyfit(np.log(lags), np.log(msi), 1)[0]
    return slope / 2.0


# ---------------------------------------------------------------------------- Surface
class TestSurface:
    def test_properties(self):
        h = np.arange(12, dtype=float).reshape(3, 4) ** 1.5
        s = Surface(h, 0.5, {"a": 1})
        assert s.shape == (3, 4)
        assert s.length == (1.5, 2.0)
        assert s.nominal_area == pytest.approx(3 * 4 * 0.25, rel=1e-15, abs=0)
        assert s.height_range == pytest.approx(h.max() - h.min(), rel=1e-15, abs=0)
        assert s.rms_height == pytest.approx(np.std(h), rel=1e-14, abs=0)
        assert s.mean_height == pytest.approx(h.mean(), rel=1e-15, abs=0)
        assert s.heights.dtype == np.float64 and s.heights.flags.c_contiguous

    def test_integer_heights_converted(self):
        s = Surface([[1, 2], [3, 4]], 1)
        assert s.heights.dtype == np.float64
        assert isinstance(s.dx, float)

    @pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
    def test_non_finite_heights(self, bad):
        h = np.zeros((4, 4))
        h[2, 1] = bad
        with pytest.raises(ValueError, match=r"\bheights\b"):
            Surface(h, 1.0)

    @pytest.mark.parametrize("h", [np.zeros(5), np.zeros((2, 2, 2)), np.zeros((0, 3))])
    def test_bad_shape(self, h):
        with pytest.raises(ValueError, match=r"\bheights\b"):
            Surface(h, 1.0)

    @pytest.mark.parametrize("dx", [0.0, -1.0, np.nan, np.inf, True, "1"])
    def test_bad_dx(self, dx):
        with pytest.raises(ValueError, match=r"\bdx\b"):
            Surface(np.zeros((3, 3)), dx)

    def test_bad_metadata(self):
        with pytest.raises(ValueError, match="metadata"):
            Surface(np.zeros((3, 3)), 1.0, metadata=[1, 2])  # type: ignore[arg-type]


# ---------------------------------------------------------------------------- RMD
class TestRMD:
    def test_same_seed_bit_identical(self):
        a = rmd(6, 2.3, seed=42)
        b = rmd(6, 2.3, seed=42)
        assert np.array_equal(a.heights, b.heights)

    def test_different_seeds_differ(self):
        a = rmd(6, 2.3, seed=1)
        b = rmd(6, 2.3, seed=2)
        assert not np.array_equal(a.heights, b.heights)
        assert np.max(np.abs(a.heights - b.heights)) > 0.1 * a.height_range

    @pytest.mark.parametrize("m", [1, 2, 5, 8])
    def test_shape_min_dx(self, m):
        s = rmd(m, 2.5, seed=0, length=3.0)
        assert s.shape == (2**m + 1, 2**m + 1)
        assert s.heights.min() == 0.0
        assert s.dx == 3.0 / 2**m
        assert s.metadata["generator"] == "rmd"
        assert s.metadata["m"] == m and s.metadata["D"] == 2.5
        assert s.metadata["H"] == pytest.approx(0.5)
        assert s.metadata["seed"] == 0 and s.metadata["length"] == 3.0
        assert s.metadata["sigma0"] == pytest.approx(SIGMA0)

    @pytest.mark.parametrize("seed", [0, 7, 123])
    @pytest.mark.parametrize("D", [2.1, 2.6])
    def test_m1_by_hand(self, seed, D):  # noqa: N803
        """The 3×3 case from the documented draws, one scalar at a time."""
        sigma0 = 2.5
        g = np.random.default_rng(seed).standard_normal(9)  # 4 corners, 1 centre, 4 edges
        f = 2.0 ** (-(3.0 - D) / 2.0)
        c00, c02, c20, c22 = (sigma0 * v for v in g[:4])
        d1 = sigma0 * f
        centre = (c00 + c02 + c20 + c22) / 4.0 + d1 * g[4]
        d2 = d1 * f
        top = (c00 + c02 + centre) / 3.0 + d2 * g[5]  # (0, 1)
        bottom = (c20 + c22 + centre) / 3.0 + d2 * g[6]  # (2, 1)
        left = (c00 + c20 + centre) / 3.0 + d2 * g[7]  # (1, 0)
        right = (c02 + c22 + centre) / 3.0 + d2 * g[8]  # (1, 2)
        expected = np.array(
            [[c00, top, c02], [left, centre, right], [c20, bottom, c22]], dtype=float
        )
        expected -= expected.min()
        got = rmd(1, D, seed=seed, sigma0=sigma0).heights
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-14 * sigma0)

    @pytest.mark.parametrize("m", [1, 2, 3, 4, 5])
    @pytest.mark.parametrize("D", [2.05, 2.5, 2.95])
    def test_matches_loop_reference(self, m, D):  # noqa: N803
        seed = 1000 + m
        ref = rmd_reference(m, D, seed)
        got = rmd(m, D, seed=seed).heights
        # same operations in the same order: bit for bit
        assert np.array_equal(got, ref), np.max(np.abs(got - ref))

    def test_sigma0_scales_linearly(self):
        a = rmd(5, 2.2, seed=3, sigma0=1.0).heights
        b = rmd(5, 2.2, seed=3, sigma0=3.0).heights
        np.testing.assert_allclose(b, 3.0 * a, rtol=1e-13, atol=1e-13)

    def test_hurst_exponent(self):
        dims = [2.1, 2.3, 2.5, 2.7]
        measured = []
        for D in dims:  # noqa: N806
            hs = [hurst_from_increments(rmd(8, D, seed=s).heights) for s in range(20)]
            measured.append(float(np.mean(hs)))
        for D, h in zip(dims, measured, strict=True):  # noqa: N806
            assert abs(h - (3.0 - D)) < 0.12, (D, h)
        assert all(a > b for a, b in zip(measured, measured[1:], strict=False)), measured

    @pytest.mark.parametrize("m", [0, -1, 2.5, 3.0, True, "4", None])
    def test_invalid_m(self, m):
        with pytest.raises(InvalidArgumentError, match=r"^m\b"):
            rmd(m, 2.2, seed=0)

    @pytest.mark.parametrize("m", [15, 40, 1000, 2**62])
    def test_too_large_m_refused_before_allocating(self, m):
        with pytest.raises(ProblemTooLargeError, match=r"^m\b") as exc:
            rmd(m, 2.2, seed=0)
        assert exc.value.estimate > exc.value.limit > 0

    def test_numpy_integer_m_accepted(self):
        assert rmd(np.int64(3), 2.2, seed=0).shape == (9, 9)

    @pytest.mark.parametrize("D", [2, 3, 2.0, 3.0, 1.5, 3.5, np.nan, np.inf, True, "2.5"])
    def test_invalid_D(self, D):  # noqa: N802,N803
        with pytest.raises(ValueError, match=r"\bD\b"):
            rmd(3, D, seed=0)

    @pytest.mark.parametrize(
        "kw, name",
        [
            ({"sigma0": 0.0}, "sigma0"),
            ({"sigma0": -1.0}, "sigma0"),
            ({"length": 0.0}, "length"),
            ({"length": np.nan}, "length"),
            ({"seed": -1}, "seed"),
            ({"seed": 1.5}, "seed"),
        ],
    )
    def test_invalid_other(self, kw, name):
        args = {"seed": 0, **kw}
        with pytest.raises(ValueError, match=rf"\b{name}\b"):
            rmd(3, 2.2, **args)

    def test_seed_none_is_recorded_and_reproducible(self):
        a = rmd(4, 2.2, seed=None)
        b = rmd(4, 2.2, seed=a.metadata["seed"])
        assert np.array_equal(a.heights, b.heights)


# ---------------------------------------------------------------------------- spectral
def _wavevectors(shape, dx):
    ny, nx = shape
    qy = 2 * np.pi * np.fft.fftfreq(ny, dx)
    qx = 2 * np.pi * np.fft.fftfreq(nx, dx)
    return np.hypot(qy[:, None], qx[None, :])


class TestSpectral:
    def test_psd_slope(self):
        hurst, n = 0.8, 512
        slopes = []
        for seed in range(3):
            s = spectral(n, hurst, seed=seed)
            q = _wavevectors(s.shape, s.dx)
            power = np.abs(np.fft.fft2(s.heights)) ** 2
            q_lo, q_hi = 2 * np.pi / s.length[1], np.pi / s.dx
            edges = np.geomspace(4 * q_lo, 0.5 * q_hi, 16)
            centres, means = [], []
            for lo, hi in zip(edges[:-1], edges[1:], strict=True):
                sel = (q >= lo) & (q < hi)
                centres.append(np.mean(q[sel]))
                means.append(np.mean(power[sel]))
            slopes.append(np.polyfit(np.log(centres), np.log(means), 1)[0])
        assert np.mean(slopes) == pytest.approx(-2 * (1 + hurst), abs=0.05), slopes

    @pytest.mark.parametrize("target", [1.0, 0.0317, 42.0])
    def test_rms_height(self, target):
        s = spectral((64, 96), 0.6, seed=5, rms_height=target, length=7.0)
        h = s.heights
        rms = np.sqrt(np.mean((h - h.mean()) ** 2))
        assert abs(rms / target - 1) < 1e-12
        assert abs(h.mean()) < 1e-12 * target

    def test_default_rms_height_is_one(self):
        h = spectral(32, 0.5, seed=0).heights
        assert abs(np.std(h) - 1.0) < 1e-12

    @pytest.mark.parametrize("target", [0.1, 1.0, 3.7])
    def test_rms_slope(self, target):
        s = spectral((96, 64), 0.3, seed=9, rms_slope=target, length=2.0)
        h, dx = s.heights, s.dx
        sx = (h[:, 1:] - h[:, :-1]) / dx
        sy = (h[1:, :] - h[:-1, :]) / dx
        slope = math.sqrt(np.mean(sx**2) + np.mean(sy**2))
        assert abs(slope / target - 1) < 1e-12

    def test_grid_and_metadata(self):
        s = spectral((32, 128), 0.7, seed=1, length=4.0)
        assert s.shape == (32, 128)
        assert s.dx == 4.0 / 128
        assert s.length == pytest.approx((1.0, 4.0))
        md = s.metadata
        assert md["generator"] == "spectral" and md["hurst"] == 0.7 and md["seed"] == 1
        assert md["long_cutoff"] == pytest.approx(4.0)
        assert md["short_cutoff"] == pytest.approx(2 * s.dx)

    @pytest.mark.parametrize(
        "shape, kw",
        [
            ((128, 128), {}),
            # Cut-offs in µm on the default 500 µm box.
            ((64, 96), {"long_cutoff": 250.0, "short_cutoff": 25.0}),
            ((63, 81), {"long_cutoff": 150.0, "short_cutoff": 50.0}),
        ],
    )
    def test_no_energy_outside_band_and_real(self, shape, kw):
        s = spectral(shape, 0.5, seed=11, **kw)
        assert np.isrealobj(s.heights)
        f = np.fft.fft2(s.heights)
        q = _wavevectors(s.shape, s.dx)
        lam_long = kw.get("long_cutoff", max(s.length))
        lam_short = kw.get("short_cutoff", 2 * s.dx)
        q_l, q_s = 2 * np.pi / lam_long, 2 * np.pi / lam_short
        inside = (q >= q_l * (1 - 1e-9)) & (q <= q_s * (1 + 1e-9))
        outside = ~inside
        assert np.max(np.abs(f[outside])) < 1e-12 * np.max(np.abs(f))
        # every in-band mode carries energy (the filter is not accidentally narrower)
        assert np.min(np.abs(f[inside])) > 0

    def test_periodic_gradient(self):
        """Periodic by construction: the wrap-around difference is a typical difference."""
        s = spectral(256, 0.8, seed=2, short_cutoff=16 / 256)
        h = s.heights
        wrap = h[:, 0] - h[:, -1]
        inner = h[:, 1:] - h[:, :-1]
        assert np.sqrt(np.mean(wrap**2)) < 2 * np.sqrt(np.mean(inner**2))

    def test_reproducible(self):
        a = spectral(64, 0.5, seed=3).heights
        b = spectral(64, 0.5, seed=3).heights
        c = spectral(64, 0.5, seed=4).heights
        assert np.array_equal(a, b)
        assert not np.array_equal(a, c)

    @pytest.mark.parametrize("hurst", [0, 1, 0.0, 1.0, -0.5, 1.5, np.nan, True])
    def test_invalid_hurst(self, hurst):
        with pytest.raises(ValueError, match=r"\bhurst\b"):
            spectral(16, hurst, seed=0)

    @pytest.mark.parametrize("shape", [1, 0, (1, 8), (8, 1), (8,), (2, 3, 4), 2.5, "8"])
    def test_invalid_shape(self, shape):
        with pytest.raises(ValueError, match=r"\bshape\b"):
            spectral(shape, 0.5, seed=0)

    def test_both_scales_rejected(self):
        with pytest.raises(ValueError, match="rms_height") as exc:
            spectral(16, 0.5, seed=0, rms_height=1.0, rms_slope=1.0)
        assert "rms_slope" in str(exc.value)

    @pytest.mark.parametrize(
        "kw, name",
        [
            ({"rms_height": 0.0}, "rms_height"),
            ({"rms_slope": -1.0}, "rms_slope"),
            ({"long_cutoff": -1.0}, "long_cutoff"),
            ({"short_cutoff": 0.0}, "short_cutoff"),
            ({"long_cutoff": 0.1, "short_cutoff": 0.2}, "short_cutoff"),
            ({"length": -2.0}, "length"),
        ],
    )
    def test_invalid_arguments(self, kw, name):
        with pytest.raises(ValueError, match=rf"\b{name}\b"):
            spectral(16, 0.5, seed=0, **kw)

    def test_empty_band(self):
        with pytest.raises(ValueError, match="band"):
            spectral(8, 0.5, seed=0, long_cutoff=0.49, short_cutoff=0.47)


# ---------------------------------------------------------------------------- roll-off
def _radial_fit(q, power, edges):
    """Least-squares line through the log of the radially averaged periodogram in log-spaced
    annuli: (slope, intercept) of ``log⟨|ĥ|²⟩`` against ``log⟨q⟩``."""
    centres, means = [], []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        sel = (q >= lo) & (q < hi)
        centres.append(np.mean(q[sel]))
        means.append(np.mean(power[sel]))
    return np.polyfit(np.log(centres), np.log(means), 1)


class TestSpectralRolloff:
    """The radially averaged periodogram (the oracle: numpy's FFT of the heights) of a surface
    with a roll-off is flat between q_L and q_r and falls as q^(−2(1+H)) from q_r to q_s."""

    N, LENGTH = 512, 500.0

    @pytest.mark.parametrize("hurst", [0.8, 0.5])
    def test_plateau_and_power_law(self, hurst):
        qL = 2 * np.pi / self.LENGTH
        qr, qs = 16 * qL, 128 * qL
        plateau_slopes, law_slopes, ratios = [], [], []
        for seed in range(6):
            s = spectral(self.N, hurst, seed=seed, rms_height=0.5, rolloff=self.LENGTH / 16,
                         short_cutoff=self.LENGTH / 128)
            q = _wavevectors(s.shape, s.dx)
            power = np.abs(np.fft.fft2(s.heights)) ** 2
            # No energy outside [q_L, q_s].
            outside = (q < qL * (1 - 1e-9)) | (q > qs * (1 + 1e-9))
            assert np.max(power[outside]) < 1e-24 * np.max(power)
            flat = _radial_fit(q, power, np.geomspace(qL * (1 - 1e-9), qr * (1 - 1e-9), 7))
            law = _radial_fit(q, power, np.geomspace(qr * (1 - 1e-9), qs * (1 + 1e-9), 9))
            plateau_slopes.append(flat[0])
            law_slopes.append(law[0])
            # The plateau's level is the power law's value at q_r: C(q) = C(q_r).
            ratios.append(np.exp(np.polyval(flat, np.log(qr)) - np.polyval(law, np.log(qr))))
            # Per surface: a flat plateau (a slope of −3.6 or −3 would be far outside) ...
            assert abs(flat[0]) < 0.7, (seed, flat)
            assert law[0] == pytest.approx(-2 * (1 + hurst), abs=0.15), (seed, law)
        # ... and over the six surfaces, the slopes and the level within their sampling noise
        # (per-surface spreads measured as 0.2, 0.03 and 0.2).
        assert np.mean(plateau_slopes) == pytest.approx(0.0, abs=0.3), plateau_slopes
        assert np.mean(law_slopes) == pytest.approx(-2 * (1 + hurst), abs=0.06), law_slopes
        assert np.mean(ratios) == pytest.approx(1.0, abs=0.25), ratios

    def test_documented_filter(self):
        """The heights are the documented filter of the seed's white noise."""
        shape, hurst, length = (48, 64), 0.7, 3.0
        lam_l, lam_r, lam_s = 2.5, 0.75, 0.2
        s = spectral(shape, hurst, seed=4, length=length, long_cutoff=lam_l, rolloff=lam_r,
                     short_cutoff=lam_s, rms_height=0.01)
        dx = length / shape[1]
        w = np.random.default_rng(4).standard_normal(shape)
        q = _wavevectors(shape, dx)
        ql, qr, qs = (2 * np.pi / lam for lam in (lam_l, lam_r, lam_s))
        a = np.where(q < qr, qr, q) ** (-(1 + hurst))
        a[(q < ql) | (q > qs)] = 0.0
        h = np.real(np.fft.ifft2(np.fft.fft2(w) * a))
        h -= h.mean()
        h *= 0.01 / np.sqrt(np.mean(h**2))
        np.testing.assert_allclose(s.heights, h, rtol=0, atol=1e-14)
        assert s.metadata["rolloff"] == lam_r

    def test_default_unchanged(self):
        """No roll-off, or a roll-off at the long cut-off, is the same surface bit for bit."""
        plain = spectral((64, 80), 0.8, seed=3, rms_height=1.0)
        at_long = spectral((64, 80), 0.8, seed=3, rms_height=1.0, rolloff=max(plain.length))
        assert np.array_equal(plain.heights, at_long.heights)
        assert plain.metadata["rolloff"] == plain.metadata["long_cutoff"]
        # The default matches the documented filter without a plateau.
        w = np.random.default_rng(3).standard_normal((64, 80))
        q = _wavevectors((64, 80), plain.dx)
        a = np.zeros_like(q)
        band = (q >= 2 * np.pi / max(plain.length) * (1 - 1e-12)) & (q <= np.pi / plain.dx)
        a[band] = q[band] ** -1.8
        h = np.real(np.fft.ifft2(np.fft.fft2(w) * a))
        h -= h.mean()
        np.testing.assert_allclose(plain.heights, h / np.sqrt(np.mean(h**2)), atol=1e-12)

    @pytest.mark.parametrize(
        "kw, words",
        [
            ({"rolloff": 600.0}, "long_cutoff"),  # above the default long cut-off (box, 500)
            ({"rolloff": 120.0, "long_cutoff": 100.0}, "long_cutoff"),
            ({"rolloff": 10.0, "short_cutoff": 10.0}, "short_cutoff"),
            ({"rolloff": 1.0}, "short_cutoff"),  # below the default 2·dx = 31.25
            ({"rolloff": 0.0}, "rolloff"),
            ({"rolloff": -50.0}, "rolloff"),
            ({"rolloff": float("nan")}, "rolloff"),
            ({"rolloff": float("inf")}, "rolloff"),
        ],
    )
    def test_invalid_rolloff(self, kw, words):
        with pytest.raises(ValueError, match=r"^rolloff\b") as exc:
            spectral(32, 0.8, seed=0, **kw)
        assert words in str(exc.value)
        assert exc.value.argument == "rolloff"

    def test_spec(self):
        from leakpath.generators import generate, parse_spec

        name, params, seed = parse_spec("spectral:n=64,hurst=0.8,seed=2,rolloff=125")
        s = generate(name, params, seed)
        assert np.array_equal(s.heights, spectral(64, 0.8, seed=2, rolloff=125.0).heights)


# ---------------------------------------------------------------------------- files
class TestSaveLoad:
    def test_npz_round_trip(self, tmp_path):
        s = rmd(4, 2.3, seed=8, length=2.0)
        s.metadata["note"] = np.float64(1.5)  # numpy scalars are stored as JSON numbers
        out = s.save(tmp_path / "s.npz")
        assert out == tmp_path / "s.npz"
        t = load(tmp_path / "s.npz")
        assert np.array_equal(t.heights, s.heights)
        assert t.dx == s.dx == 2.0 / 16
        for key in ("generator", "m", "D", "H", "seed", "sigma0", "length"):
            assert t.metadata[key] == s.metadata[key]
        assert t.metadata["note"] == 1.5
        t2 = Surface.load(str(tmp_path / "s.npz"))
        assert np.array_equal(t2.heights, s.heights)
        # the archive is a plain npz readable without pickles
        with np.load(tmp_path / "s.npz", allow_pickle=False) as data:
            assert json.loads(str(data["metadata"][()]))["generator"] == "rmd"
            assert float(data["dx"]) == s.dx

    def test_npz_no_temp_files_left(self, tmp_path):
        rmd(3, 2.3, seed=0).save(tmp_path / "a.npz")
        rmd(3, 2.3, seed=1).save(tmp_path / "a.npz")  # overwrite
        assert sorted(os.listdir(tmp_path)) == ["a.npz"]

    @pytest.mark.skipif(os.name != "posix", reason="POSIX permission bits")
    def test_saved_file_has_normal_permissions(self, tmp_path):
        """Same mode as a file written with open() (umask applies; not owner-only 0o600)."""
        reference = tmp_path / "plain.bin"
        reference.write_bytes(b"x")
        rmd(3, 2.3, seed=0).save(tmp_path / "a.npz")
        mode = (tmp_path / "a.npz").stat().st_mode & 0o777
        assert mode == reference.stat().st_mode & 0o777

    def test_failed_save_keeps_old_file(self, tmp_path, monkeypatch):
        path = tmp_path / "a.npz"
        rmd(3, 2.3, seed=0).save(path)
        before = path.read_bytes()

        def boom(*args, **kwargs):
            raise OSError("disk full")

        monkeypatch.setattr(surfaces.np, "savez", boom)
        with pytest.raises(OSError, match="disk full"):
            rmd(3, 2.3, seed=1).save(path)
        assert path.read_bytes() == before
        assert sorted(os.listdir(tmp_path)) == ["a.npz"]

    def test_save_no_overwrite(self, tmp_path):
        path = tmp_path / "a.npz"
        rmd(3, 2.3, seed=0).save(path)
        before = path.read_bytes()
        with pytest.raises(FileExistsError, match="a.npz"):
            rmd(3, 2.3, seed=1).save(path, overwrite=False)
        assert path.read_bytes() == before
        assert sorted(os.listdir(tmp_path)) == ["a.npz"]

    def test_save_bad_suffix_and_metadata(self, tmp_path):
        s = Surface(np.zeros((3, 3)), 1.0)
        with pytest.raises(ValueError, match="npz"):
            s.save(tmp_path / "a.npy")
        s.metadata["bad"] = object()
        with pytest.raises(ValueError, match="metadata"):
            s.save(tmp_path / "a.npz")
        assert not (tmp_path / "a.npz").exists()

    def test_npz_dx_mismatch(self, tmp_path):
        s = Surface(np.ones((3, 4)), 0.25)
        s.save(tmp_path / "s.npz")
        assert load(tmp_path / "s.npz", dx=0.25).dx == 0.25
        with pytest.raises(ValueError, match=r"\bdx\b"):
            load(tmp_path / "s.npz", dx=0.5)

    def test_foreign_npz_needs_dx(self, tmp_path):
        np.savez(tmp_path / "f.npz", z=np.arange(6.0).reshape(2, 3))
        with pytest.raises(ValueError, match=r"\bdx\b"):
            load(tmp_path / "f.npz")
        assert load(tmp_path / "f.npz", dx=2.0).shape == (2, 3)

    def test_npy(self, tmp_path):
        h = np.random.default_rng(0).random((5, 7))
        np.save(tmp_path / "h.npy", h)
        s = load(tmp_path / "h.npy", dx=0.1)
        assert np.array_equal(s.heights, h) and s.dx == 0.1
        assert s.metadata["source"] == str(tmp_path / "h.npy")
        with pytest.raises(ValueError, match=r"\bdx\b"):
            load(tmp_path / "h.npy")

    @pytest.mark.parametrize(
        "suffix, sep", [(".csv", ","), (".txt", " "), (".dat", "\t"), (".asc", "  ")]
    )
    def test_text(self, tmp_path, suffix, sep):
        h = np.random.default_rng(1).normal(size=(4, 6))
        path = tmp_path / f"h{suffix}"
        lines = ["# a comment line"] + [sep.join(repr(float(v)) for v in row) for row in h]
        path.write_text("\n".join(lines) + "\n")
        s = load(path, dx=2.5)
        assert np.array_equal(s.heights, h)
        assert s.dx == 2.5
        with pytest.raises(ValueError, match=r"\bdx\b"):
            load(path)

    def test_text_garbage(self, tmp_path):
        path = tmp_path / "bad.csv"
        path.write_text("1,2,3\n4,five,6\n")
        with pytest.raises(ValueError, match="bad.csv"):
            load(path, dx=1.0)

    def test_text_nan(self, tmp_path):
        path = tmp_path / "nan.txt"
        path.write_text("1 2\nnan 4\n")
        with pytest.raises(InvalidArgumentError, match=r"^path: 1 of 4 points .* undefined"):
            load(path, dx=1.0)

    def test_corrupt_npz(self, tmp_path):
        path = tmp_path / "broken.npz"
        path.write_bytes(b"not a zip file at all")
        with pytest.raises(ValueError, match="broken.npz"):
            load(path)

    def test_missing_file(self, tmp_path):
        with pytest.raises(FileNotFoundError, match="nope.npz"):
            load(tmp_path / "nope.npz")
        with pytest.raises(FileNotFoundError, match="nope.csv"):
            load(tmp_path / "nope.csv", dx=1.0)

    def test_directory(self, tmp_path):
        with pytest.raises(ValueError, match="directory"):
            load(tmp_path)

    def test_other_format_without_surfacetopography(self, tmp_path, monkeypatch):
        path = tmp_path / "scan.sur"
        path.write_bytes(b"\x00" * 16)
        monkeypatch.setitem(sys.modules, "SurfaceTopography", None)
        with pytest.raises(ImportError, match=r"leakpath\[io\]"):
            load(path)

    def _fake_st(self, heights_xy, sizes):
        """A stand-in for SurfaceTopography with heights indexed [ix, iy]."""

        class Topo:
            def __init__(self, physical_sizes):
                self.nb_grid_pts = heights_xy.shape
                self.physical_sizes = physical_sizes
                self.info = {"unit": "µm"}

            def heights(self):
                return heights_xy

        class Channel:
            dim = 2
            nb_grid_pts = heights_xy.shape
            physical_sizes = sizes

            def topography(self, physical_sizes=None):
                if sizes is not None and physical_sizes is not None:
                    raise RuntimeError("physical size already fixed by the file")
                return Topo(sizes if physical_sizes is None else physical_sizes)

        class Reader:
            default_channel = Channel()

            def __enter__(self):
                return self

            def __exit__(self, *exc):
                return False

        mod = types.ModuleType("SurfaceTopography")
        mod.open_topography = lambda fn: Reader()  # type: ignore[attr-defined]
        return mod

    def test_other_format_via_surfacetopography(self, tmp_path, monkeypatch):
        path = tmp_path / "scan.sur"
        path.write_bytes(b"\x00")
        hxy = np.arange(12.0).reshape(4, 3)  # nx = 4, ny = 3
        monkeypatch.setitem(sys.modules, "SurfaceTopography", self._fake_st(hxy, (2.0, 1.5)))
        s = load(path)
        assert np.array_equal(s.heights, hxy.T)  # axis 1 = x in leakpath
        assert s.dx == 0.5
        assert s.metadata["unit"] == "µm"
        with pytest.raises(ValueError, match=r"\bdx\b"):
            load(path, dx=0.3)

    def test_other_format_without_sizes_needs_dx(self, tmp_path, monkeypatch):
        path = tmp_path / "scan.sur"
        path.write_bytes(b"\x00")
        hxy = np.arange(12.0).reshape(4, 3)
        monkeypatch.setitem(sys.modules, "SurfaceTopography", self._fake_st(hxy, None))
        with pytest.raises(ValueError, match=r"\bdx\b"):
            load(path)
        s = load(path, dx=0.2)
        assert s.dx == pytest.approx(0.2) and s.shape == (3, 4)

    def test_other_format_non_square_pixels(self, tmp_path, monkeypatch):
        path = tmp_path / "scan.sur"
        path.write_bytes(b"\x00")
        hxy = np.arange(12.0).reshape(4, 3)
        monkeypatch.setitem(sys.modules, "SurfaceTopography", self._fake_st(hxy, (2.0, 3.0)))
        with pytest.raises(ValueError, match="square"):
            load(path)


def test_path_objects_accepted(tmp_path):
    s = Surface(np.ones((3, 3)), 1.0)
    s.save(os.fspath(tmp_path / "x.npz"))
    assert isinstance(load(Path(tmp_path) / "x.npz"), Surface)


# ---------------------------------------------------------------------------- generator specs
class TestSpecs:
    @pytest.mark.parametrize(
        "text, repeated",
        [
            ("rmd:m=3,D=2.2,m=4,seed=0", "m"),
            ("rmd:m=3,D=2.2,seed=0,seed=1", "seed"),
            ("rmd:m=3,D=2.2,D=2.2,seed=0", "D"),  # even the same value twice
            ("spectral:n=16,shape=32,hurst=0.5,seed=0", "shape"),  # an alias and its target
        ],
    )
    def test_a_repeated_key_is_refused_by_name(self, text, repeated):
        from leakpath.generators import parse_spec

        with pytest.raises(InvalidArgumentError, match=rf"gives {repeated} twice") as info:
            parse_spec(text)
        assert info.value.argument == "surface"

    @pytest.mark.parametrize("text", ["rmd:m=3,D=2.2,seed=0,bogus=1", "rmd:m=3,D=2.2,seed=0,m"])
    def test_an_unknown_or_malformed_key_is_refused(self, text):
        from leakpath.generators import parse_spec

        with pytest.raises(InvalidArgumentError, match="unknown or malformed") as info:
            parse_spec(text)
        assert info.value.argument == "surface"

    def test_each_key_once_is_accepted(self):
        from leakpath.generators import parse_spec

        assert parse_spec("rmd:m=3,D=2.2,seed=4") == ("rmd", {"m": 3, "D": 2.2}, 4)
