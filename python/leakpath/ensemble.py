"""Ensembles: many surfaces per parameter set, run in parallel, aggregated with error bands.

The paper's stated next step is statistics over many surfaces. :func:`ensemble` runs one
:func:`leakpath.sweep.sweep` per *(parameter set, seed)* — an independent **task** — on local
processes or a Dask cluster, writes every finished task to disk at once, and aggregates the
per-surface tables into mean curves with 95 % confidence bands and a distribution of the
percolation threshold.

Tasks and files
---------------
A parameter set is a dict of generator arguments (``{"m": 7, "D": 2.1}`` for ``"rmd"``);
its **key** is ``name=value`` joined by ``_`` over the sorted names (``D=2.1_m=7``; floats as
``repr``). Task ``(key, s)`` generates the surface with ``seed=s``, runs the sweep and
returns its table; the *driver* (the process that called :func:`ensemble`) writes, as soon as
the task finishes, ::

    DIR/tasks/<key>/seed-<s>.json   metadata: parameters, seed, threshold, sweep metadata
                                    (surface hash, reference values, wall times, machine)
    DIR/tasks/<key>/seed-<s>.csv    the sweep table (repr-exact floats, see leakpath.sweep)

each atomically (temporary file + ``os.replace``), the JSON first and the CSV last: the CSV
marks a finished task. Writing on the driver (not on the workers) means ``DIR`` need only be
visible to the driver, also for a multi-machine Dask cluster; workers ship the table (a few
kB) back with the result. ``DIR/manifest.json`` records what the ensemble is (generator,
sweep options, parameter sets, seeds).

After the last task the driver writes, atomically, ::

    DIR/aggregate.csv    per parameter set and level k: mean, std, 95 % band of the mean
    DIR/thresholds.csv   per surface: the percolation threshold (definition below)
    DIR/ensemble.json    run description, threshold distributions, versions, machine
    DIR/figures/         fig2_vpg_volume_gap, fig3_vpg_moments, thresholds_hist (.png, .pdf)

Statistics (per parameter set, level ``k`` and quantity ``x`` over its ``n`` surfaces)
-------------------------------------------------------------------------------------
``mean = Σ x_i / n``; ``std = √(Σ (x_i − mean)² / (n − 1))`` (ddof = 1); the 95 % confidence
band of the mean is ``mean ± t_{0.975, n−1} · std / √n`` with the Student-t quantile
:func:`student_t_ppf` (no SciPy needed). Quantities (:data:`QUANTITIES`) are the
dimensionless columns of the sweep: ``Δ*``, contact fraction ``a``, ``V*``, ``ḡ*``,
``V_pg*``, ``m0*``, ``m2*``, ``m4*``, ``α*``. A NaN in a surface's table propagates to the
mean (it does not happen for sweeps that start at ``Δ = 0``, where everything is free). With
``n = 1`` the std and the band are NaN. The tables are sorted by parameter key and seed before
aggregation, so the aggregate is byte-for-byte independent of the completion order and of the
executor.

Percolation threshold (per surface, from the sweep rows; no extra solves)
--------------------------------------------------------------------------
``k_c`` is the first level at which no free cluster spans the flow axis
(``n_spanning_axis0 == 0`` for ``axis=0``, ``n_spanning_axis1 == 0`` for ``axis=1``, both
for ``axis="either"``; for ``axis="both"``, where one cluster must span both axes, the
sweep's ``V_pg`` column for that axis is zero). The threshold is reported as

- ``contact_fraction_c = a(k_c)`` — the primary value (the first level that no longer
  percolates; the same side of the transition as
  :attr:`leakpath.threshold.PercolationThreshold.contact_fraction`, but on the sweep's grid
  of levels, so it overestimates the exact threshold by at most one level step);
- ``contact_fraction_below = a(k_c − 1)`` (the last level that percolates) and the midpoint
  ``contact_fraction_mid`` — linear interpolation of the spanning indicator between the two
  levels; the exact threshold lies in ``[below, c]``.

``approach_star_c``/``approach_star_below`` give the same bracket in ``Δ*``. A surface whose
free region spans at every level has ``found = False`` and NaN thresholds; it is counted
(``n_found`` of ``surfaces``) but left out of the distribution (mean, std, band, min,
quantiles 5/25/50/75/95 % with numpy's default linear interpolation, max). **The
distribution is censored**: with a free boundary the sweep stops at ``Δ = h_s``, where the
contact fraction is only ≈ 0.3–0.5, and surfaces whose threshold lies beyond it are missing —
so when ``n_found < surfaces`` the mean over the found ones is biased low (for 100 RMD
surfaces, m = 7, D = 2.1, the threshold was reached on 57).

Executors and threads
---------------------
``executor=None``/``"processes"``: a :class:`concurrent.futures.ProcessPoolExecutor` with
``workers`` processes (default: the CPUs available to this process) started with the
``forkserver`` method (``spawn`` where forkserver is unavailable) — never ``fork``, which is
unsafe in a process that already runs rayon/tqdm threads. The Rust core parallelises with
rayon, whose global pool reads ``RAYON_NUM_THREADS`` the first time it is used, not at
import; a pool initializer sets ``RAYON_NUM_THREADS`` (and ``OMP/OPENBLAS/MKL_NUM_THREADS``)
to ``threads_per_worker`` (default **1**) in each worker before it runs any task, so
``workers`` processes × 1 thread never oversubscribe the cores. An ensemble is embarrassingly
parallel, so one single-threaded task per core is also the most efficient layout; raise
``threads_per_worker`` only when there are fewer tasks than cores. A worker that dies
(``BrokenProcessPool``) loses only the unfinished tasks: they are resubmitted on a fresh
pool; after ``retries + 1`` consecutive broken pools without a finished task the run stops
with ``RuntimeError``. If the driver itself dies (SIGKILL, out of memory), a watchdog thread
in each worker sees the end-of-file of a pipe whose write end only the driver held and ends
the worker at once instead of leaving it orphaned. Workers, the fork server and the resource
tracker do not hold the driver's standard output and error (they point at ``/dev/null``), so
a caller reading the driver's output through a pipe is not kept waiting by them. The workers
never run the calling program again: it may be a script (guarded or not), ``python -c`` or
``python -`` (a generator defined in a script needs the usual ``__main__`` guard).

``executor=<dask.distributed.Client>`` or a scheduler address (``"tcp://host:8786"``; a
Client is created and closed here): the same task function is submitted with
``client.submit(..., retries=retries)`` and collected with ``as_completed``; Dask reschedules
the tasks of a lost worker itself. In a Dask worker the task sets ``RAYON_NUM_THREADS`` to
``threads_per_worker`` (default 1, and then only if the worker's environment does not set
it) — effective if no Rust routine ran in that worker process before. Run the workers with
``--nthreads 1`` and one worker per core: with more Dask threads per worker the concurrent
tasks share that worker's rayon pool. Workers need the same leakpath version installed.
``executor="serial"`` runs the tasks in this process with its own rayon pool (debugging).

Results do not depend on the executor, the number of workers or the completion order: a task
is a deterministic function of its parameter set, seed and rayon thread count (the sweep's
CSV reproduces bit for bit), every executor runs tasks with the same thread count (1 by
default), and the aggregate sorts before it sums. (The rayon thread count matters in the last
bits: parallel reductions in the solver round differently, ~1e-16 relative; each task's JSON
records ``worker.rayon_num_threads``.)

Resuming
--------
``resume=True`` skips every task whose CSV exists and runs only the missing ones (the
manifest must describe the same generator and sweep options; parameter sets and seeds may
grow). ``resume=False`` refuses a non-empty ``DIR`` (``FileExistsError``) unless
``overwrite=True``, which deletes this module's files (``tasks/``, ``figures/``,
``manifest.json``, ``aggregate.csv``, ``thresholds.csv``, ``ensemble.json``) and nothing else.

Testing hooks (environment of the driver; not for production use)
-----------------------------------------------------------------
``LEAKPATH_TEST_KILL_ONCE=<path>``: the first task (in a worker) that removes the existing
file ``<path>`` exits its process with ``os._exit(1)`` after its sweep (a lost worker).
``LEAKPATH_TEST_STOP_AFTER=<n>``: the driver kills itself with SIGKILL right after writing
its ``n``-th task (an interrupted run).
"""

from __future__ import annotations

import csv
import io
import itertools
import json
import math
import multiprocessing
import numbers
import os
import shutil
import signal
import socket
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from datetime import datetime, timezone
from functools import lru_cache
from pathlib import Path
from statistics import NormalDist
from typing import Any

import numpy as np

from ._core import __version__
from ._io import atomic_write_bytes, atomic_write_text, machine_info
from ._io import dumps as _dumps
from ._sweep import sweep as _sweep
from .contact import SOLVERS, contact_modulus
from .surfaces import Surface

__all__ = [
    "ensemble",
    "aggregate",
    "EnsembleResult",
    "ParamSet",
    "QUANTITIES",
    "param_key",
    "threshold_from_rows",
    "student_t_ppf",
    "t_critical",
    "regularized_incomplete_beta",
    "figure_vpg_volume_gap",
    "figure_vpg_moments",
    "figure_threshold_histograms",
    "save_ensemble_figures",
]

PathLike = str | os.PathLike[str]

