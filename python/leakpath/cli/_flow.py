"""``leakpath flow``: the leak rate through one contact state."""

from __future__ import annotations

import argparse
import json
import math
from typing import Any

from ._common import (
    UsageError,
    _surface_from_arg,
)


def _cmd_flow(args: argparse.Namespace) -> int:
    import numpy as np

    from .. import _validate
    from .._flow import flow
    from ..contact import contact_modulus, default_memory_limit, solve

    surface = _surface_from_arg(args.surface, args.dx)
    e_star = contact_modulus(args.E, args.nu)
    if args.approach is None:
        if not (math.isfinite(args.pressure) and args.pressure > 0):
            raise UsageError(f"--pressure must be a positive number, got {args.pressure!r}")
        _validate.load_scales(args.pressure, e_star, surface.dx, name="--pressure")
    state = solve(
        surface, args.approach, mean_pressure=args.pressure if args.approach is None else None,
        E=args.E, nu=args.nu, boundary=args.boundary, solver="polonsky-keer",
        memory_limit=default_memory_limit(),
    )
    gap, contact = np.maximum(state.gap, 0.0), state.contact
    approach, mean_pressure = state.approach, state.mean_pressure
    gas = {}
    if args.gas:
        gas = {
            "gas": True,
            "inlet_pressure": args.inlet_pressure,
            "outlet_pressure": args.outlet_pressure,
            "gas_constant": args.gas_constant,
            "temperature": args.temperature,
        }
    elif any(
        v is not None
        for v in (args.inlet_pressure, args.outlet_pressure, args.gas_constant, args.temperature)
    ):
        raise UsageError(
            "--inlet-pressure, --outlet-pressure, --gas-constant and --temperature need --gas"
        )
    f = flow(
        gap,
        dx=surface.dx,
        contact=contact,
        axis=args.axis,
        viscosity=args.viscosity,
        pressure_drop=None if args.gas else args.pressure_drop,
        periodic=args.boundary == "periodic",
        **gas,
    )
    result = {
        "surface": args.surface,
        "shape": list(surface.shape),
        "dx": surface.dx,
        "boundary": args.boundary,
        "approach": approach,
        "mean_pressure": mean_pressure,
        "contact_fraction": float(np.count_nonzero(contact) / contact.size),
        "axis": f.axis,
        "viscosity": f.viscosity,
        "pressure_drop": f.pressure_drop,
        "gas": f.gas,
        "flow_rate": f.flow_rate,
        "inlet_flow_rate": f.inlet_flow_rate,
        "conductance": f.conductance,
        "permeability": f.permeability,
        "hydraulic_aperture": f.hydraulic_aperture,
        "solver": f.solver,
        "n_unknowns": f.n_unknowns,
        "iterations": f.iterations,
        "residual": f.residual,
        "conservation": f.conservation,
        "seconds": f.seconds,
    }
    if f.gas:
        result.update(
            mass_flow_rate=f.mass_flow_rate,
            inlet_pressure=f.inlet_pressure,
            outlet_pressure=f.outlet_pressure,
            gas_constant=f.gas_constant,
            temperature=f.temperature,
        )
    if args.json:
        # A volume rate at zero outlet pressure is infinite: JSON has no such number.
        print(json.dumps({k: _finite_or_none(v) for k, v in result.items()}, indent=2))
    else:
        width = max(len(k) for k in result)
        for k, v in result.items():
            text = f"{v:.6g}" if isinstance(v, float) else str(v)
            print(f"{k:<{width}}  {text}")
    return 0


def _finite_or_none(v: Any) -> Any:
    return None if isinstance(v, float) and not math.isfinite(v) else v


def _add_flow_parser(subparsers: Any) -> None:
    """``leakpath flow SURFACE``: the leak rate through the gap at one approach or load."""
    p = subparsers.add_parser(
        "flow",
        help="leak rate (Reynolds flow through the gap) at one approach or mean pressure",
        description=(
            "Press SURFACE against a rigid flat (Polonsky-Keer) at --approach A (length) or "
            "mean pressure --pressure P, then solve the steady Reynolds flow through the gap "
            "along --axis with inlet pressure --pressure-drop and outlet 0 (docs/flow.md). "
            "SURFACE is a file or a spec such as spectral:n=256,hurst=0.8,seed=1,rms_height=1."
        ),
    )
    p.add_argument("surface", metavar="SURFACE", help="surface file or generator spec")
    p.add_argument("--dx", type=float, help="grid spacing for files that do not store it")
    load = p.add_mutually_exclusive_group(required=True)
    load.add_argument("--approach", type=float, help="imposed approach (length)")
    load.add_argument("--pressure", type=float, help="mean contact pressure (load control)")
    p.add_argument("--axis", type=int, choices=(0, 1), default=0, help="flow axis (default 0)")
    p.add_argument("--viscosity", type=float, default=1.0, help="dynamic viscosity (default 1)")
    p.add_argument(
        "--pressure-drop", type=float, default=1.0, help="inlet minus outlet pressure (default 1)"
    )
    p.add_argument(
        "--boundary",
        choices=("free", "periodic"),
        default="free",
        help="elastic boundary; periodic also wraps the flow across the axis (default free)",
    )
    p.add_argument("--E", type=float, default=1.0, help="Young's modulus (default 1)")
    p.add_argument("--nu", type=float, default=0.0, help="Poisson's ratio (default 0)")
    gas = p.add_argument_group(
        "ideal gas",
        "isothermal ideal gas instead of a liquid: mass flow C (p_in² − p_out²)/(2 R_s T) "
        "through the liquid conductance C (docs/flow.md); --pressure-drop is then unused",
    )
    gas.add_argument("--gas", action="store_true", help="isothermal ideal gas")
    gas.add_argument("--inlet-pressure", type=float, help="absolute inlet pressure")
    gas.add_argument("--outlet-pressure", type=float, help="absolute outlet pressure")
    gas.add_argument("--gas-constant", type=float, help="specific gas constant R_s")
    gas.add_argument("--temperature", type=float, help="absolute temperature T")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=_cmd_flow)


# ---------------------------------------------------------------------------- ensemble
