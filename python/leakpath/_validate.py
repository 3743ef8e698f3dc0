"""Argument checks shared by leakpath's public functions and its command line.

Every check returns the value in its canonical form or raises
:class:`~leakpath.errors.InvalidArgumentError` whose message starts with the argument's name:
``argument: what is wrong; what to do``. Memory estimates that exceed what leakpath may use
raise :class:`~leakpath.errors.ProblemTooLargeError` before anything is allocated.

Rules that hold everywhere:

* a bool is not a number (``True`` is not ``1`` here) and a string is not a number
  (``"0.5"`` is refused, not parsed);
* complex numbers are refused, never silently cut to their real part;
* numbers are finite unless a check says otherwise;
* integers have an upper bound, so that nothing sized by them overflows or spins.
"""

from __future__ import annotations

import errno
import math
import numbers
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np

from . import _memory
from .errors import InvalidArgumentError, ProblemTooLargeError

__all__ = [
    "AXES",
    "INT_MAX",
    "MAX_ABS_HEIGHT",
    "axis",
    "boundary",
    "choice",
    "connectivity",
    "contact_scales",
    "describe",
    "flag",
    "format_bytes",
    "integer",
    "load_scales",
    "memory_budget",
    "memory_limit",
    "optional_integer",
    "make_directory",
    "path",
    "show_path",
    "positive",
    "real",
    "real_array",
    "shape_pair",
    "spacing",
    "too_large",
]

#: Largest integer any count or size may take (iterations, threads, bytes, …): far beyond
#: any useful value, and below the 63-bit limits of the compiled core.
INT_MAX = 2**62

#: Flow directions accepted by ``axis`` arguments, in canonical form.
AXES: tuple[int | str, ...] = (0, 1, "either", "both")

_FLOAT_MIN = sys.float_info.min  # smallest normal double, ≈ 2.2e-308

#: Largest |height| leakpath accepts: squares (moments, energies) stay finite.
MAX_ABS_HEIGHT = 1e150


