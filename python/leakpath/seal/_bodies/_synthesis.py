"""Realisations of the composite surface ``h = h_upper + h_lower`` on a patch: Gaussian random
surfaces from each body's PSD, or its measured files."""

from __future__ import annotations

import math

import numpy as np

from ... import _validate
from ..._validate import invalid
from ...surfaces import Surface
from ._patch import Patch, _file_grid
from ._roughness import Roughness
from ._spectra import _load_body, _pair, _statistical_psd
from ._types import PSD, FloatArray


def available_realisations(upper: Roughness, lower: Roughness) -> int | None:
    """How many realisations the bodies can give: the number of file pairs (the smaller
    count when both have files), or ``None`` (unlimited) for statistical bodies."""
    counts = [len(r.files) for r in (upper, lower) if r.files is not None]
    return min(counts) if counts else None


def _ring_index(k: np.ndarray) -> np.ndarray:
    """Ring of the integer mode ``k = max(|kx|, |ky|)``: 0 for k ≤ 1, r for 2^(r−1) < k ≤ 2^r."""
    out = np.zeros(k.shape, dtype=np.int64)
    top = int(np.max(k, initial=0))
    r = 1
    while 2 ** (r - 1) < top:
        out[k > 2 ** (r - 1)] = r
        r += 1
    return out


def _mode_noise(key: list[int], kmax_y: int, kmax_x: int) -> np.ndarray:
    """Complex standard normals ``Z[ky, kx]`` (``E|Z|² = 1``) for ``|ky| ≤ kmax_y``,
    ``|kx| ≤ kmax_x``, each mode's value independent of the grid size.

    Modes are grouped in square rings of ``k = max(|kx|, |ky|)`` (ring 0: k ≤ 1; ring r:
    ``2^(r−1) < k ≤ 2^r``); ring r is drawn from ``default_rng(key + [r])`` in row-major order
    over its square ``[−2^r, 2^r]²``: real parts (one call), then imaginary parts. A larger grid
    draws more rings but the same values for the modes both grids have."""
    kmax = max(kmax_y, kmax_x, 1)
    rings = int(_ring_index(np.array([kmax]))[0])
    z = np.zeros((2 * kmax_y + 1, 2 * kmax_x + 1), dtype=np.complex128)
    for r in range(rings + 1):
        half = 2**r
        k = np.arange(-half, half + 1)
        kk = np.maximum(np.abs(k)[:, None], np.abs(k)[None, :])
        mask = _ring_index(kk) == r
        count = int(np.count_nonzero(mask))
        rng = np.random.default_rng([*key, r])
        re = rng.standard_normal(count)
        im = rng.standard_normal(count)
        full = np.zeros(mask.shape, dtype=np.complex128)
        full[mask] = (re + 1j * im) / math.sqrt(2.0)
        # crop the ring's square to the requested rectangle
        cy0, cx0 = half - min(kmax_y, half), half - min(kmax_x, half)
        part = full[cy0 : 2 * half + 1 - cy0, cx0 : 2 * half + 1 - cx0]
        oy, ox = kmax_y - min(kmax_y, half), kmax_x - min(kmax_x, half)
        z[oy : oy + part.shape[0], ox : ox + part.shape[1]] += part
    return z


def _fold(a: np.ndarray, n: int, axis: int) -> np.ndarray:
    """Modes ``k = −K … K`` along ``axis`` (``K = n//2``) onto the ``n`` FFT bins ``k mod n``
    (for even ``n`` the modes ``±n/2`` fall on one bin and add)."""
    kmax = (a.shape[axis] - 1) // 2
    k = np.arange(-kmax, kmax + 1) % n
    out_shape = list(a.shape)
    out_shape[axis] = n
    out = np.zeros(out_shape, dtype=a.dtype)
    if axis == 0:
        np.add.at(out, k, a)
    else:
        np.add.at(out, (slice(None), k), a)
    return out


def _gaussian_surface(psd: PSD, shape: tuple[int, int], dx: float, key: list[int]) -> FloatArray:
    """A periodic Gaussian random surface with isotropic PSD ``psd`` [m⁴] on ``shape`` points of
    spacing ``dx`` [m] (Fourier filtering of white noise):

        h(x) = Re Σ_k a_k Z_k e^{i q_k·x},   a_k = √(2 C(|q_k|) Δq_x Δq_y),

    over the modes ``|kx| ≤ nx/2``, ``|ky| ≤ ny/2`` (``q = 2π k/L`` [rad/m]), ``Z_k`` from
    :func:`_mode_noise`, ``a_0 = 0`` (zero mean). Each mode carries the variance
    ``C(q) Δq_x Δq_y``, so ``E⟨h²⟩ = Σ_k C Δq² ≈ 2π∫ q C dq``. A finer grid of the same side
    keeps every mode's value and adds the ones beyond the coarse Nyquist wavelength.
    """
    ny, nx = shape
    ky_max, kx_max = ny // 2, nx // 2
    ly, lx = ny * dx, nx * dx
    ky = np.arange(-ky_max, ky_max + 1)
    kx = np.arange(-kx_max, kx_max + 1)
    q = np.hypot(2 * math.pi * ky[:, None] / ly, 2 * math.pi * kx[None, :] / lx)
    c = np.asarray(psd(q), dtype=np.float64)
    c[ky_max, kx_max] = 0.0
    amp = np.sqrt(2.0 * c * (2 * math.pi / lx) * (2 * math.pi / ly))
    coeff = amp * _mode_noise(key, ky_max, kx_max)
    spec = _fold(_fold(coeff, ny, 0), nx, 1)
    return np.ascontiguousarray(np.fft.ifft2(spec).real * (ny * nx))