#: Dimensionless sweep columns aggregated per level (see the module docstring).
QUANTITIES: tuple[str, ...] = (
    "approach_star",
    "contact_fraction",
    "free_volume_star",
    "mean_gap_star",
    "V_pg_star",
    "m0_star",
    "m2_star",
    "m4_star",
    "alpha_star",
)
#: Statistics per quantity in ``aggregate.csv`` (column ``<quantity>_<stat>``).
STATS: tuple[str, ...] = ("mean", "std", "ci_low", "ci_high")
#: Confidence level of the bands.
CONFIDENCE = 0.95
#: Quantiles of the threshold distribution reported in ``ensemble.json``.
THRESHOLD_QUANTILES: tuple[float, ...] = (0.05, 0.25, 0.5, 0.75, 0.95)
#: Columns of ``thresholds.csv`` after the parameter columns.
THRESHOLD_COLUMNS: tuple[str, ...] = (
    "seed",
    "found",
    "k_c",
    "contact_fraction_c",
    "contact_fraction_below",
    "contact_fraction_mid",
    "approach_star_c",
    "approach_star_below",
    "respans",
)

_FORMAT = 1
_GENERATORS: dict[str, tuple[frozenset[str], frozenset[str]]] = {
    # name: (required parameters, allowed parameters)
    "rmd": (frozenset({"m", "D"}), frozenset({"m", "D", "sigma0", "length"})),
    "spectral": (
        frozenset({"shape", "hurst"}),
        frozenset(
            {"shape", "hurst", "length", "rms_height", "rms_slope", "long_cutoff", "short_cutoff"}
        ),
    ),
}
_OWN_FILES = ("manifest.json", "aggregate.csv", "thresholds.csv", "ensemble.json")
_OWN_FILES += ("leakage.csv", "leak_thresholds.csv")  # leakpath.ensemble_leakage
_OWN_DIRS = ("tasks", "figures")
_KILL_ENV = "LEAKPATH_TEST_KILL_ONCE"
_STOP_ENV = "LEAKPATH_TEST_STOP_AFTER"
_THREAD_ENV = ("RAYON_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
_AXES: tuple[Any, ...] = (0, 1, "either", "both")


# ============================================================================ Student t
_TINY = 1e-300


def _betacf(a: float, b: float, x: float) -> float:
    """Continued fraction of the incomplete beta function (modified Lentz)."""
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c = 1.0
    d = 1.0 - qab * x / qap
    d = 1.0 / (d if abs(d) > _TINY else _TINY)
    h = d
    for m in range(1, 100_000):
        m2 = 2 * m
        aa = m * (b - m) * x / ((qam + m2) * (a + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > _TINY else _TINY)
        c = 1.0 + aa / c
        c = c if abs(c) > _TINY else _TINY
        h *= d * c
        aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > _TINY else _TINY)
        c = 1.0 + aa / c
        c = c if abs(c) > _TINY else _TINY
        delta = d * c
        h *= delta
        if abs(delta - 1.0) <= 3e-16:
            return h
    raise ArithmeticError(f"incomplete beta: no convergence for a={a}, b={b}, x={x}")


# Stirling series of ln Γ(x) − [(x − ½) ln x − x + ½ ln 2π]: B_2n / (2n (2n − 1) x^(2n−1)).
_STIRLING = (
    1 / 12,
    -1 / 360,
    1 / 1260,
    -1 / 1680,
    1 / 1188,
    -691 / 360360,
    1 / 156,
    -3617 / 122400,
)


def _stirling_tail(x: float) -> float:
    inv2 = 1.0 / (x * x)
    term, total = 1.0 / x, 0.0
    for c in _STIRLING:
        total += c * term
        term *= inv2
    return total


def _lgamma_ratio(a: float, b: float) -> float:
    """``ln Γ(a + b) − ln Γ(a)`` without the cancellation of two large ``lgamma`` values.

    For ``a ≥ 10``: ``(a − ½)·ln(1 + b/a) + b·ln(a + b) − b`` plus the difference of the
    Stirling series (8 terms, truncation < 1e-17 there); else ``lgamma`` directly.
    """
    if a < 10.0:
        return math.lgamma(a + b) - math.lgamma(a)
    return (
        (a - 0.5) * math.log1p(b / a)
        + b * math.log(a + b)
        - b
        + (_stirling_tail(a + b) - _stirling_tail(a))
    )


def regularized_incomplete_beta(a: float, b: float, x: float, y: float | None = None) -> float:
    """``I_x(a, b) = B(x; a, b)/B(a, b)`` for ``a, b > 0``, ``0 ≤ x ≤ 1``.

    ``y`` may pass ``1 − x`` computed without cancellation. Continued fraction (Numerical
    Recipes §6.4, modified Lentz) on the side of ``(a + 1)/(a + b + 2)`` where it converges
    fast; the prefactor ``x^a y^b / (a B(a, b))`` in logarithms, with ``ln Γ(a + b) − ln Γ(a)``
    free of cancellation. Relative accuracy ≈ 1e-14 for ``a, b ≤ 10³``; the fraction needs
    ``O(√max(a, b))`` terms and loses about that many ulps beyond (1e-12 at ``a = 2·10⁴``).
    """
    if not (a > 0 and b > 0):
        raise ValueError(f"a, b: must be positive, got a={a!r}, b={b!r}")
    if y is None:
        y = 1.0 - x
    if not (0.0 <= x <= 1.0):
        raise ValueError(f"x: must lie in [0, 1], got {x!r}")
    if x == 0.0:
        return 0.0
    if y == 0.0:
        return 1.0
    log_x = math.log1p(-y) if y < 0.5 else math.log(x)
    log_y = math.log1p(-x) if x < 0.5 else math.log(y)
    big, small = max(a, b), min(a, b)
    log_front = _lgamma_ratio(big, small) - math.lgamma(small) + a * log_x + b * log_y
    front = math.exp(log_front)
    if x < (a + 1.0) / (a + b + 2.0):
        return front * _betacf(a, b, x) / a
    return 1.0 - front * _betacf(b, a, y) / b


def _t_upper_tail(t: float, df: float) -> float:
    """``P(T > t)`` for ``t ≥ 0``: ``½ I_{ν/(ν+t²)}(ν/2, ½)``."""
    t2 = t * t
    return 0.5 * regularized_incomplete_beta(0.5 * df, 0.5, df / (df + t2), t2 / (df + t2))


def _t_central(t: float, df: float) -> float:
    """``P(0 < T < t)`` for ``t ≥ 0``: ``½ I_{t²/(ν+t²)}(½, ν/2)`` (no cancellation near 0)."""
    t2 = t * t
    return 0.5 * regularized_incomplete_beta(0.5, 0.5 * df, t2 / (df + t2), df / (df + t2))


def _bisect_increasing(f: Callable[[float], float], target: float) -> float:
    """The ``t ≥ 0`` with ``f(t) = target`` for increasing ``f``, to the last bit."""
    lo, hi = 0.0, 1.0
    while f(hi) < target:
        lo, hi = hi, 2.0 * hi
        if hi > 1e300:  # pragma: no cover - probability within 1e-300 of 0 or 1
            return math.inf
    for _ in range(2100):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if f(mid) < target:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@lru_cache(maxsize=4096)
def student_t_ppf(p: float, df: float) -> float:
    """Quantile ``t_{p, ν}`` of Student's t distribution with ``ν = df`` degrees of freedom.

    Solves ``P(T ≤ t) = p`` by bisection to the last bit, with the tail
    ``P(T > |t|) = ½·I_{ν/(ν+t²)}(ν/2, ½)`` for ``|p − ½| ≥ ¼`` and the central mass
    ``P(0 < T < |t|) = ½·I_{t²/(ν+t²)}(½, ν/2)`` otherwise (``I`` the regularized incomplete
    beta function, :func:`regularized_incomplete_beta`; both forms avoid cancellation). For
    ``ν > 10⁵`` the Cornish–Fisher expansion in the normal quantile ``z`` to ``O(ν⁻⁴)``
    (truncation error < 1e-18 relative); ``ν = ∞`` gives the normal quantile. Relative
    accuracy ≈ 1e-14 (checked against ``scipy.stats.t.ppf`` in the tests).
    """
    p = float(p)
    df = float(df)
    if not (0.0 < p < 1.0):
        raise ValueError(f"p: must lie in (0, 1), got {p!r}")
    if not (df > 0):
        raise ValueError(f"df: must be positive, got {df!r}")
    if p == 0.5:
        return 0.0
    sign = 1.0 if p > 0.5 else -1.0
    if math.isinf(df):
        return NormalDist().inv_cdf(p)
    if df > 1e5:
        z = NormalDist().inv_cdf(p)
        g1 = (z**3 + z) / 4
        g2 = (5 * z**5 + 16 * z**3 + 3 * z) / 96
        g3 = (3 * z**7 + 19 * z**5 + 17 * z**3 - 15 * z) / 384
        g4 = (79 * z**9 + 776 * z**7 + 1482 * z**5 - 1920 * z**3 - 945 * z) / 92160
        return z + g1 / df + g2 / df**2 + g3 / df**3 + g4 / df**4
    tail = 1.0 - p if p > 0.5 else p  # exact for p ≥ ½ (Sterbenz)
    central = p - 0.5 if p > 0.5 else 0.5 - p  # exact for p ∈ [¼, 1]
    if tail <= 0.25:
        t = _bisect_increasing(lambda x: -_t_upper_tail(x, df), -tail)
    else:
        t = _bisect_increasing(lambda x: _t_central(x, df), central)
    return sign * t


def t_critical(n: int, confidence: float = CONFIDENCE) -> float:
    """Two-sided critical value ``t_{(1+c)/2, n−1}`` for a band of the mean of ``n`` values.

    NaN for ``n < 2``. ``t_critical(50) = 2.0095752…`` (95 %).
    """
    if n < 2:
        return math.nan
    return student_t_ppf(0.5 * (1.0 + confidence), n - 1)


# ============================================================================ parameters
def _format_value(value: Any) -> str:
    """Text of a parameter value in keys and CSV cells (floats as ``repr``)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        return repr(float(value))
    if isinstance(value, (list, tuple)):
        return "x".join(_format_value(v) for v in value)
    if value is None:
        return "none"
    return str(value)


def _safe(text: str) -> str:
    return "".join(ch if (ch.isascii() and (ch.isalnum() or ch in "._+-")) else "-" for ch in text)


def param_key(params: Mapping[str, Any]) -> str:
    """Directory-safe key of a parameter set: ``name=value`` over sorted names, joined by ``_``.

    ``param_key({"m": 7, "D": 2.1}) == "D=2.1_m=7"``; floats as ``repr``, sequences joined by
    ``x``; characters other than letters, digits and ``. _ + -`` become ``-``.
    """
    return "_".join(f"{_safe(str(k))}={_safe(_format_value(params[k]))}" for k in sorted(params))


def _sort_token(value: Any) -> tuple[Any, ...]:
    if isinstance(value, bool):
        return (1, int(value))
    if isinstance(value, numbers.Real):
        return (0, float(value))
    if isinstance(value, (list, tuple)):
        return (2, tuple(_sort_token(v) for v in value))
    return (3, str(value))


def _natural_order(params: Mapping[str, Any]) -> tuple[Any, ...]:
    """Sort key of a parameter set: numeric values compare as numbers (m=7 before m=10)."""
    return tuple((k, _sort_token(params[k])) for k in sorted(params))


@dataclass(frozen=True)
class ParamSet:
    """One parameter set of an ensemble: its key, generator arguments and seeds."""

    key: str
    params: dict[str, Any]
    seeds: tuple[int, ...]

    def label(self, names: Sequence[str] | None = None) -> str:
        """``"D = 2.1, m = 7"`` over ``names`` (default: all)."""
        names = sorted(self.params) if names is None else list(names)
        return ", ".join(f"{n} = {_format_value(self.params[n])}" for n in names)


def _json_roundtrip(value: Any) -> Any:
    """JSON-normalised value (tuples → lists); raises ``ValueError`` if not serialisable."""
    try:
        return json.loads(json.dumps(value, allow_nan=False))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"params: values must be JSON numbers, strings or lists ({exc})") from None


def _plain(value: Any) -> Any:
    """numpy scalars/arrays → Python numbers/lists, recursively (tuples stay tuples)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (list, tuple)):
        return type(value)(_plain(v) for v in value)
    return value


