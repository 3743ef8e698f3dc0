"""The seal workflow's configuration: typed, frozen, built from a dict, a TOML file or directly.

Every input is in SI units (m, Pa, Pa·s, J/(kg·K), K). Every key is checked when the
configuration is built; a bad or unknown key raises
:class:`~leakpath.errors.InvalidArgumentError` naming it with its dotted TOML name
(``load.mean_pressure``, ``surface.upper.hurst``), so a typo never passes silently.

TOML structure (``docs/seal.md`` lists every key with its unit and default)::

    strict = false                      # validity warnings become errors
    [surface]                           # run keys: realisations, seed, n, length, boundary
    realisations = 16
    seed = 0
    [surface.upper]                     # one body: a statistical description ...
    flat = true
    [surface.lower]
    rms_height = 1e-6                   # m (or rms_slope, dimensionless)
    hurst = 0.8
    rolloff_wavelength = 1e-4           # m
    short_wavelength = 4e-6             # m
    # ... or files = ["a.npy", ...] with dx (m), or psd = "psd.txt" (q [rad/m], C [m^4])
    [material.upper]                    # E [Pa], nu [-]
    [material.lower]                    # optional: hardness [Pa] (pressure cap, plasticity)
    [load]
    mean_pressure = [1e5, 1e6]          # Pa, nominal contact pressures
    [fluid]
    viscosity = 1e-3                    # Pa·s
    pressure_drop = 1e5                 # Pa (liquid) — or gas = true with inlet_pressure,
                                        # outlet_pressure (Pa), gas_constant (J/(kg K)),
                                        # temperature (K)
    [seal]
    length = 2e-3                       # m, land width along the leak path (L)
    width = 0.1                         # m, sealed perimeter (W)
    [flow]
    axis = "both"                       # 0, 1 or "both"
    [check]
    realisations = 2                    # re-solved on the refined grid (0: no check)
    refine = 2
    tolerance = 0.2                     # relative change of K flagged above this

Body keys written directly under ``[surface]`` (``rms_height``, ``files`` …) describe the
composite roughness on one body against a smooth other body (``upper`` smooth); they cannot be
combined with ``[surface.upper]`` / ``[surface.lower]``.
"""

from __future__ import annotations

import math
import numbers
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from .._validate import invalid
from ..errors import InvalidArgumentError

__all__ = [
    "BodySurface",
    "BodyMaterial",
    "Fluid",
    "SealGeometry",
    "ConvergenceCheck",
    "SealConfig",
    "load_config",
]

PathLike = str | os.PathLike[str]

#: Unit of every numeric key (dotted TOML names, ``*`` for either body), for metadata.
UNITS: dict[str, str] = {
    "surface.realisations": "1",
    "surface.seed": "1",
    "surface.n": "grid points per side",
    "surface.length": "m",
    "surface.*.rms_height": "m",
    "surface.*.rms_slope": "1",
    "surface.*.hurst": "1",
    "surface.*.rolloff_wavelength": "m",
    "surface.*.short_wavelength": "m",
    "surface.*.dx": "m",
    "surface.*.psd": "file: q [rad/m], C(q) [m^4]",
    "material.*.E": "Pa",
    "material.*.nu": "1",
    "material.*.hardness": "Pa",
    "load.mean_pressure": "Pa",
    "fluid.viscosity": "Pa s",
    "fluid.pressure_drop": "Pa",
    "fluid.inlet_pressure": "Pa (absolute)",
    "fluid.outlet_pressure": "Pa (absolute)",
    "fluid.gas_constant": "J/(kg K)",
    "fluid.temperature": "K",
    "seal.length": "m",
    "seal.width": "m",
    "check.tolerance": "1 (relative change of K)",
}


