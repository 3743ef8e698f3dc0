r"""Theory beside the simulation: Persson's contact area and Bruggeman's effective permeability.

Two closed-form estimates the seal workflow reports next to the simulated numbers, so users see
where theory and simulation part (docs/seal-theory.md):

* :func:`persson_contact_fraction` — Persson's contact-mechanics theory for the real contact
  area of a randomly rough surface pressed on a flat,
  ``A/A0 = erf(√2 p̄ / (E* h'_rms))``;
* :func:`bruggeman_permeability` — the 2-D effective-medium (Bruggeman) estimate of the
  permeability of a gap field from the local conductances ``g³/12`` of its cells.

Both are pure NumPy (no SciPy in the package). Units are SI as in the seal workflow, but any
consistent units work: the contact fraction is dimensionless, the permeability has the units
of the gap cubed.
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np
import numpy.typing as npt

from .._flow import GAP_FLOOR
from ..errors import InvalidArgumentError

__all__ = ["persson_contact_fraction", "bruggeman_permeability"]

FloatArray = npt.NDArray[np.float64]

_ERF = np.vectorize(math.erf, otypes=[np.float64])


def _as_float_array(value: Any, argument: str, what: str) -> FloatArray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidArgumentError(
            f"{argument}: must be a number or an array of numbers (got {value!r}); {what}",
            argument=argument,
        ) from None
    return arr


def persson_contact_fraction(
    mean_pressure: float | npt.ArrayLike,
    E_star: float | npt.ArrayLike,
    rms_slope: float | npt.ArrayLike,
) -> FloatArray | float:
    r"""Persson's relative contact area ``A/A0`` of a randomly rough surface on a flat.

    Persson's theory (B. N. J. Persson, J. Chem. Phys. 115, 3840 (2001); review: Surf. Sci.
    Rep. 61, 201 (2006), eqs. 17–20) follows the probability density ``P(σ, ζ)`` of the contact
    stress as the magnification ``ζ`` adds roughness of ever shorter wavelength. It diffuses in
    ``σ`` with ``∂P/∂G = p̄² ∂²P/∂σ²``, starts at ``δ(σ − p̄)`` and vanishes at ``σ = 0``
    (points that lose contact). The method of images gives

    .. math::

        P(σ) = \frac{1}{2 p̄ \sqrt{π G}}
               \left[e^{-(σ - p̄)^2 / (4 G p̄^2)} - e^{-(σ + p̄)^2 / (4 G p̄^2)}\right],
        \qquad
        \frac{A}{A_0} = \int_0^\infty P\,dσ = \operatorname{erf}\!\left(\frac{1}{2\sqrt{G}}\right),

    .. math::

        G = \frac{π}{4} \left(\frac{E^*}{p̄}\right)^2 \int_{q_0}^{q_1} q^3 C(q)\,dq .

    For an isotropic 2-D power spectrum normalised as in docs/surfaces.md,
    ``⟨h²⟩ = ∫ C(q) d²q = 2π ∫ q C(q) dq`` and the mean-square slope is
    ``h'²_rms = ⟨|∇h|²⟩ = 2π ∫ q³ C(q) dq``. Hence ``G = (E* h'_rms / p̄)² / 8`` and

    .. math::

        \frac{A}{A_0} = \operatorname{erf}\!\left(\frac{\sqrt{2}\, p̄}{E^* h'_\mathrm{rms}}\right)
        \;\approx\; κ \frac{p̄}{E^* h'_\mathrm{rms}},
        \quad κ = \frac{2\sqrt 2}{\sqrt π} = \sqrt{8/π} ≈ 1.596 \quad (p̄ ≪ E^* h'_\mathrm{rms}).

    Equivalently ``4 G p̄² = 2 s²`` with ``s = E* h'_rms / 2`` the standard deviation of the
    contact stress in full contact (the half-space stress of mode ``q`` is ``E*|q| h_q / 2``).
    Boundary-element simulations find the area proportional to the load with a larger constant,
    ``κ ≈ 2`` (Hyun, Pei, Molinari & Robbins, Phys. Rev. E 70, 026117 (2004); Putignano et al.,
    J. Mech. Phys. Solids 60, 973 (2012); Yastrebov, Anciaux & Molinari, Int. J. Solids
    Struct. 52, 83 (2015)): Persson's theory underestimates the contact area at small loads by
    roughly 20 %.

    Parameters
    ----------
    mean_pressure : float or array_like
        Nominal (mean) contact pressure ``p̄ = F/A0`` [Pa], finite and ``≥ 0``.
    E_star : float or array_like
        Contact modulus ``E* = [(1−ν₁²)/E₁ + (1−ν₂²)/E₂]⁻¹`` [Pa], finite and ``> 0``.
    rms_slope : float or array_like
        rms slope ``h'_rms = √⟨|∇h|²⟩`` of the composite surface [-], finite and ``≥ 0``
        (0: a smooth pair, in full contact at any positive load).

    Returns
    -------
    float or ndarray
        ``A/A0`` in ``[0, 1]``, broadcast over the inputs (a float when all are scalars);
        0 at ``p̄ = 0``.

    Raises
    ------
    InvalidArgumentError
        An argument is not a finite number in its domain (named in the message).
    """
    p = _as_float_array(mean_pressure, "mean_pressure", "pass the nominal pressure in Pa")
    e = _as_float_array(E_star, "E_star", "pass the contact modulus E* in Pa")
    s = _as_float_array(rms_slope, "rms_slope", "pass the composite rms slope (dimensionless)")
    if not (np.all(np.isfinite(p)) and np.all(p >= 0)):
        raise InvalidArgumentError(
            "mean_pressure: must be finite and >= 0; pass the nominal pressure in Pa",
            argument="mean_pressure",
        )
    if not (np.all(np.isfinite(e)) and np.all(e > 0)):
        raise InvalidArgumentError(
            "E_star: must be finite and > 0; pass the contact modulus E* in Pa "
            "(two rigid bodies have no elastic contact area)",
            argument="E_star",
        )
    if not (np.all(np.isfinite(s)) and np.all(s >= 0)):
        raise InvalidArgumentError(
            "rms_slope: must be finite and >= 0; pass the composite rms slope",
            argument="rms_slope",
        )
    p, e, s = np.broadcast_arrays(p, e, s)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.where(p > 0, np.sqrt(2.0) * p / (e * s), 0.0)
    out = _ERF(x)
    if out.ndim == 0:
        return float(out)
    return out


def _bruggeman_rows(k: FloatArray, weights: FloatArray | None = None) -> FloatArray:
    r"""Roots ``x ≥ 0`` of ``F(x) = Σ_i w_i (k_i − x)/(k_i + x) / Σ_i w_i = 0``, one per row.

    ``k`` (shape ``(m,)``) holds the conductances, ``≥ 0``, scaled so that they are at most 1
    and not subnormal; ``weights`` (shape ``(r, m)``, ``≥ 0``, each row with a positive sum)
    the multiplicity of each value in each row (``None``: one row, all weights 1).

    ``F`` is decreasing and convex in ``x`` (each term is ``−1 + 2k/(k + x)``), ``F(∞) = −1``
    and ``F(0⁺) = 1 − 2 f₀`` with ``f₀`` the weight share of the zeros. So the root is 0 when
    ``f₀ ≥ ½`` and unique and positive otherwise. Bracket: ``(k − x)/(k + x) ≥ 1 − 2x/k``
    gives ``F(x) ≥ 1 − 2f₀ − 2xH`` with ``H = Σ_{k>0} w/k / Σ w``, so
    ``F(lo) ≥ (1 − 2f₀)/2 > 0`` at ``lo = (1 − 2f₀)/(4H)``; ``F(max k) ≤ 0``. Bisection on
    ``ln x`` narrows the bracket to a factor 2, then Newton's method from its lower end climbs
    monotonically to the root (a convex decreasing function lies above its tangents, so no
    step overshoots) and stops when a step changes ``x`` by less than ``1e-15 x``.
    """
    k = np.asarray(k, dtype=np.float64)
    w = np.ones((1, k.size)) if weights is None else np.asarray(weights, dtype=np.float64)
    total = w.sum(axis=1)
    zero = k == 0
    f0 = w[:, zero].sum(axis=1) / total
    inv = np.zeros_like(k)
    with np.errstate(over="ignore"):
        inv[~zero] = 1.0 / k[~zero]  # inf for a subnormal k: the lower bracket falls to its floor
    with np.errstate(invalid="ignore"):
        h = (w * inv).sum(axis=1) / total
    present = w > 0
    kmax = np.where(present, k, -np.inf).max(axis=1)
    kmin = np.where(present, k, np.inf).min(axis=1)
    out = np.zeros(w.shape[0])
    # Every value equal and positive: the root is that value, exactly.
    same = (kmin == kmax) & (kmax > 0)
    out[same] = kmax[same]
    rows = np.flatnonzero((1.0 - 2.0 * f0 > 0) & ~same)
    if rows.size == 0:
        return out
    ws, tot = w[rows], total[rows]

    def f(x: FloatArray, sel: slice | FloatArray = slice(None)) -> FloatArray:
        xs = x[:, None]
        return (ws[sel] * ((k - xs) / (k + xs))).sum(axis=1) / tot[sel]

    with np.errstate(divide="ignore", over="ignore"):
        lo = (1.0 - 2.0 * f0[rows]) / (4.0 * h[rows])
    lo = np.clip(lo, 1e-300, None)
    hi = kmax[rows].copy()
    lo = np.minimum(lo, hi)
    for _ in range(64):  # ln(hi/lo) ≤ ln(1e300) ≈ 690: 64 halvings are ample
        wide = hi > 2.0 * lo
        if not wide.any():
            break
        mid = np.sqrt(lo) * np.sqrt(hi)  # lo·hi may underflow
        fm = f(mid)
        up = wide & (fm > 0)
        down = wide & ~(fm > 0)
        lo = np.where(up, mid, lo)
        hi = np.where(down, mid, hi)
    x = lo.copy()
    active = np.ones(x.size, dtype=bool)
    for _ in range(100):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        xa = x[idx][:, None]
        val = (ws[idx] * ((k - xa) / (k + xa))).sum(axis=1) / tot[idx]
        # k/(k + x)² as (k/(k + x))/(k + x): the square of a tiny k + x underflows.
        der = -2.0 * (ws[idx] * ((k / (k + xa)) / (k + xa))).sum(axis=1) / tot[idx]
        step = np.where(val > 0, -val / der, 0.0)
        new = np.minimum(x[idx] + step, hi[idx])
        done = ~(step > 1e-15 * x[idx]) | (new <= x[idx])
        x[idx] = np.where(new > x[idx], new, x[idx])
        active[idx[done]] = False
    out[rows] = x
    return out


def bruggeman_permeability(
    gap: npt.ArrayLike,
    dx: float,
    *,
    axis: int = 0,
    contact: npt.ArrayLike | None = None,
) -> float:
    r"""Effective-medium (2-D Bruggeman) estimate of the permeability of a gap field [m³].

    Each cell conducts like parallel plates of its gap, ``k_i = g_i³/12`` (docs/flow.md); a
    cell in contact (or with ``g ≤ 0``) conducts nothing, ``k_i = 0``. Bruggeman's symmetric
    effective-medium approximation (Kirkpatrick, Rev. Mod. Phys. 45, 574 (1973), for a
    network of coordination ``z``: ``Σ_i (k_i − k_e)/(k_i + (z/2 − 1) k_e) = 0``) with
    ``z = 4`` (the square grid, 4-connected as the flow and the percolation) reads

    .. math:: \sum_i \frac{k_i - k_e}{k_i + k_e} = 0 ,

    solved for ``k_e ≥ 0`` (the sum is decreasing in ``k_e``: one root, found by bisection in
    ``ln k_e`` then a monotone Newton iteration, to about 1e-15 relative). It is
    0 exactly when at least half of the cells are closed, the EMA percolation threshold
    ``2/z`` of the 2-D EMA (the contact area at which the leak stops is about 0.4 in
    simulations; Dapp, Lücke, Persson & Müser, Phys. Rev. Lett. 108, 244301 (2012)). Two
    properties hold exactly: a uniform gap gives ``g³/12``, and a two-valued field with
    equal shares gives ``√(k₁ k₂)``, the exact 2-D result of Keller and Dykhne for
    statistically equivalent phases. The estimate always lies between the Wiener bounds, the
    harmonic and the arithmetic mean of the ``k_i``. The approach follows Lorenz & Persson's
    leak-rate theory of seals (B. Lorenz and B. N. J. Persson, Eur. Phys. J. E 31, 159
    (2010), "Leak rate of seals: effective-medium theory and comparison with experiment").

    The EMA is isotropic: ``k_e`` does not depend on the flow direction or on ``dx``; ``axis``
    and ``dx`` are checked for the same domains as :func:`leakpath.flow` so the two calls are
    interchangeable. Open gaps below ``GAP_FLOOR · g_max`` (1e-50, docs/flow.md) are raised to
    it, as in the flow solver, so a cell is open here exactly when it is open for the flow.

    Parameters
    ----------
    gap : (ny, nx) array_like
        Gap field [m], finite; ``g ≤ 0`` is closed when no ``contact`` mask is given.
    dx : float
        Grid spacing [m], finite and ``> 0`` (checked; the estimate does not depend on it).
    axis : {0, 1}
        Flow direction (checked; the estimate does not depend on it).
    contact : (ny, nx) array_like of bool, optional
        Contact mask (closed cells), e.g. ``state.contact``; then a free cell must have
        ``g ≥ 0`` and is open when ``g > 0``. Default: closed where ``gap ≤ 0``.

    Returns
    -------
    float
        ``k_e`` [m³] (units of the gap cubed); 0 when half or more of the cells are closed.

    Raises
    ------
    InvalidArgumentError
        ``gap`` not a finite 2-D array, ``dx`` not positive, ``axis`` not 0 or 1, ``contact``
        of the wrong shape, or a negative gap on a free cell with a ``contact`` mask.
    """
    g = _as_float_array(gap, "gap", "pass the gap field in m")
    if g.ndim != 2 or g.size == 0:
        raise InvalidArgumentError(
            f"gap: must be a non-empty 2-D array (got shape {g.shape}); pass the gap field",
            argument="gap",
        )
    if not np.all(np.isfinite(g)):
        raise InvalidArgumentError(
            "gap: contains NaN or inf; pass finite gaps (closed cells: 0)", argument="gap"
        )
    if (
        isinstance(dx, bool)
        or not isinstance(dx, numbers.Real)
        or not math.isfinite(float(dx))
        or float(dx) <= 0
    ):
        raise InvalidArgumentError(
            f"dx: must be a finite number > 0 (got {dx!r}); pass the grid spacing in m",
            argument="dx",
        )
    if isinstance(axis, bool) or axis not in (0, 1):
        raise InvalidArgumentError(
            f"axis: must be 0 or 1 (got {axis!r}); pass the flow direction", argument="axis"
        )
    if contact is None:
        open_ = g > 0
    else:
        c = np.asarray(contact)
        if c.shape != g.shape:
            raise InvalidArgumentError(
                f"contact: shape {c.shape} differs from the gap's {g.shape}; pass a mask of "
                "the gap's shape",
                argument="contact",
            )
        c = c.astype(bool)
        if np.any(g[~c] < 0):
            raise InvalidArgumentError(
                "gap: negative on free cells; clip the gap at 0 or mark those cells in contact",
                argument="gap",
            )
        open_ = ~c & (g > 0)
    if not open_.any():
        return 0.0
    gmax = float(g[open_].max())
    ghat = np.zeros(g.shape)
    ghat[open_] = np.maximum(g[open_] / gmax, GAP_FLOOR)
    gh = ghat.ravel()
    khat = gh * gh * gh  # products, not numpy's pow: the same bits on every CPU
    root = float(_bruggeman_rows(khat)[0])
    return root * (gmax**3 / 12.0)