def _expand_params(params: Any) -> list[dict[str, Any]]:
    """A dict of lists → its Cartesian product; a list of dicts → itself (validated).

    In a dict, a list (or numpy array) holds the values of that parameter; anything else —
    a number, a string, a tuple such as ``shape=(64, 64)`` — is one value.
    """
    if isinstance(params, Mapping):
        if not params:
            raise ValueError("params: must name at least one parameter")
        names = list(params)
        values = []
        for name in names:
            v = _plain(params[name])
            if isinstance(v, list):
                if not v:
                    raise ValueError(f"params: the list for {name!r} is empty")
            else:
                v = [v]
            values.append(v)
        sets = [dict(zip(names, combo, strict=True)) for combo in itertools.product(*values)]
    elif isinstance(params, Sequence) and not isinstance(params, (str, bytes)):
        sets = []
        for i, item in enumerate(params):
            if not isinstance(item, Mapping):
                raise ValueError(f"params: item {i} must be a dict, got {type(item).__name__}")
            sets.append({k: _plain(v) for k, v in item.items()})
        if not sets:
            raise ValueError("params: the list of parameter sets is empty")
    else:
        raise ValueError(
            "params: expected a dict of lists (e.g. {'D': [2.1, 2.3], 'm': [7]}) or a list of "
            f"dicts, got {type(params).__name__}"
        )
    out = []
    for s in sets:
        for name in s:
            if not isinstance(name, str) or not name:
                raise ValueError(f"params: parameter names must be strings, got {name!r}")
            if name == "seed":
                raise ValueError("params: 'seed' is not a parameter; use surfaces= or seeds=")
        out.append(_json_roundtrip(s))
    return out


def _generator_name(generator: Any) -> str:
    if isinstance(generator, str):
        return generator
    module = getattr(generator, "__module__", "?")
    return f"{module}.{getattr(generator, '__qualname__', repr(generator))}"


def _check_generator(generator: Any, sets: list[dict[str, Any]]) -> None:
    if callable(generator) and not isinstance(generator, str):
        return
    if generator not in _GENERATORS:
        raise ValueError(
            f"generator: must be one of {', '.join(_GENERATORS)} or a callable, got {generator!r}"
        )
    required, allowed = _GENERATORS[generator]
    for s in sets:
        missing = sorted(required - set(s))
        unknown = sorted(set(s) - allowed)
        if missing:
            raise ValueError(f"params: generator {generator!r} needs {', '.join(missing)}")
        if unknown:
            raise ValueError(
                f"params: generator {generator!r} does not take {', '.join(unknown)} "
                f"(allowed: {', '.join(sorted(allowed))})"
            )


def _generate(generator: Any, params: Mapping[str, Any], seed: int) -> Surface:
    """The surface of one task: ``generator(**params, seed=seed)``."""
    kwargs = dict(params)
    if generator == "rmd":
        from .generators import rmd

        return rmd(seed=seed, **kwargs)
    if generator == "spectral":
        from .generators import spectral

        if isinstance(kwargs.get("shape"), list):
            kwargs["shape"] = tuple(kwargs["shape"])
        return spectral(seed=seed, **kwargs)
    surface = generator(seed=seed, **kwargs)
    if not isinstance(surface, Surface):
        raise ValueError(f"generator: must return a leakpath Surface, got {type(surface).__name__}")
    return surface


# ============================================================================ threshold
def _spans(row: Mapping[str, Any], axis: Any) -> bool:
    """Whether the free region of a sweep row spans ``axis`` (see the module docstring)."""
    if axis == 0:
        return int(row["n_spanning_axis0"]) > 0
    if axis == 1:
        return int(row["n_spanning_axis1"]) > 0
    if axis == "either":
        return int(row["n_spanning_axis0"]) > 0 or int(row["n_spanning_axis1"]) > 0
    if axis == "both":  # one cluster spanning both axes: only the V_pg column knows
        return float(row["V_pg"]) > 0.0
    raise ValueError(f"axis: must be 0, 1, 'either' or 'both', got {axis!r}")


def threshold_from_rows(rows: Sequence[Mapping[str, Any]], axis: Any = 0) -> dict[str, Any]:
    """Percolation threshold of one sweep from its rows (module docstring, no extra solves).

    Returns ``found``, ``k_c`` (first level whose free region does not span ``axis``; −1 if
    none), ``contact_fraction_c = a(k_c)``, ``contact_fraction_below = a(k_c − 1)`` (NaN for
    ``k_c = 0``), ``contact_fraction_mid`` (their mean: linear interpolation of the spanning
    indicator), ``approach_star_c``, ``approach_star_below`` and ``respans`` (a later level
    spans again, which a monotonically growing contact set rules out).
    """
    nan = math.nan
    k_c = next((k for k, row in enumerate(rows) if not _spans(row, axis)), -1)
    if k_c < 0:
        return {
            "found": False,
            "k_c": -1,
            "contact_fraction_c": nan,
            "contact_fraction_below": nan,
            "contact_fraction_mid": nan,
            "approach_star_c": nan,
            "approach_star_below": nan,
            "respans": False,
        }
    a_c = float(rows[k_c]["contact_fraction"])
    d_c = float(rows[k_c]["approach_star"])
    a_b = float(rows[k_c - 1]["contact_fraction"]) if k_c > 0 else nan
    d_b = float(rows[k_c - 1]["approach_star"]) if k_c > 0 else nan
    return {
        "found": True,
        "k_c": k_c,
        "contact_fraction_c": a_c,
        "contact_fraction_below": a_b,
        "contact_fraction_mid": 0.5 * (a_b + a_c) if k_c > 0 else a_c,
        "approach_star_c": d_c,
        "approach_star_below": d_b,
        "respans": any(_spans(row, axis) for row in rows[k_c + 1 :]),
    }


# ============================================================================ tasks
@dataclass(frozen=True)
class _TaskSpec:
    """Everything a worker needs for one task (picklable, no surface arrays)."""

    generator: Any
    params: dict[str, Any]
    key: str
    seed: int
    levels: int
    solver: str
    warm_start: bool
    axis: Any
    connectivity: int
    E: float  # noqa: N815 - Young's modulus
    nu: float
    boundary: str
    kill_once: str | None = None


@dataclass(frozen=True)
class _TaskOutput:
    key: str
    seed: int
    csv_text: str
    meta: dict[str, Any]
    seconds: float