def describe(value: Any, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters, with its type when that is not obvious."""
    text = repr(value)
    if len(text) > limit:
        text = text[: limit - 3] + "..."
    if isinstance(value, (bool, np.bool_)):
        return f"{text} (a bool)"
    if isinstance(value, str):
        return f"{text} (a string)"
    if isinstance(value, (complex, np.complexfloating)):
        return f"{text} (a complex number)"
    return text


def _scalar(value: Any) -> Any:
    """A 0-d numpy array of numbers as its scalar; anything else unchanged."""
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "fiu":
        return value[()]
    return value


def _is_real(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _is_int(value: Any) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))


# ---------------------------------------------------------------------------- numbers
def real(
    name: str,
    value: Any,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
    what: str | None = None,
    hint: str = "",
) -> float:
    """A finite real number in ``[low, high]`` (ends open on request), as ``float``.

    ``what`` describes the expected value in the message (default built from the bounds);
    ``hint`` is appended after a semicolon (what to do).
    """
    if what is None:
        what = "a finite number"
        if low is not None and high is not None:
            lb = "(" if low_open else "["
            hb = ")" if high_open else "]"
            what = f"a number in {lb}{low:g}, {high:g}{hb}"
        elif low is not None:
            what = f"a number {'>' if low_open else '≥'} {low:g}"
        elif high is not None:
            what = f"a number {'<' if high_open else '≤'} {high:g}"
    tail = f"; {hint}" if hint else ""
    value = _scalar(value)
    if not _is_real(value):
        raise InvalidArgumentError(f"{name}: must be {what}, got {describe(value)}{tail}")
    try:
        out = float(value)
    except OverflowError:  # an int beyond the float range
        out = math.inf if value > 0 else -math.inf
    bad = not math.isfinite(out)
    if low is not None and not bad:
        bad = out <= low if low_open else out < low
    if high is not None and not bad:
        bad = out >= high if high_open else out > high
    if bad:
        raise InvalidArgumentError(f"{name}: must be {what}, got {describe(value)}{tail}")
    return out


def positive(
    name: str, value: Any, *, what: str = "a positive finite number", hint: str = ""
) -> float:
    """A finite number ``> 0``, as ``float``."""
    return real(name, value, low=0.0, low_open=True, what=what, hint=hint)


def spacing(name: str, value: Any) -> float:
    """A grid spacing: positive, finite, and with ``value²`` a normal double.

    Areas ``dx²`` enter every load and volume; a spacing whose square underflows (below
    ≈ 1.5e-154) or overflows (above ≈ 1.3e154) would turn them into 0 or ∞ silently.
    """
    dx = positive(name, value, what="a positive finite grid spacing")
    sq = dx * dx
    if not (_FLOAT_MIN <= sq < math.inf):
        raise InvalidArgumentError(
            f"{name}: grid spacing {dx!r} is out of range (its square {sq!r} is not a normal "
            "double, so areas and loads would underflow or overflow); express lengths in a "
            "unit that puts dx between 1e-150 and 1e150"
        )
    return dx


def integer(
    name: str,
    value: Any,
    *,
    low: int = 0,
    high: int = INT_MAX,
    what: str | None = None,
    hint: str = "",
) -> int:
    """An integer in ``[low, high]`` (not a bool, not a float, not a string), as ``int``."""
    if what is None:
        what = f"an integer ≥ {low}" if high >= INT_MAX else f"an integer in [{low}, {high}]"
    tail = f"; {hint}" if hint else ""
    value = _scalar(value)
    if not _is_int(value):
        raise InvalidArgumentError(f"{name}: must be {what}, got {describe(value)}{tail}")
    out = int(value)
    if out < low:
        raise InvalidArgumentError(f"{name}: must be {what}, got {describe(value)}{tail}")
    if out > high:
        raise InvalidArgumentError(
            f"{name}: {describe(value)} is too large, at most {high} is allowed{tail}"
        )
    return out


def optional_integer(name: str, value: Any, **kwargs: Any) -> int | None:
    """``None`` or :func:`integer`."""
    return None if value is None else integer(name, value, **kwargs)


def threads(value: Any) -> int | None:
    """``threads=``: ``None`` (all solver threads) or a count from 1 to 4096."""
    return optional_integer(
        "threads", value, low=1, high=4096, what="a positive integer (at most 4096) or None"
    )


def flag(name: str, value: Any) -> bool:
    """``True`` or ``False`` (numpy bools too); nothing else."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise InvalidArgumentError(f"{name}: must be True or False, got {describe(value)}")


def choice(name: str, value: Any, choices: tuple[str, ...]) -> str:
    """One of the strings ``choices``."""
    if isinstance(value, str) and value in choices:
        return str(value)
    options = ", ".join(repr(c) for c in choices)
    raise InvalidArgumentError(f"{name}: must be one of {options}; got {describe(value)}")


# ---------------------------------------------------------------------------- shapes, axes
def shape_pair(
    name: str, value: Any, *, low: int = 1, allow_int: bool = True
) -> tuple[int, int]:
    """A grid size ``(ny, nx)`` of integers ``≥ low`` (or one integer ``n`` for ``(n, n)``)."""
    if allow_int and _is_int(_scalar(value)):
        dims: tuple[Any, ...] = (value, value)
    elif isinstance(value, (tuple, list)) and len(value) == 2:
        dims = tuple(value)
    else:
        form = "an integer n or a pair (ny, nx)" if allow_int else "a pair (ny, nx)"
        raise InvalidArgumentError(f"{name}: must be {form}, got {describe(value)}")
    out = []
    for n in dims:
        n = _scalar(n)
        if not _is_int(n) or not low <= int(n) <= INT_MAX:
            raise InvalidArgumentError(
                f"{name}: sizes must be integers ≥ {low} per axis, got {describe(value)}"
            )
        out.append(int(n))
    return out[0], out[1]


def axis(value: Any, name: str = "axis") -> int | str:
    """A flow direction: 0, 1, ``"either"`` or ``"both"`` (``"0"``/``"1"`` read as 0/1)."""
    v = _scalar(value)
    if _is_int(v) and int(v) in (0, 1):
        return int(v)
    if isinstance(v, str):
        key = v.strip().lower()
        if key in ("0", "1"):
            return int(key)
        if key in ("either", "both"):
            return key
    raise InvalidArgumentError(
        f"{name}: must be 0, 1, 'either' or 'both', got {describe(value)}"
    )


def flow_axis(value: Any, name: str = "axis") -> int:
    """The axis a leak flows along: 0 or 1 (the percolation axes ``"either"``/``"both"`` are
    refused: a flow has one direction). The one check behind :func:`leakpath.flow`, a
    sweep's ``flow_axis`` and the ensembles; the value crosses into the core as is."""
    v = _scalar(value)
    if _is_int(v) and int(v) in (0, 1):
        return int(v)
    raise InvalidArgumentError(
        f"{name}: must be 0 or 1 (the leak flows along one axis), got {describe(value)}",
        argument=name,
    )


def approach(
    value: Any, *, full_contact: float | None = None, name: str = "approach"
) -> float:
    """An imposed approach ``Δ``: finite and ``≥ 0``; on a periodic surface
    (``full_contact = max h − mean h``) at most full contact, values within round-off above
    it taken as it. The one check behind :meth:`leakpath.ContactProblem.solve` and a
    sweep's ``approaches``."""
    a = real(name, value, low=0.0, what="a finite number ≥ 0")
    if full_contact is None:
        return a
    if a > full_contact * (1 + 1e-12) + 1e-300:
        raise InvalidArgumentError(
            f"{name}: {a:.6g} exceeds full contact (max h − mean h) = {full_contact:.6g} of a "
            "periodic surface, where u has zero mean and the flat cannot move further; "
            "give an approach ≤ that",
            argument=name,
        )
    return min(a, full_contact)


def mean_pressure(value: Any, name: str = "mean_pressure") -> float:
    """An imposed mean pressure ``p̄ = F/A0``: finite and ``> 0``. The one check behind
    :meth:`leakpath.ContactProblem.solve` and a sweep's ``mean_pressures``."""
    return positive(name, value, what="a finite number > 0 (a mean pressure)")


def increasing(name: str, values: Any, check: Any) -> list[float]:
    """A non-empty, strictly increasing 1-D sequence whose every value passes
    ``check(value, name=name)`` (:func:`approach`, :func:`mean_pressure`)."""
    arr = real_array(name, values, ndim=1, finite=False)
    if arr.size == 0:
        raise InvalidArgumentError(f"{name}: must be a non-empty 1-D sequence of numbers")
    out = [check(float(v), name=name) for v in arr]
    if any(b <= a for a, b in zip(out, out[1:], strict=False)):
        raise InvalidArgumentError(f"{name}: must be strictly increasing")
    return out


def connectivity(value: Any, name: str = "connectivity") -> int:
    """4 (edge neighbours) or 8 (edges and corners)."""
    v = _scalar(value)
    if _is_int(v) and int(v) in (4, 8):
        return int(v)
    raise InvalidArgumentError(
        f"{name}: must be 4 (edge neighbours) or 8 (edges and corners), got {describe(value)}"
    )


def boundary(value: Any, name: str = "boundary") -> str:
    """``"free"`` or ``"periodic"``."""
    return choice(name, value, ("free", "periodic"))


# ---------------------------------------------------------------------------- arrays
def real_array(
    name: str, value: Any, *, ndim: int = 2, finite: bool = True, copy: bool = True
) -> np.ndarray:
    """A float64 array of real numbers: a new C-contiguous copy, never a view of ``value``
    (with ``copy=False``: ``value`` itself, in any memory layout, when it is float64).

    Refuses complex values (their imaginary part would be dropped), strings, bools and
    objects, arrays of the wrong dimension, and — with ``finite`` — NaN or infinities.
    """
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:  # ragged nested lists
        raise InvalidArgumentError(
            f"{name}: must be a {ndim}-D array of real numbers ({exc})"
        ) from None
    kind = arr.dtype.kind
    if kind == "O" and arr.size and all(_is_real(v) for v in arr.flat):
        kind = "f"  # an object array of plain real numbers (e.g. from a list of Fractions)
    if kind == "c":
        raise InvalidArgumentError(
            f"{name}: complex values are not accepted (the imaginary part would be dropped); "
            "pass the real part (.real) or the modulus (abs) explicitly"
        )
    if kind not in "fiu":
        raise InvalidArgumentError(
            f"{name}: must be an array of real numbers, got dtype {arr.dtype} "
            f"({_KIND_NAMES.get(kind, 'not numbers')})"
        )
    if arr.ndim != ndim:
        raise InvalidArgumentError(
            f"{name}: must be a {ndim}-D array, got {arr.ndim} dimension(s) (shape {arr.shape})"
        )
    limit = memory_budget()
    if copy and 8 * arr.size > limit:
        raise too_large(
            name, f"a copy of a {' × '.join(map(str, arr.shape))} array", 8 * arr.size, limit,
            "crop or downsample it first",
        )
    if copy:
        out = np.array(arr, dtype=np.float64, order="C", copy=True)
    else:
        out = np.asarray(arr, dtype=np.float64)
    if finite and out.size and not np.isfinite(out).all():
        bad = int(out.size - np.count_nonzero(np.isfinite(out)))
        raise InvalidArgumentError(
            f"{name}: contains {bad} NaN or infinite value(s) of {out.size}; fill or crop "
            "them first (leakpath.load(..., fill='nearest') fills undefined points of a file)"
        )
    return out


_KIND_NAMES = {
    "b": "booleans",
    "U": "strings",
    "S": "bytes",
    "O": "Python objects",
    "M": "dates",
    "m": "time spans",
    "V": "records",
}


# ---------------------------------------------------------------------------- contact
#: Largest power of ten (either sign) any scale of a contact problem may reach (below).
SCALE_EXPONENT = 250


def contact_scales(e_star: float, dx: float, height_range: float, name: str = "E") -> None:
    """Refuse unit choices whose solver arithmetic would leave the floating-point range.

    With contact modulus ``E*``, spacing ``dx`` and height range ``h_s``, the solvers work
    with the compliance ``C ≈ dx/E*`` [length/pressure], pressures ``P ≈ E*·h_s/dx``, loads
    ``P·dx²``, volumes ``h_s·dx²`` and the energies ``h_s²/C`` and ``P²·C`` of their line
    searches. Each must lie within ``10^±``:data:`SCALE_EXPONENT` (a margin of about 50
    decades below the limits of double precision for sums over many points); a scan of
    unit choices found every failure of the solvers outside that box and none inside.
    """
    log_c = math.log10(dx) - math.log10(e_star)
    terms = [("compliance dx/E*", log_c)]
    if height_range > 0:
        log_h = math.log10(height_range)
        log_p = log_h - log_c
        log_dx2 = 2.0 * math.log10(dx)
        terms += [
            ("pressure scale E*·h_s/dx", log_p),
            ("squared pressure scale", 2.0 * log_p),
            ("load scale E*·h_s·dx", log_p + log_dx2),
            ("volume scale h_s·dx²", log_h + log_dx2),
            ("energy scale h_s²·dx/E*", 2.0 * log_h + log_c),
            ("energy scale h_s·E*·h_s/dx", 2.0 * log_h - log_c),
        ]
    for what, exponent in terms:
        if abs(exponent) > SCALE_EXPONENT:
            raise InvalidArgumentError(
                f"{name}: with E* = {e_star:.3g}, dx = {dx:.3g} and h_s = {height_range:.3g} "
                f"the {what} is about 1e{exponent:+.0f}, beyond 1e±{SCALE_EXPONENT} where the "
                "solvers keep their precision; express E (pressures) or the lengths in units "
                "closer to the problem's scale",
                argument=name,
            )


def load_scales(
    mean_pressure: float, e_star: float, dx: float, name: str = "mean_pressure"
) -> None:
    """Refuse an imposed mean pressure ``p̄`` whose solver arithmetic would leave the
    floating-point range.

    Load control works with pressures ``≈ p̄`` [pressure], their squares and energies
    ``p̄²·C_00`` and the displacement ``p̄·C_00`` [length] that ``p̄`` makes at its own cell
    (``C_00 ≈ 1.12 dx/E*``); each must lie within ``10^±``:data:`SCALE_EXPONENT`, as in
    :func:`contact_scales`. Any ``p̄`` inside is solved, however far past full contact
    (``p̄ ≫ E*`` is outside small-strain elasticity, but the linear model is still solved
    exactly).
    """
    log_p = math.log10(mean_pressure)
    log_c = math.log10(dx) - math.log10(e_star)
    terms = [
        ("mean pressure", log_p),
        ("squared pressure scale p̄²", 2.0 * log_p),
        ("displacement scale p̄·dx/E*", log_p + log_c),
        ("energy scale p̄²·dx/E*", 2.0 * log_p + log_c),
    ]
    for what, exponent in terms:
        if abs(exponent) > SCALE_EXPONENT:
            raise InvalidArgumentError(
                f"{name}: p̄ = {mean_pressure:.3g} with E* = {e_star:.3g} and dx = {dx:.3g} "
                f"makes the {what} about 1e{exponent:+.0f}, beyond 1e±{SCALE_EXPONENT} where "
                "the solvers keep their precision; express pressures (p̄ and E) in a unit "
                "closer to the problem's scale",
                argument=name,
            )


# ---------------------------------------------------------------------------- memory
def memory_budget() -> int:
    """Bytes leakpath may use by default: the one default of every memory limit,
    :func:`leakpath._memory.memory_limit` (headroom under cgroup, rlimits and available
    memory, or 70 % of physical memory where none is known)."""
    return _memory.memory_limit()


def memory_limit(value: Any, name: str = "memory_limit") -> int | None:
    """``None`` (the default budget) or a positive whole number of bytes."""
    if value is None:
        return None
    return integer(
        name,
        value,
        low=1,
        what="a positive integer number of bytes (e.g. 8 << 30) or None for the default",
    )


def format_bytes(n: int | float) -> str:
    """``n`` bytes in a readable unit; exact powers of ten for numbers too big for a float."""
    if isinstance(n, int) and n.bit_length() > 1000:
        return f"about 10^{int(n.bit_length() * math.log10(2))} bytes"
    n = float(n)
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n:.0f} bytes"


