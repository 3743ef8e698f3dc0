"""Surface generators: random midpoint displacement and spectral synthesis (``docs/surfaces.md``).

:func:`rmd`
    Random midpoint displacement (Saupe's MidPointFM2D without "addition"), the paper's
    generator, on a ``(2^m + 1)²`` grid, shifted so that ``min(h) = 0``.
:func:`spectral`
    Periodic Fourier-filtered self-affine surface with PSD ``C(q) ∝ q^(−2(1+H))`` between
    two cut-offs, scaled to a requested rms height or rms slope.

:data:`GENERATORS` is the one registry of generators by name, with the arguments each takes;
:func:`parse_spec` reads a command-line spec such as ``rmd:m=7,D=2.1,seed=0`` and
:func:`generate` builds the surface (the CLI and ensembles use both).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from . import _elementary, _validate
from . import moments as _moments
from .errors import InvalidArgumentError
from .surfaces import (
    DEFAULT_UNIT,
    MAX_ABS_HEIGHT,
    Surface,
    _check_positive_finite,
    _check_seed,
    _Owned,
    check_slope,
    check_unit,
)

__all__ = [
    "DEFAULT_LENGTH",
    "rmd",
    "spectral",
    "RMD_MEMORY_LIMIT_BYTES",
    "Generator",
    "GENERATORS",
    "parse_spec",
    "generate",
]

FloatArray = npt.NDArray[np.float64]

#: Default lateral size of a generated surface, in its unit (:data:`DEFAULT_UNIT`, µm): a
#: 0.5 mm square. With heights of about 1 µm (RMD's default ``σ0``, spectral's default rms
#: height) the rms slope stays within the small-slope model: 0.035 for ``rmd(7, 2.1)``,
#: 0.05 for ``spectral(128, 0.8)`` (``docs/surfaces.md``).
DEFAULT_LENGTH = 500.0

#: :func:`rmd` refuses grids whose estimated peak memory exceeds this (8 GiB).
#: The estimate is ``3 · 8 · (2^m + 1)²`` bytes: the height array plus the random normals
#: and temporaries of the finest level. m = 14 (≈ 6.0 GiB) is the largest accepted size.
RMD_MEMORY_LIMIT_BYTES: int = 8 * 2**30


def generator_memory_limit() -> int:
    """Bytes a surface generator may use: :data:`RMD_MEMORY_LIMIT_BYTES` or 70 % of physical
    memory, whichever is smaller."""
    return min(RMD_MEMORY_LIMIT_BYTES, _validate.memory_budget())


def _rmd_bytes(m: int) -> int:
    """Estimated peak bytes of :func:`rmd`: ``3 · 8 · (2^m + 1)²``."""
    n = 2**m + 1
    return 3 * 8 * n * n


def _rmd_check_m(m: Any) -> int:
    m_int = _validate.integer(
        "m", m, low=1, high=2**1024, what="an integer ≥ 1 (grid (2^m + 1)²)"
    )
    limit = generator_memory_limit()
    largest = max((k for k in range(1, 40) if _rmd_bytes(k) <= limit), default=0)
    if m_int > largest:
        # 2^m itself is not computed for absurd m (2^(2^62) would never finish).
        estimate = _rmd_bytes(m_int) if m_int < 64 else 24 * 2**128  # a lower bound
        what = (
            f"an RMD surface with m = {m_int} ((2^{m_int} + 1)² points)"
            if m_int < 64
            else f"an RMD surface with m = {m_int} (more than 2^128 points)"
        )
        hint = f"use m <= {largest}" if largest else "free some memory"
        raise _validate.too_large("m", what, estimate, limit, hint)
    return m_int


def _check_fractal_dimension(D: Any) -> float:  # noqa: N803
    return _validate.real(
        "D", D, low=2.0, high=3.0, low_open=True, high_open=True,
        what="a fractal dimension in the open interval (2, 3)",
    )


def _check_height_scale(h: FloatArray, name: str) -> None:
    """Refuse generated heights that overflowed or exceed :data:`MAX_ABS_HEIGHT`."""
    peak = float(np.max(np.abs(h)))
    if not peak <= MAX_ABS_HEIGHT:
        raise InvalidArgumentError(
            f"{name}: too large, the heights reach {peak:.3g} (limit {MAX_ABS_HEIGHT:g}); "
            "express them in a larger length unit"
        )


def rmd(
    m: int,
    D: float,  # noqa: N803 - the paper's symbol
    *,
    seed: int | None,
    sigma0: float = 1.0 / math.sqrt(0.09),
    length: float = DEFAULT_LENGTH,
    unit: str = DEFAULT_UNIT,
) -> Surface:
    """Random-midpoint-displacement surface (Saupe's MidPointFM2D without addition).

    Builds heights on a ``(2^m + 1) × (2^m + 1)`` grid with Hurst exponent ``H = 3 − D``,
    then shifts them so that ``min(h) = 0``. Grid spacing ``dx = length / 2^m``.

    Algorithm (``N = 2^m``, ``G`` standard normals, ``δ`` a standard deviation)::

        δ = σ0;  f = 2^(−H/2)
        h[0,0], h[0,N], h[N,0], h[N,N] = σ0·G           (4 draws, in this order)
        for level = 1 … m:                              (D_ = N/2^(level−1), d = D_/2)
            δ ← f·δ
            centres   h[d::D_, d::D_]  = mean of the 4 diagonal corners + δ·G
            δ ← f·δ
            edge mid. h[0::D_, d::D_]  = mean of the axis neighbours + δ·G   (on rows)
                      h[d::D_, 0::D_]  = mean of the axis neighbours + δ·G   (on columns)
        h ← h − min(h)

    A point's "axis neighbours" are the ``d``-distant points along both axes: 4 inside the
    grid, 3 on its boundary. The corner mean is summed in the order
    ``h[i−d,j−d] + h[i−d,j+d] + h[i+d,j−d] + h[i+d,j+d]`` and divided by 4; an edge midpoint
    sums its two neighbours along its own edge (lower index first) and then the existing
    ones across it (lower index first), and divides by their count (4 or 3).

    **Draw order** (``rng = numpy.random.default_rng(seed)``; every draw is one call to
    ``rng.standard_normal``; arrays fill in row-major order):

    1. ``rng.standard_normal(4)`` for the corners ``(0,0), (0,N), (N,0), (N,N)``;
    2. per level, ``rng.standard_normal((k, k))`` with ``k = 2^(level−1)`` for the square
       centres ``h[d::D_, d::D_]``;
    3. then one ``rng.standard_normal(2·k·(k+1))``: its first ``(k+1)·k`` values, reshaped to
       ``(k+1, k)``, go to the midpoints on grid rows ``h[0::D_, d::D_]``; the remaining
       ``k·(k+1)``, reshaped to ``(k, k+1)``, go to the midpoints on grid columns
       ``h[d::D_, 0::D_]``.

    Each level is vectorised with numpy slicing (m = 12, a 4097² grid, takes well under 2 s).

    **Reading of the paper's variance.** The paper writes "variance σ1² = σ0²/2^((3−D)/2)".
    Read literally as a variance, it would halve the Hurst exponent. Following Saupe, the
    factor ``2^(−H/2)`` is applied to the *standard deviation* ``δ`` before each of the two
    half-steps of a level (so δ falls by ``2^(−H)`` per halving of the spacing, as
    self-affinity with exponent H requires). Midpoint displacement without addition is known
    to bias the measured Hurst exponent low for smooth surfaces (H near 1); see
    ``docs/surfaces.md`` for the measured values.

    Parameters
    ----------
    m : int
        Number of refinement levels, ``1 ≤ m ≤ 14`` (grid ``(2^m + 1)²``; the estimated
        peak memory ``3·8·(2^m + 1)²`` bytes must not exceed :func:`generator_memory_limit`,
        8 GiB or 70 % of physical memory, whichever is smaller).
    D : float
        Fractal dimension, ``2 < D < 3``; Hurst exponent ``H = 3 − D``.
    seed : int or None
        Seed for ``numpy.random.default_rng``; the same seed gives the same surface bit for
        bit. ``None`` draws fresh entropy, which is recorded in ``metadata["seed"]``.
    sigma0 : float
        Standard deviation of the corner heights (and the initial ``δ``) [unit]; default
        ``1/√0.09`` (rms heights of about 1.3–1.8 µm after the shift).
    length : float
        Physical size of the square (``2^m·dx``) [unit]; default :data:`DEFAULT_LENGTH`
        (500 µm).
    unit : str
        Length unit of ``sigma0``, ``length`` and the result (default ``"µm"``).

    Returns
    -------
    Surface
        ``metadata`` records ``generator="rmd"``, ``m``, ``D``, ``H``, ``seed``, ``sigma0``,
        ``length`` and ``unit``. Warns (:class:`leakpath.errors.SlopeWarning`) when its rms
        slope exceeds :data:`leakpath.surfaces.MAX_RMS_SLOPE`.

    Raises
    ------
    InvalidArgumentError (a ``ValueError``)
        Invalid ``m``, ``D``, ``seed``, ``sigma0`` or ``length`` (the message names it).
    ProblemTooLargeError (a ``MemoryError``)
        ``m`` so large that the estimated peak memory ``3·8·(2^m + 1)²`` bytes exceeds
        :func:`generator_memory_limit` (checked before anything is allocated).
    """
    m_int = _rmd_check_m(m)
    d_frac = _check_fractal_dimension(D)
    sigma0_f = _check_positive_finite("sigma0", sigma0)
    length_f = _check_positive_finite("length", length)
    unit = check_unit(unit)
    seed_i = _check_seed(seed)
    hurst = 3.0 - d_frac
    dx = length_f / 2**m_int
    try:
        _validate.spacing("dx", dx)
    except InvalidArgumentError:
        raise InvalidArgumentError(
            f"length: {length_f!r} gives a grid spacing dx = length/2^m = {dx!r} out of range "
            "(dx² must be a normal double); express lengths in another unit"
        ) from None

    rng = np.random.default_rng(seed_i)
    big_n = 2**m_int
    h = np.zeros((big_n + 1, big_n + 1), dtype=np.float64)
    corners = rng.standard_normal(4)
    h[0, 0], h[0, big_n], h[big_n, 0], h[big_n, big_n] = sigma0_f * corners
    factor = 2.0 ** (-0.5 * hurst)
    delta = sigma0_f
    step = big_n  # D_ in the docstring: spacing of the already-known lattice
    for level in range(1, m_int + 1):
        half = step // 2
        k = 2 ** (level - 1)
        # --- square centres: mean of the 4 diagonal neighbours
        delta *= factor
        c = h[0:big_n:step, 0:big_n:step] + h[0:big_n:step, step::step]
        c += h[step::step, 0:big_n:step]
        c += h[step::step, step::step]
        c /= 4.0
        c += delta * rng.standard_normal((k, k))
        h[half::step, half::step] = c
        # --- edge midpoints
        delta *= factor
        g = rng.standard_normal(2 * k * (k + 1))
        centres = h[half::step, half::step]  # (k, k), just computed
        # on grid rows: (k+1, k); along-edge neighbours are lattice points left/right,
        # across-edge neighbours are the centres above/below (absent on rows 0 and N).
        s = h[0::step, 0:big_n:step] + h[0::step, step::step]
        s[1:, :] += centres
        s[:-1, :] += centres
        s[1:-1, :] /= 4.0
        s[0, :] /= 3.0
        s[-1, :] /= 3.0
        s += delta * g[: (k + 1) * k].reshape(k + 1, k)
        h[0::step, half::step] = s
        # on grid columns: (k, k+1); along-edge neighbours above/below, centres left/right.
        t = h[0:big_n:step, 0::step] + h[step::step, 0::step]
        t[:, 1:] += centres
        t[:, :-1] += centres
        t[:, 1:-1] /= 4.0
        t[:, 0] /= 3.0
        t[:, -1] /= 3.0
        t += delta * g[(k + 1) * k :].reshape(k, k + 1)
        h[half::step, 0::step] = t
        step = half
    h -= h.min()
    _check_height_scale(h, "sigma0")
    metadata = {
        "generator": "rmd",
        "m": m_int,
        "D": d_frac,
        "H": hurst,
        "seed": seed_i,
        "sigma0": sigma0_f,
        "length": length_f,
    }
    surface = Surface(_Owned(h), dx, metadata, unit)
    check_slope(surface)
    return surface


# ---------------------------------------------------------------------------- spectral
def _check_shape(shape: Any) -> tuple[int, int]:
    return _validate.shape_pair("shape", shape, low=2)


#: Bytes :func:`spectral` needs per grid point at its peak (white noise, its half spectrum,
#: the wavevector magnitudes and filter, the filtered spectrum, the result and the FFT's
#: work space: 48.5 measured with tracemalloc, rounded up).
SPECTRAL_BYTES_PER_POINT = 56


def _check_spectral_size(ny: int, nx: int) -> None:
    limit = generator_memory_limit()
    estimate = SPECTRAL_BYTES_PER_POINT * ny * nx
    if estimate > limit:
        side = math.isqrt(limit // SPECTRAL_BYTES_PER_POINT)
        raise _validate.too_large(
            "shape",
            f"a spectral surface of {ny} × {nx} points",
            estimate,
            limit,
            f"use at most about {side} × {side} points",
        )


def spectral(
    shape: int | tuple[int, int],
    hurst: float,
    *,
    seed: int | None,
    length: float = DEFAULT_LENGTH,
    unit: str = DEFAULT_UNIT,
    rms_height: float | None = None,
    rms_slope: float | None = None,
    long_cutoff: float | None = None,
    short_cutoff: float | None = None,
    rolloff: float | None = None,
) -> Surface:
    """Periodic self-affine surface by Fourier filtering of white noise.

    With ``w`` a ``(ny, nx)`` array of standard normals from
    ``numpy.random.default_rng(seed).standard_normal((ny, nx))`` (one call)::

        h = irfft2( A(q) · rfft2(w) ),   A(q) = q_r^(−(1+H))   for q_L ≤ |q| < q_r
                                         A(q) = |q|^(−(1+H))   for q_r ≤ |q| ≤ q_s
                                         A(q) = 0              otherwise

    so the power spectrum ``C(q) ∝ A²`` is flat, ``C(q) = C(q_r)``, on the roll-off plateau
    ``q_L ≤ |q| < q_r``, follows the self-affine power law ``C(q) ∝ |q|^(−2(1+H))`` for
    ``q_r ≤ |q| ≤ q_s``, and is exactly zero outside the band (including ``q = 0``, so the
    mean height is zero): the spectrum of Persson's and Müser's contact-mechanics challenge
    surfaces. Without a roll-off (the default, ``q_r = q_L``) there is no plateau and the
    power law spans the whole band. Filtering real white noise
    gives a Gaussian field with uniformly random phases whose spectrum is Hermitian by
    construction: the result is exactly real and exactly periodic (a finite sum of the
    grid's Fourier modes). It is then scaled by one constant to the requested rms height or
    rms slope.

    **Wavevectors** are angular: ``q = 2π/λ`` in radians per length unit, with
    ``q_x = 2π·fftfreq(nx, dx)``, ``q_y = 2π·fftfreq(ny, dx)``; the cut-offs are given as
    wavelengths, ``q_L = 2π/long_cutoff``, ``q_r = 2π/rolloff``, ``q_s = 2π/short_cutoff``
    (the band edges are inclusive and the plateau ends below ``q_r``, each with a relative
    tolerance of 1e-12).

    **Grid:** square pixels, ``dx = length / nx``; ``length`` is the size along x (axis 1)
    and the size along y is ``ny·dx``.

    Parameters
    ----------
    shape : int or (int, int)
        ``n`` for an ``n × n`` grid or ``(ny, nx)``; at least 2 per axis.
    hurst : float
        Hurst exponent ``0 < H < 1``.
    seed : int or None
        Seed for ``numpy.random.default_rng``; ``None`` draws fresh entropy (recorded).
    length : float
        Size along x, ``nx·dx`` [unit]; default :data:`DEFAULT_LENGTH` (500 µm).
    unit : str
        Length unit of every length argument and of the result (default ``"µm"``).
    rms_height : float, optional
        Requested ``√m0 = √(mean((h − h̄)²))`` [unit]. Default 1 when neither rms value is
        given.
    rms_slope : float, optional
        Requested ``√(⟨h_x²⟩ + ⟨h_y²⟩) = √(2·m2)`` with the *same non-periodic forward
        differences* as :func:`leakpath.moments.nayak_moments` (so ``nayak_moments`` reports
        exactly ``m2 = rms_slope²/2``). Mutually exclusive with ``rms_height``.
    long_cutoff : float, optional
        Longest wavelength ``λ_L`` [unit]; default the box size ``max(ny, nx)·dx`` (the
        lowest non-zero mode).
    short_cutoff : float, optional
        Shortest wavelength ``λ_s`` [unit]; default ``2·dx`` (the Nyquist wavelength).
    rolloff : float, optional
        Roll-off wavelength ``λ_r`` [unit], ``short_cutoff < λ_r ≤ long_cutoff``: the
        spectrum is flat for wavelengths between ``λ_r`` and ``long_cutoff`` and a power law
        below ``λ_r``. Default ``long_cutoff`` (no plateau, the same surface bit for bit as
        without a roll-off). Contact-mechanics studies put it at a fraction of the box, e.g.
        ``λ_r = L/4`` with ``long_cutoff = L``.

    Returns
    -------
    Surface
        Zero-mean heights; ``metadata`` records the generator and all parameters.

    Raises
    ------
    InvalidArgumentError (a ``ValueError``)
        ``hurst`` outside (0, 1); ``shape`` < 2 on an axis; both ``rms_height`` and
        ``rms_slope`` given; non-positive values; ``short_cutoff >= long_cutoff``;
        ``rolloff`` above ``long_cutoff`` or not above ``short_cutoff``; a band that contains
        no Fourier mode of the grid.
    ProblemTooLargeError (a ``MemoryError``)
        A grid whose estimated peak memory (:data:`SPECTRAL_BYTES_PER_POINT` bytes per
        point) exceeds :func:`generator_memory_limit`, refused before allocating.
    """
    ny, nx = _check_shape(shape)
    hurst_f = _validate.real(
        "hurst", hurst, low=0.0, high=1.0, low_open=True, high_open=True,
        what="a Hurst exponent in the open interval (0, 1)",
    )
    length_f = _check_positive_finite("length", length)
    seed_i = _check_seed(seed)
    if rms_height is not None and rms_slope is not None:
        raise InvalidArgumentError(
            "rms_height: give either rms_height or rms_slope, not both", argument="rms_height"
        )
    target_height = None
    target_slope = None
    if rms_slope is not None:
        target_slope = _check_positive_finite("rms_slope", rms_slope)
    else:
        target_height = _check_positive_finite(
            "rms_height", 1.0 if rms_height is None else rms_height
        )
    dx = length_f / nx
    try:
        _validate.spacing("dx", dx)
    except InvalidArgumentError:
        raise InvalidArgumentError(
            f"length: {length_f!r} gives a grid spacing dx = length/nx = {dx!r} out of range "
            "(dx² must be a normal double); express lengths in another unit"
        ) from None
    _check_spectral_size(ny, nx)
    lam_long = (
        max(ny, nx) * dx
        if long_cutoff is None
        else _check_positive_finite("long_cutoff", long_cutoff)
    )
    lam_short = (
        2.0 * dx if short_cutoff is None else _check_positive_finite("short_cutoff", short_cutoff)
    )
    if not lam_short < lam_long:
        raise InvalidArgumentError(
            f"short_cutoff: {lam_short!r} must be smaller than long_cutoff ({lam_long!r})"
        )
    lam_roll = lam_long if rolloff is None else _check_positive_finite("rolloff", rolloff)
    if not lam_roll <= lam_long:
        raise InvalidArgumentError(
            f"rolloff: {lam_roll!r} must not exceed long_cutoff ({lam_long!r}"
            + (", the box size" if long_cutoff is None else "")
            + "); the plateau lies between the roll-off and the long cut-off",
            argument="rolloff",
        )
    if not lam_short < lam_roll:
        raise InvalidArgumentError(
            f"rolloff: {lam_roll!r} must be larger than short_cutoff ({lam_short!r}); the "
            "power law lies between the short cut-off and the roll-off",
            argument="rolloff",
        )
    q_long = 2.0 * math.pi / lam_long
    q_short = 2.0 * math.pi / lam_short

    qy = 2.0 * np.pi * np.fft.fftfreq(ny, dx)
    qx = 2.0 * np.pi * np.fft.rfftfreq(nx, dx)
    q = np.hypot(qy[:, None], qx[None, :])
    band = (q >= q_long * (1.0 - 1e-12)) & (q <= q_short * (1.0 + 1e-12))
    if not np.any(band):
        raise InvalidArgumentError(
            f"short_cutoff: no Fourier mode of the {ny}×{nx} grid (dx={dx!r}) lies between "
            f"long_cutoff={lam_long!r} and short_cutoff={lam_short!r}; widen the band"
        )
    amplitude = np.zeros_like(q)
    # The C library's pow on every CPU (numpy's would use SVML on AVX-512 ones).
    amplitude[band] = _elementary.power(q[band], -(1.0 + hurst_f))
    if rolloff is not None:
        q_roll = 2.0 * math.pi / lam_roll
        plateau = band & (q < q_roll * (1.0 - 1e-12))
        amplitude[plateau] = q_roll ** (-(1.0 + hurst_f))

    rng = np.random.default_rng(seed_i)
    white = rng.standard_normal((ny, nx))
    h = np.fft.irfft2(np.fft.rfft2(white) * amplitude, s=(ny, nx))
    h -= h.mean()
    if target_slope is not None:
        current = _moments.rms_slope(h, dx)
        target = target_slope
    else:
        current = float(np.sqrt(np.mean(h * h)))
        target = target_height  # type: ignore[assignment]
    if not current > 0.0:
        raise InvalidArgumentError(
            "short_cutoff: the band-limited surface is flat on this grid (only Nyquist modes "
            "in the band?); widen the band between long_cutoff and short_cutoff"
        )
    h *= target / current
    _check_height_scale(h, "rms_height" if target_slope is None else "rms_slope")
    metadata = {
        "generator": "spectral",
        "shape": [ny, nx],
        "hurst": hurst_f,
        "seed": seed_i,
        "length": length_f,
        "long_cutoff": lam_long,
        "short_cutoff": lam_short,
        "rolloff": lam_roll,
        "rms_height": target_height,
        "rms_slope": target_slope,
        "wavevector": "q = 2*pi/lambda [rad/length]",
    }
    surface = Surface(_Owned(h), dx, metadata, unit)
    check_slope(surface)
    return surface



# ---------------------------------------------------------------------------- registry
def _shape_text(text: str) -> tuple[int, int]:
    """``N`` or ``NYxNX`` (also ``NY,NX``) as a shape."""
    parts = text.lower().replace(",", "x").split("x")
    try:
        dims = [int(p) for p in parts]
    except ValueError:
        raise ValueError(f"expected N or NYxNX, got {text!r}") from None
    if len(dims) == 1:
        return dims[0], dims[0]
    if len(dims) == 2:
        return dims[0], dims[1]
    raise ValueError(f"expected N or NYxNX, got {text!r}")


@dataclass(frozen=True)
class Generator:
    """A surface generator by name: its function and the parameters it takes.

    ``parameters`` maps each parameter (``seed`` excluded) to the converter of its text form
    in a spec; ``required`` are the ones without a default; ``aliases`` are alternative spec
    keys (``n`` for ``spectral``'s ``shape``); ``example`` is a complete spec.
    """

    name: str
    function: Callable[..., Surface]
    parameters: Mapping[str, Callable[[str], Any]]
    required: tuple[str, ...]
    example: str
    aliases: Mapping[str, str] = field(default_factory=dict)

    def __call__(self, params: Mapping[str, Any], seed: int | None) -> Surface:
        """The surface ``function(**params, seed=seed)``."""
        kwargs = dict(params)
        if isinstance(kwargs.get("shape"), list):  # from JSON
            kwargs["shape"] = tuple(kwargs["shape"])
        return self.function(seed=seed, **kwargs)


#: The generators a spec or an ensemble can name.
GENERATORS: dict[str, Generator] = {
    "rmd": Generator(
        "rmd",
        rmd,
        {"m": int, "D": float, "sigma0": float, "length": float},
        ("m", "D"),
        "rmd:m=7,D=2.1,seed=0",
    ),
    "spectral": Generator(
        "spectral",
        spectral,
        {
            "shape": _shape_text,
            "hurst": float,
            "length": float,
            "rms_height": float,
            "rms_slope": float,
            "long_cutoff": float,
            "short_cutoff": float,
            "rolloff": float,
        },
        ("shape", "hurst"),
        "spectral:n=256,hurst=0.8,seed=1",
        aliases={"n": "shape"},
    ),
}


def parse_spec(text: str) -> tuple[str, dict[str, Any], int] | None:
    """Parse a generator spec such as ``rmd:m=8,D=2.3,seed=4`` or
    ``spectral:n=256,hurst=0.8,seed=1,rms_height=1``.

    Returns ``(generator name, parameters, seed)``, or ``None`` when ``text`` does not start
    with a generator's name and a colon (then it names a file). A malformed spec raises
    :class:`~leakpath.errors.InvalidArgumentError` (``argument="surface"``).
    """
    name, sep, rest = text.partition(":")
    gen = GENERATORS.get(name.lower()) if sep else None
    if gen is None:
        return None
    params: dict[str, Any] = {}
    seed: int | None = None
    keys = ", ".join(f"{k}=" for k in (*gen.aliases, *gen.parameters, "seed"))
    given: dict[str, str] = {}  # canonical key -> the item that gave it
    for item in filter(None, (part.strip() for part in rest.split(","))):
        key, eq, value = item.partition("=")
        key = key.strip().replace("-", "_")
        key = gen.aliases.get(key, key)
        if not eq or (key not in gen.parameters and key != "seed"):
            raise InvalidArgumentError(
                f"surface: spec {text!r} has an unknown or malformed item {item!r}; "
                f"{gen.name} takes {keys}",
                argument="surface",
            )
        if key in given:  # never let a later value silently win
            raise InvalidArgumentError(
                f"surface: spec {text!r} gives {key} twice ({given[key]!r} and {item!r}); "
                "give each parameter once",
                argument="surface",
            )
        given[key] = item
        try:
            if key == "seed":
                seed = int(value.strip())
            else:
                params[key] = gen.parameters[key](value.strip())
        except ValueError:
            raise InvalidArgumentError(
                f"surface: spec {text!r} has a bad value for {key}: {value!r}",
                argument="surface",
            ) from None
    missing = [k for k in gen.required if k not in params] + (["seed"] if seed is None else [])
    if missing:
        shown = [next((a for a, t in gen.aliases.items() if t == k), k) for k in missing]
        raise InvalidArgumentError(
            f"surface: spec {text!r} is missing {', '.join(shown)} (e.g. {gen.example})",
            argument="surface",
        )
    return gen.name, params, seed  # type: ignore[return-value]


def generate(name: str, params: Mapping[str, Any], seed: int | None) -> Surface:
    """The surface of generator ``name`` (a key of :data:`GENERATORS`) with ``params``."""
    if name not in GENERATORS:
        raise InvalidArgumentError(
            f"generator: unknown generator {name!r}; choose one of {', '.join(GENERATORS)}",
            argument="generator",
        )
    return GENERATORS[name](params, seed)
