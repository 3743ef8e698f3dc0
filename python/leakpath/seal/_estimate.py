r"""From patch permeabilities to a seal's: the upscaling estimator, its interval, the leak rate.

A seal is much larger than the simulated patch. Its interface is treated as a 2-D random
medium tiled by patch-sized blocks, each with the permeability ``k_i`` of one independent
realisation (docs/seal-theory.md):

* for an isotropic 2-D medium whose log-permeability is symmetric (e.g. lognormal), the
  effective permeability is the **geometric mean** (Matheron, *Éléments pour une théorie des
  milieux poreux*, Masson 1967; Dykhne, Sov. Phys. JETP 32, 63 (1971));
* any medium lies between the **Wiener bounds**, harmonic ≤ K_eff ≤ arithmetic mean (Wiener
  1912; series and parallel arrangements of the blocks);
* a patch through which nothing percolates has ``k_i = 0``: the geometric and harmonic means
  are then 0 however many patches leak, which is wrong near the percolation threshold.

The estimator is therefore the **self-consistent (Bruggeman) effective medium** of the blocks
in 2-D, ``Σ_i (k_i − K)/(k_i + K) = 0`` (Kirkpatrick, Rev. Mod. Phys. 45, 574 (1973)). For a
log-symmetric distribution its root is the median, i.e. the geometric mean (substitute
``k = K e^u``: each term is ``tanh(u/2)``, odd in ``u``), it reproduces Dykhne's exact
``√(k₁k₂)`` for two equally likely values, it lies between the Wiener bounds, and it is 0
exactly when at least half of the patches are closed (the 2-D effective-medium threshold).

The confidence interval is a percentile bootstrap over realisations (Efron & Tibshirani, *An
Introduction to the Bootstrap*, 1993, ch. 13): ``B = 2000`` resamples drawn with
``numpy.random.default_rng(seed)``, so the interval is the same bits for the same inputs.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .. import _elementary
from ..errors import InvalidArgumentError
from ._theory import _bruggeman_rows

__all__ = [
    "BOOTSTRAP_RESAMPLES",
    "PermeabilityEstimate",
    "effective_permeability",
    "liquid_leak_rate",
    "gas_mass_flow",
]

BOOTSTRAP_RESAMPLES = 2000
"""Bootstrap resamples ``B`` of :func:`effective_permeability`'s interval."""

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class PermeabilityEstimate:
    """The seal's effective permeability from patch realisations.

    Attributes
    ----------
    value : float
        ``K_eff`` [m³]: the self-consistent (Bruggeman) estimate over the realisations.
    low, high : float
        Confidence interval of ``K_eff`` [m³] (percentile bootstrap); NaN from one realisation.
    arithmetic, harmonic, geometric : float
        Means of the ``k_i`` [m³]: the Wiener bounds (harmonic ≤ K_eff ≤ arithmetic) and
        Matheron's geometric mean; harmonic and geometric are 0 when any ``k_i`` is 0.
    n : int
        Number of permeabilities given.
    n_leaking : int
        How many are positive.
    leak_fraction : float
        ``n_leaking / n``.
    method : str
        The estimator and the interval, in words.
    """

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


def _check_seed(seed: object) -> int:
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or int(seed) < 0:
        raise InvalidArgumentError(
            f"seed: must be a non-negative integer (got {seed!r}); pass e.g. seed=0",
            argument="seed",
        )
    return int(seed)


def _self_consistent(k: FloatArray, weights: FloatArray | None = None) -> FloatArray:
    """Bruggeman roots of ``k`` (any scale) per weight row, in the units of ``k``."""
    kmax = float(k.max())
    if kmax == 0:
        return np.zeros(1 if weights is None else weights.shape[0])
    return _bruggeman_rows(k / kmax, weights) * kmax


