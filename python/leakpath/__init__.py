"""leakpath: rough-surface contact mechanics and the percolating free volume.

A rough elastic surface is pressed against a rigid flat; for every imposed approach leakpath
reports the contact area, load, free volume, the part of the free volume that belongs to
channels crossing the interface, the leak rate through it, and Nayak's spectral moments of
the deformed surface. The conventions, solvers and layout are documented in the ``docs/``
folder of the source repository (``docs/conventions.md``, ``docs/flow.md``,
``docs/architecture.md``); every public function's docstring states its formulas and units.
"""

from ._checkpoint import CheckpointMismatch
from ._core import __version__
from ._flow import Flow, flow
from ._percolation import Percolation, label, percolation
from ._sweep import sweep
from ._table import SweepResult
from .contact import ContactProblem, ContactState, solve
from .elastic import kernel_table
from .generators import rmd, spectral
from .moments import Moments, nayak_moments, rms_height, rms_slope
from .seal import SealConfig, SealResult, seal_leakage
from .surfaces import Surface, load
from .threshold import PercolationThreshold, percolation_threshold, percolation_thresholds

__all__ = [
    "__version__",
    "CheckpointMismatch",
    "ContactProblem",
    "ContactState",
    "Flow",
    "Moments",
    "Percolation",
    "PercolationThreshold",
    "SealConfig",
    "SealResult",
    "SweepResult",
    "flow",
    "label",
    "percolation",
    "percolation_threshold",
    "percolation_thresholds",
    "seal_leakage",
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
