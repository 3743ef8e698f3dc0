"""leakpath: rough-surface contact mechanics and the percolating free volume.

A rough elastic surface is pressed against a rigid flat; for every imposed approach leakpath
reports the contact area, load, free volume, the part of the free volume that belongs to
channels crossing the interface, and Nayak's spectral moments of the deformed surface.
"""

from . import _validate
from ._core import __version__
from ._core import kernel_table as _kernel_table
from .contact import ContactProblem, ContactState, solve
from .flow import Flow, flow
from .moments import Moments, nayak_moments, rms_height, rms_slope
from .percolation import Percolation, percolation
from .surfaces import Surface, load, rmd, spectral
from .sweep import SweepResult, sweep
from .threshold import PercolationThreshold, percolation_threshold

__all__ = [
    "__version__",
    "ContactProblem",
    "ContactState",
    "Flow",
    "Moments",
    "Percolation",
    "PercolationThreshold",
    "SweepResult",
    "flow",
    "percolation",
    "percolation_threshold",
    "sweep",
    "rms_height",
    "rms_slope",
    "solve",
    "Surface",
    "load",
    "nayak_moments",
    "rmd",
    "spectral",
    "kernel_table",
]


def kernel_table(shape: tuple[int, int], dx: float, e_star: float = 1.0):
    """Love influence table ``K[|di|, |dj|]`` of shape ``shape`` (see :mod:`leakpath._core`).

    ``K[0, 0] = 4·dx·ln(1 + √2)/(π E*)``; units: length / (pressure) per unit pressure.
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
