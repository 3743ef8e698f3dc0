"""Nayak's spectral moments of a sampled surface (``docs/conventions.md``).

Conventions
-----------
Heights ``s[i, j]`` live on a uniform grid of spacing ``dx`` (length units): axis 0 = rows = y,
axis 1 = columns = x. Every moment below is a mean over grid points, so it does not depend on
the grid size; units are ``[m0] = length²``, ``[m2] = 1`` (slope²), ``[m4] = 1/length²``
(curvature²), and ``alpha`` is dimensionless.

Finite-difference estimator (``method="fd"``, the default, non-periodic)::

    s̄  = mean(s)
    m0 = mean((s − s̄)²)
    s_x[i, j]  = (s[i, j+1] − s[i, j]) / dx                      (ny × (nx−1) forward differences)
    s_y[i, j]  = (s[i+1, j] − s[i, j]) / dx                      ((ny−1) × nx forward differences)
    m2 = ½ (⟨s_x²⟩ + ⟨s_y²⟩)
    s_xx[i, j] = (s[i, j+1] − 2 s[i, j] + s[i, j−1]) / dx²       (ny × (nx−2), interior columns)
    s_yy[i, j] = (s[i+1, j] − 2 s[i, j] + s[i−1, j]) / dx²       ((ny−2) × nx, interior rows)
    m4 = ½ (⟨s_xx²⟩ + ⟨s_yy²⟩)
    alpha = m0 · m4 / m2²                                        (Nayak's bandwidth parameter)

``⟨·⟩`` is the mean over every difference the grid provides (no wrap-around). The paper
prints the bandwidth parameter as "m0 m4²/m2"; that is a typo (it is not dimensionless) —
Nayak's definition, used here, is ``m0 m4 / m2²``. For an isotropic Gaussian surface
``alpha ≥ 1.5`` (a continuum bound; for a narrow-band spectrum close to the grid scale the
slightly anisotropic FD stencils can give a value just below it).

Spectral estimator (``method="spectral"``, assumes the sample is one period of a periodic
surface): with ``ĥ = fft2(s − s̄)`` and ``N = ny·nx``, ``P_q = |ĥ_q|²/N²`` so that
``Σ_q P_q = m0`` (Parseval), and wavevectors in **radians per length unit**
``q_x = 2π·fftfreq(nx, dx)``, ``q_y = 2π·fftfreq(ny, dx)`` (a wavelength λ has ``q = 2π/λ``)::

    m0 = Σ P_q
    m2 = ½ Σ (w_x q_x² + w_y q_y²) P_q      = ½ ⟨|∇s|²⟩
    m4 = ½ Σ (w_x q_x⁴ + w_y q_y⁴) P_q      = ½ (⟨s_xx²⟩ + ⟨s_yy²⟩)

The weights ``w_x``, ``w_y`` are 1 except on the Nyquist column/row of an even-sized axis
(``|q| = π/dx``), where they are ½: a sampled Nyquist mode ``a·(−1)^j`` is the band-limited
cosine ``a·cos(πx/dx)``, whose derivatives averaged over a period have half the weight of a
travelling wave of the same sampled power. For a well-resolved surface the two estimators
agree (the FD stencils underestimate a mode of wavevector q by the factors
``sinc²(q·dx/2)`` for m2 and ``sinc⁴(q·dx/2)`` for m4).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Literal, Protocol

import numpy as np
import numpy.typing as npt

from . import _validate
from .errors import InvalidArgumentError


class _HeightMap(Protocol):
    """Anything with ``heights`` and ``dx`` (e.g. :class:`leakpath.Surface`)."""

    heights: np.ndarray
    dx: float


Surface = _HeightMap  # the annotations below accept a Surface structurally


def _as_height_map(obj: Any) -> tuple[np.ndarray, float] | None:
    """``(heights, dx)`` of a surface-like object, ``None`` for arrays and array-likes."""
    if isinstance(obj, np.ndarray) or not (hasattr(obj, "heights") and hasattr(obj, "dx")):
        return None
    return obj.heights, float(obj.dx)


__all__ = ["Moments", "nayak_moments", "rms_height", "rms_slope", "rms_curvature"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Moments:
    """Nayak's moments of a surface; see :mod:`leakpath.moments` for the definitions.

    Attributes
    ----------
    m0 : float
        Height variance about the mean, ``mean((s − s̄)²)`` [length²].
    m2 : float
        Half the mean-square gradient, ``½(⟨s_x²⟩ + ⟨s_y²⟩)`` [dimensionless].
    m4 : float
        Half the mean-square second derivatives, ``½(⟨s_xx²⟩ + ⟨s_yy²⟩)`` [1/length²].
    alpha : float
        Bandwidth parameter ``m0·m4/m2²`` (``nan`` for a flat surface, where ``m2 = 0``).
    """

    m0: float
    m2: float
    m4: float
    alpha: float

    def as_dict(self) -> dict[str, float]:
        """The four moments as a plain ``dict`` (e.g. for JSON output)."""
        return asdict(self)


def _coerce(heights: Any, dx: float | None, *, min_points: int) -> tuple[FloatArray, float]:
    """Validate ``heights``/``dx`` (or a :class:`~leakpath.Surface`); return both."""
    parts = _as_height_map(heights)
    if parts is not None:
        if dx is not None and _validate.spacing("dx", dx) != parts[1]:
            raise InvalidArgumentError(
                f"dx: {dx!r} differs from the surface's dx={parts[1]!r}; "
                "omit dx when passing a Surface"
            )
        return parts
    arr = _validate.real_array("heights", heights, finite=False, copy=False)
    # Differences and their squares: a few temporaries of the heights' size.
    limit = _validate.memory_budget()
    if 4 * 8 * arr.size > limit:
        raise _validate.too_large(
            "heights", f"moments of {arr.shape[0]} × {arr.shape[1]} heights", 4 * 8 * arr.size,
            limit, "crop or downsample them first",
        )
    if min(arr.shape) < min_points:
        raise InvalidArgumentError(
            f"heights: must have at least {min_points} points along each axis, got shape "
            f"{arr.shape}"
        )
    if not np.all(np.isfinite(arr)):
        raise InvalidArgumentError(
            "heights: contains NaN or infinite values; fill or crop them first"
        )
    if arr.size and float(np.max(np.abs(arr))) > _validate.MAX_ABS_HEIGHT:
        raise InvalidArgumentError(
            f"heights: values beyond {_validate.MAX_ABS_HEIGHT:g} overflow when squared; "
            "express them in a larger length unit"
        )
    if dx is None:
        raise InvalidArgumentError("dx: the grid spacing is required when heights is a plain array")
    return arr, _validate.spacing("dx", dx)


def _mean_sq_per_dx(d: FloatArray, dx: float, power: int, what: str) -> float:
    """``mean(d²) / dx^(2·power)``: the mean square of differences ``d`` divided by ``dx^power``.

    The squares are taken on the raw differences (heights are bounded, so they stay finite)
    and divided by ``dx²`` ``power`` times; a result that does not fit in a double (a slope
    or curvature scale far beyond the floating-point range for this ``dx``) is refused
    instead of coming back as ``inf`` or ``0``.
    """
    raw = float(np.mean(d * d))
    if raw == 0.0:
        return 0.0
    exponent = math.log10(raw) - 2 * power * math.log10(dx)
    if not -300.0 < exponent < 300.0:
        raise InvalidArgumentError(
            f"dx: with dx = {dx!r} the mean square {what} of these heights is about "
            f"1e{exponent:+.0f}, beyond the floating-point range; express heights and dx in "
            "a length unit closer to the surface's scale"
        )
    out = raw
    dx2 = dx * dx
    for _ in range(power):
        out /= dx2
    return out


def _fd_slopes_sq(s: FloatArray, dx: float) -> tuple[float, float]:
    """``(⟨s_x²⟩, ⟨s_y²⟩)`` with forward differences (axis 1 = x, axis 0 = y)."""
    sx2 = _mean_sq_per_dx(np.diff(s, axis=1), dx, 1, "slope")
    sy2 = _mean_sq_per_dx(np.diff(s, axis=0), dx, 1, "slope")
    return sx2, sy2


def _fd_curvatures_sq(s: FloatArray, dx: float) -> tuple[float, float]:
    """``(⟨s_xx²⟩, ⟨s_yy²⟩)`` with central second differences at interior points."""
    sxx = s[:, 2:] - 2.0 * s[:, 1:-1] + s[:, :-2]
    syy = s[2:, :] - 2.0 * s[1:-1, :] + s[:-2, :]
    return (
        _mean_sq_per_dx(sxx, dx, 2, "curvature"),
        _mean_sq_per_dx(syy, dx, 2, "curvature"),
    )


def _spectral_weights(n: int, dx: float) -> tuple[FloatArray, FloatArray]:
    """``(q, w)`` along one axis: ``q = 2π·fftfreq(n, dx)`` [rad/length], Nyquist weight ½."""
    q = 2.0 * np.pi * np.fft.fftfreq(n, dx)
    w = np.ones(n)
    if n % 2 == 0:
        w[n // 2] = 0.5
    return q, w


def _alpha(m0: float, m2: float, m4: float) -> float:
    return m0 * m4 / (m2 * m2) if m2 > 0.0 else float("nan")


def nayak_moments(
    heights: FloatArray | Surface | npt.ArrayLike,
    dx: float | None = None,
    method: Literal["fd", "spectral"] = "fd",
) -> Moments:
    """Nayak's moments ``m0, m2, m4`` and ``alpha = m0·m4/m2²`` of a surface.

    Parameters
    ----------
    heights : (ny, nx) array_like or Surface
        Heights ``s[i, j]`` (axis 0 = y, axis 1 = x); at least 3 points per axis, all finite.
        A :class:`~leakpath.Surface` supplies its own ``dx``.
    dx : float, optional
        Grid spacing [length]; required for a plain array.
    method : {"fd", "spectral"}
        ``"fd"`` (default): non-periodic forward/central finite differences
        (``docs/conventions.md``).
        ``"spectral"``: from the periodogram, treating the sample as one period of a periodic
        surface; wavevectors ``q = 2π·fftfreq(n, dx)`` in rad/length.

    Returns
    -------
    Moments
        ``m0`` [length²], ``m2`` [1], ``m4`` [1/length²], ``alpha`` [1].

    Notes
    -----
    FD definitions (``⟨·⟩`` = mean over all available differences)::

        m0 = mean((s − s̄)²)
        m2 = ½(⟨s_x²⟩ + ⟨s_y²⟩),     s_x = (s[:, j+1] − s[:, j])/dx
        m4 = ½(⟨s_xx²⟩ + ⟨s_yy²⟩),   s_xx = (s[:, j+1] − 2 s[:, j] + s[:, j−1])/dx²

    Spectral definitions (``P_q = |fft2(s − s̄)|²/N²``, Nyquist rows/columns weighted ½)::

        m0 = Σ P_q,  m2 = ½ Σ (q_x² + q_y²) P_q,  m4 = ½ Σ (q_x⁴ + q_y⁴) P_q

    The paper's "m0 m4²/m2" is a typo for Nayak's ``alpha = m0 m4/m2²``.

    Raises
    ------
    InvalidArgumentError (a ``ValueError``)
        ``heights`` not a 2-D array of real numbers, with fewer than 3 points on an axis, or
        containing NaN/inf; ``dx`` missing, non-positive, not finite or out of range
        (``dx²`` not a normal double); unknown ``method``.
    """
    _validate.choice("method", method, ("fd", "spectral"))
    s, dx_f = _coerce(heights, dx, min_points=3)
    mean = float(np.mean(s))
    d = s - mean
    m0 = float(np.mean(d * d))
    if method == "fd":
        sx2, sy2 = _fd_slopes_sq(s, dx_f)
        sxx2, syy2 = _fd_curvatures_sq(s, dx_f)
        m2 = 0.5 * (sx2 + sy2)
        m4 = 0.5 * (sxx2 + syy2)
    else:
        ny, nx = s.shape
        power = np.abs(np.fft.fft2(d)) ** 2 / float(ny * nx) ** 2
        qy, wy = _spectral_weights(ny, dx_f)
        qx, wx = _spectral_weights(nx, dx_f)
        # Marginal sums: Σ_q f(q_x) P_q = Σ_{q_x} f(q_x) Σ_{q_y} P_q, likewise for y.
        px = power.sum(axis=0)  # power per q_x
        py = power.sum(axis=1)  # power per q_y
        qx2, qy2 = qx * qx, qy * qy
        with np.errstate(over="ignore", under="ignore"):
            m2 = 0.5 * (float(np.sum(wx * qx2 * px)) + float(np.sum(wy * qy2 * py)))
        with np.errstate(over="ignore", under="ignore"):
            m4 = 0.5 * (float(np.sum(wx * qx2 * qx2 * px)) + float(np.sum(wy * qy2 * qy2 * py)))
        if not (math.isfinite(m2) and math.isfinite(m4)):
            raise InvalidArgumentError(
                f"dx: with dx = {dx_f!r} the spectral moments of these heights overflow; "
                "express heights and dx in a length unit closer to the surface's scale"
            )
    return Moments(m0=m0, m2=m2, m4=m4, alpha=_alpha(m0, m2, m4))


def rms_height(heights: FloatArray | Surface | npt.ArrayLike) -> float:
    r"""Root-mean-square height about the mean, ``h_rms = √m0``.

    .. math:: h_\mathrm{rms} = \sqrt{\langle (s - \bar s)^2 \rangle}

    Parameters
    ----------
    heights : (ny, nx) array_like or Surface
        Heights (any length unit); at least one point, all finite.

    Returns
    -------
    float
        ``h_rms`` in the unit of the heights.
    """
    parts = _as_height_map(heights)
    if parts is not None:
        s = parts[0]
    else:
        s, _ = _coerce(heights, 1.0, min_points=1)
    d = s - float(np.mean(s))
    return float(np.sqrt(np.mean(d * d)))


def rms_slope(heights: FloatArray | Surface | npt.ArrayLike, dx: float | None = None) -> float:
    r"""Root-mean-square gradient with forward differences, ``h'_rms = √(2 m2)``.

    .. math:: h'_\mathrm{rms} = \sqrt{\langle s_x^2 \rangle + \langle s_y^2 \rangle},
              \quad s_x = \frac{s_{i,j+1} - s_{i,j}}{\Delta x},
              \quad s_y = \frac{s_{i+1,j} - s_{i,j}}{\Delta x}

    Each mean runs over the available (non-periodic) differences, exactly as in
    :func:`nayak_moments` with ``method="fd"``, so ``rms_slope(s, dx)**2 == 2*m2``.

    Parameters
    ----------
    heights : (ny, nx) array_like or Surface
        Heights; at least 2 points per axis, all finite.
    dx : float, optional
        Grid spacing [length]; required for a plain array.

    Returns
    -------
    float
        Dimensionless rms slope.
    """
    s, dx_f = _coerce(heights, dx, min_points=2)
    sx2, sy2 = _fd_slopes_sq(s, dx_f)
    return float(np.sqrt(sx2 + sy2))


def rms_curvature(heights: FloatArray | Surface | npt.ArrayLike, dx: float | None = None) -> float:
    r"""Root-mean-square curvature with central second differences, ``√(2 m4)``.

    .. math:: \kappa_\mathrm{rms} = \sqrt{\langle s_{xx}^2 \rangle + \langle s_{yy}^2 \rangle},
              \quad s_{xx} = \frac{s_{i,j+1} - 2 s_{i,j} + s_{i,j-1}}{\Delta x^2}

    Means over interior points along the differentiated axis (see :func:`nayak_moments`).

    Parameters
    ----------
    heights : (ny, nx) array_like or Surface
        Heights; at least 3 points per axis, all finite.
    dx : float, optional
        Grid spacing [length]; required for a plain array.

    Returns
    -------
    float
        rms curvature [1/length].
    """
    s, dx_f = _coerce(heights, dx, min_points=3)
    sxx2, syy2 = _fd_curvatures_sq(s, dx_f)
    return float(np.sqrt(sxx2 + syy2))
