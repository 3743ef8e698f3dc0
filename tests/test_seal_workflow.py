"""The seal workflow: configuration, run, tables, files, executors, resume, CLI.

Oracles: the per-realisation permeability is recomputed with leakpath's contact solve and an
independent scipy finite-volume solve written here (docs/flow.md conventions); the seal leak
rate with ``Q = K (W/L) Δp/η`` by hand; E* with its formula; measured files against the same
heights summed by hand.
"""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
import scipy.sparse.linalg as spla

import leakpath
from leakpath.errors import InvalidArgumentError
from leakpath.seal import (
    BodyMaterial,
    BodySurface,
    ConvergenceCheck,
    Fluid,
    SealConfig,
    SealConvergenceWarning,
    SealGeometry,
    SealValidityWarning,
)
from leakpath.seal._result import DIMENSIONLESS, UNIT_SUFFIXES

E_RUBBER, NU_RUBBER, E_STEEL, NU_STEEL = 10e6, 0.5, 210e9, 0.3


def base_config(**over) -> dict:
    """A small seal run: 32² grid, 2 realisations, 2 pressures (SI units)."""
    cfg = {
        "surface": {
            "realisations": 2,
            "seed": 3,
            "n": 32,
            "length": 4e-4,
            "upper": {"flat": True},
            "lower": {"rms_height": 1e-6, "hurst": 0.8, "rolloff_wavelength": 1e-4,
                      "short_wavelength": 5e-5},
        },
        "material": {"upper": {"E": E_RUBBER, "nu": NU_RUBBER},
                     "lower": {"E": E_STEEL, "nu": NU_STEEL}},
        "load": {"mean_pressure": [3e5, 1e5]},
        "fluid": {"viscosity": 1e-3, "pressure_drop": 1e5},
        "seal": {"length": 2e-3, "width": 0.1},
        "check": {"realisations": 1},
    }
    for key, value in over.items():
        cfg[key] = value
    return cfg


def run(cfg, **kw):
    kw.setdefault("workers", 1)
    kw.setdefault("progress", False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SealValidityWarning)
        if not kw.pop("_convergence_warnings", False):
            warnings.simplefilter("ignore", SealConvergenceWarning)
        return leakpath.seal_leakage(cfg, **kw)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("seal") / "ref"
    return run(base_config(), out=out), out


# ---------------------------------------------------------------- independent flow oracle
def fv_permeability(gap: np.ndarray, contact: np.ndarray, dx: float, axis: int,
                    periodic: bool) -> float:
    """K [m³] of a gap field by cell-centred finite volumes (docs/flow.md): conductance
    g³/12 per open cell, harmonic-mean faces, reservoirs half a cell outside the first and
    last rows (conductance 2c), side walls closed or wrapped; only clusters reaching both
    reservoirs carry flow. K = Q η L/(W Δp) with η = Δp = 1."""
    if axis == 1:
        gap, contact = gap.T, contact.T
    ny, nx = gap.shape
    g = np.where(contact, 0.0, np.clip(gap, 0.0, None))
    gmax = g.max()
    if gmax == 0:
        return 0.0
    c = (g / gmax) ** 3 / 12.0  # scaled; K is multiplied by gmax³ at the end
    idx = np.arange(ny * nx).reshape(ny, nx)
    rows, cols, vals = [], [], []

    def face(a, b, ca, cb):
        with np.errstate(invalid="ignore", divide="ignore"):
            f = np.where((ca > 0) & (cb > 0), 2 * ca * cb / (ca + cb), 0.0)
        rows.append(a.ravel())
        cols.append(b.ravel())
        vals.append(f.ravel())

    face(idx[:-1, :], idx[1:, :], c[:-1, :], c[1:, :])
    face(idx[:, :-1], idx[:, 1:], c[:, :-1], c[:, 1:])
    if periodic:
        face(idx[:, -1], idx[:, 0], c[:, -1], c[:, 0])
    r, q, w = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
    keep = w > 0
    r, q, w = r[keep], q[keep], w[keep]
    n = ny * nx
    graph = sp.coo_matrix((np.ones_like(w), (r, q)), shape=(n, n))
    _, label = csgraph.connected_components(graph, directed=False)
    open_ = c.ravel() > 0
    inlet = set(label[idx[0][open_[idx[0]]]])
    outlet = set(label[idx[-1][open_[idx[-1]]]])
    spanning = inlet & outlet
    active = open_ & np.isin(label, list(spanning))
    if not active.any():
        return 0.0
    pos = -np.ones(n, dtype=int)
    pos[active] = np.arange(active.sum())
    m = int(active.sum())
    sel = active[r] & active[q]
    rr, qq, ww = pos[r[sel]], pos[q[sel]], w[sel]
    diag = np.zeros(m)
    np.add.at(diag, rr, ww)
    np.add.at(diag, qq, ww)
    b = np.zeros(m)
    cf = c.ravel()
    first, last = idx[0], idx[-1]
    for cells, value in ((first, 1.0), (last, 0.0)):
        cells = cells[active[cells]]
        np.add.at(diag, pos[cells], 2 * cf[cells])
        np.add.at(b, pos[cells], 2 * cf[cells] * value)
    a = sp.coo_matrix((np.r_[-ww, -ww, diag], (np.r_[rr, qq, np.arange(m)],
                                                np.r_[qq, rr, np.arange(m)])), shape=(m, m))
    phi = spla.spsolve(a.tocsc(), b)
    out = last[active[last]]
    flow = float(np.sum(2 * cf[out] * phi[pos[out]]))
    return flow * gmax**3 * ny / nx  # K = Q L/W, L = ny dx, W = nx dx


