"""The seal figure: leak rate, contact fraction against theory, and the distribution of K.

Built on :class:`matplotlib.figure.Figure` (no pyplot, no global state, no display needed):

1. the seal leak rate against the nominal pressure p̄ [Pa] (log–log) with the confidence
   band of K_eff carried through ``Q ∝ K``, and the Bruggeman (effective-medium) estimate;
2. the simulated contact fraction A/A0 (mean ± one standard deviation over realisations)
   against Persson's theory;
3. the per-realisation patch permeabilities K [m³] at each pressure (zeros, non-leaking
   patches, drawn at the bottom edge and counted), with K_eff and the arithmetic/harmonic
   bounds.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["seal_figure"]


def _positive(y: np.ndarray) -> np.ndarray:
    return np.where(y > 0, y, np.nan)


def seal_figure(result: Any) -> Any:
    """The three-panel figure of a :class:`~leakpath.seal.SealResult` (module docstring)."""
    from matplotlib.figure import Figure

    s = result.summary
    p = s.column("mean_pressure_Pa")
    gas = result.gas
    stem, unit, label = (
        ("mass_flow", "_kg_per_s", "mass flow ṁ [kg/s]") if gas
        else ("leak_rate", "_m3_per_s", "leak rate Q [m³/s]")
    )
    fig = Figure(figsize=(13.5, 4.3), layout="constrained")
    ax1, ax2, ax3 = fig.subplots(1, 3)

    q = _positive(s.column(stem + unit))
    lo = _positive(s.column(stem + "_low" + unit))
    hi = _positive(s.column(stem + "_high" + unit))
    qb = _positive(s.column(stem + "_bruggeman" + unit))
    conf = result.metadata.get("estimator", {}).get("method", "")
    ax1.fill_between(p, np.where(np.isnan(lo), np.nanmin(np.r_[q, hi, 1.0]) * 1e-3, lo), hi,
                     color="tab:blue", alpha=0.25, label="confidence interval")
    ax1.plot(p, q, "o-", color="tab:blue", label="simulation, K_eff")
    ax1.plot(p, qb, "s--", color="tab:orange", label="Bruggeman (effective medium)")
    ax1.set_xscale("log")
    finite = np.r_[q, lo, hi, qb]
    finite = finite[np.isfinite(finite)]
    if finite.size:
        ax1.set_yscale("log")
        zero = s.column(stem + unit) == 0
        if np.any(zero):  # K_eff = 0: no leak path at the patch scale
            bottom = finite.min() / 30
            ax1.plot(p[zero], np.full(int(zero.sum()), bottom), "v", color="tab:blue",
                     markerfacecolor="none", label="K_eff = 0 (drawn at the bottom)")
            ax1.set_ylim(bottom=bottom / 2)
    ax1.set_xlabel("nominal contact pressure p̄ [Pa]")
    ax1.set_ylabel(label)
    ax1.set_title("seal leak rate" + (f"\n{conf}" if conf and len(conf) < 60 else ""),
                  fontsize=10)
    ax1.legend(fontsize=7)

    a = s.column("contact_fraction")
    da = s.column("contact_fraction_std")
    ax2.errorbar(p, a, yerr=da, fmt="o", color="tab:blue", capsize=3,
                 label=f"simulation (mean ± std, N = {result.config.realisations})")
    pp = np.geomspace(p.min(), p.max(), 50) if len(p) > 1 else p
    theory = _persson_curve(result, pp)
    ax2.plot(pp if theory is not None else p,
             theory if theory is not None else s.column("persson_contact_fraction"),
             "-", color="tab:red", label="Persson's theory")
    ax2.set_xscale("log")
    ax2.set_xlabel("nominal contact pressure p̄ [Pa]")
    ax2.set_ylabel("contact fraction A/A₀ [–]")
    ax2.set_title("contact area", fontsize=10)
    ax2.legend(fontsize=8)

    r = result.realisations
    axes = sorted(set(r.column("axis").tolist()))
    k = r.column("permeability_m3")
    pr = r.column("mean_pressure_Pa")
    kpos = k[k > 0]
    floor = kpos.min() / 10 if kpos.size else 1e-30
    for i, pv in enumerate(p):
        sel = pr == pv
        kk = k[sel]
        offsets = (np.arange(kk.size) % 7 - 3) * 0.012
        x = pv * 10 ** offsets
        ax3.scatter(x, np.where(kk > 0, kk, floor), s=10, alpha=0.6, color="tab:gray",
                    marker="o", label="patches (axes " + ", ".join(map(str, axes)) + ")"
                    if i == 0 else None)
        zeros = int(np.count_nonzero(kk == 0))
        if zeros:
            ax3.annotate(f"{zeros}×0", (pv, floor), textcoords="offset points",
                         xytext=(0, -12), ha="center", fontsize=7)
    ax3.plot(p, _positive(s.column("permeability_m3")), "o-", color="tab:blue", label="K_eff")
    ax3.plot(p, _positive(s.column("permeability_arithmetic_m3")), "v:", color="tab:green",
             label="arithmetic mean (upper bound)")
    ax3.plot(p, _positive(s.column("permeability_harmonic_m3")), "^:", color="tab:purple",
             label="harmonic mean (lower bound)")
    ax3.set_xscale("log")
    if kpos.size:
        ax3.set_yscale("log")
        ax3.set_ylim(bottom=floor / 3)
    ax3.set_xlabel("nominal contact pressure p̄ [Pa]")
    ax3.set_ylabel("patch permeability K [m³]")
    ax3.set_title("distribution of K (0 = patch does not leak)", fontsize=10)
    ax3.legend(fontsize=7)
    return fig


def _persson_curve(result: Any, p: np.ndarray) -> np.ndarray | None:
    """Persson's A/A0 on a fine pressure grid, when the theory module is importable."""
    try:
        from . import _theory
    except ImportError:  # pragma: no cover - the theory module ships with the package
        return None
    e_star = result.metadata.get("E_star_Pa")
    slope = result.metadata.get("composite_rms_slope")
    if e_star is None or slope is None:
        return None
    return np.asarray(_theory.persson_contact_fraction(p, e_star, slope), dtype=float)
