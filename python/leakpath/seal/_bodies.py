"""Two rough elastic bodies as one composite rough surface against a rigid flat.

The mapping (Johnson, *Contact Mechanics*, 1985, §4.2 and §13.1; derivation in
``docs/seal-bodies.md``): two elastic half-spaces with small surface slopes, pressed together
without friction, touch exactly like a rigid flat pressed on an elastic half-space with

* the **composite** roughness ``h = h_upper + h_lower`` [m], each body's heights measured from
  its own mean plane towards the other body, and
* the **contact modulus** ``E* = [(1 − ν₁²)/E₁ + (1 − ν₂²)/E₂]⁻¹`` [Pa].

For independent random surfaces the power spectral densities add, ``C = C_upper + C_lower``
[m⁴]. The PSD convention (Persson, J. Phys.: Condens. Matter 18, 7789 (2006); Jacobs, Junge &
Pastewka, Surf. Topogr.: Metrol. Prop. 5, 013001 (2017)) is the isotropic 2-D one with angular
wavevectors ``q = 2π/λ`` [rad/m] (``docs/surfaces.md``):

    ⟨h²⟩ = ∫ d²q C(q) = 2π ∫ q C(q) dq,     ⟨|∇h|²⟩ = 2π ∫ q³ C(q) dq.

Public names (re-exported by :mod:`leakpath.seal`): :class:`Material`,
:func:`contact_modulus_pair`, :class:`Roughness`, :func:`composite_psd`,
:func:`composite_rms_slope`, :func:`composite_rms_height`, :class:`Patch`,
:func:`choose_patch`, :func:`validity_warnings`, :func:`composite_surface`, and the helpers
:func:`body_psd`, :func:`available_realisations`.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import _validate
from ..errors import InvalidArgumentError
from ..moments import rms_slope as _fd_rms_slope
from ..surfaces import Surface, load

__all__ = [
    "MAX_RMS_SLOPE",
    "MIN_POINTS_PER_SHORT_WAVELENGTH",
    "MIN_ROLLOFFS_PER_PATCH",
    "Material",
    "Patch",
    "Roughness",
    "available_realisations",
    "body_psd",
    "choose_patch",
    "composite_psd",
    "composite_rms_height",
    "composite_rms_slope",
    "composite_surface",
    "contact_modulus_pair",
    "validity_warnings",
]

FloatArray = npt.NDArray[np.float64]
PSD = Callable[[npt.ArrayLike], FloatArray]

#: Validity limits checked by :func:`validity_warnings` (``docs/seal-bodies.md``).
#: Small-slope (half-space) theory: composite rms slope at most this.
MAX_RMS_SLOPE = 0.3
#: The shortest wavelength of the spectrum needs at least this many grid points.
MIN_POINTS_PER_SHORT_WAVELENGTH = 4.0
#: The patch side must hold at least this many roll-off wavelengths.
MIN_ROLLOFFS_PER_PATCH = 2.0

#: Relative tolerance of band edges (as in :func:`leakpath.spectral`).
_EDGE = 1e-12


def _fail(argument: str, message: str) -> InvalidArgumentError:
    return InvalidArgumentError(f"{argument}: {message}", argument=argument)


# ============================================================================ materials
@dataclass(frozen=True)
class Material:
    """One elastic body: Young's modulus ``E`` [Pa] (``math.inf`` for a rigid body) and
    Poisson's ratio ``ν``, ``−1 < ν ≤ 0.5`` (0.5: incompressible, e.g. rubber).

    ``name`` only prefixes error messages (``"material.upper"`` → ``material.upper.E: …``).
    """

    E: float
    nu: float
    name: str = field(default="material", compare=False, repr=False)

    def __post_init__(self) -> None:
        e = _validate._scalar(self.E)
        if _validate._is_real(e) and float(e) == math.inf:
            e_f = math.inf
        else:
            e_f = _validate.real(
                f"{self.name}.E", e, low=0.0, low_open=True,
                what="a positive Young's modulus in Pa (math.inf for a rigid body)",
            )
        nu_f = _validate.real(
            f"{self.name}.nu", self.nu, low=-1.0, high=0.5, low_open=True,
            what="a Poisson's ratio in (-1, 0.5]",
        )
        object.__setattr__(self, "E", e_f)
        object.__setattr__(self, "nu", nu_f)

    @property
    def rigid(self) -> bool:
        """True for ``E = ∞``."""
        return self.E == math.inf

    @property
    def compliance(self) -> float:
        """``(1 − ν²)/E`` [1/Pa]; 0 for a rigid body."""
        return 0.0 if self.rigid else (1.0 - self.nu * self.nu) / self.E


def contact_modulus_pair(upper: Material, lower: Material) -> float:
    """Contact modulus of two elastic half-spaces [Pa] (Johnson, *Contact Mechanics*, eq. 4.22):

        E* = [(1 − ν₁²)/E₁ + (1 − ν₂²)/E₂]⁻¹

    A rigid body (``E = math.inf``) contributes no compliance, so a rubber on rigid steel gives
    ``E* = E_rubber/(1 − ν²)``. Symmetric in the two bodies. Two rigid bodies are refused
    (there is no elastic contact to solve).
    """
    for name, m in (("upper", upper), ("lower", lower)):
        if not isinstance(m, Material):
            raise _fail(f"material.{name}", f"must be a Material(E=..., nu=...), got {m!r}")
    compliance = upper.compliance + lower.compliance
    if compliance == 0.0:
        raise _fail(
            "material",
            "both bodies are rigid (E = inf); at least one must be elastic (give a finite E)",
        )
    e_star = 1.0 / compliance
    if not (sys.float_info.min <= e_star < math.inf):
        raise _fail(
            "material",
            f"the contact modulus E* = {e_star!r} Pa is outside the floating-point range; "
            "check the units of E (Pa)",
        )
    return e_star


# ============================================================================ roughness
def _psd_table(name: str, value: Any) -> tuple[FloatArray, FloatArray]:
    arg = f"{name}.psd"
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise _fail(arg, "must be a pair (q [rad/m], C [m^4]) of 1-D arrays")
    q = _validate.real_array(arg, value[0], ndim=1)
    c = _validate.real_array(arg, value[1], ndim=1)
    if q.shape != c.shape or q.size < 2:
        raise _fail(
            arg, f"q and C must have the same length, at least 2; got {q.size} and {c.size}"
        )
    if not (np.all(q > 0) and np.all(np.diff(q) > 0)):
        raise _fail(arg, "q must be positive and strictly increasing [rad/m]")
    if not np.all(c > 0):
        raise _fail(
            arg, "C must be positive (it is interpolated log-log); drop zero entries — the "
            "spectrum is taken as 0 beyond the table's largest q",
        )
    q.setflags(write=False)
    c.setflags(write=False)
    return q, c


@dataclass(frozen=True, eq=False)
class Roughness:
    """One body's surface; heights [m] from its own mean plane towards the other body.

    Exactly one of four descriptions:

    * **statistics**: ``hurst`` ``H`` in (0, 1), ``short_wavelength`` ``λ_s`` [m], exactly one of
      ``rms_height`` [m] or ``rms_slope`` [-], and optionally ``rolloff_wavelength`` ``λ_r`` [m]
      (> ``λ_s``). The PSD is Persson's self-affine spectrum with roll-off::

          C(q) = C0                          0 < q < q_r = 2π/λ_r
          C(q) = C0 (q/q_r)^(−2(1+H))        q_r ≤ q ≤ q_s = 2π/λ_s
          C(q) = 0                           q > q_s

      with ``C0`` [m⁴] set by the requested rms of **this body** over the whole spectrum
      (``0 < q ≤ q_s``). Without a roll-off the spectrum is self-affine down to the patch's
      lowest mode ``q_L = 2π/L`` and zero below it, so its statistics depend on the patch
      side ``L`` (functions then need ``length``).
    * **tabulated**: ``psd = (q [rad/m], C [m⁴])``, interpolated log-log, flat below the
      table's first ``q`` (a roll-off at ``λ_r = 2π/q[0]``), zero above its last
      (``λ_s = 2π/q[-1]``); ``rms_height`` or ``rms_slope`` optionally rescales it.
    * **files**: measured topographies, one per realisation, read by :func:`leakpath.load`
      (``dx`` [m] when the file stores none); each file's mean is subtracted.
    * **flat**: a smooth body (:meth:`smooth`), contributing no roughness.

    ``name`` (not part of equality) prefixes error messages, e.g. ``"surface.upper"`` gives
    ``surface.upper.rms_height: …``, the config key.
    """

    hurst: float | None = None
    rms_height: float | None = None
    rms_slope: float | None = None
    rolloff_wavelength: float | None = None
    short_wavelength: float | None = None
    psd: tuple[np.ndarray, np.ndarray] | None = None
    files: tuple[str, ...] | None = None
    dx: float | None = None
    flat: bool = False
    name: str = field(default="surface", repr=False)

    @classmethod
    def smooth(cls, name: str = "surface") -> Roughness:
        """A smooth (flat) body."""
        return cls(flat=True, name=name)

    # ------------------------------------------------------------------ validation
    def __post_init__(self) -> None:
        name = self.name
        if not isinstance(name, str):
            raise _fail("name", f"must be a string, got {_validate.describe(name)}")
        flat = _validate.flag(f"{name}.flat", self.flat)
        object.__setattr__(self, "flat", flat)
        stats = ("hurst", "rms_height", "rms_slope", "rolloff_wavelength", "short_wavelength")
        given = [k for k in (*stats, "psd", "files", "dx") if getattr(self, k) is not None]
        if flat:
            if given:
                raise _fail(
                    f"{name}.{given[0]}",
                    "a flat (smooth) body has no roughness; drop this key or set flat = false",
                )
            return
        for key in ("rms_height", "rolloff_wavelength", "short_wavelength", "dx"):
            value = getattr(self, key)
            if value is not None:
                object.__setattr__(
                    self, key, _validate.positive(f"{name}.{key}", value, what="a positive "
                                                  "length in m")
                )
        if self.rms_slope is not None:
            object.__setattr__(
                self, "rms_slope",
                _validate.positive(f"{name}.rms_slope", self.rms_slope, what="a positive "
                                   "dimensionless rms slope"),
            )
        if self.rms_height is not None and self.rms_slope is not None:
            raise _fail(f"{name}.rms_height", "give either rms_height or rms_slope, not both")
        if self.files is not None:
            self._check_files(stats)
            return
        if self.dx is not None:
            raise _fail(
                f"{name}.dx", "is the spacing of measured files; without files the grid comes "
                "from the patch (give n or length to the patch instead)",
            )
        if self.psd is not None:
            for key in ("hurst", "rolloff_wavelength", "short_wavelength"):
                if getattr(self, key) is not None:
                    raise _fail(
                        f"{name}.{key}",
                        "a tabulated psd fixes the spectrum's shape and cut-offs; drop this key",
                    )
            object.__setattr__(self, "psd", _psd_table(name, self.psd))
            return
        if self.hurst is None and self.rms_height is None and self.rms_slope is None:
            raise _fail(
                name,
                "no roughness given; give hurst, short_wavelength and rms_height or rms_slope "
                "(optionally rolloff_wavelength), or psd, or files, or flat = true",
            )
        if self.hurst is None:
            raise _fail(f"{name}.hurst", "required with rms_height/rms_slope: give 0 < H < 1")
        object.__setattr__(
            self, "hurst",
            _validate.real(f"{name}.hurst", self.hurst, low=0.0, high=1.0, low_open=True,
                           high_open=True, what="a Hurst exponent in the open interval (0, 1)"),
        )
        if self.rms_height is None and self.rms_slope is None:
            raise _fail(f"{name}.rms_height", "give rms_height [m] or rms_slope [-]")
        if self.short_wavelength is None:
            raise _fail(
                f"{name}.short_wavelength",
                "required: the shortest wavelength of the roughness [m] (the rms slope of a "
                "self-affine surface depends on it)",
            )
        if self.rolloff_wavelength is not None and not (
            self.rolloff_wavelength > self.short_wavelength
        ):
            raise _fail(
                f"{name}.rolloff_wavelength",
                f"{self.rolloff_wavelength!r} m must exceed short_wavelength "
                f"({self.short_wavelength!r} m)",
            )

    def _check_files(self, stats: tuple[str, ...]) -> None:
        name = self.name
        for key in (*stats, "psd"):
            if getattr(self, key) is not None:
                raise _fail(
                    f"{name}.{key}",
                    "measured files carry their own statistics; drop this key or the files",
                )
        files = self.files
        if isinstance(files, (str, bytes, os.PathLike)):
            files = (files,)  # type: ignore[assignment]
        if not isinstance(files, Sequence) or len(files) == 0:
            raise _fail(f"{name}.files", "must be a non-empty list of paths, one per realisation")
        out = []
        for f in files:
            if not isinstance(f, (str, os.PathLike)):
                raise _fail(f"{name}.files", f"must hold paths, got {_validate.describe(f)}")
            out.append(os.fspath(f))
        object.__setattr__(self, "files", tuple(out))

    # ------------------------------------------------------------------ identity
    def _key(self) -> tuple[Any, ...]:
        psd = None
        if self.psd is not None:
            psd = (self.psd[0].tobytes().hex(), self.psd[1].tobytes().hex())
        return (self.hurst, self.rms_height, self.rms_slope, self.rolloff_wavelength,
                self.short_wavelength, psd, self.files, self.dx, self.flat)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Roughness):
            return NotImplemented
        return self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def _digest(self) -> list[int]:
        """Four 32-bit words of the SHA-256 of the description (stable across runs)."""
        text = json.dumps(self._key(), default=repr)
        d = hashlib.sha256(text.encode()).digest()
        return [int.from_bytes(d[4 * i : 4 * i + 4], "little") for i in range(4)]

    @property
    def kind(self) -> str:
        """``"flat"``, ``"files"``, ``"psd"`` or ``"statistics"``."""
        if self.flat:
            return "flat"
        if self.files is not None:
            return "files"
        return "psd" if self.psd is not None else "statistics"


# ============================================================================ spectra
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
        out[band] = np.exp(np.interp(np.log(qb), np.log(self.q), np.log(self.c)))
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
        raise _fail(
            "length",
            f"{r.name} has no rolloff_wavelength, so its spectrum runs down to the patch's "
            "lowest mode 2π/L and its statistics depend on the patch side L; pass length=L [m] "
            "(e.g. patch.length) or give rolloff_wavelength",
        )
    length_f = _validate.positive("length", length, what="a positive patch side in m")
    if not 2.0 * math.pi / length_f < 2.0 * math.pi / r.short_wavelength:  # type: ignore[operator]
        raise _fail(
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
            raise _fail(name, f"must be a Roughness, got {_validate.describe(r)}")


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


# ============================================================================ patch
@dataclass(frozen=True)
class Patch:
    """A square periodic patch: ``n`` points per side, side ``length`` [m], ``dx = length/n``
    [m]; ``rule`` says how it was chosen (for metadata)."""

    n: int
    length: float
    dx: float
    rule: str

    def __post_init__(self) -> None:
        n = _validate.integer("patch.n", self.n, low=2)
        length = _validate.positive("patch.length", self.length, what="a positive side in m")
        dx = _validate.spacing("patch.dx", self.dx)
        if not math.isclose(dx * n, length, rel_tol=1e-9):
            raise _fail("patch.dx", f"{dx!r} m must equal length/n = {length / n!r} m")
        object.__setattr__(self, "n", n)
        object.__setattr__(self, "length", length)
        object.__setattr__(self, "dx", dx)
        object.__setattr__(self, "rule", str(self.rule))


def _scales(r: Roughness) -> tuple[float | None, float | None]:
    """``(λ_r, λ_s)`` [m] of a statistics/psd body (``λ_r`` None without roll-off)."""
    if r.psd is not None:
        return 2.0 * math.pi / float(r.psd[0][0]), 2.0 * math.pi / float(r.psd[0][-1])
    return r.rolloff_wavelength, r.short_wavelength


def _file_grid(upper: Roughness, lower: Roughness, k: int = 0) -> tuple[tuple[int, int], float]:
    grids = []
    for r in (upper, lower):
        if r.files is not None:
            s = load(r.files[k], dx=r.dx)
            grids.append((r, s.shape, s.dx))
    (r0, shape0, dx0) = grids[0]
    for r, shape, dx in grids[1:]:
        if shape != shape0 or not math.isclose(dx, dx0, rel_tol=1e-12):
            raise _fail(
                f"{r.name}.files",
                f"realisation {k}: {r.files[k]!r} is {shape[0]}×{shape[1]} with dx={dx!r} m but "
                f"{r0.files[k]!r} is {shape0[0]}×{shape0[1]} with dx={dx0!r} m; paired files "
                "need the same shape and spacing",
            )
    return shape0, dx0


def _is_pow2(n: int) -> bool:
    return n >= 2 and n & (n - 1) == 0


def choose_patch(
    upper: Roughness,
    lower: Roughness,
    *,
    n: int | None = None,
    length: float | None = None,
    points_per_short_wavelength: float = 4.0,
    rolloffs_per_patch: float = 4.0,
    max_n: int = 1024,
) -> Patch:
    """Grid and patch for the composite (rules in ``docs/seal-bodies.md``; Yastrebov et al.,
    Tribol. Lett. 65, 2017 and Müser et al., Tribol. Lett. 65:118, 2017):

    1. resolution: ``dx ≤ λ_s / points_per_short_wavelength`` with ``λ_s`` the shortest
       short-wavelength cut-off of the two bodies;
    2. size: ``L ≥ rolloffs_per_patch · λ_r`` with ``λ_r`` the longest roll-off wavelength
       (a self-affine spectrum without roll-off has no largest scale: ``length`` is then
       required);
    3. ``n`` = the smallest power of two with ``n·dx ≥ L`` (``dx`` kept, ``L = n·dx``);
    4. capped at ``max_n``: the resolution is kept and the patch shrunk to ``max_n·dx`` (fewer
       roll-offs per patch, which more realisations partly make up for; a coarser grid would
       bias every realisation the same way). ``rule`` says what was given up.

    ``n`` and/or ``length`` [m] override the rules (``n`` a power of two ≤ ``max_n``; with
    ``length`` alone ``n`` follows from rule 1 and ``dx = length/n``). Measured files fix the
    grid: ``n = nx``, ``dx`` from the files (non-square files keep their shape; ``Patch.n`` is
    then the number of columns), and ``n``/``length`` may only repeat them.
    """
    _pair(upper, lower)
    pps = _validate.positive("points_per_short_wavelength", points_per_short_wavelength)
    rpp = _validate.positive("rolloffs_per_patch", rolloffs_per_patch)
    max_n_i = _validate.integer("max_n", max_n, low=2)
    n_i = _validate.optional_integer("n", n, low=2)
    length_f = None if length is None else _validate.positive(
        "length", length, what="a positive patch side in m"
    )
    if upper.flat and lower.flat:
        raise _fail("surface", "both bodies are smooth; give at least one rough surface")

    if upper.files is not None or lower.files is not None:
        (ny, nx), dx = _file_grid(upper, lower)
        if n_i is not None and n_i != nx:
            raise _fail("n", f"{n_i} differs from the files' {nx} columns; drop n")
        if length_f is not None and not math.isclose(length_f, nx * dx, rel_tol=1e-9):
            raise _fail("length", f"{length_f!r} m differs from the files' {nx * dx!r} m")
        return Patch(nx, nx * dx, dx, f"from the files: {ny}×{nx} points, dx = {dx:.6g} m")

    bodies = [r for r in (upper, lower) if not r.flat]
    shorts = [_scales(r)[1] for r in bodies]
    rolls = [s for s in (_scales(r)[0] for r in bodies) if s is not None]
    lam_s = min(shorts)  # type: ignore[type-var]
    lam_r = max(rolls) if rolls else None
    dx_rule = lam_s / pps  # type: ignore[operator]

    if n_i is not None:
        if not _is_pow2(n_i):
            raise _fail("n", f"must be a power of two (refinement doubles it), got {n_i}")
        if n_i > max_n_i:
            raise _fail("n", f"{n_i} exceeds max_n = {max_n_i}; raise max_n or lower n")
        if length_f is not None:
            return Patch(
                n_i, length_f, length_f / n_i, f"given: n = {n_i}, length = {length_f:.6g} m"
            )
        return Patch(n_i, n_i * dx_rule, dx_rule,
                     f"given n = {n_i}; dx = λ_s/{pps:g} = {dx_rule:.6g} m (λ_s = {lam_s:.6g} m)")
    if length_f is not None:
        need = max(2, 2 ** math.ceil(math.log2(max(length_f / dx_rule, 2.0) * (1 - 1e-12))))
        if need > max_n_i:
            raise _fail(
                "length",
                f"{length_f:.6g} m at dx ≤ λ_s/{pps:g} = {dx_rule:.6g} m needs n = {need} > "
                f"max_n = {max_n_i}; raise max_n, lower points_per_short_wavelength or give n",
            )
        return Patch(need, length_f, length_f / need,
                     f"given length = {length_f:.6g} m; n = {need} for dx ≤ λ_s/{pps:g}")
    if lam_r is None:
        raise _fail(
            "length",
            "no body has a roll-off wavelength: a self-affine spectrum without roll-off has no "
            "largest scale to size the patch by; give rolloff_wavelength or the patch length",
        )
    want = rpp * lam_r
    need = max(2, 2 ** math.ceil(math.log2(max(want / dx_rule, 2.0) * (1 - 1e-12))))
    rule = (f"dx = λ_s/{pps:g} = {dx_rule:.6g} m (λ_s = {lam_s:.6g} m); "
            f"L ≥ {rpp:g}·λ_r = {want:.6g} m (λ_r = {lam_r:.6g} m); n = {need} (power of two)")
    if need > max_n_i:
        # Keep a power of two: the largest one ≤ max_n.
        n_cap = 2 ** int(math.floor(math.log2(max_n_i)))
        got = n_cap * dx_rule / lam_r
        rule += (f"; capped at max_n = {max_n_i}: n = {n_cap}, kept dx and gave up patch size: "
                 f"L = {n_cap * dx_rule:.6g} m holds {got:.3g} roll-off wavelengths instead of "
                 f"{rpp:g}")
        need = n_cap
    return Patch(need, need * dx_rule, dx_rule, rule)


def validity_warnings(upper: Roughness, lower: Roughness, patch: Patch) -> list[str]:
    """Messages for inputs outside the method's validity (empty when fine):

    * composite rms slope > :data:`MAX_RMS_SLOPE` (0.3): the small-slope half-space theory
      behind the composite mapping and the boundary-element kernel degrades;
    * a short-wavelength cut-off resolved by fewer than
      :data:`MIN_POINTS_PER_SHORT_WAVELENGTH` (4) points, ``λ_s/dx < 4``;
    * a patch smaller than :data:`MIN_ROLLOFFS_PER_PATCH` (2) roll-off wavelengths,
      ``L < 2 λ_r`` (a patch is then not representative of the surface).
    """
    _pair(upper, lower)
    if not isinstance(patch, Patch):
        raise _fail("patch", f"must be a Patch, got {_validate.describe(patch)}")
    out: list[str] = []
    slope = composite_rms_slope(upper, lower, length=patch.length)
    if slope > MAX_RMS_SLOPE:
        out.append(
            f"composite rms slope {slope:.3g} exceeds {MAX_RMS_SLOPE:g}: the small-slope "
            "(half-space) contact theory behind the two-body mapping is outside its validity"
        )
    for r in (upper, lower):
        if r.flat or r.files is not None:
            continue
        lam_r, lam_s = _scales(r)
        pts = lam_s / patch.dx  # type: ignore[operator]
        if pts < MIN_POINTS_PER_SHORT_WAVELENGTH * (1 - 1e-12):
            out.append(
                f"{r.name}: short wavelength {lam_s:.6g} m is resolved by {pts:.3g} grid points "
                f"(dx = {patch.dx:.6g} m), fewer than {MIN_POINTS_PER_SHORT_WAVELENGTH:g}; "
                "contact area and gaps are then grid-dependent"
            )
        if lam_r is not None and patch.length < MIN_ROLLOFFS_PER_PATCH * lam_r * (1 - 1e-12):
            out.append(
                f"{r.name}: patch side {patch.length:.6g} m is smaller than "
                f"{MIN_ROLLOFFS_PER_PATCH:g} roll-off wavelengths ({lam_r:.6g} m); a patch is "
                "then not representative of the surface"
            )
    return out


# ============================================================================ surfaces
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
        raise _fail("patch", f"must be a Patch, got {_validate.describe(patch)}")
    k = _validate.integer("realisation", realisation)
    seed_i = _validate.integer("seed", seed, high=2**63 - 1)
    ref = _validate.integer("refine", refine, low=1, high=64)
    if not (ref & (ref - 1) == 0):
        raise _fail("refine", f"must be a power of two (1, 2, 4 …), got {ref}")
    if upper.flat and lower.flat:
        raise _fail("surface", "both bodies are smooth; give at least one rough surface")
    files = upper.files is not None or lower.files is not None
    available = available_realisations(upper, lower)
    if files:
        if ref != 1:
            raise _fail("refine", "measured files have a fixed grid; refine > 1 is refused for "
                        "files (use refine = 1)")
        if k >= available:  # type: ignore[operator]
            raise _fail(
                "realisation",
                f"{k} needs file pair {k}, but only {available} are given (0 … {available - 1})",  # type: ignore[operator]
            )
        shape, dx = _file_grid(upper, lower, k)
        if not math.isclose(dx, patch.dx, rel_tol=1e-9):
            raise _fail("patch", f"dx = {patch.dx!r} m differs from the files' {dx!r} m; use "
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