def test_fv_oracle_parallel_plates():
    """The oracle itself: plates of gap g give K = g³/12 exactly; a closed row gives 0."""
    g = np.full((8, 6), 2e-6)
    assert fv_permeability(g, g < 0, 1e-5, 0, True) == pytest.approx(2e-6**3 / 12, rel=1e-12, abs=0)
    contact = np.zeros_like(g, dtype=bool)
    contact[4, :] = True
    assert fv_permeability(g, contact, 1e-5, 0, True) == 0.0
    assert fv_permeability(g, contact, 1e-5, 1, False) > 0


def e_star_by_hand() -> float:
    return 1.0 / ((1 - NU_RUBBER**2) / E_RUBBER + (1 - NU_STEEL**2) / E_STEEL)


# ---------------------------------------------------------------- configuration
def test_config_toml_equals_dict_equals_object(tmp_path):
    toml = tmp_path / "seal.toml"
    toml.write_text(
        """
[surface]
realisations = 2
seed = 3
n = 32
length = 4e-4
[surface.upper]
flat = true
[surface.lower]
rms_height = 1e-6
hurst = 0.8
rolloff_wavelength = 1e-4
short_wavelength = 5e-5
[material.upper]
E = 10e6
nu = 0.5
[material.lower]
E = 210e9
nu = 0.3
[load]
mean_pressure = [3e5, 1e5]
[fluid]
viscosity = 1e-3
pressure_drop = 1e5
[seal]
length = 2e-3
width = 0.1
[check]
realisations = 1
""",
        encoding="utf-8",
    )
    from_toml = SealConfig.from_toml(toml)
    from_dict = SealConfig.from_dict(base_config())
    typed = SealConfig(
        upper=BodySurface(flat=True),
        lower=BodySurface(rms_height=1e-6, hurst=0.8, rolloff_wavelength=1e-4,
                          short_wavelength=5e-5),
        upper_material=BodyMaterial(10e6, 0.5),
        lower_material=BodyMaterial(210e9, 0.3),
        mean_pressure=(1e5, 3e5),
        fluid=Fluid(viscosity=1e-3, pressure_drop=1e5),
        seal=SealGeometry(length=2e-3, width=0.1),
        realisations=2, seed=3, n=32, length=4e-4,
        check=ConvergenceCheck(realisations=1),
    )
    assert from_toml == from_dict == typed
    assert SealConfig.from_dict(typed.to_dict()) == typed
    assert typed.mean_pressure == (1e5, 3e5)  # ascending
    # defaults
    d = base_config()
    del d["surface"]["realisations"]
    del d["check"]
    cfg = SealConfig.from_dict(d)
    assert (cfg.realisations, cfg.axis, cfg.axes, cfg.boundary) == (16, "both", (0, 1), "periodic")
    assert cfg.check == ConvergenceCheck(2, 2, 0.2)


