"""Isothermal ideal-gas flow through the gap against the 1-D analytic solution."""

from __future__ import annotations

import numpy as np
import pytest

import leakpath
from leakpath.errors import InvalidArgumentError

R_AIR = 287.05  # J/(kg K)


@pytest.mark.parametrize("axis", [0, 1])
def test_parallel_plates_against_the_analytic_gas_flow(axis):
    ny, nx, g, dx = 30, 17, 2e-6, 1e-5
    eta, T, p_in, p_out = 1.8e-5, 293.15, 3e5, 1e5
    f = leakpath.flow(
        np.full((ny, nx), g),
        dx=dx,
        axis=axis,
        viscosity=eta,
        gas=True,
        inlet_pressure=p_in,
        outlet_pressure=p_out,
        gas_constant=R_AIR,
        temperature=T,
    )
    n_along, n_across = (ny, nx) if axis == 0 else (nx, ny)
    L, W = n_along * dx, n_across * dx  # noqa: N806
    # 1-D isothermal compressible Poiseuille flow between plates:
    # ṁ = W g³ (p_in² − p_out²) / (24 η R_s T L), p(x) = √(p_in² − (p_in² − p_out²) x/L).
    mdot = W * g**3 * (p_in**2 - p_out**2) / (24 * eta * R_AIR * T * L)
    assert f.gas and f.mass_flow_rate == pytest.approx(mdot, rel=1e-11, abs=0)
    x = (np.arange(n_along) + 0.5) * dx  # cell centres from the inlet reservoir
    p_exact = np.sqrt(p_in**2 - (p_in**2 - p_out**2) * x / L)
    p = f.pressure if axis == 0 else f.pressure.T
    np.testing.assert_allclose(p, np.broadcast_to(p_exact[:, None], p.shape), rtol=1e-11)
    # Volume flow at the outlet density; the same conductance as the liquid's.
    assert f.flow_rate == pytest.approx(mdot * R_AIR * T / p_out, rel=1e-11, abs=0)
    liquid = leakpath.flow(np.full((ny, nx), g), dx=dx, axis=axis, viscosity=eta)
    assert f.conductance == pytest.approx(liquid.conductance, rel=1e-12, abs=0)
    # The outlet faces carry the mass flow (mass fluxes).
    out = f.flux_axis0[-1, :] if axis == 0 else f.flux_axis1[:, -1]
    assert out.sum() == pytest.approx(mdot, rel=1e-11, abs=0)
    assert f.pressure_drop == p_in - p_out


def test_gas_through_a_contact_equals_the_liquid_conductance_times_the_squares():
    s = leakpath.spectral(32, 0.8, seed=3, rms_height=1.0)
    st = leakpath.contact.ContactProblem(s, boundary="periodic").solve(0.8)
    liquid = st.flow()
    gas = st.flow(
        gas=True, inlet_pressure=2.0, outlet_pressure=1.0, gas_constant=1.0, temperature=1.0
    )
    assert gas.mass_flow_rate == pytest.approx(liquid.conductance * 3.0 / 2.0, rel=1e-10, abs=0)
    ok = np.isfinite(liquid.pressure)
    assert np.array_equal(ok, np.isfinite(gas.pressure))
    # p² = p_out² + (p_in² − p_out²)·(liquid pressure at unit drop): the same φ field.
    np.testing.assert_allclose(gas.pressure[ok] ** 2, 1.0 + 3.0 * liquid.pressure[ok], rtol=1e-9)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"gas": True, "outlet_pressure": 1.0, "gas_constant": 1.0, "temperature": 1.0},
         "inlet_pressure"),
        ({"gas": True, "inlet_pressure": -1.0, "outlet_pressure": 1.0, "gas_constant": 1.0,
          "temperature": 1.0}, "inlet_pressure"),
        ({"gas": True, "inlet_pressure": 2.0, "outlet_pressure": 1.0, "gas_constant": 0.0,
          "temperature": 1.0}, "gas_constant"),
        ({"gas": True, "inlet_pressure": 2.0, "outlet_pressure": 1.0, "gas_constant": 1.0,
          "temperature": 1.0, "pressure_drop": 1.0}, "pressure_drop"),
        ({"inlet_pressure": 2.0}, "inlet_pressure"),
        ({"gas": "yes"}, "gas"),
    ],
)
def test_bad_gas_arguments_name_the_argument(kwargs, name):
    with pytest.raises(InvalidArgumentError) as exc:
        leakpath.flow(np.ones((4, 4)), dx=1.0, **kwargs)
    assert exc.value.argument == name
    assert str(exc.value).startswith(name + ":")


def test_cli_gas_flow_matches_the_api(capsys):
    import json

    from leakpath.cli import main

    spec = "spectral:n=64,hurst=0.8,seed=2,rms_height=1"
    gas = ["--gas", "--inlet-pressure", "3", "--outlet-pressure", "1", "--gas-constant",
           "287", "--temperature", "300"]
    rc = main(["flow", spec, "--approach", "1.0", "--viscosity", "2", "--json", *gas])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    s = leakpath.spectral(64, 0.8, seed=2, rms_height=1.0)
    st = leakpath.solve(s, 1.0, solver="polonsky-keer")
    f = st.flow(viscosity=2.0, gas=True, inlet_pressure=3.0, outlet_pressure=1.0,
                gas_constant=287.0, temperature=300.0)
    assert out["gas"] is True
    assert out["mass_flow_rate"] == pytest.approx(f.mass_flow_rate, rel=1e-9, abs=0)
    # ṁ = C (p_in² − p_out²)/(2 R_s T) with the liquid conductance of the same gap.
    liquid = st.flow(viscosity=2.0)
    assert out["mass_flow_rate"] == pytest.approx(
        liquid.conductance * (9.0 - 1.0) / (2 * 287.0 * 300.0), rel=1e-9, abs=0
    )
    # Gas inputs without --gas, and --gas without them, are refused in one line.
    assert main(["flow", spec, "--approach", "1", "--temperature", "300"]) == 2
    assert "--gas" in capsys.readouterr().err
    assert main(["flow", spec, "--approach", "1", "--gas"]) == 2
    assert "inlet_pressure" in capsys.readouterr().err
