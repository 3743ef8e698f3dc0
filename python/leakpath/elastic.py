"""The elastic half-space: the Love influence table of uniformly loaded square elements.

``docs/conventions.md`` ("Element") gives the element and the influence coefficients; the
FFT operators that apply them live in the compiled core.
"""

from __future__ import annotations

import numpy as np

from . import _validate
from ._core import kernel_table as _kernel_table

__all__ = ["kernel_table"]


def kernel_table(shape: tuple[int, int], dx: float, e_star: float = 1.0) -> np.ndarray:
    """Love influence table ``K[|di|, |dj|]`` of shape ``shape``: the displacement at a point
    ``(di, dj)`` elements away from a ``dx × dx`` square carrying unit pressure.

    ``K[0, 0] = 4·dx·ln(1 + √2)/(π E*)``; units: length per unit pressure (pressure in the
    unit of ``e_star``).
    """
    ny, nx = _validate.shape_pair("shape", shape, allow_int=False)
    limit = _validate.memory_budget()
    if 8 * ny * nx > limit:
        raise _validate.too_large(
            "shape", f"a kernel table of {ny} × {nx} values", 8 * ny * nx, limit,
            "ask for a smaller table",
        )
    dx = _validate.spacing("dx", dx)
    e_star = _validate.positive("e_star", e_star)
    return _kernel_table(ny, nx, dx, e_star)
