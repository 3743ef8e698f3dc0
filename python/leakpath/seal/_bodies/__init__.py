"""Two rough elastic bodies as one composite rough surface against a rigid flat.

The mapping (Johnson, *Contact Mechanics*, 1985, §4.2 and §13.1; derivation in
``docs/seal-bodies.md``): two elastic half-spaces with small surface slopes, pressed together
without friction, touch exactly like a rigid flat pressed on an elastic half-space with

* the **composite** roughness ``h = h_upper + h_lower`` [m], each body's heights measured from
  its own mean plane towards the other body, and
* the **contact modulus** ``E* = [(1 − ν₁²)/E₁ + (1 − ν₂²)/E₂]⁻¹`` [Pa].

For independent random surfaces the power spectral densities add, ``C = C_upper + C_lower``
[m⁴]. The PSD convention (Persson, J. Phys.: Condens. Matter 18, 7789 (2006); Jacobs, Junge &
Pastewka, Surf. Topogr.: Metrol. Prop. 5, 013001 (2017)) is the isotropic 2-D one with angular
wavevectors ``q = 2π/λ`` [rad/m] (``docs/surfaces.md``):

    ⟨h²⟩ = ∫ d²q C(q) = 2π ∫ q C(q) dq,     ⟨|∇h|²⟩ = 2π ∫ q³ C(q) dq.

Public names (re-exported by :mod:`leakpath.seal`): :class:`Material`,
:func:`contact_modulus_pair`, :class:`Roughness`, :func:`composite_psd`,
:func:`composite_rms_slope`, :func:`composite_rms_height`, :class:`Patch`,
:func:`choose_patch`, :func:`validity_warnings`, :func:`composite_surface`, and the helpers
:func:`body_psd`, :func:`available_realisations`.

One module a concept: ``_material`` (materials, the contact modulus), ``_roughness`` (one
body's description), ``_spectra`` (PSDs and rms statistics), ``_patch`` (the patch and the
validity limits), ``_synthesis`` (realisations of the composite surface).
"""

from __future__ import annotations

from ._material import Material, contact_modulus_pair
from ._patch import (
    MAX_RMS_SLOPE,
    MIN_POINTS_PER_SHORT_WAVELENGTH,
    MIN_ROLLOFFS_PER_PATCH,
    Patch,
    choose_patch,
    validity_warnings,
)
from ._roughness import Roughness
from ._spectra import body_psd, composite_psd, composite_rms_height, composite_rms_slope
from ._synthesis import available_realisations, composite_surface

__all__ = [
    "MAX_RMS_SLOPE",
    "MIN_POINTS_PER_SHORT_WAVELENGTH",
    "MIN_ROLLOFFS_PER_PATCH",
    "Material",
    "Patch",
    "Roughness",
    "available_realisations",
    "body_psd",
    "choose_patch",
    "composite_psd",
    "composite_rms_height",
    "composite_rms_slope",
    "composite_surface",
    "contact_modulus_pair",
    "validity_warnings",
]