# ============================================================================ checks
def _real(name: str, value: Any, *, positive: bool = False, low: float | None = None,
          high: float | None = None, open_high: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise invalid(name, f"must be a number, got {value!r}")
    x = float(value)
    if not math.isfinite(x):
        raise invalid(name, f"must be finite, got {value!r}")
    if positive and not x > 0:
        raise invalid(name, f"must be > 0, got {value!r}")
    if low is not None and x < low:
        raise invalid(name, f"must be ≥ {low:g}, got {value!r}")
    if high is not None and (x >= high if open_high else x > high):
        raise invalid(name, f"must be {'<' if open_high else '≤'} {high:g}, got {value!r}")
    return x


def _modulus(name: str, value: Any) -> float:
    """Young's modulus [Pa]: positive, or ``inf`` (a rigid body; TOML ``inf``)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise invalid(name, f"must be a number in Pa, got {value!r}")
    x = float(value)
    if x == math.inf:
        return x
    return _real(name, x, positive=True)


def _integer(name: str, value: Any, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < low:
        raise invalid(name, f"must be an integer ≥ {low}, got {value!r}")
    return int(value)


def _boolean(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise invalid(name, f"must be true or false, got {value!r}")
    return value


def _unknown(name: str, data: Mapping[str, Any], allowed: set[str]) -> None:
    for key in data:
        if key not in allowed:
            where = f"{name}.{key}" if name else str(key)
            raise invalid(where, f"unknown key (allowed: {', '.join(sorted(allowed))})")


def _table(name: str, value: Any) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise invalid(name, f"must be a table (TOML [{name}]), got {type(value).__name__}")
    return value


# ============================================================================ typed parts
@dataclass(frozen=True)
class BodySurface:
    """One body's roughness, heights from its mean plane towards the other body [m].

    Exactly one description: ``flat`` (smooth), ``files`` (measured topographies, one per
    realisation, spacing ``dx`` [m] when the files carry none), or a statistical one:
    ``hurst`` H with exactly one of ``rms_height`` [m] / ``rms_slope`` [-], the roll-off
    wavelength λ_r [m] (C(q) flat for q < 2π/λ_r), the short-wavelength cutoff λ_s [m]
    (C(q) = 0 for q > 2π/λ_s), or a tabulated isotropic PSD file ``psd`` (two columns:
    q [rad/m], C(q) [m⁴]).
    """

    flat: bool = False
    hurst: float | None = None
    rms_height: float | None = None
    rms_slope: float | None = None
    rolloff_wavelength: float | None = None
    short_wavelength: float | None = None
    psd: str | None = None
    files: tuple[str, ...] | None = None
    dx: float | None = None

    def check(self, name: str) -> BodySurface:
        """This description, checked (errors name ``name.<key>``)."""
        kinds = [self.flat, self.files is not None, self.psd is not None,
                 any(v is not None for v in (self.hurst, self.rms_height, self.rms_slope))]
        if sum(bool(k) for k in kinds) == 0:
            raise invalid(name, "give flat = true, files, psd, or hurst with rms_height/rms_slope")
        if self.flat:
            _boolean(f"{name}.flat", self.flat)
            extra = [f.name for f in fields(self) if f.name != "flat"
                     and getattr(self, f.name) is not None]
            if extra:
                raise invalid(f"{name}.{extra[0]}", "a flat body takes no roughness keys")
            return self
        if self.files is not None:
            files = self.files
            if isinstance(files, (str, bytes)) or not all(
                isinstance(f, (str, os.PathLike)) for f in files
            ) or not files:
                raise invalid(f"{name}.files", f"must be a non-empty list of paths, got {files!r}")
            files = tuple(os.fspath(f) for f in files)
            for f in files:
                if not Path(f).is_file():
                    raise invalid(f"{name}.files", f"{f!r} is not a file")
            dx = None if self.dx is None else _real(f"{name}.dx", self.dx, positive=True)
            others = [k for k in ("hurst", "rms_height", "rms_slope", "rolloff_wavelength",
                                  "short_wavelength", "psd") if getattr(self, k) is not None]
            if others:
                raise invalid(f"{name}.{others[0]}", "measured files take only dx besides files")
            return replace(self, files=files, dx=dx)
        if self.dx is not None:
            raise invalid(f"{name}.dx", "dx is the spacing of measured files; give files too")
        values: dict[str, Any] = {}
        if self.psd is not None:
            if not isinstance(self.psd, (str, os.PathLike)) or not Path(self.psd).is_file():
                raise invalid(f"{name}.psd", f"must be a file (q [rad/m], C [m^4]), got "
                            f"{self.psd!r}")
            values["psd"] = os.fspath(self.psd)
        if self.hurst is not None:
            values["hurst"] = _real(f"{name}.hurst", self.hurst, low=0.0, high=1.0,
                                    open_high=True)
            if values["hurst"] == 0.0:
                raise invalid(f"{name}.hurst", "must be in (0, 1), got 0")
        elif self.psd is None:
            raise invalid(f"{name}.hurst", "required with rms_height or rms_slope")
        if self.psd is None and (self.rms_height is None) == (self.rms_slope is None):
            raise invalid(f"{name}.rms_height", "give exactly one of rms_height and rms_slope")
        for key in ("rms_height", "rms_slope", "rolloff_wavelength", "short_wavelength"):
            v = getattr(self, key)
            if v is not None:
                values[key] = _real(f"{name}.{key}", v, positive=True)
        lr, ls = values.get("rolloff_wavelength"), values.get("short_wavelength")
        if lr is not None and ls is not None and not ls < lr:
            raise invalid(f"{name}.short_wavelength",
                        f"must be below rolloff_wavelength = {lr:g} m, got {ls:g} m")
        return replace(self, **values)


@dataclass(frozen=True)
class BodyMaterial:
    """One elastic body: Young's modulus ``E`` [Pa] (``inf``: rigid) and Poisson's ratio
    ``nu`` (−1 < ν ≤ 0.5); optionally its ``hardness`` [Pa], where it yields (perfectly
    plastic: the contact pressure is capped at the smaller hardness of the two bodies,
    ``docs/plasticity.md``)."""

    E: float  # noqa: N815 - Young's modulus
    nu: float
    hardness: float | None = None

    def check(self, name: str) -> BodyMaterial:
        E = _modulus(f"{name}.E", self.E)  # noqa: N806
        nu = _real(f"{name}.nu", self.nu, low=-1.0, high=0.5)
        if nu == -1.0:
            raise invalid(f"{name}.nu", "must be > -1")
        hardness = self.hardness
        if hardness is not None:
            hardness = _real(f"{name}.hardness", hardness, positive=True)
            if not math.isfinite(hardness):
                raise invalid(f"{name}.hardness", "must be finite (omit it for no cap)")
        return BodyMaterial(E, nu, hardness)


@dataclass(frozen=True)
class Fluid:
    """The sealed fluid: a liquid (``viscosity`` η [Pa·s], ``pressure_drop`` Δp [Pa]) or an
    isothermal ideal gas (``gas = true``; absolute ``inlet_pressure`` / ``outlet_pressure``
    [Pa], specific ``gas_constant`` R_s [J/(kg·K)], ``temperature`` T [K])."""

    viscosity: float
    pressure_drop: float | None = None
    gas: bool = False
    inlet_pressure: float | None = None
    outlet_pressure: float | None = None
    gas_constant: float | None = None
    temperature: float | None = None

    def check(self, name: str = "fluid") -> Fluid:
        eta = _real(f"{name}.viscosity", self.viscosity, positive=True)
        gas = _boolean(f"{name}.gas", self.gas)
        gas_keys = ("inlet_pressure", "outlet_pressure", "gas_constant", "temperature")
        if not gas:
            if self.pressure_drop is None:
                raise invalid(f"{name}.pressure_drop", "required for a liquid (Pa)")
            for k in gas_keys:
                if getattr(self, k) is not None:
                    raise invalid(f"{name}.{k}", "applies to a gas only (set gas = true)")
            return Fluid(eta, _real(f"{name}.pressure_drop", self.pressure_drop, positive=True))
        if self.pressure_drop is not None:
            raise invalid(f"{name}.pressure_drop", "a gas takes inlet_pressure and "
                        "outlet_pressure instead")
        vals = {}
        for k in gas_keys:
            v = getattr(self, k)
            if v is None:
                raise invalid(f"{name}.{k}", "required for a gas")
            vals[k] = _real(f"{name}.{k}", v, low=0.0, positive=k != "outlet_pressure")
        if not vals["inlet_pressure"] > vals["outlet_pressure"]:
            raise invalid(f"{name}.inlet_pressure", "must exceed outlet_pressure")
        return Fluid(eta, None, True, **vals)


@dataclass(frozen=True)
class SealGeometry:
    """The seal: ``length`` L [m], the land width along the leak path, and ``width`` W [m],
    the sealed perimeter across it (``Q = K_eff (W/L) Δp/η``)."""

    length: float
    width: float

    def check(self, name: str = "seal") -> SealGeometry:
        return SealGeometry(
            _real(f"{name}.length", self.length, positive=True),
            _real(f"{name}.width", self.width, positive=True),
        )


@dataclass(frozen=True)
class ConvergenceCheck:
    """Grid-convergence check: the first ``realisations`` realisations are solved again with
    ``refine`` × the points per side (the same Fourier modes plus those the finer grid adds),
    and the relative change of K at each pressure is flagged above ``tolerance``."""

    realisations: int = 2
    refine: int = 2
    tolerance: float = 0.2

    def check(self, name: str = "check") -> ConvergenceCheck:
        return ConvergenceCheck(
            _integer(f"{name}.realisations", self.realisations, 0),
            _integer(f"{name}.refine", self.refine, 2),
            _real(f"{name}.tolerance", self.tolerance, positive=True),
        )


_AXES = (0, 1, "both")


@dataclass(frozen=True)
class SealConfig:
    """Everything a seal leak-rate run needs (SI units; module docstring for the TOML keys).

    Construct directly (every field is checked in ``__post_init__``), with
    :meth:`from_dict` (the TOML structure) or :meth:`from_toml`.
    """

    upper: BodySurface
    lower: BodySurface
    upper_material: BodyMaterial
    lower_material: BodyMaterial
    mean_pressure: tuple[float, ...]
    fluid: Fluid
    seal: SealGeometry
    realisations: int | None = None  # default 16, or the number of measured files
    seed: int = 0
    n: int | None = None
    length: float | None = None
    boundary: str = "periodic"
    axis: int | str = "both"
    check: ConvergenceCheck = field(default_factory=ConvergenceCheck)
    strict: bool = False

    @property
    def hardness(self) -> float | None:
        """The pressure cap [Pa]: the smaller hardness of the two bodies (``None``: elastic)."""
        given = [m.hardness for m in (self.upper_material, self.lower_material)
                 if m.hardness is not None]
        return min(given) if given else None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        for name, cls in (("upper", BodySurface), ("lower", BodySurface)):
            if not isinstance(getattr(self, name), cls):
                raise invalid(f"surface.{name}", f"must be a {cls.__name__}")
            set_(self, name, getattr(self, name).check(f"surface.{name}"))
        for name in ("upper", "lower"):
            m = getattr(self, f"{name}_material")
            if not isinstance(m, BodyMaterial):
                raise invalid(f"material.{name}", "must be a BodyMaterial")
            set_(self, f"{name}_material", m.check(f"material.{name}"))
        if math.isinf(self.upper_material.E) and math.isinf(self.lower_material.E):
            raise invalid("material.upper.E", "both bodies are rigid (E = inf); one must deform")
        p = self.mean_pressure
        if isinstance(p, (str, bytes)) or not hasattr(p, "__iter__"):
            p = (p,)
        p = tuple(_real("load.mean_pressure", v, positive=True) for v in p)
        if not p:
            raise invalid("load.mean_pressure", "give at least one nominal pressure (Pa)")
        if len(set(p)) != len(p):
            raise invalid("load.mean_pressure", f"values must be distinct, got {list(p)}")
        set_(self, "mean_pressure", tuple(sorted(p)))
        h = self.hardness
        if h is not None and p and max(p) > h:
            side = "lower" if self.lower_material.hardness == h else "upper"
            raise invalid(
                f"material.{side}.hardness",
                f"{h!r} Pa is below the largest load.mean_pressure {max(p)!r} Pa; a perfectly "
                "plastic surface carries at most the hardness",
            )
        if not isinstance(self.fluid, Fluid):
            raise invalid("fluid", "must be a Fluid")
        set_(self, "fluid", self.fluid.check())
        if not isinstance(self.seal, SealGeometry):
            raise invalid("seal", "must be a SealGeometry")
        set_(self, "seal", self.seal.check())
        files = [b.files for b in (self.upper, self.lower) if b.files is not None]
        if len(files) == 2 and len(files[0]) != len(files[1]):
            raise invalid("surface.lower.files", f"{len(files[1])} files do not pair up with the "
                        f"{len(files[0])} of surface.upper.files")
        if self.realisations is None:
            set_(self, "realisations", len(files[0]) if files else 16)
        else:
            r = _integer("surface.realisations", self.realisations, 1)
            if files and r > len(files[0]):
                raise invalid("surface.realisations", f"{r} exceeds the {len(files[0])} files")
            set_(self, "realisations", r)
        set_(self, "seed", _integer("surface.seed", self.seed, 0))
        if self.n is not None:
            n = _integer("surface.n", self.n, 8)
            if n & (n - 1):
                raise invalid("surface.n", f"must be a power of two, got {n}")
            set_(self, "n", n)
        if self.length is not None:
            set_(self, "length", _real("surface.length", self.length, positive=True))
        if self.boundary not in ("periodic", "free"):
            raise invalid("surface.boundary", f"must be 'periodic' or 'free', got "
                        f"{self.boundary!r}")
        if isinstance(self.axis, bool) or self.axis not in _AXES:
            raise invalid("flow.axis", f"must be 0, 1 or \"both\", got {self.axis!r}")
        if not isinstance(self.check, ConvergenceCheck):
            raise invalid("check", "must be a ConvergenceCheck")
        chk = self.check.check()
        if files and chk.realisations:
            chk = replace(chk, realisations=0)  # measured files cannot be refined
        set_(self, "check", replace(chk, realisations=min(chk.realisations, self.realisations)))
        set_(self, "strict", _boolean("strict", self.strict))
        # The bodies module's own checks (e.g. a statistical body needs short_wavelength),
        # with the config keys in their messages.
        from . import _bodies

        for side in ("upper", "lower"):
            _roughness(_bodies, getattr(self, side), f"surface.{side}")

    # ------------------------------------------------------------------ derived
    @property
    def axes(self) -> tuple[int, ...]:
        """The flow axes run: ``(0, 1)`` for ``"both"``."""
        return (0, 1) if self.axis == "both" else (int(self.axis),)

    # ------------------------------------------------------------------ conversions
    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, base: PathLike | None = None) -> SealConfig:
        """Build from a mapping with the TOML structure; relative file paths are taken from
        ``base`` (the TOML file's directory) when given."""
        return _from_dict(data, None if base is None else Path(base))

    @classmethod
    def from_toml(cls, path: PathLike) -> SealConfig:
        """Read a TOML file (relative paths in it are relative to its directory)."""
        return load_config(path)

    def to_dict(self) -> dict[str, Any]:
        """The TOML structure of this configuration (every default filled in)."""
        def body(b: BodySurface) -> dict[str, Any]:
            d = {f.name: getattr(b, f.name) for f in fields(b)}
            d = {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()
                 if v is not None and not (k == "flat" and v is False)}
            return d

        fluid = {f.name: getattr(self.fluid, f.name) for f in fields(self.fluid)}
        fluid = {k: v for k, v in fluid.items() if v is not None}
        if not self.fluid.gas:
            fluid.pop("gas")
        surface: dict[str, Any] = {
            "realisations": self.realisations,
            "seed": self.seed,
            "boundary": self.boundary,
            "upper": body(self.upper),
            "lower": body(self.lower),
        }
        if self.n is not None:
            surface["n"] = self.n
        if self.length is not None:
            surface["length"] = self.length
        return {
            "strict": self.strict,
            "surface": surface,
            "material": {
                side: {
                    "E": m.E,
                    "nu": m.nu,
                    **({} if m.hardness is None else {"hardness": m.hardness}),
                }
                for side, m in (("upper", self.upper_material), ("lower", self.lower_material))
            },
            "load": {"mean_pressure": list(self.mean_pressure)},
            "fluid": fluid,
            "seal": {"length": self.seal.length, "width": self.seal.width},
            "flow": {"axis": self.axis},
            "check": {
                "realisations": self.check.realisations,
                "refine": self.check.refine,
                "tolerance": self.check.tolerance,
            },
        }


_BODY_KEYS = {f.name for f in fields(BodySurface)}
_RUN_KEYS = {"realisations", "seed", "n", "length", "boundary"}


def _body(name: str, data: Mapping[str, Any], base: Path | None) -> BodySurface:
    _unknown(name, data, _BODY_KEYS)
    kw = dict(data)
    if "files" in kw:
        files = kw["files"]
        if isinstance(files, (str, bytes)) or not isinstance(files, (list, tuple)):
            raise invalid(f"{name}.files", f"must be a list of paths, got {files!r}")
        kw["files"] = tuple(_resolve(f, base, f"{name}.files") for f in files)
    if "psd" in kw:
        kw["psd"] = _resolve(kw["psd"], base, f"{name}.psd")
    return BodySurface(**kw)


def _resolve(path: Any, base: Path | None, name: str) -> str:
    if not isinstance(path, (str, os.PathLike)):
        raise invalid(name, f"must be a path, got {path!r}")
    p = Path(path).expanduser()
    if base is not None and not p.is_absolute():
        p = base / p
    return os.fspath(p)


def _roughness(bodies: Any, b: BodySurface, name: str) -> Any:
    """The bodies module's ``Roughness`` of one configured body (errors name ``name.key``)."""
    if b.flat:
        return bodies.Roughness.smooth(name)
    if b.files is not None:
        return bodies.Roughness(files=b.files, dx=b.dx, name=name)
    psd = None
    if b.psd is not None:
        try:
            table = np.loadtxt(b.psd, ndmin=2)
        except ValueError as exc:
            raise InvalidArgumentError(f"{name}.psd: cannot read {b.psd!r} ({exc})",
                                       argument=f"{name}.psd") from None
        if table.shape[1] != 2:
            raise InvalidArgumentError(f"{name}.psd: {b.psd!r} needs two columns, q [rad/m] "
                                       "and C [m^4]", argument=f"{name}.psd")
        psd = (table[:, 0].copy(), table[:, 1].copy())
    return bodies.Roughness(
        hurst=b.hurst, rms_height=b.rms_height, rms_slope=b.rms_slope,
        rolloff_wavelength=b.rolloff_wavelength, short_wavelength=b.short_wavelength, psd=psd,
        name=name,
    )


def _from_dict(data: Mapping[str, Any], base: Path | None) -> SealConfig:
    data = _table("config", data)
    _unknown("", data, {"strict", "surface", "material", "load", "fluid", "seal", "flow",
                        "check"})
    for required in ("surface", "material", "load", "fluid", "seal"):
        if required not in data:
            raise invalid(required, f"the [{required}] table is missing")
    surface = _table("surface", data["surface"])
    _unknown("surface", surface, _RUN_KEYS | _BODY_KEYS | {"upper", "lower"})
    direct = {k: v for k, v in surface.items() if k in _BODY_KEYS}
    two = {k for k in ("upper", "lower") if k in surface}
    if direct and two:
        raise invalid(f"surface.{next(iter(direct))}", "give the roughness either directly under "
                    "[surface] or in [surface.upper]/[surface.lower], not both")
    if direct:
        upper = BodySurface(flat=True)
        lower = _body("surface", direct, base)
    else:
        if two != {"upper", "lower"}:
            missing = ({"upper", "lower"} - two).pop()
            raise invalid(f"surface.{missing}", "missing (flat = true for a smooth body)")
        upper = _body("surface.upper", _table("surface.upper", surface["upper"]), base)
        lower = _body("surface.lower", _table("surface.lower", surface["lower"]), base)
    material = _table("material", data["material"])
    _unknown("material", material, {"upper", "lower"})
    mats = {}
    for side in ("upper", "lower"):
        if side not in material:
            raise invalid(f"material.{side}", "missing (E [Pa], nu)")
        m = _table(f"material.{side}", material[side])
        _unknown(f"material.{side}", m, {"E", "nu", "hardness"})
        for k in ("E", "nu"):
            if k not in m:
                raise invalid(f"material.{side}.{k}", "required")
        mats[side] = BodyMaterial(m["E"], m["nu"], m.get("hardness"))
    load = _table("load", data["load"])
    _unknown("load", load, {"mean_pressure"})
    if "mean_pressure" not in load:
        raise invalid("load.mean_pressure", "required (Pa)")
    fluid = _table("fluid", data["fluid"])
    _unknown("fluid", fluid, {f.name for f in fields(Fluid)})
    if "viscosity" not in fluid:
        raise invalid("fluid.viscosity", "required (Pa s)")
    seal = _table("seal", data["seal"])
    _unknown("seal", seal, {"length", "width"})
    for k in ("length", "width"):
        if k not in seal:
            raise invalid(f"seal.{k}", "required (m)")
    flow = _table("flow", data.get("flow", {}))
    _unknown("flow", flow, {"axis"})
    check = _table("check", data.get("check", {}))
    _unknown("check", check, {f.name for f in fields(ConvergenceCheck)})
    kw = {k: surface[k] for k in _RUN_KEYS if k in surface}
    return SealConfig(
        upper=upper,
        lower=lower,
        upper_material=mats["upper"],
        lower_material=mats["lower"],
        mean_pressure=load["mean_pressure"],
        fluid=Fluid(**fluid),
        seal=SealGeometry(seal["length"], seal["width"]),
        axis=flow.get("axis", "both"),
        check=ConvergenceCheck(**check),
        strict=data.get("strict", False),
        **kw,
    )


def load_config(path: PathLike) -> SealConfig:
    """Read a TOML configuration file (``tomllib``; ``tomli`` before Python 3.11)."""
    try:
        import tomllib
    except ImportError:  # pragma: no cover - Python 3.10
        import tomli as tomllib  # type: ignore[no-redef]
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise InvalidArgumentError(f"config: {str(p)!r} is not valid TOML ({exc})",
                                   argument="config") from None
    return _from_dict(data, p.resolve().parent)


def as_config(config: SealConfig | Mapping[str, Any] | PathLike) -> SealConfig:
    """A :class:`SealConfig` from a config object, a dict with the TOML structure, or a path."""
    if isinstance(config, SealConfig):
        return config
    if isinstance(config, Mapping):
        return SealConfig.from_dict(config)
    if isinstance(config, (str, os.PathLike)):
        p = Path(config)
        if not p.is_file():
            raise InvalidArgumentError(f"config: {str(p)!r} is not a file", argument="config")
        return load_config(p)
    raise InvalidArgumentError(
        f"config: expected a SealConfig, a dict or a TOML path, got {type(config).__name__}",
        argument="config",
    )
