"""The periodic patch the composite is solved on: its choice from the bodies' scales and the
method's validity limits."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ... import _validate
from ..._validate import invalid
from ...surfaces import load
from ._roughness import Roughness
from ._spectra import _pair, composite_rms_slope

#: Validity limits checked by :func:`validity_warnings` (``docs/seal-bodies.md``).
#: Small-slope (half-space) theory: composite rms slope at most this.
MAX_RMS_SLOPE = 0.3
#: The shortest wavelength of the spectrum needs at least this many grid points.
MIN_POINTS_PER_SHORT_WAVELENGTH = 4.0
#: The patch side must hold at least this many roll-off wavelengths.
MIN_ROLLOFFS_PER_PATCH = 2.0


@dataclass(frozen=True)
class Patch:
    """A square periodic patch: ``n`` points per side, side ``length`` [m], ``dx = length/n``
    [m]; ``rule`` says how it was chosen (for metadata)."""

    n: int
    length: float
    dx: float
    rule: str

    def __post_init__(self) -> None:
        n = _validate.integer("patch.n", self.n, low=2)
        length = _validate.positive("patch.length", self.length, what="a positive side in m")
        dx = _validate.spacing("patch.dx", self.dx)
        if not math.isclose(dx * n, length, rel_tol=1e-9):
            raise invalid("patch.dx", f"{dx!r} m must equal length/n = {length / n!r} m")
        object.__setattr__(self, "n", n)
        object.__setattr__(self, "length", length)
        object.__setattr__(self, "dx", dx)
        object.__setattr__(self, "rule", str(self.rule))


def _scales(r: Roughness) -> tuple[float | None, float | None]:
    """``(λ_r, λ_s)`` [m] of a statistics/psd body (``λ_r`` None without roll-off)."""
    if r.psd is not None:
        return 2.0 * math.pi / float(r.psd[0][0]), 2.0 * math.pi / float(r.psd[0][-1])
    return r.rolloff_wavelength, r.short_wavelength


def _file_grid(upper: Roughness, lower: Roughness, k: int = 0) -> tuple[tuple[int, int], float]:
    grids = []
    for r in (upper, lower):
        if r.files is not None:
            s = load(r.files[k], dx=r.dx)
            grids.append((r, s.shape, s.dx))
    (r0, shape0, dx0) = grids[0]
    for r, shape, dx in grids[1:]:
        if shape != shape0 or not math.isclose(dx, dx0, rel_tol=1e-12):
            raise invalid(
                f"{r.name}.files",
                f"realisation {k}: {r.files[k]!r} is {shape[0]}×{shape[1]} with dx={dx!r} m but "
                f"{r0.files[k]!r} is {shape0[0]}×{shape0[1]} with dx={dx0!r} m; paired files "
                "need the same shape and spacing",
            )
    return shape0, dx0


def _is_pow2(n: int) -> bool:
    return n >= 2 and n & (n - 1) == 0


def choose_patch(
    upper: Roughness,
    lower: Roughness,
    *,
    n: int | None = None,
    length: float | None = None,
    points_per_short_wavelength: float = 4.0,
    rolloffs_per_patch: float = 4.0,
    max_n: int = 1024,
) -> Patch:
    """Grid and patch for the composite (rules in ``docs/seal-bodies.md``; Yastrebov et al.,
    Tribol. Lett. 65, 2017 and Müser et al., Tribol. Lett. 65:118, 2017):

    1. resolution: ``dx ≤ λ_s / points_per_short_wavelength`` with ``λ_s`` the shortest
       short-wavelength cut-off of the two bodies;
    2. size: ``L ≥ rolloffs_per_patch · λ_r`` with ``λ_r`` the longest roll-off wavelength
       (a self-affine spectrum without roll-off has no largest scale: ``length`` is then
       required);
    3. ``n`` = the smallest power of two with ``n·dx ≥ L`` (``dx`` kept, ``L = n·dx``);
    4. capped at ``max_n``: the resolution is kept and the patch shrunk to ``max_n·dx`` (fewer
       roll-offs per patch, which more realisations partly make up for; a coarser grid would
       bias every realisation the same way). ``rule`` says what was given up.

    ``n`` and/or ``length`` [m] override the rules (``n`` a power of two ≤ ``max_n``; with
    ``length`` alone ``n`` follows from rule 1 and ``dx = length/n``). Measured files fix the
    grid: ``n = nx``, ``dx`` from the files (non-square files keep their shape; ``Patch.n`` is
    then the number of columns), and ``n``/``length`` may only repeat them.
    """
    _pair(upper, lower)
    pps = _validate.positive("points_per_short_wavelength", points_per_short_wavelength)
    rpp = _validate.positive("rolloffs_per_patch", rolloffs_per_patch)
    max_n_i = _validate.integer("max_n", max_n, low=2)
    n_i = _validate.optional_integer("n", n, low=2)
    length_f = None if length is None else _validate.positive(
        "length", length, what="a positive patch side in m"
    )
    if upper.flat and lower.flat:
        raise invalid("surface", "both bodies are smooth; give at least one rough surface")

    if upper.files is not None or lower.files is not None:
        (ny, nx), dx = _file_grid(upper, lower)
        if n_i is not None and n_i != nx:
            raise invalid("n", f"{n_i} differs from the files' {nx} columns; drop n")
        if length_f is not None and not math.isclose(length_f, nx * dx, rel_tol=1e-9):
            raise invalid("length", f"{length_f!r} m differs from the files' {nx * dx!r} m")
        return Patch(nx, nx * dx, dx, f"from the files: {ny}×{nx} points, dx = {dx:.6g} m")

    bodies = [r for r in (upper, lower) if not r.flat]
    shorts = [_scales(r)[1] for r in bodies]
    rolls = [s for s in (_scales(r)[0] for r in bodies) if s is not None]
    lam_s = min(shorts)  # type: ignore[type-var]
    lam_r = max(rolls) if rolls else None
    dx_rule = lam_s / pps  # type: ignore[operator]

    if n_i is not None:
        if not _is_pow2(n_i):
            raise invalid("n", f"must be a power of two (refinement doubles it), got {n_i}")
        if n_i > max_n_i:
            raise invalid("n", f"{n_i} exceeds max_n = {max_n_i}; raise max_n or lower n")
        if length_f is not None:
            return Patch(
                n_i, length_f, length_f / n_i, f"given: n = {n_i}, length = {length_f:.6g} m"
            )
        return Patch(n_i, n_i * dx_rule, dx_rule,
                     f"given n = {n_i}; dx = λ_s/{pps:g} = {dx_rule:.6g} m (λ_s = {lam_s:.6g} m)")
    if length_f is not None:
        need = max(2, 2 ** math.ceil(math.log2(max(length_f / dx_rule, 2.0) * (1 - 1e-12))))
        if need > max_n_i:
            raise invalid(
                "length",
                f"{length_f:.6g} m at dx ≤ λ_s/{pps:g} = {dx_rule:.6g} m needs n = {need} > "
                f"max_n = {max_n_i}; raise max_n, lower points_per_short_wavelength or give n",
            )
        return Patch(need, length_f, length_f / need,
                     f"given length = {length_f:.6g} m; n = {need} for dx ≤ λ_s/{pps:g}")
    if lam_r is None:
        raise invalid(
            "length",
            "no body has a roll-off wavelength: a self-affine spectrum without roll-off has no "
            "largest scale to size the patch by; give rolloff_wavelength or the patch length",
        )
    want = rpp * lam_r
    need = max(2, 2 ** math.ceil(math.log2(max(want / dx_rule, 2.0) * (1 - 1e-12))))
    rule = (f"dx = λ_s/{pps:g} = {dx_rule:.6g} m (λ_s = {lam_s:.6g} m); "
            f"L ≥ {rpp:g}·λ_r = {want:.6g} m (λ_r = {lam_r:.6g} m); n = {need} (power of two)")
    if need > max_n_i:
        # Keep a power of two: the largest one ≤ max_n.
        n_cap = 2 ** int(math.floor(math.log2(max_n_i)))
        got = n_cap * dx_rule / lam_r
        rule += (f"; capped at max_n = {max_n_i}: n = {n_cap}, kept dx and gave up patch size: "
                 f"L = {n_cap * dx_rule:.6g} m holds {got:.3g} roll-off wavelengths instead of "
                 f"{rpp:g}")
        need = n_cap
    return Patch(need, need * dx_rule, dx_rule, rule)


def validity_warnings(upper: Roughness, lower: Roughness, patch: Patch) -> list[str]:
    """Messages for inputs outside the method's validity (empty when fine):

    * composite rms slope > :data:`MAX_RMS_SLOPE` (0.3): the small-slope half-space theory
      behind the composite mapping and the boundary-element kernel degrades;
    * a short-wavelength cut-off resolved by fewer than
      :data:`MIN_POINTS_PER_SHORT_WAVELENGTH` (4) points, ``λ_s/dx < 4``;
    * a patch smaller than :data:`MIN_ROLLOFFS_PER_PATCH` (2) roll-off wavelengths,
      ``L < 2 λ_r`` (a patch is then not representative of the surface).
    """
    _pair(upper, lower)
    if not isinstance(patch, Patch):
        raise invalid("patch", f"must be a Patch, got {_validate.describe(patch)}")
    out: list[str] = []
    slope = composite_rms_slope(upper, lower, length=patch.length)
    if slope > MAX_RMS_SLOPE:
        out.append(
            f"composite rms slope {slope:.3g} exceeds {MAX_RMS_SLOPE:g}: the small-slope "
            "(half-space) contact theory behind the two-body mapping is outside its validity"
        )
    for r in (upper, lower):
        if r.flat or r.files is not None:
            continue
        lam_r, lam_s = _scales(r)
        pts = lam_s / patch.dx  # type: ignore[operator]
        if pts < MIN_POINTS_PER_SHORT_WAVELENGTH * (1 - 1e-12):
            out.append(
                f"{r.name}: short wavelength {lam_s:.6g} m is resolved by {pts:.3g} grid points "
                f"(dx = {patch.dx:.6g} m), fewer than {MIN_POINTS_PER_SHORT_WAVELENGTH:g}; "
                "contact area and gaps are then grid-dependent"
            )
        if lam_r is not None and patch.length < MIN_ROLLOFFS_PER_PATCH * lam_r * (1 - 1e-12):
            out.append(
                f"{r.name}: patch side {patch.length:.6g} m is smaller than "
                f"{MIN_ROLLOFFS_PER_PATCH:g} roll-off wavelengths ({lam_r:.6g} m); a patch is "
                "then not representative of the surface"
            )
    return out
