"""Seal leak rates: how much does a seal leak at a given contact pressure?

Two real rough bodies (measured topographies or roughness statistics, SI units) are mapped
onto one composite surface against a rigid flat (heights summed, ``E* = [(1−ν₁²)/E₁ +
(1−ν₂²)/E₂]⁻¹``); N realisations of a representative patch are pressed at the nominal
pressures, the Reynolds flow through each gap gives the patch permeability K [m³], the
realisations are upscaled to the seal (an estimator with a confidence interval), and the
seal's leak rate follows as ``Q = K_eff (W/L) Δp/η`` [m³/s] for a liquid or the isothermal
ideal-gas mass flow [kg/s]. ``docs/seal.md`` describes the mapping, the patch, the
estimator, the configuration keys and the outputs.

Modules: ``_config`` (typed configuration), ``_bodies`` (materials, roughness, spectra,
patch, composite surfaces; one module each), ``_theory`` (Persson, Bruggeman),
``_estimate`` (upscaling, leak-rate formulas), ``_run`` (the run), ``_result`` (tables,
files), ``_figures``.
"""

from ._config import (
    BodyMaterial,
    BodySurface,
    ConvergenceCheck,
    Fluid,
    SealConfig,
    SealGeometry,
    load_config,
)
from ._result import SealResult, Table
from ._run import SealConvergenceWarning, SealValidityWarning, seal_leakage

__all__ = [
    "BodyMaterial",
    "BodySurface",
    "ConvergenceCheck",
    "Fluid",
    "SealConfig",
    "SealConvergenceWarning",
    "SealGeometry",
    "SealResult",
    "SealValidityWarning",
    "Table",
    "load_config",
    "seal_leakage",
]