@pytest.mark.parametrize(
    "path, value, name",
    [
        (("laod",), {}, "laod"),
        (("surface", "lower", "hurts"), 0.8, "surface.lower.hurts"),
        (("surface", "lower", "hurst"), 1.2, "surface.lower.hurst"),
        (("surface", "lower", "rms_height"), -1e-6, "surface.lower.rms_height"),
        (("load", "mean_pressure"), [1e5, -2.0], "load.mean_pressure"),
        (("material", "upper", "nu"), 0.7, "material.upper.nu"),
        (("material", "lower", "E"), "210 GPa", "material.lower.E"),
        (("fluid", "viscosity"), 0.0, "fluid.viscosity"),
        (("fluid", "gas"), True, "fluid.pressure_drop"),
        (("seal", "width"), None, "seal.width"),
        (("flow", "axis"), 2, "flow.axis"),
        (("check", "tolerence"), 0.1, "check.tolerence"),
        (("surface", "n"), 48, "surface.n"),
        (("surface", "realisations"), 0, "surface.realisations"),
    ],
)
def test_bad_config_keys_are_named(path, value, name):
    cfg = base_config()
    cfg.setdefault("flow", {})
    node = cfg
    for key in path[:-1]:
        node = node[key]
    if value is None:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    with pytest.raises(InvalidArgumentError) as info:
        SealConfig.from_dict(cfg)
    assert info.value.argument == name
    assert str(info.value).startswith(name + ":")


def test_validity_warning_or_strict_refusal():
    """16 points on the 0.4 mm patch: dx = 25 µm resolves the 50 µm cutoff by 2 points."""
    cfg = base_config(check={"realisations": 0})
    cfg["surface"]["n"] = 16
    with pytest.warns(SealValidityWarning, match="resolved by 2 grid points"):
        res = leakpath.seal_leakage(cfg, workers=1, progress=False)
    assert res.metadata["validity_warnings"]
    with pytest.raises(InvalidArgumentError, match="strict = true") as info:
        leakpath.seal_leakage({**cfg, "strict": True}, workers=1, progress=False)
    assert info.value.argument == "surface"
    with warnings.catch_warnings():
        warnings.simplefilter("error", SealValidityWarning)  # the 32² default is valid
        leakpath.seal_leakage(base_config(check={"realisations": 0}), workers=1,
                              progress=False)


# ---------------------------------------------------------------- the numbers
def test_realisation_K_matches_independent_pipeline(reference):
    """Per realisation, axis and pressure: K from leakpath's contact + the scipy finite
    volumes above, to 1e-8; E* by hand; the warm-started load-control chain."""
    result, _ = reference
    from leakpath.seal import _bodies

    cfg = result.config
    upper = _bodies.Roughness.smooth()
    lower = _bodies.Roughness(hurst=0.8, rms_height=1e-6, rolloff_wavelength=1e-4,
                              short_wavelength=5e-5)
    patch = _bodies.choose_patch(upper, lower, n=32, length=4e-4)
    assert result.metadata["E_star_Pa"] == pytest.approx(e_star_by_hand(), rel=1e-14)
    table = result.realisations.rows()
    assert len(table) == 2 * 2 * 2
    checked = 0
    for k in range(cfg.realisations):
        surface = _bodies.composite_surface(upper, lower, patch, realisation=k, seed=3)
        problem = leakpath.ContactProblem(surface, E=e_star_by_hand(), nu=0.0,
                                          boundary="periodic")
        state = None
        for p in (1e5, 3e5):
            state = problem.solve(mean_pressure=p, warm_start=state)
            for axis in (0, 1):
                (row,) = [r for r in table if (r["realisation"], r["axis"],
                                               r["mean_pressure_Pa"]) == (k, axis, p)]
                want = fv_permeability(state.gap, state.pressure > 0, surface.dx, axis, True)
                assert row["permeability_m3"] == pytest.approx(want, rel=1e-8, abs=0)
                assert row["leaks"] == (want > 0)
                assert row["contact_fraction"] == np.mean(state.pressure > 0)
                checked += want > 0
    assert checked >= 2  # the comparison saw leaking patches, not only zeros