def effective_permeability(
    k: npt.ArrayLike,
    *,
    confidence: float = 0.95,
    seed: int = 0,
    groups: npt.ArrayLike | None = None,
) -> PermeabilityEstimate:
    r"""Estimate the permeability of a seal much larger than the patch from patch realisations.

    ``value`` solves the 2-D self-consistent (Bruggeman) condition over the patches

    .. math:: \sum_i \frac{k_i - K}{k_i + K} = 0, \qquad K \ge 0,

    which equals Matheron's geometric mean ``exp(mean ln k)`` for a log-symmetric distribution
    of ``k`` in 2-D, stays between the Wiener bounds ``harmonic ≤ K ≤ arithmetic``, and is 0
    when at least half of the patches do not leak (module docstring; docs/seal-theory.md).

    The interval is the ``(1 ± confidence)/2`` percentile range of ``K`` over
    ``B = 2000`` bootstrap resamples of the realisations, drawn with
    ``numpy.random.default_rng(seed)`` (deterministic). With ``groups`` the resampling draws
    whole groups (e.g. the two flow directions of one realisation, which are not
    independent) and keeps every ``k`` of a drawn group. From a single realisation (or a
    single group) there is nothing to resample and no spread to learn from: ``low`` and
    ``high`` are NaN. When no ``k_i`` is positive the interval is ``[0, 0]``: the bootstrap
    cannot see leaks that never occurred; ``leak_fraction`` = 0 of ``n`` bounds the share of
    leaking patches only to about ``3/n`` at 95 % (the "rule of three").

    Parameters
    ----------
    k : array_like, 1-D
        Permeabilities ``k_i ≥ 0`` of the realisations [m³] (0: that patch does not leak).
    confidence : float
        Confidence level of the interval, in (0, 1); default 0.95.
    seed : int
        Seed of the bootstrap, ``≥ 0``.
    groups : array_like, 1-D, optional
        Group label of each ``k_i`` (any hashable values, ``k``'s length); default: each
        ``k_i`` its own group.

    Returns
    -------
    PermeabilityEstimate

    Raises
    ------
    InvalidArgumentError
        ``k`` empty, not 1-D, negative, NaN or inf; ``confidence`` outside (0, 1); ``seed``
        not a non-negative integer; ``groups`` of another length.
    """
    try:
        ka = np.asarray(k, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidArgumentError(
            "k: must be an array of numbers; pass the patch permeabilities in m^3",
            argument="k",
        ) from None
    if ka.ndim != 1 or ka.size == 0:
        raise InvalidArgumentError(
            f"k: must be a non-empty 1-D array (got shape {ka.shape}); pass one permeability "
            "per realisation",
            argument="k",
        )
    if not np.all(np.isfinite(ka)):
        raise InvalidArgumentError(
            "k: contains NaN or inf; pass finite permeabilities (0 for a patch that does not "
            "leak)",
            argument="k",
        )
    if np.any(ka < 0):
        raise InvalidArgumentError(
            f"k: negative permeability {float(ka.min())!r}; permeabilities are >= 0 "
            "(0 for a patch that does not leak)",
            argument="k",
        )
    if (
        isinstance(confidence, bool)
        or not isinstance(confidence, numbers.Real)
        or not 0 < float(confidence) < 1
    ):
        raise InvalidArgumentError(
            f"confidence: must be a number in (0, 1) (got {confidence!r}); pass e.g. 0.95",
            argument="confidence",
        )
    seed = _check_seed(seed)
    if groups is None:
        labels = np.arange(ka.size)
    else:
        g = np.asarray(groups)
        if g.shape != ka.shape:
            raise InvalidArgumentError(
                f"groups: shape {g.shape} differs from k's {ka.shape}; pass one label per k",
                argument="groups",
            )
        labels = np.unique(g, return_inverse=True)[1].ravel()
    n = int(ka.size)
    n_leaking = int(np.count_nonzero(ka > 0))
    arithmetic = float(ka.mean())
    if n_leaking < n:
        harmonic = geometric = 0.0
    else:
        small = float(ka.min())  # k_min/k <= 1: no overflow
        harmonic = float(n / np.sum(small / ka)) * small
        geometric = float(_elementary.exp(np.mean(_elementary.log(ka))))
    value = float(_self_consistent(ka)[0])
    # Rounding can put the root a few ulps outside the bounds it provably lies between.
    value = min(max(value, harmonic), arithmetic)
    n_groups = int(labels.max()) + 1
    level = float(confidence)
    grouping = "" if groups is None else f" of {n_groups} groups"
    if n_groups < 2:
        low = high = math.nan
        interval = f"no interval from a single {'group' if groups is not None else 'realisation'}"
    else:
        rng = np.random.default_rng(seed)
        draws = rng.integers(0, n_groups, size=(BOOTSTRAP_RESAMPLES, n_groups))
        counts = np.zeros((BOOTSTRAP_RESAMPLES, n_groups))
        np.add.at(counts, (np.arange(BOOTSTRAP_RESAMPLES)[:, None], draws), 1.0)
        weights = counts[:, labels]
        boot = _self_consistent(ka, weights)
        low, high = (float(v) for v in np.quantile(boot, [(1 - level) / 2, (1 + level) / 2]))
        interval = (
            f"{100 * level:g} % percentile bootstrap{grouping}, B={BOOTSTRAP_RESAMPLES}, "
            f"seed {seed}"
        )
    method = f"bruggeman (2-D self-consistent effective medium of the patches); {interval}"
    return PermeabilityEstimate(
        value=value,
        low=low,
        high=high,
        arithmetic=arithmetic,
        harmonic=harmonic,
        geometric=geometric,
        n=n,
        n_leaking=n_leaking,
        leak_fraction=n_leaking / n,
        method=method,
    )


def _positive(value: object, argument: str, what: str) -> float:
    if (
        isinstance(value, bool)
        or not isinstance(value, numbers.Real)
        or not math.isfinite(float(value))
        or float(value) <= 0
    ):
        raise InvalidArgumentError(
            f"{argument}: must be a finite number > 0 (got {value!r}); {what}", argument=argument
        )
    return float(value)


def _finite(value: object, argument: str, what: str, *, minimum: float | None = None) -> float:
    if (
        isinstance(value, bool)
        or not isinstance(value, numbers.Real)
        or not math.isfinite(float(value))
        or (minimum is not None and float(value) < minimum)
    ):
        bound = "" if minimum is None else f" >= {minimum:g}"
        raise InvalidArgumentError(
            f"{argument}: must be a finite number{bound} (got {value!r}); {what}",
            argument=argument,
        )
    return float(value)


def _permeability(k_eff: float | npt.ArrayLike) -> FloatArray:
    try:
        k = np.asarray(k_eff, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidArgumentError(
            "k_eff: must be a number or an array of numbers; pass K_eff in m^3",
            argument="k_eff",
        ) from None
    if np.any(np.isinf(k)) or np.any(k < 0):
        raise InvalidArgumentError(
            "k_eff: must be >= 0 and finite (NaN passes through as 'no value'); pass K_eff in "
            "m^3",
            argument="k_eff",
        )
    return k


def _out(x: FloatArray) -> FloatArray | float:
    return float(x) if x.ndim == 0 else x


def liquid_leak_rate(
    k_eff: float | npt.ArrayLike,
    *,
    width: float,
    length: float,
    viscosity: float,
    pressure_drop: float,
) -> FloatArray | float:
    r"""Volume leak rate of an incompressible liquid through the seal [m³/s].

    .. math:: Q = K_\mathrm{eff} \frac{W}{L} \frac{Δp}{η}

    the definition of the permeability in docs/flow.md (``Q/W = (K/η) Δp/L``) applied to the
    whole seal: ``W`` the sealed perimeter (width across the flow), ``L`` the leak-path length
    (the land width, along the flow).

    Parameters
    ----------
    k_eff : float or array_like
        Effective permeability [m³], ``≥ 0``; NaN (an undefined interval end) gives NaN.
    width : float
        Sealed perimeter ``W`` [m], ``> 0``.
    length : float
        Leak-path length ``L`` [m], ``> 0``.
    viscosity : float
        Dynamic viscosity ``η`` [Pa·s], ``> 0`` (water at 20 °C: 1.0e-3).
    pressure_drop : float
        ``Δp = p_in − p_out`` [Pa], finite (negative: the flow reverses).

    Returns
    -------
    float or ndarray
        ``Q`` [m³/s], shaped like ``k_eff``.
    """
    k = _permeability(k_eff)
    w = _positive(width, "width", "pass the sealed perimeter in m")
    length_ = _positive(length, "length", "pass the leak-path length (land width) in m")
    eta = _positive(viscosity, "viscosity", "pass the dynamic viscosity in Pa s")
    dp = _finite(pressure_drop, "pressure_drop", "pass p_in - p_out in Pa")
    return _out(k * (w / length_) * dp / eta)


def gas_mass_flow(
    k_eff: float | npt.ArrayLike,
    *,
    width: float,
    length: float,
    viscosity: float,
    inlet_pressure: float,
    outlet_pressure: float,
    gas_constant: float,
    temperature: float,
) -> FloatArray | float:
    r"""Mass leak rate of an isothermal ideal gas through the seal [kg/s].

    With ``ρ = p/(R_s T)`` the mass flux per unit width is
    ``−(K/(η R_s T)) p ∇p = −(K/(2 η R_s T)) ∇(p²)``: steady mass conservation is the liquid's
    equation for ``p²`` (docs/flow.md, "Ideal gas", the convention of
    ``leakpath.flow(gas=True)``), so

    .. math::

        \dot m = K_\mathrm{eff} \frac{W}{L} \frac{p_\mathrm{in}^2 - p_\mathrm{out}^2}{2 η R_s T}.

    Inertia, slip (Knudsen number ≪ 1) and heating are neglected.

    Parameters
    ----------
    k_eff : float or array_like
        Effective permeability [m³], ``≥ 0``; NaN gives NaN.
    width, length : float
        Sealed perimeter ``W`` and leak-path length ``L`` [m], ``> 0``.
    viscosity : float
        Dynamic viscosity of the gas ``η`` [Pa·s], ``> 0`` (air at 20 °C: 1.8e-5).
    inlet_pressure, outlet_pressure : float
        Absolute pressures [Pa], finite and ``≥ 0``.
    gas_constant : float
        Specific gas constant ``R_s`` [J/(kg·K)], ``> 0`` (air: 287.05).
    temperature : float
        Absolute temperature ``T`` [K], ``> 0``.

    Returns
    -------
    float or ndarray
        ``ṁ`` [kg/s], shaped like ``k_eff``.
    """
    k = _permeability(k_eff)
    w = _positive(width, "width", "pass the sealed perimeter in m")
    length_ = _positive(length, "length", "pass the leak-path length (land width) in m")
    eta = _positive(viscosity, "viscosity", "pass the gas's dynamic viscosity in Pa s")
    p_in = _finite(inlet_pressure, "inlet_pressure", "pass the absolute pressure in Pa", minimum=0)
    p_out = _finite(
        outlet_pressure, "outlet_pressure", "pass the absolute pressure in Pa", minimum=0
    )
    r_s = _positive(gas_constant, "gas_constant", "pass R_s in J/(kg K) (air: 287.05)")
    t = _positive(temperature, "temperature", "pass the absolute temperature in K")
    return _out(k * (w / length_) * (p_in**2 - p_out**2) / (2.0 * eta * r_s * t))