def _stream_keys(
    upper: Roughness, lower: Roughness, seed: int, realisation: int
) -> list[list[int]]:
    """Per-body stream keys: ``[seed, realisation, digest of the body's description (4 words),
    duplicate]`` — a body's noise depends on its own description, not on its position, so
    swapping the bodies gives the identical composite; two identical bodies get duplicates
    0 and 1 (independent)."""
    du, dl = upper._digest(), lower._digest()
    dup = 1 if du == dl else 0
    return [[seed, realisation, *du, 0], [seed, realisation, *dl, dup]]


def composite_surface(
    upper: Roughness,
    lower: Roughness,
    patch: Patch,
    *,
    realisation: int,
    seed: int,
    refine: int = 1,
) -> Surface:
    """Heights [m] of realisation ``realisation`` (0-based) of the composite
    ``h = h_upper + h_lower`` on ``patch``, periodic, zero mean per body.

    Statistical bodies: a Gaussian random surface per body from its own PSD
    (:func:`body_psd`, scaled to that body's own requested rms in expectation — each
    realisation's measured rms scatters about it), drawn from independent streams keyed by
    ``(seed, realisation, body)``. Deterministic in ``(seed, realisation)``. ``refine = 2``
    (a power of two) gives the SAME realisation on a ``refine·n`` grid (``dx/refine``, same
    side): every Fourier mode of the ``refine = 1`` surface keeps its value; the finer grid adds
    only the modes between the two Nyquist wavelengths (if the spectrum has any).

    Files: realisation ``k`` pairs ``upper.files[k]`` with ``lower.files[k]`` (same shape and
    ``dx`` required), each file's mean subtracted; a statistical partner is generated on the
    files' grid; ``refine > 1`` is refused. A flat body contributes 0.
    """
    _pair(upper, lower)
    if not isinstance(patch, Patch):
        raise invalid("patch", f"must be a Patch, got {_validate.describe(patch)}")
    k = _validate.integer("realisation", realisation)
    seed_i = _validate.integer("seed", seed, high=2**63 - 1)
    ref = _validate.integer("refine", refine, low=1, high=64)
    if not (ref & (ref - 1) == 0):
        raise invalid("refine", f"must be a power of two (1, 2, 4 …), got {ref}")
    if upper.flat and lower.flat:
        raise invalid("surface", "both bodies are smooth; give at least one rough surface")
    files = upper.files is not None or lower.files is not None
    available = available_realisations(upper, lower)
    if files:
        if ref != 1:
            raise invalid("refine", "measured files have a fixed grid; refine > 1 is refused for "
                        "files (use refine = 1)")
        if k >= available:  # type: ignore[operator]
            raise invalid(
                "realisation",
                f"{k} needs file pair {k}, but only {available} are given (0 … {available - 1})",  # type: ignore[operator]
            )
        shape, dx = _file_grid(upper, lower, k)
        if not math.isclose(dx, patch.dx, rel_tol=1e-9):
            raise invalid("patch", f"dx = {patch.dx!r} m differs from the files' {dx!r} m; use "
                        "choose_patch for measured files")
    else:
        shape, dx = (patch.n * ref, patch.n * ref), patch.length / (patch.n * ref)
    keys = _stream_keys(upper, lower, seed_i, k)
    parts = []
    for r, key in zip((upper, lower), keys, strict=True):
        if r.flat:
            parts.append(np.zeros(shape))
        elif r.files is not None:
            parts.append(np.asarray(_load_body(r, k).heights))
        else:
            law = _statistical_psd(r, patch.length)
            parts.append(_gaussian_surface(law, shape, dx, key))
    heights = parts[0] + parts[1]
    metadata = {
        "generator": "leakpath.seal composite",
        "seed": seed_i,
        "realisation": k,
        "refine": ref,
        "patch_rule": patch.rule,
        "upper": upper.kind,
        "lower": lower.kind,
        "wavevector": "q = 2*pi/lambda [rad/m]",
    }
    if files:
        metadata["files"] = [r.files[k] for r in (upper, lower) if r.files is not None]  # type: ignore[index]
    return Surface(heights, dx, metadata, unit="m")  # SI, as every seal input
