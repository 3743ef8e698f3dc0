"""The elementwise functions with the same bits on every CPU (leakpath._elementary): ``pow``,
``exp``, ``log`` and ``log10`` against Python's ``math`` module (the C library's scalar
functions, value by value), ``cbrt`` against exact rational arithmetic, and the spectral
generator built on them.

numpy's own ``power``/``exp``/``log``/``log10``/``cbrt`` use SVML on CPUs with AVX-512, whose
results differ from the C library's in the last bits of some values: on such a CPU the
generator test below fails if the generator goes back to numpy's ``**``.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

import leakpath
from leakpath import _core, _elementary
from leakpath.errors import InvalidArgumentError


def _values() -> np.ndarray:
    rng = np.random.default_rng(11)
    x = 10.0 ** rng.uniform(-300, 300, 20_000)  # numpy's power: any bits will do here
    edges = [5e-324, 2.2250738585072014e-308, 0.5, 1.0, 2.0, 10.0, 1e308, math.inf]
    return np.concatenate([x, rng.uniform(0.0, 50.0, 20_000), edges])


def _oracle(f, x: np.ndarray) -> np.ndarray:
    out = []
    for v in x:
        try:
            out.append(f(float(v)))
        except OverflowError:  # past the float range: ±inf, the sign of x (x³, eˣ)
            out.append(math.copysign(math.inf, v))
    return np.array(out)


@pytest.mark.parametrize(
    ("ours", "theirs", "signed"),
    [
        (lambda x: _elementary.power(x, -1.8), lambda v: math.pow(v, -1.8), False),
        (lambda x: _elementary.power(x, 0.37), lambda v: math.pow(v, 0.37), False),
        (lambda x: _elementary.power(x, 3.0), lambda v: math.pow(v, 3.0), True),
        (_elementary.log, math.log, False),
        (_elementary.log10, math.log10, False),
    ],
    ids=["power -1.8", "power 0.37", "power 3", "log", "log10"],
)
def test_each_value_is_the_c_librarys(ours, theirs, signed):
    x = _values()
    if signed:
        x = np.concatenate([x, -x[:1000]])
    got = ours(x)
    assert got.dtype == np.float64 and got.shape == x.shape
    np.testing.assert_array_equal(got.view(np.uint64), _oracle(theirs, x).view(np.uint64))


def test_cbrt_is_within_one_ulp_of_the_exact_cube_root():
    """Exact rational arithmetic: the true cube root of ``x`` lies within one ulp of the
    result, ``(r − ulp)³ ≤ x ≤ (r + ulp)³`` (x > 0; odd in x)."""
    x = _values()[::20]
    x = x[np.isfinite(x)]
    r = _elementary.cbrt(x)
    np.testing.assert_array_equal(_elementary.cbrt(-x), -r)
    for v, c in zip(x, r, strict=True):
        below = Fraction(float(np.nextafter(c, 0.0)))
        above = Fraction(float(np.nextafter(c, np.inf)))
        assert below**3 <= Fraction(float(v)) <= above**3, (v, c)


def test_exp_is_the_c_librarys():
    x = np.random.default_rng(5).uniform(-745.0, 709.0, 40_000)
    np.testing.assert_array_equal(
        _elementary.exp(x).view(np.uint64), _oracle(math.exp, x).view(np.uint64)
    )


def test_shapes_scalars_and_strided_input():
    a = np.arange(1.0, 25.0).reshape(4, 6)
    np.testing.assert_array_equal(_elementary.power(a.T, 2.0), a.T * a.T)
    assert _elementary.cbrt(27.0).shape == () and float(_elementary.cbrt(27.0)) == 3.0
    assert _elementary.log10(np.zeros((0, 3))).shape == (0, 3)
    assert math.isnan(float(_elementary.log(-1.0)))


@pytest.mark.parametrize(
    ("function", "exponent"), [("sqrt", None), ("power", None), ("exp", 2.0)]
)
def test_a_bad_function_is_refused_by_name(function, exponent):
    with pytest.raises(InvalidArgumentError) as err:
        _core.elementary(np.ones(3), function, exponent)
    assert err.value.argument == "function"


def test_spectral_heights_use_the_c_librarys_pow():
    """The generator's documented formula with the amplitude from ``math.pow``, value by
    value: the same bits, so a seed draws the same surface on every CPU."""
    ny, nx, hurst, length = 24, 40, 0.7, 80.0
    s = leakpath.spectral(
        (ny, nx), hurst, seed=9, length=length, long_cutoff=40.0, short_cutoff=6.0,
        rms_height=1.5,
    )
    dx = length / nx
    qy = 2.0 * np.pi * np.fft.fftfreq(ny, dx)
    qx = 2.0 * np.pi * np.fft.rfftfreq(nx, dx)
    q = np.hypot(qy[:, None], qx[None, :])
    q_long, q_short = 2.0 * math.pi / 40.0, 2.0 * math.pi / 6.0
    band = (q >= q_long * (1.0 - 1e-12)) & (q <= q_short * (1.0 + 1e-12))
    amplitude = np.zeros_like(q)
    amplitude[band] = [math.pow(v, -(1.0 + hurst)) for v in q[band]]
    white = np.random.default_rng(9).standard_normal((ny, nx))
    h = np.fft.irfft2(np.fft.rfft2(white) * amplitude, s=(ny, nx))
    h -= h.mean()
    h *= 1.5 / float(np.sqrt(np.mean(h * h)))
    np.testing.assert_array_equal(s.heights, h)


# numpy float64 functions that run through SVML on CPUs with AVX-512 (their bits differ from
# the C library's there); `**` with an exponent other than 2 on an array is numpy's `power`.
_VECTORISED = {
    "power", "float_power", "exp", "exp2", "expm1", "log", "log2", "log10", "log1p", "cbrt",
    "arctan2", "arcsin", "arccos", "arctan", "sinh", "cosh", "tan", "arcsinh", "arccosh",
    "arctanh",
}


def test_no_numeric_module_calls_numpys_vectorised_elementary_functions():
    """The modules that compute numbers (not the figures') call these through
    ``leakpath._elementary``: a regression guard read from the source (calls by name only;
    ``x ** y`` on an array is not seen here, the spectral test above covers the generator's)."""
    import ast
    from pathlib import Path

    root = Path(leakpath.__file__).parent
    found = []
    for path in root.rglob("*.py"):
        if "plotting" in path.parts:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Attribute)
                and isinstance(node.func.value, ast.Name)
                and node.func.value.id in ("np", "numpy")
                and node.func.attr in _VECTORISED
            ):
                found.append(f"{path.relative_to(root)}:{node.lineno} np.{node.func.attr}")
    assert not found, found
