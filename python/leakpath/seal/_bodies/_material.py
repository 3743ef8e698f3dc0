"""One elastic body's material and the contact modulus of two (Johnson, *Contact Mechanics*,
1985, eq. 4.22)."""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field

from ... import _validate
from ..._validate import invalid


@dataclass(frozen=True)
class Material:
    """One elastic body: Young's modulus ``E`` [Pa] (``math.inf`` for a rigid body) and
    Poisson's ratio ``ν``, ``−1 < ν ≤ 0.5`` (0.5: incompressible, e.g. rubber).

    ``name`` only prefixes error messages (``"material.upper"`` → ``material.upper.E: …``).
    """

    E: float
    nu: float
    name: str = field(default="material", compare=False, repr=False)

    def __post_init__(self) -> None:
        e = _validate._scalar(self.E)
        if _validate._is_real(e) and float(e) == math.inf:
            e_f = math.inf
        else:
            e_f = _validate.real(
                f"{self.name}.E", e, low=0.0, low_open=True,
                what="a positive Young's modulus in Pa (math.inf for a rigid body)",
            )
        nu_f = _validate.real(
            f"{self.name}.nu", self.nu, low=-1.0, high=0.5, low_open=True,
            what="a Poisson's ratio in (-1, 0.5]",
        )
        object.__setattr__(self, "E", e_f)
        object.__setattr__(self, "nu", nu_f)

    @property
    def rigid(self) -> bool:
        """True for ``E = ∞``."""
        return self.E == math.inf

    @property
    def compliance(self) -> float:
        """``(1 − ν²)/E`` [1/Pa]; 0 for a rigid body."""
        return 0.0 if self.rigid else (1.0 - self.nu * self.nu) / self.E


def contact_modulus_pair(upper: Material, lower: Material) -> float:
    """Contact modulus of two elastic half-spaces [Pa] (Johnson, *Contact Mechanics*, eq. 4.22):

        E* = [(1 − ν₁²)/E₁ + (1 − ν₂²)/E₂]⁻¹

    A rigid body (``E = math.inf``) contributes no compliance, so a rubber on rigid steel gives
    ``E* = E_rubber/(1 − ν²)``. Symmetric in the two bodies. Two rigid bodies are refused
    (there is no elastic contact to solve).
    """
    for name, m in (("upper", upper), ("lower", lower)):
        if not isinstance(m, Material):
            raise invalid(f"material.{name}", f"must be a Material(E=..., nu=...), got {m!r}")
    compliance = upper.compliance + lower.compliance
    if compliance == 0.0:
        raise invalid(
            "material",
            "both bodies are rigid (E = inf); at least one must be elastic (give a finite E)",
        )
    e_star = 1.0 / compliance
    if not (sys.float_info.min <= e_star < math.inf):
        raise invalid(
            "material",
            f"the contact modulus E* = {e_star!r} Pa is outside the floating-point range; "
            "check the units of E (Pa)",
        )
    return e_star