def _run_task(spec: _TaskSpec) -> _TaskOutput:
    """Generate the surface, run the sweep, return its CSV and metadata (runs in a worker)."""
    t0 = time.perf_counter()
    c0 = time.process_time()
    surface = _generate(spec.generator, spec.params, spec.seed)
    result = _sweep(
        surface,
        levels=spec.levels,
        solver=spec.solver,
        warm_start=spec.warm_start,
        axis=spec.axis,
        connectivity=spec.connectivity,
        E=spec.E,
        nu=spec.nu,
        boundary=spec.boundary,
    )
    if spec.kill_once:  # test hook: a worker lost after doing its work
        try:
            os.remove(spec.kill_once)
        except FileNotFoundError:
            pass
        else:
            os._exit(1)
    seconds = time.perf_counter() - t0
    cpu_seconds = time.process_time() - c0
    meta = {
        "format": _FORMAT,
        "key": spec.key,
        "params": spec.params,
        "seed": spec.seed,
        "generator": _generator_name(spec.generator),
        "threshold": threshold_from_rows(result.rows, spec.axis),
        "task_seconds": seconds,
        # CPU time of the whole worker process (all its threads) during the task: the task's
        # own CPU time when the worker runs one task at a time (local processes).
        "task_cpu_seconds": cpu_seconds,
        "worker": {
            "host": socket.gethostname(),
            "pid": os.getpid(),
            "rayon_num_threads": os.environ.get("RAYON_NUM_THREADS"),
        },
        "sweep": result.metadata(),
    }
    return _TaskOutput(spec.key, spec.seed, result.csv_text(), meta, seconds)


def _run_task_dask(spec: _TaskSpec, threads: int | None) -> _TaskOutput:
    """:func:`_run_task` in a Dask worker, with ``RAYON_NUM_THREADS`` set first.

    ``threads=None``: 1 unless the worker's environment sets ``RAYON_NUM_THREADS``; an
    integer overrides it. Takes effect if rayon's global pool has not started in this worker
    process yet (it starts on the first Rust routine, i.e. in the first task).
    """
    if threads is None:
        os.environ.setdefault("RAYON_NUM_THREADS", "1")
    else:
        os.environ["RAYON_NUM_THREADS"] = str(int(threads))
    return _run_task(spec)


def _watch_driver(alive: Any) -> None:
    """Exit this worker as soon as the driver process is gone (never returns otherwise).

    ``alive`` is the read end of a pipe whose only write end the driver holds and never
    writes to: the read end sees end-of-file when the driver dies, however it dies, and
    unlike a probe of its process id it cannot mistake a killed driver that its own parent
    has not reaped yet (a zombie) for a live one.
    """
    try:
        alive.poll(None)
    except (OSError, EOFError):
        pass
    os._exit(1)


def _init_worker(threads: int, alive: Any = None) -> None:
    """Process-pool initializer: limit rayon (and BLAS) threads before any task runs.

    rayon builds its global pool on first use and reads ``RAYON_NUM_THREADS`` then, so
    setting it here — after ``leakpath`` may already have been imported, but before any
    Rust routine ran — takes effect. BLAS libraries read their variables when numpy is
    loaded; leakpath's hot loops do not use BLAS, so those are set for any child processes.

    The worker's standard output and error go to ``/dev/null``: a worker must not keep the
    driver's (a pipe its caller may be reading to the end) open. Results and errors travel
    back through the pool.

    With ``alive`` (see :func:`_watch_driver`), a daemon thread ends the worker as soon as
    the driver dies (a killed driver cannot shut its pool down; the workers would otherwise
    wait for work forever).
    """
    for name in _THREAD_ENV:
        os.environ[name] = str(int(threads))
    _detach_stdio()
    if alive is not None:
        import threading

        threading.Thread(
            target=_watch_driver, args=(alive,), name="leakpath-driver-watch", daemon=True
        ).start()


def _flush_std_streams() -> None:
    """Flush Python's stdout and stderr before their file descriptors are redirected."""
    for stream in (sys.stdout, sys.stderr):
        try:
            if stream is not None:
                stream.flush()
        except (OSError, ValueError):
            pass


def _detach_stdio() -> None:
    """Point file descriptors 1 and 2 of this process at ``/dev/null``."""
    _flush_std_streams()
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        for fd in (1, 2):
            os.dup2(devnull, fd)
    finally:
        os.close(devnull)


class _StartingChildren:
    """While the pool starts its helper processes (fork server, resource tracker, workers):

    * fds 1 and 2 point at ``/dev/null``, so none of them inherits the driver's standard
      output or error — a killed driver's caller reading them through a pipe then sees
      end-of-file at once;
    * ``__main__`` hides its path, unless the generator is a function defined there:
      ``spawn``/``forkserver`` children would otherwise run the calling program again as
      their main module — which fails when it is not a file (``python -``, a piped script,
      an interactive session) and starts the ensemble again in every worker when a script
      lacks the ``if __name__ == "__main__"`` guard. The tasks need nothing else from it.
    """

    def __init__(self, keep_main: bool = False) -> None:
        self.keep_main = keep_main

    def __enter__(self) -> _StartingChildren:
        self.saved: list[tuple[int, int]] = []
        _flush_std_streams()
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            for fd in (1, 2):
                try:
                    self.saved.append((fd, os.dup(fd)))
                except OSError:
                    continue
                os.dup2(devnull, fd)
        finally:
            os.close(devnull)
        self.main = sys.modules.get("__main__")
        self.main_file = getattr(self.main, "__file__", None)
        self.hidden = (
            not self.keep_main
            and self.main is not None
            and self.main_file is not None
            and getattr(self.main, "__spec__", None) is None
        )
        if self.hidden:
            del self.main.__file__
        return self

    def __exit__(self, *exc: Any) -> None:
        if self.hidden:
            self.main.__file__ = self.main_file
        for fd, copy in self.saved:
            os.dup2(copy, fd)
            os.close(copy)


# ============================================================================ file layout
def _task_dir(out: Path, key: str) -> Path:
    return out / "tasks" / key


def _task_csv(out: Path, key: str, seed: int) -> Path:
    return _task_dir(out, key) / f"seed-{seed}.csv"


def _task_json(out: Path, key: str, seed: int) -> Path:
    return _task_dir(out, key) / f"seed-{seed}.json"


def _write_task(out: Path, result: _TaskOutput) -> None:
    """Write a finished task: its JSON, then its CSV (the completion marker), atomically."""
    directory = _task_dir(out, result.key)
    directory.mkdir(parents=True, exist_ok=True)
    atomic_write_text(_task_json(out, result.key, result.seed), _dumps(result.meta))
    atomic_write_text(_task_csv(out, result.key, result.seed), result.csv_text)


def _task_done(out: Path, key: str, seed: int) -> bool:
    return _task_csv(out, key, seed).is_file() and _task_json(out, key, seed).is_file()


def _clean_stale_temporaries(out: Path) -> None:
    """Remove the hidden temporaries of atomic writes cut short by a killed run: in the task
    directories, ``figures/`` and ``DIR`` itself."""
    patterns = ("tasks/*/.*.tmp", "figures/.*.tmp", ".*.tmp")
    for pattern in patterns:
        for stale in out.glob(pattern):
            try:
                stale.unlink()
            except OSError:
                pass