def test_summary_leak_rate_and_units(reference):
    result, _ = reference
    s = result.summary
    k = s.column("permeability_m3")
    q = s.column("leak_rate_m3_per_s")
    # Q = K_eff (W/L) Δp/η with W = 0.1 m, L = 2 mm, Δp = 1e5 Pa, η = 1e-3 Pa s
    np.testing.assert_allclose(q, k * (0.1 / 2e-3) * 1e5 / 1e-3, rtol=1e-12)
    assert np.all(s.column("leak_rate_low_m3_per_s") <= q)
    assert np.all(q <= s.column("leak_rate_high_m3_per_s"))
    assert np.all(s.column("mean_pressure_Pa") == [1e5, 3e5])
    for table in (result.summary, result.realisations):
        for c in table.columns:
            assert c in DIMENSIONLESS or c.endswith(UNIT_SUFFIXES), c
    for required in ("realisation", "axis", "mean_pressure_Pa", "contact_fraction",
                     "permeability_m3", "leaks", "mean_gap_m", "percolates"):
        assert required in result.realisations.columns
    meta = result.metadata
    assert meta["columns"]["summary"]["leak_rate_m3_per_s"] == "m^3/s"
    assert meta["units"]["load.mean_pressure"] == "Pa"
    assert len(meta["surfaces"]) == 3 and all(len(x["sha256"]) == 64 for x in meta["surfaces"])


def test_convergence_check_reported_and_flagged(reference):
    result, _ = reference
    s, chk, r = result.summary, result.check, result.realisations
    leaking = 0
    for p, change in zip(s.column("mean_pressure_Pa"), s.column("grid_check_relative_change"),
                         strict=True):
        fine = chk.column("permeability_m3")[chk.column("mean_pressure_Pa") == p].mean()
        sel = (r.column("mean_pressure_Pa") == p) & (r.column("realisation") == 0)
        base = r.column("permeability_m3")[sel].mean()
        if base > 0:
            assert change == pytest.approx(abs(fine - base) / base, rel=1e-12, abs=0)
            leaking += 1
        else:  # no flow on the base grid: no change, or an infinite one
            assert change == (0.0 if fine == 0 else math.inf)
    assert leaking >= 1
    assert chk.column("realisation").tolist() == [0, 0, 0, 0]
    with pytest.warns(SealConvergenceWarning, match="check.tolerance"):
        tight = run(base_config(check={"realisations": 1, "tolerance": 1e-12}),
                    _convergence_warnings=True)
    assert not tight.converged and not tight.summary.column("converged").all()


def test_gas_mass_flow_columns():
    fluid = {"viscosity": 1.8e-5, "gas": True, "inlet_pressure": 2e5, "outlet_pressure": 1e5,
             "gas_constant": 287.05, "temperature": 293.15}
    res = run(base_config(fluid=fluid, check={"realisations": 0}))
    s = res.summary
    assert "leak_rate_m3_per_s" not in s.columns
    want = (s.column("permeability_m3") * (0.1 / 2e-3) * (2e5**2 - 1e5**2)
            / (2 * 1.8e-5 * 287.05 * 293.15))
    np.testing.assert_allclose(s.column("mass_flow_kg_per_s"), want, rtol=1e-12)
    assert np.isnan(s.column("grid_check_relative_change")).all()


