"""The solved contact at one approach or load: :class:`ContactState` (fields on the surface
grid, derived areas, volumes and plastic deformation, and the percolation and flow of its
gap). Solved by :class:`leakpath.contact.ContactProblem`; the conventions are in
``docs/conventions.md`` and ``docs/plasticity.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from . import _validate
from ._flow import DEFAULT_TOL as _FLOW_TOL

if TYPE_CHECKING:
    from ._flow import Flow
    from ._percolation import Percolation


@dataclass(frozen=True, eq=False)
class ContactState:
    """The solved contact at one imposed approach.

    Fields are 2-D arrays on the surface grid; scalars are in the surface's length units and
    the pressure units of ``E``.
    """

    approach: float
    pressure: np.ndarray
    displacement: np.ndarray
    gap: np.ndarray
    heights: np.ndarray = field(repr=False)
    dx: float
    e_star: float
    boundary: str
    solver: str
    iterations: int
    kkt: float
    seconds: float
    #: Polonsky–Keer: operator applications ``C x`` (forward + inverse real FFT of the padded
    #: grid) and preconditioner applications (FFT pairs on the unpadded grid); 0 for the
    #: exact solvers, which work on dense blocks.
    fft_products: int = 0
    preconditioner_products: int = 0
    #: The coarse-to-fine start of a cold Polonsky–Keer solve: FFT products on the coarse
    #: grids, each weighted by its grid's share of the fine points (a 2× coarser product
    #: counts ¼); 0 when there was none.
    coarse_fft_products: float = 0.0
    #: The hardness ``H`` [pressure] the pressure was capped at (``None``: elastic).
    hardness: float | None = None
    #: Permanent plastic displacement ``w_p ≥ 0`` [length] of the surface, relative to
    #: ``heights``: the interpenetration ``−g`` at the points that yielded (``p = H``) in this
    #: solve plus the deformation of the surface it was solved on (an unloading problem);
    #: ``None``: none (zeros).
    plastic_displacement_field: np.ndarray | None = field(default=None, repr=False)
    #: Name of the length unit (:attr:`leakpath.Surface.unit`) the state's lengths are in;
    #: ``None`` for a state built by hand (then printed as "length").
    unit: str | None = field(default=None, repr=False)

    def __repr__(self) -> str:
        # One line of scalars: the fields are grids, shown by their shape only.
        try:
            ny, nx = self.shape
            u = self.unit or "length"
            return (
                f"ContactState({ny}x{nx} grid, approach={self.approach:.6g} {u}, "
                f"contact_fraction={self.contact_fraction:.4g}, "
                f"mean_pressure={self.mean_pressure:.4g} (unit of E), "
                f"mean_gap={self.mean_gap:.4g} {u}, "
                f"solver={self.solver!r}, iterations={self.iterations}, kkt={self.kkt:.1e}, "
                + (
                    ""
                    if self.hardness is None
                    else f"hardness={self.hardness:.4g} (unit of E), "
                    f"plastic_fraction={self.plastic_fraction:.4g}, "
                )
                + f"seconds={self.seconds:.3g} s)"
            )
        except Exception:  # malformed fields (a hand-built state refused as a warm start)
            return (
                f"ContactState(approach={_validate.describe(self.approach, 40)}, "
                f"pressure={type(self.pressure).__name__} of shape "
                f"{getattr(self.pressure, 'shape', '?')})"
            )

    @property
    def shape(self) -> tuple[int, int]:
        return self.pressure.shape  # type: ignore[return-value]

    @property
    def n_points(self) -> int:
        return int(self.pressure.size)

    @property
    def nominal_area(self) -> float:
        """``A0 = ny·nx·dx²``."""
        return self.n_points * self.dx**2

    @cached_property
    def contact(self) -> np.ndarray:
        """Contact mask ``p > 0``."""
        return self.pressure > 0

    @property
    def deformed(self) -> np.ndarray:
        """Deformed surface ``s = h − w_p − u`` (``w_p``: the plastic displacement, 0 for
        elastic contact)."""
        if self.plastic_displacement_field is None:
            return self.heights - self.displacement
        return self.heights - self.plastic_displacement_field - self.displacement

    @property
    def plastic_displacement(self) -> np.ndarray:
        """Permanent plastic displacement ``w_p ≥ 0`` [length] (zeros for elastic contact):
        ``−g`` of the elastic–plastic solution at points at the hardness, plus any deformation
        the solved surface already had (``docs/plasticity.md``)."""
        if self.plastic_displacement_field is None:
            return np.zeros_like(self.pressure)
        return self.plastic_displacement_field

    @property
    def permanent_surface(self) -> np.ndarray:
        """The permanently deformed surface ``h − w_p`` [length]: what is left after
        complete unloading (the elastic part recovers)."""
        return self.heights - self.plastic_displacement

    @cached_property
    def plastic(self) -> np.ndarray:
        """Plastically deformed points ``w_p > 0``."""
        return self.plastic_displacement > 0

    @cached_property
    def yielding(self) -> np.ndarray:
        """Points at the hardness in this state, ``p ≥ H`` (all False without one)."""
        if self.hardness is None:
            return np.zeros(self.pressure.shape, dtype=bool)
        return self.pressure >= self.hardness

    @property
    def plastic_fraction(self) -> float:
        """``a_pl = #(w_p > 0)/N``: area fraction deformed plastically."""
        return float(np.count_nonzero(self.plastic) / self.n_points)

    @property
    def plastic_volume(self) -> float:
        """``V_pl = dx² Σ w_p`` [length³]: volume displaced plastically."""
        return float(self.plastic_displacement.sum() * self.dx**2)

    @property
    def load(self) -> float:
        """Total load ``F = dx² Σ p``."""
        return float(self.pressure.sum() * self.dx**2)

    @property
    def mean_pressure(self) -> float:
        """``p̄ = F / A0``."""
        return float(self.pressure.mean())

    @property
    def contact_fraction(self) -> float:
        """``a = #(p > 0) / N``."""
        return float(np.count_nonzero(self.contact) / self.n_points)

    @property
    def contact_area(self) -> float:
        """``A = #(p > 0)·dx²``."""
        return float(np.count_nonzero(self.contact) * self.dx**2)

    @property
    def free_volume(self) -> float:
        """``V = dx² Σ g``."""
        return float(self.gap.sum() * self.dx**2)

    @property
    def mean_gap(self) -> float:
        """``ḡ = V / A0``."""
        return float(self.gap.mean())

    def percolation(
        self, axis: Any = 0, connectivity: int = 4, threads: int | None = None
    ) -> Percolation:
        """Percolation classes of the free region (see :func:`leakpath.percolation`;
        ``threads`` does not change the result, so it is not part of the cache key)."""
        from ._percolation import percolation

        key = (axis, connectivity)
        cache = self.__dict__.setdefault("_percolation_cache", {})
        if key not in cache:
            cache[key] = percolation(self, axis=axis, connectivity=connectivity, threads=threads)
        return cache[key]

    @property
    def percolating_volume(self) -> float:
        """``V_pg``: free volume of the clusters spanning along axis 0 (4-connectivity)."""
        return float(self.percolation().spanning_volume)

    @property
    def dead_end_volume(self) -> float:
        """Free volume of clusters touching the boundary without spanning (axis 0)."""
        return float(self.percolation().dead_end_volume)

    @property
    def trapped_volume(self) -> float:
        """Free volume of clusters touching no boundary."""
        return float(self.percolation().trapped_volume)

    def summary(self) -> dict[str, float | int | str]:
        """Scalars of this state, for tables."""
        return {
            "approach": self.approach,
            "contact_fraction": self.contact_fraction,
            "load": self.load,
            "mean_pressure": self.mean_pressure,
            "free_volume": self.free_volume,
            "mean_gap": self.mean_gap,
            "solver": self.solver,
            "iterations": self.iterations,
            "kkt": self.kkt,
            "seconds": self.seconds,
            **(
                {}
                if self.hardness is None
                else {
                    "hardness": self.hardness,
                    "plastic_fraction": self.plastic_fraction,
                    "plastic_volume": self.plastic_volume,
                }
            ),
        }

    def flow(
        self,
        *,
        axis: int = 0,
        viscosity: float = 1.0,
        pressure_drop: float | None = None,
        periodic: bool | None = None,
        tol: float = _FLOW_TOL,
        max_iter: int | None = None,
        memory_limit: int | None = None,
        solver: str = "auto",
        gas: bool = False,
        inlet_pressure: float | None = None,
        outlet_pressure: float | None = None,
        gas_constant: float | None = None,
        temperature: float | None = None,
        threads: int | None = None,
    ) -> Flow:
        """Leak rate: Reynolds flow through this gap (:func:`leakpath.flow`, whose docstring
        gives every argument and unit; ``dx``, ``contact`` and the wrap come from this
        state). It reuses the labelling of this state's open cells that its percolation
        made (or makes it for both)."""
        from ._flow import flow

        return flow(
            self,
            axis=axis,
            viscosity=viscosity,
            pressure_drop=pressure_drop,
            periodic=periodic,
            tol=tol,
            max_iter=max_iter,
            memory_limit=memory_limit,
            solver=solver,
            gas=gas,
            inlet_pressure=inlet_pressure,
            outlet_pressure=outlet_pressure,
            gas_constant=gas_constant,
            temperature=temperature,
            threads=threads,
        )
