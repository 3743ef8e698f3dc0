"""One body's roughness: its description (statistics, a tabulated PSD, measured files or flat)
and its checks."""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ... import _validate
from ..._validate import invalid
from ._types import FloatArray


def _psd_table(name: str, value: Any) -> tuple[FloatArray, FloatArray]:
    arg = f"{name}.psd"
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise invalid(arg, "must be a pair (q [rad/m], C [m^4]) of 1-D arrays")
    q = _validate.real_array(arg, value[0], ndim=1)
    c = _validate.real_array(arg, value[1], ndim=1)
    if q.shape != c.shape or q.size < 2:
        raise invalid(
            arg, f"q and C must have the same length, at least 2; got {q.size} and {c.size}"
        )
    if not (np.all(q > 0) and np.all(np.diff(q) > 0)):
        raise invalid(arg, "q must be positive and strictly increasing [rad/m]")
    if not np.all(c > 0):
        raise invalid(
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
            raise invalid("name", f"must be a string, got {_validate.describe(name)}")
        flat = _validate.flag(f"{name}.flat", self.flat)
        object.__setattr__(self, "flat", flat)
        stats = ("hurst", "rms_height", "rms_slope", "rolloff_wavelength", "short_wavelength")
        given = [k for k in (*stats, "psd", "files", "dx") if getattr(self, k) is not None]
        if flat:
            if given:
                raise invalid(
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
            raise invalid(f"{name}.rms_height", "give either rms_height or rms_slope, not both")
        if self.files is not None:
            self._check_files(stats)
            return
        if self.dx is not None:
            raise invalid(
                f"{name}.dx", "is the spacing of measured files; without files the grid comes "
                "from the patch (give n or length to the patch instead)",
            )
        if self.psd is not None:
            for key in ("hurst", "rolloff_wavelength", "short_wavelength"):
                if getattr(self, key) is not None:
                    raise invalid(
                        f"{name}.{key}",
                        "a tabulated psd fixes the spectrum's shape and cut-offs; drop this key",
                    )
            object.__setattr__(self, "psd", _psd_table(name, self.psd))
            return
        if self.hurst is None and self.rms_height is None and self.rms_slope is None:
            raise invalid(
                name,
                "no roughness given; give hurst, short_wavelength and rms_height or rms_slope "
                "(optionally rolloff_wavelength), or psd, or files, or flat = true",
            )
        if self.hurst is None:
            raise invalid(f"{name}.hurst", "required with rms_height/rms_slope: give 0 < H < 1")
        object.__setattr__(
            self, "hurst",
            _validate.real(f"{name}.hurst", self.hurst, low=0.0, high=1.0, low_open=True,
                           high_open=True, what="a Hurst exponent in the open interval (0, 1)"),
        )
        if self.rms_height is None and self.rms_slope is None:
            raise invalid(f"{name}.rms_height", "give rms_height [m] or rms_slope [-]")
        if self.short_wavelength is None:
            raise invalid(
                f"{name}.short_wavelength",
                "required: the shortest wavelength of the roughness [m] (the rms slope of a "
                "self-affine surface depends on it)",
            )
        if self.rolloff_wavelength is not None and not (
            self.rolloff_wavelength > self.short_wavelength
        ):
            raise invalid(
                f"{name}.rolloff_wavelength",
                f"{self.rolloff_wavelength!r} m must exceed short_wavelength "
                f"({self.short_wavelength!r} m)",
            )

    def _check_files(self, stats: tuple[str, ...]) -> None:
        name = self.name
        for key in (*stats, "psd"):
            if getattr(self, key) is not None:
                raise invalid(
                    f"{name}.{key}",
                    "measured files carry their own statistics; drop this key or the files",
                )
        files = self.files
        if isinstance(files, (str, bytes, os.PathLike)):
            files = (files,)  # type: ignore[assignment]
        if not isinstance(files, Sequence) or len(files) == 0:
            raise invalid(f"{name}.files", "must be a non-empty list of paths, one per realisation")
        out = []
        for f in files:
            if not isinstance(f, (str, os.PathLike)):
                raise invalid(f"{name}.files", f"must hold paths, got {_validate.describe(f)}")
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