def test_measured_files_equal_same_heights_through_python_api(tmp_path):
    """Two bodies from .npy files (dx given) against the hand-summed heights solved with
    leakpath's contact and flow directly."""
    dx = 1.25e-5
    heights = {}
    for side, salt in (("upper", 10), ("lower", 20)):
        files = []
        for k in range(2):
            h = leakpath.spectral(32, 0.7, seed=salt + k, length=32 * dx, rms_height=5e-7,
                                  short_cutoff=5e-5).heights
            path = tmp_path / f"{side}{k}.npy"
            np.save(path, h)
            files.append(path.name)
            heights[side, k] = h
        heights[side] = files
    cfg = base_config(check={"realisations": 0})
    cfg["surface"] = {
        "upper": {"files": heights["upper"], "dx": dx},
        "lower": {"files": heights["lower"], "dx": dx},
    }
    toml = tmp_path / "files.toml"
    toml.write_text(_to_toml(cfg), encoding="utf-8")
    res = run(toml)
    assert res.config.realisations == 2
    rows = res.realisations.rows()
    for k in range(2):
        # each body's heights from its own mean plane
        hu, hl = heights["upper", k], heights["lower", k]
        surface = leakpath.Surface((hu - hu.mean()) + (hl - hl.mean()), dx)
        problem = leakpath.ContactProblem(surface, E=e_star_by_hand(), nu=0.0,
                                          boundary="periodic")
        state = None
        for p in (1e5, 3e5):
            state = problem.solve(mean_pressure=p, warm_start=state)
            for axis in (0, 1):
                (row,) = [r for r in rows if (r["realisation"], r["axis"],
                                              r["mean_pressure_Pa"]) == (k, axis, p)]
                want = state.flow(axis=axis).permeability
                assert row["permeability_m3"] == pytest.approx(want, rel=1e-12, abs=0)
                assert row["contact_fraction"] == state.contact_fraction
    assert [x["shape"] for x in res.metadata["surfaces"]] == [[32, 32], [32, 32]]


def _to_toml(cfg: dict, prefix: str = "") -> str:
    """A tiny TOML writer for these tests' nested dicts."""
    scalars = {k: v for k, v in cfg.items() if not isinstance(v, dict)}
    lines = [f"[{prefix}]"] if prefix and scalars else []
    for k, v in scalars.items():
        lines.append(f"{k} = {json.dumps(v)}")
    for k, v in cfg.items():
        if isinstance(v, dict):
            lines.append(_to_toml(v, f"{prefix}.{k}" if prefix else k))
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------- files, resume, executors
def test_resume_after_interrupt_gives_identical_csvs(reference, tmp_path):
    _, ref_dir = reference
    out = tmp_path / "interrupted"
    with pytest.raises(KeyboardInterrupt):
        run(base_config(), out=out, _stop_after=1)
    records = sorted(p.name for p in (out / "checkpoints").glob("*_*.json"))
    assert records == ["main_0000.json"]
    assert not (out / "summary.csv").exists()
    # an edited record is not trusted: recomputed, with a warning
    resumed = None
    with pytest.warns(RuntimeWarning, match="recomputing main_0000"):
        path = out / "checkpoints" / "main_0000.json"
        path.write_text(path.read_text().replace("true", "false", 1))
        resumed = run(base_config(), out=out, resume=True)
    assert resumed.metadata["run"]["tasks_resumed"] == 0
    with pytest.raises(KeyboardInterrupt):
        run(base_config(), out=tmp_path / "again", _stop_after=2)
    resumed = run(base_config(), out=tmp_path / "again", resume=True)
    assert resumed.metadata["run"]["tasks_resumed"] == 2
    for name in ("summary.csv", "realisations.csv", "check.csv"):
        assert (tmp_path / "again" / name).read_bytes() == (ref_dir / name).read_bytes(), name
        assert (out / name).read_bytes() == (ref_dir / name).read_bytes(), name
    with pytest.raises(InvalidArgumentError, match="different seal run"):
        run(base_config(load={"mean_pressure": [2e5]}), out=out, resume=True)


def test_out_directory_overwrite_removes_only_own_files(reference, tmp_path):
    out = tmp_path / "o"
    run(base_config(), out=out)
    (out / "notes.txt").write_text("mine")
    with pytest.raises(InvalidArgumentError, match="not empty") as info:
        run(base_config(), out=out)
    assert info.value.argument == "out"
    written = json.loads((out / ".leakpath-outputs.json").read_text())["files"]
    assert {"summary.csv", "metadata.json", "figures/seal.png",
            "checkpoints/main_0001.json"} <= set(written)
    run(base_config(load={"mean_pressure": [2e5]}), out=out, overwrite=True)
    assert (out / "notes.txt").read_text() == "mine"
    assert "300000.0" not in (out / "checkpoints" / "main_0000.json").read_text()
    assert "300000.0" not in (out / "summary.csv").read_text()


