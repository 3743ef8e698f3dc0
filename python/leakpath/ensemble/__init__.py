"""Ensembles: many surfaces per parameter set, run in parallel, aggregated with error bands.

The paper's stated next step is statistics over many surfaces. :func:`ensemble` runs one
sweep per *(parameter set, seed)* — an independent **task** — on local processes or a Dask
cluster, writes every finished task to disk at once, and aggregates the tables into per-level
bands and per-surface percolation thresholds.

Modules, bottom to top: ``_stats`` (Student-t intervals without scipy), ``_params``
(parameter sets and the generator of a task), ``_layout`` (the directory: task files,
manifest, CSV), ``_leakage`` (leak-rate bands and the contact fraction where the leak stops),
``_aggregate`` (bands, thresholds, :class:`EnsembleResult`), ``_executors`` (serial, local
processes, Dask), ``_run`` (:func:`ensemble`). The figures live in
:mod:`leakpath.plotting.ensemble`.
"""

from .._outputs import OverwriteNote
from ._aggregate import (
    STATS,
    THRESHOLD_COLUMNS,
    EnsembleResult,
    aggregate,
    threshold_from_rows,
)
from ._layout import QUANTITIES
from ._params import ParamSet, param_key
from ._run import ensemble
from ._stats import (
    CONFIDENCE,
    THRESHOLD_QUANTILES,
    regularized_incomplete_beta,
    student_t_ppf,
    t_critical,
)

__all__ = [
    "ensemble",
    "aggregate",
    "EnsembleResult",
    "OverwriteNote",
    "ParamSet",
    "QUANTITIES",
    "STATS",
    "CONFIDENCE",
    "THRESHOLD_COLUMNS",
    "THRESHOLD_QUANTILES",
    "param_key",
    "threshold_from_rows",
    "student_t_ppf",
    "t_critical",
    "regularized_incomplete_beta",
]