def too_large(
    argument: str, what: str, estimate: int, limit: int, hint: str
) -> ProblemTooLargeError:
    """The error for a problem refused up front: ``argument: what needs ~X (limit Y); hint``."""
    return ProblemTooLargeError(
        f"{argument}: {what} needs {format_bytes(estimate)} (limit {format_bytes(limit)}); "
        f"{hint}",
        estimate=min(int(estimate), 2**63 - 1),
        limit=int(limit),
        what=what,
    )


# ---------------------------------------------------------------------------- paths
#: Longest file name (one path component, in bytes) and whole path the checks allow when
#: the system does not say: the Linux and macOS limits of the common file systems.
NAME_MAX = 255
PATH_MAX = 4096


def show_path(text: str | os.PathLike[str], limit: int = 80) -> str:
    """``repr`` of a path for a message, shortened in the middle when it is long."""
    text = os.fspath(text)
    if len(text) <= limit:
        return repr(text)
    return f"{text[: limit // 2]!r}…{text[-(limit // 4):]!r} ({len(text)} characters)"


def _limits(text: str) -> tuple[int, int]:
    """``(NAME_MAX, PATH_MAX)`` of the file system holding the nearest existing ancestor."""
    here = Path(text).parent if text else Path(".")
    for candidate in (here, *here.parents, Path(".")):
        try:
            return (
                int(os.pathconf(candidate, "PC_NAME_MAX")),
                int(os.pathconf(candidate, "PC_PATH_MAX")),
            )
        except (OSError, ValueError, AttributeError):
            continue
    return NAME_MAX, PATH_MAX  # pragma: no cover - no pathconf