def _parse_cell(text: str) -> Any:
    """CSV cell → int (no point/exponent), float (``repr`` text, exact) or the string."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def _read_table(path: Path) -> list[dict[str, Any]]:
    """A per-surface CSV as rows of ints/floats/strings (the CSV floats round-trip exactly)."""
    with open(path, encoding="utf-8", newline="") as fh:
        rows = [
            {name: _parse_cell(text) for name, text in raw.items()} for raw in csv.DictReader(fh)
        ]
    if not rows:
        raise ValueError(f"{str(path)!r}: empty table")
    missing = [c for c in (*QUANTITIES, "n_spanning_axis0", "n_spanning_axis1") if c not in rows[0]]
    if missing:
        raise ValueError(f"{str(path)!r}: missing columns {', '.join(missing)}")
    return rows


# ============================================================================ manifest
def _identity(
    generator: Any,
    levels: int,
    solver: str,
    warm_start: bool,
    axis: Any,
    connectivity: int,
    E: float,
    nu: float,
    boundary: str,  # noqa: N803
) -> dict[str, Any]:
    return {
        "generator": _generator_name(generator),
        "levels": levels,
        "solver": solver,
        "warm_start": warm_start,
        "axis": axis,
        "connectivity": connectivity,
        "E": E,
        "nu": nu,
        "boundary": boundary,
    }


def _read_manifest(out: Path) -> dict[str, Any]:
    path = out / "manifest.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ValueError(
            f"out: {str(out)!r} holds no leakpath ensemble (no manifest.json)"
        ) from None
    except (OSError, ValueError) as exc:
        raise ValueError(f"out: cannot read {str(path)!r} ({exc})") from None
    if data.get("kind") != "leakpath-ensemble" or data.get("format") != _FORMAT:
        raise ValueError(f"out: {str(path)!r} is not a leakpath ensemble manifest")
    return data


def _param_sets_from_manifest(manifest: Mapping[str, Any]) -> list[ParamSet]:
    sets = [
        ParamSet(str(p["key"]), dict(p["params"]), tuple(int(s) for s in p["seeds"]))
        for p in manifest["param_sets"]
    ]
    return sorted(sets, key=lambda ps: _natural_order(ps.params))


# ============================================================================ result
@dataclass(eq=False)
class EnsembleResult:
    """Aggregated ensemble (see the module docstring for the files and definitions).

    Attributes
    ----------
    directory : Path
        The ensemble directory ``DIR``.
    param_sets : list of ParamSet
        In natural order of their parameters (numbers compare as numbers).
    identity : dict
        Generator and sweep options (``levels``, ``solver``, ``warm_start``, ``axis``, …).
    aggregate : list of dict
        Rows of ``aggregate.csv``: ``param_key``, the parameters, ``k``, ``n`` and
        ``<quantity>_<stat>`` for :data:`QUANTITIES` × :data:`STATS`.
    thresholds : list of dict
        Rows of ``thresholds.csv`` (one per surface).
    threshold_summary : dict
        Per key: ``n``, ``n_found``, ``mean``, ``std``, ``ci_low``, ``ci_high``, ``min``,
        ``max`` and ``quantiles`` of ``contact_fraction_c`` (and the same for
        ``approach_star_c`` under ``"approach_star"``).
    run : dict or None
        How the run went (executor, workers, tasks run/resumed, pool restarts, wall time);
        ``None`` for :func:`aggregate` alone.
    """

    directory: Path
    param_sets: list[ParamSet]
    identity: dict[str, Any]
    aggregate: list[dict[str, Any]]
    thresholds: list[dict[str, Any]]
    threshold_summary: dict[str, dict[str, Any]]
    run: dict[str, Any] | None = None
    figures: list[Path] = field(default_factory=list)

    def __repr__(self) -> str:
        # The aggregate and threshold tables have hundreds of rows: summarise them.
        surfaces = sum(len(ps.seeds) for ps in self.param_sets)
        return (
            f"EnsembleResult(directory={str(self.directory)!r}, "
            f"param_sets=[{', '.join(self.keys)}], surfaces={surfaces}, "
            f"levels={self.identity.get('levels')}, aggregate_rows={len(self.aggregate)}, "
            f"figures={len(self.figures)})"
        )

    @property
    def keys(self) -> list[str]:
        return [ps.key for ps in self.param_sets]

    def param_set(self, key: str) -> ParamSet:
        for ps in self.param_sets:
            if ps.key == key:
                return ps
        raise KeyError(key)

    def curve(self, key: str, quantity: str) -> dict[str, np.ndarray]:
        """``k``, ``mean``, ``std``, ``ci_low``, ``ci_high`` of ``quantity`` over the levels."""
        if quantity not in QUANTITIES:
            raise ValueError(f"quantity: must be one of {', '.join(QUANTITIES)}, got {quantity!r}")
        rows = [r for r in self.aggregate if r["param_key"] == key]
        if not rows:
            raise KeyError(key)
        out = {"k": np.array([r["k"] for r in rows], dtype=np.int64)}
        for stat in STATS:
            out[stat] = np.array([r[f"{quantity}_{stat}"] for r in rows], dtype=np.float64)
        return out

    def threshold_values(self, key: str, column: str = "contact_fraction_c") -> np.ndarray:
        """Per-surface thresholds of one parameter set (found ones only), in seed order."""
        return np.array(
            [r[column] for r in self.thresholds if r["param_key"] == key and r["found"]],
            dtype=np.float64,
        )

    def table(self, key: str, seed: int) -> list[dict[str, Any]]:
        """The per-surface sweep table of task ``(key, seed)``, read from its CSV."""
        return _read_table(_task_csv(self.directory, key, seed))

    @property
    def aggregate_path(self) -> Path:
        return self.directory / "aggregate.csv"

    @property
    def thresholds_path(self) -> Path:
        return self.directory / "thresholds.csv"

    @property
    def json_path(self) -> Path:
        return self.directory / "ensemble.json"

    def summary(self) -> dict[str, Any]:
        """The content of ``ensemble.json``."""
        return json.loads(self.json_path.read_text(encoding="utf-8"))

    def plot(
        self, outdir: PathLike | None = None, formats: Sequence[str] = ("png", "pdf")
    ) -> list[Path]:
        """Write the ensemble figures (default ``DIR/figures``); see
        :func:`save_ensemble_figures`."""
        return save_ensemble_figures(self, outdir, formats=formats)


# ============================================================================ aggregation
def _cell(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    text = _format_value(value)
    if any(c in text for c in ',"\n\r'):
        text = '"' + text.replace('"', '""') + '"'
    return text


def _csv(rows: Sequence[Mapping[str, Any]], columns: Sequence[str]) -> str:
    lines = [",".join(columns)]
    lines += [",".join(_cell(row.get(c, "")) for c in columns) for row in rows]
    return "\n".join(lines) + "\n"


def _describe(values: np.ndarray) -> dict[str, Any]:
    """n, mean, std (ddof 1), 95 % band of the mean, min, quantiles, max of finite values."""
    v = values[np.isfinite(values)]
    n = int(v.size)
    nan = math.nan
    if n == 0:
        return {
            "n": 0,
            "mean": nan,
            "std": nan,
            "ci_low": nan,
            "ci_high": nan,
            "min": nan,
            "max": nan,
            "quantiles": {str(q): nan for q in THRESHOLD_QUANTILES},
        }
    mean = float(np.mean(v))
    std = float(np.std(v, ddof=1)) if n > 1 else nan
    half = t_critical(n) * std / math.sqrt(n) if n > 1 else nan
    return {
        "n": n,
        "mean": mean,
        "std": std,
        "ci_low": mean - half,
        "ci_high": mean + half,
        "min": float(np.min(v)),
        "max": float(np.max(v)),
        "quantiles": {str(q): float(np.quantile(v, q)) for q in THRESHOLD_QUANTILES},
    }


def _aggregate_set(
    ps: ParamSet, tables: list[list[dict[str, Any]]], param_names: Sequence[str]
) -> list[dict[str, Any]]:
    """Rows of ``aggregate.csv`` for one parameter set (tables in seed order)."""
    n_levels = {len(t) for t in tables}
    if len(n_levels) != 1:
        raise ValueError(
            f"{ps.key}: the per-surface tables have different numbers of levels "
            f"({sorted(n_levels)})"
        )
    levels = n_levels.pop()
    n = len(tables)
    tcrit = t_critical(n)
    data = {
        q: np.array([[row[q] for row in t] for t in tables], dtype=np.float64) for q in QUANTITIES
    }  # (n surfaces, levels)
    rows = []
    for k in range(levels):
        row: dict[str, Any] = {"param_key": ps.key}
        row.update({name: ps.params.get(name, "") for name in param_names})
        row["k"] = k
        row["n"] = n
        for q in QUANTITIES:
            x = data[q][:, k]
            mean = float(np.mean(x))
            if n > 1:
                std = float(np.std(x, ddof=1))
                half = tcrit * std / math.sqrt(n)
            else:
                std = half = math.nan
            row[f"{q}_mean"] = mean
            row[f"{q}_std"] = std
            row[f"{q}_ci_low"] = mean - half
            row[f"{q}_ci_high"] = mean + half
        rows.append(row)
    return rows


def aggregate(
    out: PathLike, *, figures: bool = True, run: Mapping[str, Any] | None = None
) -> EnsembleResult:
    """Aggregate the finished ensemble in ``out`` (every task of its manifest must exist).

    Writes ``aggregate.csv``, ``thresholds.csv`` and ``ensemble.json`` atomically (and the
    figures with ``figures=True``) and returns the :class:`EnsembleResult`. The output depends
    only on the per-surface CSVs and the manifest: tables are read in the order of the
    parameter sets (natural order of their values) and seeds (ascending).

    Raises
    ------
    ValueError
        ``out`` holds no ensemble, or a task's table is missing or malformed.
    """
    directory = Path(out)
    manifest = _read_manifest(directory)
    identity = dict(manifest["identity"])
    axis = identity["axis"]
    param_sets = _param_sets_from_manifest(manifest)
    missing = [
        f"{ps.key}/seed-{s}"
        for ps in param_sets
        for s in ps.seeds
        if not _task_csv(directory, ps.key, s).is_file()
    ]
    if missing:
        more = f" (and {len(missing) - 5} more)" if len(missing) > 5 else ""
        raise ValueError(
            f"out: {len(missing)} task(s) not finished: {', '.join(missing[:5])}{more}; "
            "run the ensemble with resume=True (CLI --resume) to finish them"
        )
    param_names = sorted({name for ps in param_sets for name in ps.params})
    agg_rows: list[dict[str, Any]] = []
    thr_rows: list[dict[str, Any]] = []
    summary: dict[str, dict[str, Any]] = {}
    leak_sets = []  # leakpath.ensemble_leakage
    for ps in param_sets:
        seeds = sorted(ps.seeds)
        tables = [_read_table(_task_csv(directory, ps.key, s)) for s in seeds]
        leak_sets.append((ps, seeds, tables))  # leakpath.ensemble_leakage
        agg_rows += _aggregate_set(ps, tables, param_names)
        set_thr = []
        for seed, table in zip(seeds, tables, strict=True):
            thr = threshold_from_rows(table, axis)
            row = {
                "param_key": ps.key,
                **{n: ps.params.get(n, "") for n in param_names},
                "seed": seed,
                **thr,
            }
            set_thr.append(row)
        thr_rows += set_thr
        a_c = np.array([r["contact_fraction_c"] for r in set_thr], dtype=np.float64)
        d_c = np.array([r["approach_star_c"] for r in set_thr], dtype=np.float64)
        summary[ps.key] = {
            "params": ps.params,
            "surfaces": len(seeds),
            "n_found": int(sum(1 for r in set_thr if r["found"])),
            "n_respans": int(sum(1 for r in set_thr if r["respans"])),
            "contact_fraction": _describe(a_c),
            "approach_star": _describe(d_c),
        }

    agg_columns = ["param_key", *param_names, "k", "n"] + [
        f"{q}_{s}" for q in QUANTITIES for s in STATS
    ]
    thr_columns = ["param_key", *param_names, *THRESHOLD_COLUMNS]
    atomic_write_text(directory / "aggregate.csv", _csv(agg_rows, agg_columns))
    atomic_write_text(directory / "thresholds.csv", _csv(thr_rows, thr_columns))
    from .ensemble_leakage import write_leak_statistics  # leak-rate bands and thresholds

    leak_summary = write_leak_statistics(directory, leak_sets, param_names, axis, figures)

    result = EnsembleResult(
        directory=directory,
        param_sets=param_sets,
        identity=identity,
        aggregate=agg_rows,
        thresholds=thr_rows,
        threshold_summary=summary,
        run=dict(run) if run is not None else None,
    )
    if figures:
        result.figures = save_ensemble_figures(result)
    doc = {
        "format": _FORMAT,
        "kind": "leakpath-ensemble-summary",
        "leakpath_version": __version__,
        "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "directory": str(directory.resolve()),
        "identity": identity,
        "param_sets": [
            {"key": ps.key, "params": ps.params, "seeds": sorted(ps.seeds)} for ps in param_sets
        ],
        "quantities": list(QUANTITIES),
        "statistics": {
            "mean": "sum(x_i)/n over the surfaces of a parameter set, per level k",
            "std": "sqrt(sum((x_i - mean)^2)/(n - 1))",
            "ci": f"mean -/+ t_((1+c)/2, n-1) * std/sqrt(n), c = {CONFIDENCE}",
        },
        "threshold_definition": (
            "k_c = first level whose free region does not span the flow axis (n_spanning == 0);"
            " contact_fraction_c = a(k_c) (primary); contact_fraction_below = a(k_c - 1); "
            "contact_fraction_mid = their mean (linear interpolation of the spanning "
            "indicator); distribution statistics over surfaces with found = true"
        ),
        "thresholds": summary,
        "leakage": leak_summary,  # leakpath.ensemble_leakage
        "run": result.run,
        "files": {
            "aggregate": "aggregate.csv",
            "thresholds": "thresholds.csv",
            "tasks": "tasks/<param_key>/seed-<s>.csv (+ .json)",
            "figures": [str(p.relative_to(directory)) for p in result.figures],
        },
        "machine": machine_info(),
    }
    atomic_write_text(directory / "ensemble.json", _dumps(doc))
    return result


# ============================================================================ executors
def _cpus() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))  # type: ignore[attr-defined]
    except (AttributeError, OSError):  # pragma: no cover - non-Linux
        return max(1, os.cpu_count() or 1)


def _mp_context() -> multiprocessing.context.BaseContext:
    methods = multiprocessing.get_all_start_methods()
    return multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")


def _is_dask_client(obj: Any) -> bool:
    try:
        from distributed import Client
    except ImportError:
        return False
    return isinstance(obj, Client)


def _dask_client(address: str) -> Any:
    try:
        from distributed import Client
    except ImportError:
        raise ImportError(
            "executor: a Dask scheduler address needs dask.distributed; "
            "install it with pip install 'leakpath[dask]'"
        ) from None
    return Client(address)


class _Driver:
    """Bookkeeping shared by the executors: write finished tasks, count, report progress."""

    def __init__(self, out: Path, total: int, done_before: int, progress: bool):
        self.out = out
        self.written: list[tuple[str, int]] = []
        self.failed: list[tuple[str, int, str]] = []
        self.compute_seconds = 0.0
        stop = os.environ.get(_STOP_ENV)
        self.stop_after = int(stop) if stop else None
        self.bar = None
        if progress:
            from tqdm.auto import tqdm

            self.bar = tqdm(
                total=total,
                initial=done_before,
                desc="ensemble",
                unit="task",
                file=sys.stderr,
                disable=None,
                dynamic_ncols=True,
            )

    def done(self, result: _TaskOutput) -> None:
        _write_task(self.out, result)
        self.written.append((result.key, result.seed))
        self.compute_seconds += result.seconds
        if self.bar is not None:
            self.bar.update(1)
        if self.stop_after is not None and len(self.written) >= self.stop_after:
            # test hook: an interrupted driver (no clean-up at all)
            os.kill(os.getpid(), getattr(signal, "SIGKILL", signal.SIGTERM))

    def error(self, spec: _TaskSpec, exc: BaseException) -> None:
        self.failed.append((spec.key, spec.seed, f"{type(exc).__name__}: {exc}"))
        if self.bar is not None:
            self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _run_serial(specs: list[_TaskSpec], driver: _Driver) -> dict[str, Any]:
    for spec in specs:
        try:
            result = _run_task(spec)
        except (KeyboardInterrupt, SystemExit):
            raise
        except Exception as exc:  # noqa: BLE001 - reported per task
            driver.error(spec, exc)
        else:
            driver.done(result)
    return {"executor": "serial", "workers": 1}


def _run_processes(
    specs: list[_TaskSpec], driver: _Driver, workers: int, threads: int, retries: int
) -> dict[str, Any]:
    """Local process pool; a broken pool is replaced and the unfinished tasks resubmitted."""
    ctx = _mp_context()
    pending = {(s.key, s.seed): s for s in specs}
    # Workers watch the read end; only this process holds the write end (see _watch_driver).
    alive_r, alive_w = ctx.Pipe(duplex=False)
    try:
        return _run_pools(ctx, pending, driver, workers, threads, retries, alive_r)
    finally:
        alive_r.close()
        alive_w.close()


def _run_pools(
    ctx: Any,
    pending: dict[tuple[str, int], _TaskSpec],
    driver: _Driver,
    workers: int,
    threads: int,
    retries: int,
    alive: Any,
) -> dict[str, Any]:
    restarts = 0
    stalls = 0
    generator = next(iter(pending.values())).generator
    keep_main = getattr(generator, "__module__", None) == "__main__"
    while pending:
        # Worker processes start while the pool is built and tasks are submitted.
        with _StartingChildren(keep_main):
            pool = ProcessPoolExecutor(
                max_workers=min(workers, len(pending)),
                mp_context=ctx,
                initializer=_init_worker,
                initargs=(threads, alive),
            )
        broken = False
        finished_here = 0
        clean = False
        try:
            with _StartingChildren(keep_main):
                futures = {pool.submit(_run_task, spec): tid for tid, spec in pending.items()}
            not_done = set(futures)
            while not_done:
                done, not_done = wait(not_done, return_when=FIRST_COMPLETED)
                for fut in sorted(done, key=lambda f: futures[f]):
                    tid = futures[fut]
                    try:
                        result = fut.result()
                    except BrokenProcessPool:
                        broken = True
                        continue
                    except Exception as exc:  # noqa: BLE001 - the task's own error
                        driver.error(pending.pop(tid), exc)
                        finished_here += 1
                        continue
                    driver.done(result)
                    pending.pop(tid)
                    finished_here += 1
            clean = True
        finally:
            # After Ctrl-C or an error in the driver do not wait for running tasks.
            pool.shutdown(wait=clean, cancel_futures=True)
        if broken and pending:
            restarts += 1
            stalls = 0 if finished_here else stalls + 1
            if stalls > retries:
                names = ", ".join(f"{k}/seed-{s}" for k, s in list(pending)[:5])
                raise RuntimeError(
                    f"worker processes died {stalls} times in a row without finishing a task "
                    f"(unfinished: {names}{' …' if len(pending) > 5 else ''}); the finished "
                    "tasks are saved, rerun with resume=True"
                )
    return {
        "executor": "processes",
        "start_method": ctx.get_start_method(),
        "workers": workers,
        "threads_per_worker": threads,
        "pool_restarts": restarts,
    }


def _run_dask(
    client: Any, specs: list[_TaskSpec], driver: _Driver, retries: int, threads: int | None
) -> dict[str, Any]:
    """Submit every task to a Dask cluster; write each result as it arrives."""
    from distributed import as_completed

    token = os.urandom(4).hex()
    futures = {}
    for spec in specs:
        fut = client.submit(
            _run_task_dask,
            spec,
            threads,
            key=f"leakpath-ensemble-{token}-{spec.key}-seed-{spec.seed}",
            pure=False,
            retries=retries,
        )
        futures[fut.key] = (fut, spec)
    try:
        for fut in as_completed([f for f, _ in futures.values()]):
            spec = futures[fut.key][1]
            if fut.status == "finished":
                driver.done(fut.result())
            else:
                try:
                    exc = fut.exception()
                except BaseException as err:  # noqa: BLE001 - e.g. CancelledError
                    exc = err
                driver.error(spec, exc if exc is not None else RuntimeError(fut.status))
            fut.release()
    except BaseException:
        for fut, _ in futures.values():
            fut.cancel()
        raise
    try:
        info = client.scheduler_info()
        n_workers = len(info.get("workers", {}))
        total = sum(int(w.get("nthreads", 0)) for w in info.get("workers", {}).values())
    except Exception:  # noqa: BLE001 - informational only
        n_workers = total = None
    return {
        "executor": "dask",
        "scheduler": getattr(getattr(client, "scheduler", None), "address", None),
        "workers": n_workers,
        "dask_threads": total,
        "rayon_threads_per_task": threads if threads is not None else "1 (or worker env)",
        "retries": retries,
    }


# ============================================================================ validation
def _check_int(name: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        raise ValueError(f"{name}: must be an integer ≥ {minimum}, got {value!r}")
    return int(value)


def _resolve_seeds(surfaces: Any, seeds: Any) -> tuple[int, ...]:
    if seeds is None:
        n = 50 if surfaces is None else _check_int("surfaces", surfaces, 1)
        return tuple(range(n))
    if isinstance(seeds, (str, bytes)) or not isinstance(seeds, Iterable):
        raise ValueError(f"seeds: must be a sequence of non-negative integers, got {seeds!r}")
    out = tuple(_check_int("seeds", s, 0) for s in seeds)
    if not out:
        raise ValueError("seeds: must not be empty")
    if len(set(out)) != len(out):
        raise ValueError("seeds: must be distinct")
    if surfaces is not None and _check_int("surfaces", surfaces, 1) != len(out):
        raise ValueError(f"surfaces: {surfaces} does not match the {len(out)} seeds given")
    return tuple(sorted(out))


def _prepare_directory(out: Path, resume: bool, overwrite: bool) -> dict[str, Any] | None:
    """Check/clean ``out`` for a new run or a resumed one; returns the old manifest if any."""
    if resume and overwrite:
        raise ValueError("resume, overwrite: choose one (resume keeps finished tasks)")
    if out.exists() and not out.is_dir():
        raise ValueError(f"out: {str(out)!r} exists and is not a directory")
    if not out.exists():
        out.mkdir(parents=True)
        return None
    if resume:
        if (out / "manifest.json").exists():
            return _read_manifest(out)
        if any(out.iterdir()):
            raise ValueError(
                f"out: {str(out)!r} is not empty and holds no leakpath ensemble to resume"
            )
        return None
    if overwrite:
        for name in _OWN_DIRS:
            if (out / name).is_dir():
                shutil.rmtree(out / name)
        for name in _OWN_FILES:
            if (out / name).is_file():
                (out / name).unlink()
        return None
    if any(out.iterdir()):
        raise FileExistsError(
            f"out: {str(out)!r} is not empty; resume the ensemble there (resume=True, CLI "
            "--resume) or replace it (overwrite=True, CLI --overwrite)"
        )
    return None


# ============================================================================ entry point
def ensemble(
    *,
    generator: str | Callable[..., Surface] = "rmd",
    params: Mapping[str, Any] | Sequence[Mapping[str, Any]],
    surfaces: int | None = None,
    seeds: Iterable[int] | None = None,
    levels: int = 20,
    solver: str = "auto",
    warm_start: bool = True,
    axis: int | str = 0,
    connectivity: int = 4,
    E: float = 1.0,  # noqa: N803 - Young's modulus
    nu: float = 0.0,
    boundary: str = "free",
    out: PathLike,
    executor: Any = None,
    workers: int | None = None,
    threads_per_worker: int | None = None,
    retries: int = 2,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool = True,
    figures: bool = True,
) -> EnsembleResult:
    """Run one sweep per (parameter set, seed) in parallel and aggregate them.

    Parameters
    ----------
    generator : "rmd", "spectral" or callable
        Surface generator: :func:`leakpath.rmd` (parameters ``m``, ``D``, optional
        ``sigma0``, ``length``), :func:`leakpath.spectral` (``shape``, ``hurst``, …) or a
        picklable callable ``f(*, seed, **params) -> Surface``.
    params : dict of lists, or list of dicts
        ``{"D": [2.1, 2.3, 2.5], "m": [7]}`` runs the Cartesian product (a scalar counts as a
        one-element list); a list of dicts gives the sets explicitly.
    surfaces : int, optional
        Surfaces per parameter set, seeds ``0 … surfaces − 1`` (default 50).
    seeds : sequence of int, optional
        Explicit seeds instead (the same for every parameter set).
    levels, solver, warm_start, axis, connectivity, E, nu, boundary
        Passed to :func:`leakpath.sweep.sweep` (``levels + 1`` rows from ``Δ = 0`` to
        ``h_s``); ``axis`` is also the flow axis of the threshold.
    out : path
        The ensemble directory ``DIR`` (created if needed). For a multi-machine Dask cluster
        it only needs to be on the driver's machine: the driver writes every file.
    executor : None, "processes", "serial", a ``dask.distributed.Client`` or an address
        Where tasks run (module docstring). Default: local processes.
    workers : int, optional
        Local worker processes (default: all CPUs available). Only for local processes.
    threads_per_worker : int, optional
        rayon threads per task (``RAYON_NUM_THREADS`` in each worker). Default 1 — one
        single-threaded task per core, reproducible across executors; for Dask the default
        also respects a ``RAYON_NUM_THREADS`` already set in the workers' environment.
    retries : int
        Dask: ``retries`` of a failed task; processes: consecutive broken pools tolerated
        without any task finishing.
    resume : bool
        Skip tasks whose table exists in ``DIR``; run only the missing ones.
    overwrite : bool
        Delete a previous ensemble's files in ``DIR`` first (only this module's files).
    progress : bool
        tqdm progress bar over tasks on stderr (silent when stderr is not a terminal).
    figures : bool
        Write the figures into ``DIR/figures``.

    Returns
    -------
    EnsembleResult
        With ``run`` recording the executor, tasks run and resumed, wall and compute time.

    Raises
    ------
    ValueError
        A bad argument (the message names it), or ``resume`` on a different ensemble.
    FileExistsError
        ``DIR`` is not empty and neither ``resume`` nor ``overwrite`` was given.
    ImportError
        A scheduler address without ``dask.distributed`` installed.
    RuntimeError
        Some tasks failed (their errors are listed; the finished ones are on disk, so
        ``resume=True`` reruns only the failed ones), or local workers kept dying.
    """
    t_start = time.perf_counter()
    sets = _expand_params(params)
    _check_generator(generator, sets)
    seed_tuple = _resolve_seeds(surfaces, seeds)
    levels = _check_int("levels", levels, 1)
    if solver not in SOLVERS:
        raise ValueError(f"solver: must be one of {', '.join(SOLVERS)}; got {solver!r}")
    if not isinstance(warm_start, (bool, np.bool_)):
        raise ValueError(f"warm_start: must be True or False, got {warm_start!r}")
    if isinstance(axis, (bool, np.bool_)) or axis not in _AXES:
        raise ValueError(f"axis: must be 0, 1, 'either' or 'both', got {axis!r}")
    if isinstance(connectivity, bool) or connectivity not in (4, 8):
        raise ValueError(f"connectivity: must be 4 or 8, got {connectivity!r}")
    if boundary not in ("free", "periodic"):
        raise ValueError(f"boundary: must be 'free' or 'periodic', got {boundary!r}")
    # The elastic constants are used only inside the tasks: check them here, before any
    # worker starts or any file is written.
    for name, value in (("E", E), ("nu", nu)):
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
            raise ValueError(f"{name}: must be a number, got {value!r}")
    contact_modulus(E, nu)
    retries = _check_int("retries", retries, 0)
    if workers is not None:
        workers = _check_int("workers", workers, 1)
    if threads_per_worker is not None:
        threads_per_worker = _check_int("threads_per_worker", threads_per_worker, 1)

    mode: str
    if executor is None or executor == "processes":
        mode = "processes"
    elif executor == "serial":
        mode = "serial"
    elif isinstance(executor, str):
        if "://" not in executor and ":" not in executor:
            raise ValueError(
                "executor: must be None, 'processes', 'serial', a dask.distributed.Client or a "
                f"scheduler address like 'tcp://host:8786', got {executor!r}"
            )
        mode = "dask-address"
    elif _is_dask_client(executor):
        mode = "dask"
    else:
        raise ValueError(
            f"executor: expected None, 'processes', 'serial', a dask.distributed.Client or "
            f"an address, got {type(executor).__name__}"
        )
    if mode != "serial" and not isinstance(generator, str):
        import pickle

        try:
            pickle.dumps(generator)
        except Exception as exc:  # noqa: BLE001 - any pickling failure
            raise ValueError(
                f"generator: must be picklable to run in worker processes (a module-level "
                f"function, not a lambda or closure): {exc}"
            ) from None
    if workers is not None and mode not in ("processes",):
        raise ValueError("workers: applies to local processes only (size the Dask cluster itself)")

    # Parameter sets: keys, natural order, validity (one cheap trial generation per set).
    param_sets: list[ParamSet] = []
    seen: dict[str, dict[str, Any]] = {}
    for s in sets:
        key = param_key(s)
        if key in seen:
            raise ValueError(f"params: two parameter sets share the key {key!r}")
        seen[key] = s
        try:
            _generate(generator, s, seed_tuple[0])
        except ValueError as exc:
            raise ValueError(f"params ({key}): {exc}") from None
        param_sets.append(ParamSet(key, s, seed_tuple))
    param_sets.sort(key=lambda ps: _natural_order(ps.params))

    # Connect to a scheduler address first: a missing dask or an unreachable scheduler must
    # not leave a half-initialised output directory behind.
    client = executor if mode == "dask" else None
    own_client = _dask_client(executor) if mode == "dask-address" else None
    if own_client is not None:
        client = own_client
    try:
        identity = _identity(
            generator,
            levels,
            solver,
            bool(warm_start),
            axis,
            int(connectivity),
            float(E),
            float(nu),
            boundary,
        )
        directory = Path(out)
        old = _prepare_directory(directory, resume, overwrite)
        if old is not None and old.get("identity") != json.loads(_dumps(identity)):
            diff = sorted(k for k in identity if old["identity"].get(k) != identity[k])
            raise ValueError(
                f"resume: {str(directory)!r} holds an ensemble with different "
                f"{', '.join(diff) or 'options'}; use another directory or overwrite=True"
            )
        _clean_stale_temporaries(directory)
        manifest = {
            "format": _FORMAT,
            "kind": "leakpath-ensemble",
            "leakpath_version": __version__,
            "identity": identity,
            "param_sets": [
                {"key": ps.key, "params": ps.params, "seeds": list(ps.seeds)} for ps in param_sets
            ],
        }
        atomic_write_text(directory / "manifest.json", _dumps(manifest))

        kill_once = os.environ.get(_KILL_ENV) or None
        all_tasks = [(ps, seed) for ps in param_sets for seed in ps.seeds]
        todo: list[_TaskSpec] = []
        resumed: list[tuple[str, int]] = []
        for ps, seed in all_tasks:
            if resume and _task_done(directory, ps.key, seed):
                resumed.append((ps.key, seed))
                continue
            todo.append(
                _TaskSpec(
                    generator=generator,
                    params=ps.params,
                    key=ps.key,
                    seed=seed,
                    levels=levels,
                    solver=solver,
                    warm_start=bool(warm_start),
                    axis=axis,
                    connectivity=int(connectivity),
                    E=float(E),
                    nu=float(nu),
                    boundary=boundary,
                    kill_once=kill_once if mode != "serial" else None,
                )
            )

        driver = _Driver(directory, len(all_tasks), len(resumed), progress)
        t_run = time.perf_counter()
        try:
            if not todo:
                info: dict[str, Any] = {"executor": mode}
            elif mode == "serial":
                info = _run_serial(todo, driver)
            elif mode == "processes":
                n_workers = min(workers or _cpus(), len(todo))
                threads = 1 if threads_per_worker is None else threads_per_worker
                info = _run_processes(todo, driver, n_workers, threads, retries)
            else:
                info = _run_dask(client, todo, driver, retries, threads_per_worker)
        finally:
            driver.close()
        run_seconds = time.perf_counter() - t_run
        if driver.failed:
            lines = "; ".join(f"{k}/seed-{s}: {msg}" for k, s, msg in driver.failed[:5])
            more = f" (and {len(driver.failed) - 5} more)" if len(driver.failed) > 5 else ""
            raise RuntimeError(
                f"{len(driver.failed)} of {len(todo)} task(s) failed: {lines}{more}; the "
                f"{len(driver.written)} finished task(s) are saved in {str(directory)!r}, rerun "
                "with resume=True to retry the rest"
            )
        run = {
            **info,
            "tasks_total": len(all_tasks),
            "tasks_run": len(driver.written),
            "tasks_resumed": len(resumed),
            "ran": [[k, s] for k, s in driver.written],
            "run_seconds": run_seconds,
            "compute_seconds": driver.compute_seconds,
            "wall_seconds": time.perf_counter() - t_start,
        }
        return aggregate(directory, figures=figures, run=run)
    finally:
        if own_client is not None:
            own_client.close()


# ============================================================================ figures
_BAND_ALPHA = 0.22


def _colours(n: int) -> list[Any]:
    from matplotlib import colormaps

    if n <= 10:
        cmap = colormaps["tab10"]
        return [cmap(i) for i in range(n)]
    cmap = colormaps["viridis"]
    return [cmap(i / max(1, n - 1)) for i in range(n)]


def _varying(result: EnsembleResult) -> list[str]:
    names = sorted({n for ps in result.param_sets for n in ps.params})
    varying = [
        n for n in names if len({_format_value(ps.params.get(n)) for ps in result.param_sets}) > 1
    ]
    return varying or names


def _mean_band(result: EnsembleResult, ax: Any, xq: str, xlabel: str, title: str) -> None:
    names = _varying(result)
    for ps, colour in zip(result.param_sets, _colours(len(result.param_sets)), strict=True):
        x = result.curve(ps.key, xq)
        y = result.curve(ps.key, "V_pg_star")
        n = len(ps.seeds)
        ax.plot(
            x["mean"],
            y["mean"],
            color=colour,
            marker="o",
            markersize=3,
            linewidth=1.3,
            label=f"{ps.label(names)} (n = {n})",
        )
        if n > 1:
            ax.fill_between(
                x["mean"], y["ci_low"], y["ci_high"], color=colour, alpha=_BAND_ALPHA, linewidth=0
            )
            ax.errorbar(
                x["mean"],
                y["mean"],
                xerr=[x["mean"] - x["ci_low"], x["ci_high"] - x["mean"]],
                fmt="none",
                ecolor=colour,
                elinewidth=0.8,
                alpha=0.7,
            )
    ax.set_xlabel(xlabel)
    ax.set_ylabel(r"$V_{pg}^* = V_{pg} / V_{pg}(\Delta = 0)$")
    ax.set_title(title)
    ax.set_ylim(-0.03, 1.05)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small", title=f"mean, {int(CONFIDENCE * 100)} % band")


def figure_vpg_volume_gap(result: EnsembleResult) -> Any:
    """Fig. 2 over the ensemble: mean ``V_pg*`` against mean (a) ``V*``, (b) ``ḡ*``.

    One colour per parameter set; the shaded band is the 95 % confidence band of the mean
    ``V_pg*`` per level, the horizontal bars that of the abscissa.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.5, 4.4), layout="constrained")
    ax_a, ax_b = fig.subplots(1, 2)
    _mean_band(
        result,
        ax_a,
        "free_volume_star",
        r"$V^* = V / (A_0 \sigma)$",
        "(a) percolating vs free volume",
    )
    _mean_band(
        result,
        ax_b,
        "mean_gap_star",
        r"$\bar g^* = \bar g / \bar g(\Delta = 0)$",
        "(b) percolating volume vs mean gap",
    )
    return fig


