"""Power spectral densities and rms statistics of one body and of the composite of two
(``C = C_upper + C_lower`` for independent surfaces; convention of ``docs/surfaces.md``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ... import _elementary, _validate
from ..._validate import invalid
from ...moments import rms_slope as _fd_rms_slope
from ...surfaces import Surface, load
from ._roughness import Roughness
from ._types import PSD, FloatArray

#: Relative tolerance of band edges (as in :func:`leakpath.spectral`).
_EDGE = 1e-12


@dataclass(frozen=True)
class _PowerLaw:
    """Piecewise power-law PSD: ``C`` log-log linear between ``nodes``; flat at ``c[0]`` from
    ``floor`` to ``q[0]`` (``floor = 0``: a roll-off; ``floor = q[0]``: nothing below), zero
    above ``q[-1]``."""

    q: FloatArray
    c: FloatArray
    floor: float

    def __call__(self, q: npt.ArrayLike) -> FloatArray:
        qa = np.asarray(q, dtype=np.float64)
        out = np.zeros(qa.shape)
        lo, hi = self.q[0], self.q[-1]
        flat = (qa >= self.floor * (1 - _EDGE)) & (qa < lo)
        if self.floor == 0.0:
            flat &= qa > 0
        out[flat] = self.c[0]
        band = (qa >= lo * (1 - _EDGE)) & (qa <= hi * (1 + _EDGE))
        qb = np.clip(qa[band], lo, hi)
        out[band] = _elementary.exp(
            np.interp(_elementary.log(qb), _elementary.log(self.q), _elementary.log(self.c))
        )
        return out

    def moment(self, a: int) -> float:
        """``2π ∫ q^a C(q) dq`` over the whole spectrum, exactly (piecewise power laws)."""
        q, c = self.q, self.c
        total = c[0] * (q[0] ** (a + 1) - self.floor ** (a + 1)) / (a + 1)
        for i in range(q.size - 1):
            s = math.log(c[i + 1] / c[i]) / math.log(q[i + 1] / q[i])
            e = a + 1 + s
            ratio = q[i + 1] / q[i]
            if abs(e) < 1e-12:
                seg = math.log(ratio)
            else:
                seg = math.expm1(e * math.log(ratio)) / e
            total += c[i] * q[i] ** (a + 1) * seg
        return 2.0 * math.pi * total

    def scaled(self, factor: float) -> _PowerLaw:
        return _PowerLaw(self.q, self.c * factor, self.floor)


def _need_length(r: Roughness, length: float | None) -> float:
    if length is None:
        raise invalid(
            "length",
            f"{r.name} has no rolloff_wavelength, so its spectrum runs down to the patch's "
            "lowest mode 2π/L and its statistics depend on the patch side L; pass length=L [m] "
            "(e.g. patch.length) or give rolloff_wavelength",
        )
    length_f = _validate.positive("length", length, what="a positive patch side in m")
    if not 2.0 * math.pi / length_f < 2.0 * math.pi / r.short_wavelength:  # type: ignore[operator]
        raise invalid(
            "length",
            f"the patch side {length_f!r} m must exceed {r.name}.short_wavelength "
            f"({r.short_wavelength!r} m)",
        )
    return length_f


def _statistical_psd(r: Roughness, length: float | None) -> _PowerLaw:
    """The model spectrum of a statistics/psd body, scaled to its requested rms."""
    if r.psd is not None:
        law = _PowerLaw(np.asarray(r.psd[0]), np.asarray(r.psd[1]), 0.0)
    else:
        h = float(r.hurst)  # type: ignore[arg-type]
        q_s = 2.0 * math.pi / float(r.short_wavelength)  # type: ignore[arg-type]
        if r.rolloff_wavelength is not None:
            q_0, floor = 2.0 * math.pi / r.rolloff_wavelength, 0.0
        else:
            q_0 = 2.0 * math.pi / _need_length(r, length)
            floor = q_0
        nodes = np.array([q_0, q_s])
        law = _PowerLaw(nodes, np.array([1.0, (q_s / q_0) ** (-2.0 * (1.0 + h))]), floor)
    if r.rms_height is not None:
        return law.scaled(r.rms_height**2 / law.moment(1))
    if r.rms_slope is not None:
        return law.scaled(r.rms_slope**2 / law.moment(3))
    return law


def _load_body(r: Roughness, k: int) -> Surface:
    s = load(r.files[k], dx=r.dx)  # type: ignore[index]
    return Surface(s.heights - s.mean_height, s.dx, dict(s.metadata))


def _periodogram_psd(r: Roughness) -> tuple[PSD, float, float]:
    """Radially averaged periodogram of a body's files (averaged over files), its m0 [m²]
    and FD mean-square slope, measured from the data.

    Mode k of a mean-subtracted ``ny × nx`` sample carries the variance
    ``P_k = |FFT(h)_k|²/(ny nx)²`` (``Σ P_k = m0``). Modes are binned by ``j = round(|q|/Δq)``,
    ``Δq = 2π/L``; bin j ≥ 1 gets ``C_j = Σ_bin P_k / (2π j Δq²)`` (its variance over the
    annulus area), so the binned spectrum integrates to the data's m0 less the few modes
    below ``Δq/2``."""
    variance: dict[int, float] = {}
    step = None
    nfiles = len(r.files)  # type: ignore[arg-type]
    m0 = slope2 = 0.0
    for k in range(nfiles):
        s = _load_body(r, k)
        h = s.heights
        ny, nx = h.shape
        p = np.abs(np.fft.fft2(h)) ** 2 / (ny * nx) ** 2
        qy = 2 * math.pi * np.fft.fftfreq(ny, s.dx)
        qx = 2 * math.pi * np.fft.fftfreq(nx, s.dx)
        q = np.hypot(qy[:, None], qx[None, :])
        if step is None:
            step = 2 * math.pi / (max(ny, nx) * s.dx)
        j = np.rint(q / step).astype(np.int64).ravel()
        sums = np.bincount(j, weights=p.ravel())
        for i in np.nonzero(sums)[0]:
            variance[int(i)] = variance.get(int(i), 0.0) + float(sums[i])
        m0 += float(np.mean(h * h))
        slope2 += _fd_rms_slope(h, s.dx) ** 2 if min(ny, nx) >= 2 else 0.0
    idx = np.array(sorted(i for i in variance if i > 0), dtype=np.int64)
    qb = idx * step
    cb = np.array([variance[int(i)] / nfiles / (2 * math.pi * i * step**2) for i in idx])
    keep = cb > 0
    law = _PowerLaw(qb[keep], cb[keep], 0.0) if np.count_nonzero(keep) >= 2 else None

    def psd(q: npt.ArrayLike) -> FloatArray:
        if law is None:
            return np.zeros(np.shape(q))
        return law(q)

    return psd, m0 / nfiles, slope2 / nfiles


def body_psd(r: Roughness, *, length: float | None = None) -> PSD:
    """Isotropic PSD ``C(q)`` [m⁴] of one body, ``q`` in rad/m (``⟨h²⟩ = 2π∫ q C dq``).

    Statistics or tabulated: the model spectrum scaled to the body's own requested rms.
    Files: the radially averaged periodogram of the mean-subtracted data (bins of width
    ``2π/L``, averaged over the files; no window, so an estimate). Flat: 0. ``length`` [m] is
    the patch side, needed only for a statistical body without roll-off.
    """
    if r.flat:
        return lambda q: np.zeros(np.shape(q))
    if r.files is not None:
        return _periodogram_psd(r)[0]
    return _statistical_psd(r, length)


def _body_moments(r: Roughness, length: float | None) -> tuple[float, float]:
    """``(⟨h²⟩ [m²], ⟨|∇h|²⟩ [-])`` of one body."""
    if r.flat:
        return 0.0, 0.0
    if r.files is not None:
        _, m0, s2 = _periodogram_psd(r)
        return m0, s2
    law = _statistical_psd(r, length)
    return law.moment(1), law.moment(3)


def _pair(upper: Roughness, lower: Roughness) -> None:
    for name, r in (("surface.upper", upper), ("surface.lower", lower)):
        if not isinstance(r, Roughness):
            raise invalid(name, f"must be a Roughness, got {_validate.describe(r)}")


def composite_psd(
    upper: Roughness, lower: Roughness, *, length: float | None = None
) -> PSD:
    """``C(q) = C_upper(q) + C_lower(q)`` [m⁴] of the composite of two independent surfaces,
    isotropic, ``q`` in rad/m (convention of ``docs/surfaces.md``; ``⟨h²⟩ = 2π∫ q C dq``).

    Measured files: estimated from the data (:func:`body_psd`). ``length`` [m] (the patch side)
    is needed only when a statistical body has no roll-off (compatible addition to the shared
    interface).
    """
    _pair(upper, lower)
    cu = body_psd(upper, length=length)
    cl = body_psd(lower, length=length)

    def psd(q: npt.ArrayLike) -> FloatArray:
        return cu(q) + cl(q)

    return psd


def composite_rms_height(
    upper: Roughness, lower: Roughness, *, length: float | None = None
) -> float:
    """rms height of the composite [m]: ``√(m0_upper + m0_lower)``, ``m0 = 2π∫ q C dq``
    (exact for the model spectra; files: the mean-square of the mean-subtracted data)."""
    _pair(upper, lower)
    return math.sqrt(_body_moments(upper, length)[0] + _body_moments(lower, length)[0])


def composite_rms_slope(
    upper: Roughness, lower: Roughness, *, length: float | None = None
) -> float:
    """rms slope of the composite [-]: ``√⟨|∇h|²⟩``, ``⟨|∇h|²⟩ = 2π∫ q³ C dq`` summed over
    the bodies (the continuum slope of the model spectra; files: forward differences of the
    data as :func:`leakpath.rms_slope`)."""
    _pair(upper, lower)
    return math.sqrt(_body_moments(upper, length)[1] + _body_moments(lower, length)[1])