def test_processes_serial_and_dask_give_identical_tables(reference, tmp_path):
    ref, ref_dir = reference
    procs = run(base_config(), out=tmp_path / "p", workers=2)
    assert procs.metadata["run"]["executor"] == "processes"
    distributed = pytest.importorskip("distributed")
    with (
        distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                 dashboard_address=None) as cluster,
        distributed.Client(cluster) as client,
    ):
        dask = run(base_config(), out=tmp_path / "d", scheduler=client, workers=None)
        address = run(base_config(check={"realisations": 0}), scheduler=cluster.scheduler_address,
                      workers=None)
    assert dask.metadata["run"]["executor"] == "dask"
    assert address.realisations.csv_text() == ref.realisations.csv_text()
    for name in ("summary.csv", "realisations.csv", "check.csv"):
        want = (ref_dir / name).read_bytes()
        assert (tmp_path / "p" / name).read_bytes() == want, name
        assert (tmp_path / "d" / name).read_bytes() == want, name


# ---------------------------------------------------------------- result, figure, CLI
def test_plot_returns_figure_and_repr(reference):
    from matplotlib.figure import Figure

    result, out = reference
    fig = result.plot()
    assert isinstance(fig, Figure)
    axes = fig.get_axes()
    assert len(axes) == 3
    assert axes[0].get_yscale() == "log"
    for ax in axes:
        assert "[" in ax.get_xlabel() and "[" in ax.get_ylabel()
    assert (out / "figures" / "seal.png").stat().st_size > 0
    text = repr(result)
    assert text.startswith("SealResult(2 realisations × 2 pressures × 2 axes") and "m³/s" in text
    meta = json.loads((out / "metadata.json").read_text())
    assert meta["patch"]["n"] == 32 and meta["inputs"]["fluid"]["viscosity"] == 1e-3


def test_cli_seal(tmp_path, capsys):
    from leakpath.cli import main

    cfg = base_config()
    toml = tmp_path / "seal.toml"
    toml.write_text(_to_toml(cfg), encoding="utf-8")
    out = tmp_path / "out"
    assert main(["seal", str(toml), "--out", str(out), "--workers", "1"]) == 0
    printed = capsys.readouterr().out
    assert "1e+05 Pa" in printed and "m3/s" in printed and "E* = " in printed
    assert (out / "summary.csv").exists()
    assert main(["seal", str(toml), "--out", str(out), "--workers", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("leakpath: error: --out:")
    bad = tmp_path / "bad.toml"
    bad.write_text(_to_toml({**cfg, "load": {"mean_pressure": [1e5, "x"]}}), encoding="utf-8")
    assert main(["seal", str(bad), "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("leakpath: error: load.mean_pressure:")


def test_worked_example_config():
    """The README's example: the patch rule gives 512² points of 1 µm, E* by hand, no
    validity warning (rms slope ≈ 0.15)."""
    from leakpath.seal import _bodies
    from leakpath.seal._config import _roughness

    root = Path(__file__).resolve().parents[1]
    cfg = SealConfig.from_toml(root / "examples" / "seal_water.toml")
    assert cfg.realisations == 16 and len(cfg.mean_pressure) == 6 and cfg.axes == (0, 1)
    assert cfg.mean_pressure[0] == 1e5 and cfg.mean_pressure[-1] == 1e6
    upper = _roughness(_bodies, cfg.upper, "surface.upper")
    lower = _roughness(_bodies, cfg.lower, "surface.lower")
    patch = _bodies.choose_patch(upper, lower)
    assert (patch.n, patch.dx) == (512, pytest.approx(1e-6, rel=1e-12, abs=0))
    assert _bodies.validity_warnings(upper, lower, patch) == []
