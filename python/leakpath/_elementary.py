"""Elementwise ``power``, ``exp``, ``log``, ``log10`` and ``cbrt`` with the same bits on every CPU.

numpy evaluates these (and ``x ** y`` on arrays, ``x ** 3`` included) with Intel's SVML on
CPUs that have AVX-512 and with the C library's scalar functions on the others; the two
differ in the last bits of some values. leakpath's surfaces, seal spectra and fitted
numbers go through these functions instead, which compute every element with one scalar
function whatever the CPU: the C library's ``pow``, ``exp``, ``log`` and ``log10``, and the
cube root compiled into leakpath (``leakpath._core.elementary``; ``docs/conventions.md``,
"The same numbers on every machine"). Each takes an array-like of real numbers and returns a
float64 array of its shape (a 0-d array for a scalar).
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from . import _core

__all__ = ["cbrt", "exp", "log", "log10", "power"]

_F64 = npt.NDArray[np.float64]


def _map(
    x: Any, function: Literal["power", "exp", "log", "log10", "cbrt"], exponent: float | None
) -> _F64:
    a = np.asarray(x, dtype=np.float64)
    flat = np.ascontiguousarray(a).reshape(-1)
    return _core.elementary(flat, function, exponent).reshape(a.shape)


def power(x: Any, exponent: float) -> _F64:
    """``x ** exponent`` element by element (C ``pow``)."""
    return _map(x, "power", float(exponent))


def exp(x: Any) -> _F64:
    """``eˣ`` element by element (C ``exp``)."""
    return _map(x, "exp", None)


def log(x: Any) -> _F64:
    """The natural logarithm element by element (C ``log``)."""
    return _map(x, "log", None)


def log10(x: Any) -> _F64:
    """The decimal logarithm element by element (C ``log10``)."""
    return _map(x, "log10", None)


def cbrt(x: Any) -> _F64:
    """The cube root element by element (within one ulp; odd in ``x``)."""
    return _map(x, "cbrt", None)