def figure_vpg_moments(result: EnsembleResult) -> Any:
    """Fig. 3 over the ensemble: mean ``V_pg*`` against mean (a) ``m0*``, (b) ``m2*``."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.5, 4.4), layout="constrained")
    ax_a, ax_b = fig.subplots(1, 2)
    _mean_band(
        result, ax_a, "m0_star", r"$m_0^* = m_0 / m_0(h)$", "(a) percolating volume vs $m_0^*$"
    )
    _mean_band(
        result, ax_b, "m2_star", r"$m_2^* = m_2 / m_2(h)$", "(b) percolating volume vs $m_2^*$"
    )
    return fig


def figure_threshold_histograms(result: EnsembleResult) -> Any:
    """Histogram of the per-surface thresholds ``a_c`` (one panel per parameter set).

    Shared bins; the solid line is the mean, the shaded span its 95 % band, dashed lines
    the 5 % and 95 % quantiles.
    """
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    sets = result.param_sets
    n = len(sets)
    ncols = min(3, n)
    nrows = math.ceil(n / ncols)
    fig = Figure(figsize=(max(6.0, 4.2 * ncols), 3.5 * nrows + 0.4), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols, sharex=True, squeeze=False)).ravel()
    values = [result.threshold_values(ps.key) for ps in sets]
    pooled = np.concatenate([v for v in values if v.size] or [np.zeros(0)])
    if pooled.size:
        lo, hi = float(pooled.min()), float(pooled.max())
        if hi - lo < 1e-12:
            lo, hi = lo - 0.01, hi + 0.01
        bins = np.linspace(lo, hi, int(np.clip(np.sqrt(pooled.size / max(n, 1)) * 2, 5, 30)) + 1)
    else:
        bins = np.linspace(0.0, 1.0, 11)
    names = _varying(result)
    for ax, ps, v, colour in zip(axes, sets, values, _colours(n), strict=False):
        s = result.threshold_summary[ps.key]["contact_fraction"]
        ax.hist(v, bins=bins, color=colour, alpha=0.75, edgecolor="white")
        if v.size:
            ax.axvline(s["mean"], color="black", linewidth=1.2, label=f"mean {s['mean']:.4f}")
            if math.isfinite(s["ci_low"]):
                ax.axvspan(
                    s["ci_low"],
                    s["ci_high"],
                    color="black",
                    alpha=0.15,
                    label=f"{int(CONFIDENCE * 100)} % band of the mean",
                )
            for q in ("0.05", "0.95"):
                ax.axvline(s["quantiles"][q], color="black", linestyle="--", linewidth=0.8)
        found = result.threshold_summary[ps.key]["n_found"]
        ax.set_title(
            f"{ps.label(names)}: threshold reached on {found}/{len(ps.seeds)} surfaces",
            fontsize="medium",
        )
        pad = 0.05 * (bins[-1] - bins[0])
        ax.set_xlim(bins[0] - pad, bins[-1] + pad)  # a wide band of the mean is clipped
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel(r"contact fraction at the threshold $a_c$")
        ax.set_ylabel("surfaces")
        ax.grid(True, alpha=0.3)
        if v.size:
            ax.legend(fontsize="x-small")
    for ax in axes[n:]:
        ax.set_visible(False)
    axis = result.identity.get("axis", 0)
    fig.suptitle(
        f"Percolation threshold: first level without a spanning cluster (flow along axis "
        f"{axis})\nsurfaces still percolating at the last level are not in the histogram",
        fontsize="medium",
    )
    return fig


def save_ensemble_figures(
    result: EnsembleResult,
    outdir: PathLike | None = None,
    *,
    formats: Sequence[str] = ("png", "pdf"),
    dpi: int = 150,
) -> list[Path]:
    """Write ``fig2_vpg_volume_gap``, ``fig3_vpg_moments`` and ``thresholds_hist`` in every
    format (``png``, ``pdf``, ``svg``) into ``outdir`` (default ``DIR/figures``), atomically.
    """
    if isinstance(formats, str):
        formats = (formats,)
    bad = [f for f in formats if f not in ("png", "pdf", "svg")]
    if bad or not formats:
        raise ValueError(f"formats: choose from png, pdf, svg; got {list(formats)!r}")
    directory = Path(outdir) if outdir is not None else result.directory / "figures"
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for stem, make in (
        ("fig2_vpg_volume_gap", figure_vpg_volume_gap),
        ("fig3_vpg_moments", figure_vpg_moments),
        ("thresholds_hist", figure_threshold_histograms),
    ):
        fig = make(result)
        for fmt in formats:
            buf = io.BytesIO()
            fig.savefig(buf, format=fmt, dpi=dpi)
            paths.append(atomic_write_bytes(directory / f"{stem}.{fmt}", buf.getvalue()))
    return paths
