"""Temporary stand-ins for leakpath.seal._bodies / _theory / _estimate (INTERFACE.md), used by
tests/test_seal_workflow.py only while those modules are not merged yet. Crude on purpose."""

from __future__ import annotations

import math
import sys
import types
from dataclasses import dataclass

import numpy as np

import leakpath


@dataclass(frozen=True)
class Material:
    E: float  # noqa: N815
    nu: float


def contact_modulus_pair(upper, lower):
    c = sum(0.0 if math.isinf(m.E) else (1 - m.nu**2) / m.E for m in (upper, lower))
    return 1.0 / c


@dataclass(frozen=True)
class Roughness:
    hurst: float | None = None
    rms_height: float | None = None
    rms_slope: float | None = None
    rolloff_wavelength: float | None = None
    short_wavelength: float | None = None
    psd: tuple | None = None
    files: tuple | None = None
    dx: float | None = None
    flat: bool = False

    @classmethod
    def smooth(cls):
        return cls(flat=True)


@dataclass(frozen=True)
class Patch:
    n: int
    length: float
    dx: float
    rule: str


def choose_patch(upper, lower, *, n=None, length=None, **_):
    for b in (upper, lower):
        if b.files:
            h = leakpath.load(b.files[0], dx=b.dx)
            return Patch(h.shape[0], h.shape[0] * h.dx, h.dx, "files")
    rough = upper if not upper.flat else lower
    n = n or 64
    length = length or 4 * rough.rolloff_wavelength
    return Patch(n, length, length / n, "stand-in")


def validity_warnings(upper, lower, patch):
    return []


def _body(b, patch, realisation, seed, refine, salt):
    n = patch.n * refine
    if b.flat:
        return np.zeros((n, n))
    if b.files:
        return leakpath.load(b.files[realisation], dx=b.dx).heights
    return leakpath.spectral(
        n, b.hurst, seed=seed * 1000 + realisation * 2 + salt, length=patch.length,
        rms_height=b.rms_height, rms_slope=b.rms_slope, long_cutoff=b.rolloff_wavelength,
        short_cutoff=b.short_wavelength).heights


def composite_surface(upper, lower, patch, *, realisation, seed, refine=1):
    h = _body(upper, patch, realisation, seed, refine, 0) + _body(
        lower, patch, realisation, seed, refine, 1)
    return leakpath.Surface(h, patch.dx / refine)


def composite_rms_slope(upper, lower):
    p = choose_patch(upper, lower)
    return leakpath.rms_slope(composite_surface(upper, lower, p, realisation=0, seed=0))


def persson_contact_fraction(mean_pressure, E_star, rms_slope):  # noqa: N803
    from scipy.special import erf

    return erf(np.sqrt(2.0) * np.asarray(mean_pressure) / (E_star * rms_slope))


def bruggeman_permeability(gap, dx, *, axis=0):
    k = np.asarray(gap, float).ravel() ** 3 / 12
    if not np.any(k > 0):
        return 0.0
    lo, hi = 1e-300, k.max()
    f = lambda ke: np.sum((k - ke) / (k + ke))  # noqa: E731
    if f(lo) <= 0:
        return 0.0
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if f(mid) > 0 else (lo, mid)
    return float(hi)


@dataclass(frozen=True)
class PermeabilityEstimate:
    value: float
    low: float
    high: float
    arithmetic: float
    harmonic: float
    geometric: float
    n: int
    n_leaking: int
    leak_fraction: float
    method: str


def effective_permeability(k, *, confidence=0.95, seed=0):
    k = np.asarray(k, float)
    pos = k > 0
    geo = float(np.exp(np.mean(np.log(k)))) if np.all(pos) else 0.0
    harm = float(1 / np.mean(1 / k)) if np.all(pos) else 0.0
    return PermeabilityEstimate(geo, harm, float(k.mean()), float(k.mean()), harm, geo,
                                k.size, int(pos.sum()), float(pos.mean()), "stand-in")


def liquid_leak_rate(k_eff, *, width, length, viscosity, pressure_drop):
    return k_eff * width / length * pressure_drop / viscosity


def gas_mass_flow(k_eff, *, width, length, viscosity, inlet_pressure, outlet_pressure,
                  gas_constant, temperature):
    return (k_eff * width / length * (inlet_pressure**2 - outlet_pressure**2)
            / (2 * viscosity * gas_constant * temperature))


def install() -> bool:
    """Put the stand-ins in place of modules that do not exist yet; True if any was."""
    import leakpath.seal as pkg

    used = False
    me = sys.modules[__name__]
    for name in ("_bodies", "_theory", "_estimate"):
        try:
            __import__(f"leakpath.seal.{name}")
        except ImportError:
            mod = types.ModuleType(f"leakpath.seal.{name}")
            mod.__dict__.update({k: v for k, v in vars(me).items() if not k.startswith("__")})
            sys.modules[f"leakpath.seal.{name}"] = mod
            setattr(pkg, name, mod)
            used = True
    return used
