"""Sweeps with a hardness and an unloading branch, their checkpoints, the command line, the
figures and the seal configuration's hardness."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from leakpath import cli
from leakpath._sweep import sweep
from leakpath._table import _csv_text
from leakpath.contact import ContactProblem
from leakpath.errors import InvalidArgumentError
from leakpath.seal import SealConfig, SealValidityWarning, seal_leakage
from leakpath.surfaces import Surface

DX = 1.0
H = 0.3
PRESSURES = [0.01, 0.03, 0.08]


def rough(n: int = 48, seed: int = 4) -> Surface:
    rng = np.random.default_rng(seed)
    k = np.hypot(*np.meshgrid(np.fft.fftfreq(n), np.fft.fftfreq(n), indexing="ij"))
    k[0, 0] = 1.0
    h = np.real(np.fft.ifft2(np.fft.fft2(rng.standard_normal((n, n))) * k**-1.8))
    return Surface(h / h.std(), DX)


def test_loading_and_unloading_branches() -> None:
    s = rough()
    r = sweep(s, mean_pressures=PRESSURES, hardness=H, unload=True)
    branch = r.column("branch").tolist()
    assert branch == ["loading"] * 3 + ["unloading"] * 2
    p = r.column("mean_pressure")
    assert np.allclose(p, PRESSURES + PRESSURES[-2::-1], rtol=1e-9)
    # Loading rows: each is the capped solve on the original surface.
    problem = ContactProblem(s, hardness=H)
    top = problem.solve(mean_pressure=PRESSURES[-1])
    assert r.rows[2]["plastic_volume"] == pytest.approx(top.plastic_volume, rel=1e-6)
    assert r.rows[2]["plastic_fraction"] == pytest.approx(top.plastic_fraction, abs=1e-9)
    assert r.rows[2]["plastic_fraction"] > 0
    # Unloading rows: the elastic contact of the permanent surface (solved independently).
    perm = ContactProblem(Surface(top.permanent_surface, DX))
    for row in r.rows[3:]:
        ref = perm.solve(mean_pressure=row["mean_pressure"], solver="polonsky-keer")
        one = 2 / s.heights.size
        assert row["contact_fraction"] == pytest.approx(ref.contact_fraction, abs=one)
        assert row["approach"] == pytest.approx(
            ref.approach + s.heights.max() - top.permanent_surface.max(), rel=1e-6
        )
        # The plastic deformation does not recover.
        assert row["plastic_volume"] == r.rows[2]["plastic_volume"]
    # Units of the new columns.
    assert r.units["plastic_volume"] == f"{s.unit}^3"
    assert r.units["plastic_fraction"] == "1"
    # The leak rate is tabulated on both branches; the flattened surface seals better.
    q = r.column("Q")
    assert np.all(np.isfinite(q))
    assert q[3] <= q[1] and q[4] <= q[0]


def test_elastic_sweep_has_loading_rows_without_plastic_columns() -> None:
    r = sweep(rough(24), levels=3, flow=False)
    assert set(r.column("branch")) == {"loading"}
    assert np.all(r.column("plastic_volume") == 0)


def test_resume_mid_unloading_is_byte_identical(tmp_path: Path) -> None:
    s = rough(40, 6)
    d = tmp_path / "ck"
    full = sweep(s, mean_pressures=PRESSURES, hardness=H, unload=True, checkpoint_dir=d)
    for k in (2, 4):  # the top loading level and the last unloading level
        (d / f"level_{k:04d}.json").unlink()
    again = sweep(s, mean_pressures=PRESSURES, hardness=H, unload=True, checkpoint_dir=d)
    assert again.resumed == [0, 1, 3]
    assert _csv_text(again.rows) == _csv_text(full.rows)
    # Only the last unloading level missing: the plastic field comes from the checkpoint.
    (d / "level_0004.json").unlink()
    third = sweep(s, mean_pressures=PRESSURES, hardness=H, unload=True, checkpoint_dir=d)
    assert third.resumed == [0, 1, 2, 3]
    assert _csv_text(third.rows) == _csv_text(full.rows)


def test_displacement_controlled_unloading() -> None:
    s = rough(32, 2)
    r = sweep(s, levels=4, hardness=0.5, unload=True, flow=False)
    a = r.column("approach")
    assert len(r) == 9
    assert np.allclose(a[5:], a[3::-1])
    # At the same approach the deformed surface carries less load.
    assert np.all(r.column("mean_pressure")[5:8] <= r.column("mean_pressure")[3:0:-1] + 1e-15)


def test_bad_arguments_name_themselves() -> None:
    s = rough(16)
    for kw, name in (
        ({"hardness": -1.0}, "hardness"),
        ({"hardness": "x"}, "hardness"),
        ({"hardness": 0.01, "mean_pressures": [0.005, 0.02]}, "mean_pressures"),
        ({"hardness": 1.0, "solver": "active-set"}, "solver"),
        ({"unload": "yes"}, "unload"),
    ):
        with pytest.raises(InvalidArgumentError) as e:
            sweep(s, flow=False, **kw)  # type: ignore[arg-type]
        assert e.value.argument == name, kw


def test_plot_draws_the_plastic_figures() -> None:
    r = sweep(rough(24), mean_pressures=[0.02, 0.05], hardness=H, unload=True)
    figs = r.plot()
    assert "fig5_plastic_leak_rate" in figs and "fig6_plastic_area" in figs
    ax = figs["fig5_plastic_leak_rate"].axes[0]
    assert ax.get_yscale() == "log"
    assert "[" in ax.get_xlabel() and "[" in ax.get_ylabel()
    assert "fig5_plastic_leak_rate" not in sweep(rough(24), levels=2).plot()


def test_cli_hardness_and_unload(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    spec = "spectral:n=32,hurst=0.8,seed=1,rms_height=0.01"
    args = ["sweep", spec, "--mean-pressures", "0.01,0.03", "--hardness", "0.1", "--unload"]
    # No level leaks here: the leak-rate figure still lays out without a warning (an empty
    # line on its log axes used to collapse the layout).
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert cli.main([*args, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "unloading" in text and "V_pl[L^3]" in text
    header = (out / "table.csv").read_text().splitlines()[0].split(",")
    assert {"branch", "plastic_fraction", "plastic_volume"} <= set(header)
    figs = {p.name for p in (out / "figures").iterdir()}
    assert {"fig5_plastic_leak_rate.png", "fig6_plastic_area.png"} <= figs
    meta = json.loads((out / "metadata.json").read_text())
    assert meta["parameters"]["hardness"] == 0.1 and meta["parameters"]["unload"] is True
    # Resume: every level from the checkpoints.
    assert cli.main([*args, "--out", str(out), "--resume"]) == 0
    for bad in (["--hardness", "-2"], ["--hardness", "0.02"]):
        code = cli.main(["sweep", spec, "--mean-pressures", "0.01,0.03", *bad, "--out",
                         str(tmp_path / "bad")])
        assert code != 0
        assert "--hardness" in capsys.readouterr().err


def seal_config(hardness: float | None) -> dict:
    lower = {"E": 210e9, "nu": 0.3}
    if hardness is not None:
        lower["hardness"] = hardness
    return {
        "surface": {
            "realisations": 1,
            "seed": 3,
            "n": 32,
            "length": 4e-4,
            "upper": {"flat": True},
            "lower": {"rms_height": 1e-6, "hurst": 0.8, "rolloff_wavelength": 1e-4,
                      "short_wavelength": 5e-5},
        },
        "material": {"upper": {"E": 10e6, "nu": 0.5}, "lower": lower},
        "load": {"mean_pressure": [1e5, 3e5]},
        "fluid": {"viscosity": 1e-3, "pressure_drop": 1e5},
        "seal": {"length": 2e-3, "width": 0.1},
        "check": {"realisations": 0},
    }


def test_seal_config_takes_a_hardness() -> None:
    cfg = SealConfig.from_dict(seal_config(2e6))
    assert cfg.hardness == 2e6
    assert SealConfig.from_dict(cfg.to_dict()) == cfg
    assert "hardness" not in SealConfig.from_dict(seal_config(None)).to_dict()["material"]["lower"]
    for bad in (-1.0, 1e5, float("inf")):
        with pytest.raises(InvalidArgumentError) as e:
            SealConfig.from_dict(seal_config(bad))
        assert e.value.argument == "material.lower.hardness"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SealValidityWarning)
        elastic = seal_leakage(seal_config(None), workers=1, progress=False)
        capped = seal_leakage(seal_config(4e5), workers=1, progress=False)
    ka = elastic.summary.column("contact_fraction")
    kb = capped.summary.column("contact_fraction")
    # The cap spreads the load over more contact.
    assert np.all(kb >= ka) and np.any(kb > ka)