def path(argument: str, value: Any) -> Path:
    """``value`` as a :class:`~pathlib.Path` the operating system can use.

    Refused by name: a value that is not a ``str`` or ``os.PathLike``, a path holding a NUL
    character, a file name or path longer than the file system allows, a path that runs
    into a loop of symbolic links or through a file as if it were a directory, and one that
    cannot be looked up at all (permissions). Whether it exists is left to the caller.
    """
    if isinstance(value, (bytes, bool)) or not isinstance(value, (str, os.PathLike)):
        raise InvalidArgumentError(
            f"{argument}: must be a file path (str or os.PathLike), got {describe(value)}",
            argument=argument,
        )
    text = os.fspath(value)
    if not isinstance(text, str):
        raise InvalidArgumentError(
            f"{argument}: must be a text path, got the bytes path {describe(text)}",
            argument=argument,
        )
    shown = show_path(text)
    if "\x00" in text:
        raise InvalidArgumentError(
            f"{argument}: {shown} contains a NUL character, which no path may hold; "
            "remove it",
            argument=argument,
        )
    name_max, path_max = _limits(text)
    longest = max((len(os.fsencode(part)) for part in Path(text).parts), default=0)
    if len(os.fsencode(text)) >= path_max or longest > name_max:
        raise InvalidArgumentError(
            f"{argument}: {shown} is too long for the file system (names of at most "
            f"{name_max} bytes, paths under {path_max}); use a shorter path",
            argument=argument,
        )
    try:
        os.stat(text)
    except FileNotFoundError:
        pass  # the caller decides whether it must exist
    except OSError as exc:
        why = {
            errno.ELOOP: "runs into a loop of symbolic links; fix or remove the link",
            errno.ENAMETOOLONG: "is too long for the file system; use a shorter path",
            errno.ENOTDIR: "goes through a file as if it were a directory; check the path",
        }.get(exc.errno or 0, f"cannot be looked up ({exc.strerror}); check the path")
        raise InvalidArgumentError(f"{argument}: {shown} {why}", argument=argument) from None
    except ValueError as exc:  # anything else the platform refuses in a path
        raise InvalidArgumentError(
            f"{argument}: {shown} is not a usable path ({exc})", argument=argument
        ) from None
    return Path(text)


def make_directory(argument: str, directory: Path) -> Path:
    """Create ``directory`` (and its parents) if needed; a failure is refused by name."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise InvalidArgumentError(
            f"{argument}: {show_path(directory)} exists and is not a directory; choose "
            "another path",
            argument=argument,
        ) from None
    except OSError as exc:
        raise InvalidArgumentError(
            f"{argument}: cannot create the directory {show_path(directory)} "
            f"({exc.strerror}); choose a path you can write to",
            argument=argument,
        ) from None
    return directory


def invalid(name: str, message: str) -> InvalidArgumentError:
    """The error of argument ``name``: ``name: message``."""
    return InvalidArgumentError(f"{name}: {message}", argument=name)
