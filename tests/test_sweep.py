"""Sweeps over the approach (leakpath.sweep), their files, figures and the paper/sweep CLI.

Reference values are computed here from the heights and the returned fields with plain numpy
(free volume, moments, dimensionless ratios), never copied from a previous run.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import signal
import struct
import subprocess
import sys
import time

import numpy as np
import pytest

from leakpath import SweepResult, rmd, sweep
from leakpath._table import COLUMNS

LEVELS = 10


@pytest.fixture(scope="module")
def surface():
    return rmd(5, 2.1, seed=3)


@pytest.fixture(scope="module")
def result(surface) -> SweepResult:
    return sweep(surface, levels=LEVELS, solver="active-set", keep_fields=True)


def fd_moments(s: np.ndarray, dx: float) -> tuple[float, float, float]:
    """m0, m2, m4 with the finite differences of docs/conventions.md, written out independently."""
    m0 = np.mean((s - s.mean()) ** 2)
    m2 = 0.5 * (np.mean(np.diff(s, axis=1) ** 2) + np.mean(np.diff(s, axis=0) ** 2)) / dx**2
    sxx = s[:, 2:] - 2 * s[:, 1:-1] + s[:, :-2]
    syy = s[2:, :] - 2 * s[1:-1, :] + s[:-2, :]
    m4 = 0.5 * (np.mean(sxx**2) + np.mean(syy**2)) / dx**4
    return float(m0), float(m2), float(m4)


# ---------------------------------------------------------------------------- the table
def test_levels_and_row_zero_is_the_undeformed_state(surface, result):
    h, dx = surface.heights, surface.dx
    h_s = h.max() - h.min()
    assert len(result) == LEVELS + 1
    np.testing.assert_allclose(
        result.column("approach"), h_s * np.arange(LEVELS + 1) / LEVELS, rtol=1e-14, atol=0
    )
    row = result.rows[0]
    v0 = dx**2 * np.sum(h.max() - h)
    assert row["approach"] == 0.0
    assert row["free_volume"] == pytest.approx(v0, rel=1e-12)
    assert row["mean_gap"] == pytest.approx(np.mean(h.max() - h), rel=1e-12)
    assert row["load"] == 0.0 and row["n_contact"] == 0 and row["contact_fraction"] == 0.0
    assert row["V_pg_star"] == 1.0
    # Nothing in contact: one free cluster spanning both axes holds all the free volume.
    for ax in ("axis0", "axis1"):
        assert row[f"V_pg_{ax}"] == pytest.approx(v0, rel=1e-12)
        assert row[f"n_spanning_{ax}"] == 1
        assert row[f"V_dead_{ax}"] == 0.0 and row[f"V_trapped_{ax}"] == 0.0
    assert row["m0"] == pytest.approx(np.var(h), rel=1e-12)


def test_monotone_in_the_approach(result):
    a = result.column("contact_fraction")
    load = result.column("load")
    v = result.column("free_volume")
    g = result.column("mean_gap")
    assert np.all(np.diff(a) >= 0) and a[-1] > 0.2
    assert np.all(np.diff(load) > 0)
    assert np.all(np.diff(v) < 0)
    assert np.all(np.diff(g) < 0)
    assert np.all(np.diff(result.column("approach")) > 0)


def test_dimensionless_columns_divide_by_independent_references(surface, result):
    h, dx = surface.heights, surface.dx
    ny, nx = h.shape
    area = ny * nx * dx**2
    sigma = np.std(h)
    g0 = np.mean(h.max() - h)
    m0, m2, m4 = fd_moments(h, dx)
    alpha = m0 * m4 / m2**2
    col = result.column
    np.testing.assert_allclose(col("approach_star"), col("approach") / np.ptp(h), rtol=1e-13)
    np.testing.assert_allclose(
        col("free_volume_star"), col("free_volume") / (area * sigma), rtol=1e-12
    )
    np.testing.assert_allclose(col("mean_gap_star"), col("mean_gap") / g0, rtol=1e-12)
    np.testing.assert_allclose(col("V_pg_star"), col("V_pg") / col("V_pg")[0], rtol=1e-13)
    np.testing.assert_allclose(col("m0_star"), col("m0") / m0, rtol=1e-12)
    np.testing.assert_allclose(col("m2_star"), col("m2") / m2, rtol=1e-12)
    np.testing.assert_allclose(col("m4_star"), col("m4") / m4, rtol=1e-12)
    np.testing.assert_allclose(col("alpha_star"), col("alpha") / alpha, rtol=1e-12)
    assert col("approach_star")[-1] == pytest.approx(1.0, rel=1e-14, abs=0)


def test_dimensional_columns_agree_with_the_fields(surface, result):
    h, dx = surface.heights, surface.dx
    f = result.fields
    assert f is not None and f["pressure"].shape == (LEVELS + 1, *h.shape)
    for k, row in enumerate(result.rows):
        p, g = f["pressure"][k], f["gap"][k]
        assert row["n_contact"] == np.count_nonzero(p > 0)
        assert row["contact_fraction"] == np.count_nonzero(p > 0) / p.size
        assert row["load"] == pytest.approx(dx**2 * p.sum(), rel=1e-12)
        assert row["free_volume"] == pytest.approx(dx**2 * g.sum(), rel=1e-12, abs=1e-300)
        # KKT of the returned solution, checked here.
        assert g.min() > -1e-9 * np.ptp(h)
        assert np.all(np.abs(g[p > 0]) <= 1e-9 * np.ptp(h))
        # Deformed surface s = h − u = max h − Δ − g: its moments from the gap alone.
        s = h.max() - row["approach"] - g
        m0, m2, m4 = fd_moments(s, dx)
        assert row["m0"] == pytest.approx(m0, rel=1e-9)
        assert row["m2"] == pytest.approx(m2, rel=1e-9, abs=0)
        assert row["m4"] == pytest.approx(m4, rel=1e-9, abs=0)
        assert row["alpha"] == pytest.approx(m0 * m4 / m2**2, rel=1e-8)
        # Volume balance along both axes.
        for ax in ("axis0", "axis1"):
            parts = row[f"V_pg_{ax}"] + row[f"V_dead_{ax}"] + row[f"V_trapped_{ax}"]
            assert parts == pytest.approx(row["free_volume"], rel=1e-9)


def test_percolation_columns_against_an_independent_labelling(result):
    from scipy import ndimage

    for k in (0, LEVELS // 2, LEVELS):
        p, g = result.fields["pressure"][k], result.fields["gap"][k]
        # Open cells (docs/conventions.md): not in contact and g > 0; 4-connectivity.
        labels, n = ndimage.label((p <= 0) & (g > 0))
        dx2 = result.surface.dx**2
        for axis, key in ((0, "axis0"), (1, "axis1")):
            first = np.take(labels, 0, axis=axis)
            last = np.take(labels, -1, axis=axis)
            span = np.intersect1d(first[first > 0], last[last > 0])
            v = dx2 * g[np.isin(labels, span)].sum()
            assert result.rows[k][f"n_spanning_{key}"] == len(span)
            assert result.rows[k][f"V_pg_{key}"] == pytest.approx(v, rel=1e-9, abs=1e-300)
        classes = result.class_map(k)
        assert np.array_equal(classes == 0, (p > 0) | (g <= 0))  # closed cells
        assert np.array_equal(result.contact_mask(k), p > 0)


def test_warm_and_cold_give_the_same_minimiser(surface, result):
    cold = sweep(surface, levels=LEVELS, solver="active-set", warm_start=False)
    for name in ("contact_fraction", "load", "free_volume", "V_pg", "m2"):
        np.testing.assert_allclose(cold.column(name), result.column(name), rtol=1e-9, atol=1e-14)


def test_explicit_approaches_and_modulus(surface, result):
    h_s = surface.height_range
    other = sweep(surface, approaches=[0.0, 0.5 * h_s, h_s], E=2.0, nu=0.0)
    assert len(other) == 3
    ref = result.rows
    for row, k in zip(other.rows, (0, LEVELS // 2, LEVELS), strict=True):
        assert row["contact_fraction"] == pytest.approx(ref[k]["contact_fraction"])
        assert row["load"] == pytest.approx(2.0 * ref[k]["load"], rel=1e-9, abs=1e-300)
    assert other.parameters["approaches"] == [0.0, 0.5 * h_s, h_s]


@pytest.mark.parametrize(
    "kwargs, word",
    [
        ({"approaches": [0.0, 0.2, 0.1]}, "approaches"),
        ({"approaches": [-0.1, 0.2]}, "approaches"),
        ({"approaches": [0.0, 1e9], "boundary": "periodic"}, "approaches"),
        ({"approaches": []}, "approaches"),
        ({"levels": 0}, "levels"),
        ({"axis": 2}, "axis"),
        ({"connectivity": 6}, "connectivity"),
        ({"solver": "magic"}, "solver"),
        ({"boundary": "open"}, "boundary"),
        ({"E": -1.0}, "E"),
    ],
)
def test_bad_arguments_name_the_argument(surface, kwargs, word):
    with pytest.raises(ValueError, match=word):
        sweep(surface, **kwargs)


# ---------------------------------------------------------------------------- files
def test_csv_is_exact_and_ordered(tmp_path, result):
    path = result.to_csv(tmp_path / "t.csv")
    text = path.read_text(encoding="utf-8")
    reader = csv.reader(io.StringIO(text))
    header = next(reader)
    assert tuple(header) == COLUMNS
    lines = list(reader)
    assert len(lines) == len(result)
    for line, row in zip(lines, result.rows, strict=True):
        for name, cell in zip(header, line, strict=True):
            value = row[name]
            if isinstance(value, float):
                assert float(cell) == value or (np.isnan(value) and cell == "nan")
            else:
                assert cell == str(value)
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind


def test_json_metadata(tmp_path, surface, result):
    data = json.loads(result.to_json(tmp_path / "m.json").read_text(encoding="utf-8"))
    digest = hashlib.sha256(
        surface.heights.astype("<f8").tobytes() + struct.pack("<d", surface.dx)
    ).hexdigest()
    assert data["surface"]["sha256"] == digest
    assert data["surface"]["seed"] == 3 and data["surface"]["generator"] == "rmd"
    assert data["parameters"]["solver"] == "active-set"
    assert data["parameters"]["levels"] == LEVELS
    assert data["leakpath_version"] and data["machine"]["cpu_count"] >= 1
    assert len(data["rows"]) == len(result) and "seconds" in data["rows"][0]


def test_save_fields(tmp_path, result, surface):
    path = result.save_fields(tmp_path / "f.npz")
    with np.load(path) as z:
        assert z["pressure"].shape == (LEVELS + 1, *surface.shape)
        assert np.array_equal(z["gap"], result.fields["gap"])
        assert z["labels"].shape == z["classes"].shape == z["pressure"].shape


def test_checkpoints_resume_exactly(tmp_path, surface):
    ck = tmp_path / "ck"
    full = sweep(surface, levels=LEVELS, checkpoint_dir=ck)
    assert full.resumed == []
    # Drop the last levels, as if the run had been killed after level 5.
    for k in range(6, LEVELS + 1):
        (ck / f"level_{k:04d}.json").unlink()
    again = sweep(surface, levels=LEVELS, checkpoint_dir=ck)
    assert again.resumed == list(range(6))
    assert again.csv_text() == full.csv_text()
    plain = sweep(surface, levels=LEVELS)
    assert plain.csv_text() == full.csv_text()
    with pytest.raises(ValueError, match="checkpoint_dir"):
        sweep(surface, levels=LEVELS + 1, checkpoint_dir=ck)


def check_figures(directory) -> None:
    pngs = sorted(directory.glob("*.png"))
    pdfs = sorted(directory.glob("*.pdf"))
    stems = {p.stem for p in pngs}
    assert {"fig1_topography_moments", "fig2_vpg_volume_gap", "fig3_vpg_moments"} <= stems
    assert any(s.startswith("map_k") for s in stems)
    assert stems == {p.stem for p in pdfs}
    for p in pngs:
        data = p.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000, p
    for p in pdfs:
        data = p.read_bytes()
        assert data[:5] == b"%PDF-" and b"%%EOF" in data[-1024:] and len(data) > 5_000, p


def test_plots_write_png_and_pdf_without_pyplot(tmp_path, result):
    paths = result.plot(tmp_path / "figs", levels_to_map=[0, LEVELS])
    # Figs. 1-3, two class maps, the leak-rate figure and the last leaking row's flux map.
    leaking = [k for k, r in enumerate(result.rows) if r["Q"] > 0]
    assert {p.stem for p in paths} >= {"fig4_leak_rate", f"flux_k{leaking[-1]:02d}"}
    assert len(paths) == 2 * 7
    check_figures(tmp_path / "figs")
    if "matplotlib.pyplot" in sys.modules:
        import matplotlib.pyplot as plt

        assert plt.get_fignums() == []
    with pytest.raises(ValueError, match="levels_to_map"):
        result.plot(tmp_path / "x", levels_to_map=[LEVELS + 1])


def test_plot_without_a_directory_returns_figures_and_writes_nothing(
    tmp_path, monkeypatch, result
):
    from matplotlib.figure import Figure

    monkeypatch.chdir(tmp_path)
    figures = result.plot(levels_to_map=[0, LEVELS], flux_levels=[1, 3])
    assert list(tmp_path.iterdir()) == []
    assert list(figures) == [
        "fig1_topography_moments", "fig2_vpg_volume_gap", "fig3_vpg_moments",
        "map_k00", f"map_k{LEVELS:02d}", "fig4_leak_rate", "flux_k01", "flux_k03",
    ]
    assert all(isinstance(f, Figure) for f in figures.values())
    # The leak-rate figure draws K* of the leaking rows in each of its three panels.
    k_star = result.column("K_star")
    leaking = k_star[np.isfinite(k_star) & (k_star > 0)]
    panels = figures["fig4_leak_rate"].axes
    assert len(panels) == 3
    for ax in panels:
        np.testing.assert_array_equal(ax.get_lines()[0].get_ydata(), leaking)
    if "matplotlib.pyplot" in sys.modules:
        import matplotlib.pyplot as plt

        assert plt.get_fignums() == []


def test_plot_default_levels_match_the_written_files(tmp_path, result):
    figures = result.plot()
    paths = result.plot(tmp_path, formats=("png",))
    assert list(figures) == [p.stem for p in paths]
    assert "fig4_leak_rate" in figures


def test_plot_without_flow_columns_has_no_leak_rate_figures(surface):
    no_flow = sweep(surface, levels=3, solver="active-set", flow=False)
    figures = no_flow.plot()
    assert "fig4_leak_rate" not in figures and "fig1_topography_moments" in figures
    assert not any(name.startswith("flux_") for name in figures)
    with pytest.raises(ValueError, match="flux_levels"):
        no_flow.plot(flux_levels=[1])


def test_plot_into_a_directory_writes_the_files_of_the_cli(tmp_path, capsys):
    from leakpath import cli

    out = tmp_path / "cli"
    assert cli.main(["sweep", "rmd:m=4,D=2.2,seed=2", "--levels", "3", "--flux-maps", "1",
                     "--out", str(out)]) == 0
    capsys.readouterr()
    cli_figures = sorted(p.name for p in (out / "figures").iterdir())
    assert "fig4_leak_rate.png" in cli_figures and "flux_k01.pdf" in cli_figures
    same = sweep(rmd(4, 2.2, seed=2), levels=3)
    written = same.plot(tmp_path / "py", flux_levels=[1])
    assert sorted(p.name for p in written) == cli_figures
    assert sorted(p.name for p in (tmp_path / "py").iterdir()) == cli_figures
    # PNGs carry no date: the same table draws the same bytes.
    for name in ("fig1_topography_moments.png", "fig4_leak_rate.png"):
        assert (tmp_path / "py" / name).read_bytes() == (out / "figures" / name).read_bytes()


# ---------------------------------------------------------------------------- CLI
def leakpath_cli(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "leakpath", *args], capture_output=True, text=True, timeout=timeout
    )


def assert_usage_error(proc: subprocess.CompletedProcess[str]) -> None:
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("leakpath: error: "), proc.stderr
    assert proc.stdout == ""


@pytest.mark.parametrize(
    "args", [["--help"], ["paper", "--help"], ["sweep", "--help"], ["surface", "--help"]]
)
def test_help(args):
    proc = leakpath_cli(*args)
    assert proc.returncode == 0, proc.stderr
    assert "usage: leakpath" in proc.stdout


@pytest.mark.parametrize(
    "args",
    [
        ["sweep", "rmd:m=4,D=2.1"],  # no seed
        ["sweep", "rmd:m=4,D=2.1,seed=1,colour=red"],
        ["sweep", "rmd:m=4,D=3.5,seed=1"],
        ["sweep", "spectral:n=16,hurst=0.8"],
        ["sweep", "no-such-file.npy", "--dx", "1"],
        ["sweep", "rmd:m=4,D=2.1,seed=1", "--levels", "0"],
        ["sweep", "rmd:m=4,D=2.1,seed=1", "--axis", "2"],
        ["sweep", "rmd:m=4,D=2.1,seed=1", "--solver", "magic"],
        ["sweep", "rmd:m=4,D=2.1,seed=1", "--nu", "0.7"],
        ["sweep", "rmd:m=4,D=2.1,seed=1", "--overwrite", "--resume"],
        ["paper", "--seed", "x"],
        ["paper", "--solver", "fastest"],
        ["sweep"],
    ],
)
def test_bad_arguments_exit_2_with_one_line(tmp_path, capsys, args):
    from leakpath import cli

    assert cli.main([*args, "--out", str(tmp_path / "out")]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("leakpath: error: "), captured.err
    assert captured.out == ""
    assert not (tmp_path / "out" / "table.csv").exists()


def test_bad_argument_in_a_subprocess(tmp_path):
    assert_usage_error(leakpath_cli("sweep", "rmd:m=4,D=2.1", "--out", str(tmp_path / "o")))


SPEC = "rmd:m=6,D=2.1,seed=3"
SWEEP_ARGS = ["sweep", SPEC, "--levels", "40"]


def test_cli_sigkill_resume_overwrite(tmp_path):
    """Kill a run after a few checkpointed levels, resume it, and compare with a clean run."""
    killed = tmp_path / "killed"
    proc = subprocess.Popen(
        [sys.executable, "-m", "leakpath", *SWEEP_ARGS, "--out", str(killed)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    ck = killed / "checkpoints"
    deadline = time.monotonic() + 90
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            if len(list(ck.glob("level_*.json"))) >= 3:
                proc.send_signal(signal.SIGKILL)
                break
            time.sleep(0.002)
    finally:
        if proc.poll() is None and time.monotonic() >= deadline:
            proc.kill()
        proc.wait()
    assert proc.returncode == -signal.SIGKILL, "the run ended before it could be killed"
    done = sorted(ck.glob("level_*.json"))
    assert 3 <= len(done) < 41
    assert not (killed / "table.csv").exists()

    # A non-empty output directory is refused without --resume/--overwrite.
    assert_usage_error(leakpath_cli(*SWEEP_ARGS, "--out", str(killed)))
    # A different sweep cannot resume this directory.
    assert_usage_error(
        leakpath_cli("sweep", SPEC, "--levels", "30", "--out", str(killed), "--resume")
    )

    resumed = leakpath_cli(*SWEEP_ARGS, "--out", str(killed), "--resume", "--json")
    assert resumed.returncode == 0, resumed.stderr
    summary = json.loads(resumed.stdout)
    assert summary["resumed_levels"] == list(range(len(done)))
    assert len(summary["summary"]) == 41

    # The uninterrupted run, into a directory holding a stale table and a user's file.
    clean = tmp_path / "clean"
    clean.mkdir()
    (clean / "table.csv").write_text("stale\n")
    (clean / "notes.txt").write_text("keep me\n")
    assert_usage_error(leakpath_cli(*SWEEP_ARGS, "--out", str(clean)))
    full = leakpath_cli(*SWEEP_ARGS, "--out", str(clean), "--overwrite")
    assert full.returncode == 0, full.stderr
    assert (clean / "notes.txt").read_text() == "keep me\n"

    table = (clean / "table.csv").read_bytes()
    assert (killed / "table.csv").read_bytes() == table
    # ... and the same table as the library without checkpoints.
    assert sweep(rmd(6, 2.1, seed=3), levels=40).csv_text().encode() == table
    check_figures(clean / "figures")
    meta = json.loads((clean / "metadata.json").read_text(encoding="utf-8"))
    assert meta["command"] == "sweep" and meta["surface"]["seed"] == 3
    assert "Delta*" in full.stdout and len(full.stdout.strip().splitlines()) >= 43


class _SweepStarted(Exception):
    """Raised by a stand-in for leakpath.sweep: the command got as far as solving."""


@pytest.fixture
def no_solving(monkeypatch):
    """Replace the sweep the command line calls; the list records each call."""
    from leakpath import _sweep

    calls: list[dict] = []

    def fake(surface, **kwargs):
        calls.append(kwargs)
        raise _SweepStarted

    monkeypatch.setattr(_sweep, "sweep", fake)
    return calls


@pytest.mark.parametrize(
    "args, flag",
    [
        # --levels 4 gives rows 0 … 4: row 5 and row 99 do not exist.
        (["sweep", "rmd:m=4,D=2.1,seed=1", "--levels", "4", "--flux-maps", "99"], "--flux-maps"),
        (["sweep", "rmd:m=4,D=2.1,seed=1", "--levels", "4", "--flux-maps", "2,5"], "--flux-maps"),
        # Two imposed pressures give rows 0 and 1.
        (["sweep", "rmd:m=4,D=2.1,seed=1", "--mean-pressures", "0.01,0.02", "--flux-maps", "2"],
         "--flux-maps"),
        (["sweep", "rmd:m=4,D=2.1,seed=1", "--no-flow", "--flux-maps", "1"], "--flux-maps"),
        (["sweep", "rmd:m=4,D=2.1,seed=1", "--mean-pressures", "0.2,0.1"], "--mean-pressures"),
        # The paper's sweep has 20 levels: rows 0 … 20.
        (["paper", "--flux-maps", "21"], "--flux-maps"),
        (["sweep", "rmd:m=3,D=2.2,m=4,seed=0"], "m twice"),
    ],
)
def test_every_option_is_checked_before_solving(tmp_path, capsys, no_solving, args, flag):
    from leakpath import cli

    out = tmp_path / "out"
    out.mkdir()
    (out / "table.csv").write_text("an earlier table\n")
    assert cli.main([*args, "--out", str(out), "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("leakpath: error: ") and flag in err, err
    assert no_solving == []
    # Nothing in the output directory was touched.
    assert (out / "table.csv").read_text() == "an earlier table\n"


@pytest.mark.parametrize(
    "args",
    [
        ["sweep", "rmd:m=4,D=2.1,seed=1", "--levels", "4", "--flux-maps", "0,4"],
        ["sweep", "rmd:m=4,D=2.1,seed=1", "--mean-pressures", "0.01,0.02", "--flux-maps", "1"],
        ["paper", "--flux-maps", "20"],
    ],
)
def test_rows_that_exist_pass_the_early_checks(tmp_path, capsys, no_solving, args):
    from leakpath import cli

    assert cli.main([*args, "--out", str(tmp_path / "out")]) == 1  # the stand-in's exception
    assert len(no_solving) == 1


# ---------------------------------------------------------------------------- --overwrite
def files_in(directory) -> set[str]:
    """Every file below ``directory``, relative, in POSIX form."""
    return {p.relative_to(directory).as_posix() for p in directory.rglob("*") if p.is_file()}


def run_main(capsys, *argv: str) -> str:
    """Run the CLI in this process; returns its stderr, asserting success."""
    from leakpath import cli

    status = cli.main(list(argv))
    err = capsys.readouterr().err
    assert status == 0, err
    return err


RUN_1 = ["sweep", "rmd:m=4,D=2.2,seed=1", "--levels", "6", "--keep-fields"]
RUN_2 = ["sweep", "rmd:m=4,D=2.2,seed=2", "--levels", "3"]
USER_FILES = {
    "figures/fig_my_notes.pdf": "my own figure",  # named like the run's figures
    "notes.txt": "keep me",
    "checkpoints/level_0099.json": "{\"mine\": true}",  # named like a checkpoint record
    "flux_k01.png": "a file of the user's at the top level",
}


def add_user_files(out) -> None:
    for rel, text in USER_FILES.items():
        (out / rel).parent.mkdir(parents=True, exist_ok=True)
        (out / rel).write_text(text)


def assert_user_files_intact(out) -> None:
    for rel, text in USER_FILES.items():
        assert (out / rel).read_text() == text, rel


@pytest.fixture(scope="module")
def run_2_files(tmp_path_factory) -> set[str]:
    """What RUN_2 writes into an empty directory (the reference listing)."""
    from leakpath import cli

    out = tmp_path_factory.mktemp("fresh") / "out"
    assert cli.main([*RUN_2, "--out", str(out)]) == 0
    return files_in(out)


def test_overwrite_removes_exactly_the_files_the_earlier_run_wrote(tmp_path, capsys, run_2_files):
    out = tmp_path / "out"
    run_main(capsys, *RUN_1, "--out", str(out))
    first = files_in(out)
    add_user_files(out)
    err = run_main(capsys, *RUN_2, "--out", str(out), "--overwrite")
    assert_user_files_intact(out)
    # The earlier run's files that this run does not write are gone (its level 4 … 6
    # checkpoints, fields.npz, maps of other rows); nothing else is there.
    assert files_in(out) == run_2_files | set(USER_FILES)
    assert {"fields.npz", "checkpoints/level_0006.json"} <= first - run_2_files
    assert "note" not in err


def test_overwrite_keeps_a_recorded_file_that_changed_since(tmp_path, capsys, run_2_files):
    out = tmp_path / "out"
    run_main(capsys, *RUN_1, "--out", str(out))
    with open(out / "fields.npz", "ab") as fh:  # the user appended to it: no longer the run's
        fh.write(b"edited")
    err = run_main(capsys, *RUN_2, "--out", str(out), "--overwrite")
    assert (out / "fields.npz").read_bytes().endswith(b"edited")
    assert "fields.npz" in err and "changed" in err
    assert files_in(out) == run_2_files | {"fields.npz"}


def test_overwrite_without_a_record_deletes_nothing_it_cannot_recognise(
    tmp_path, capsys, run_2_files
):
    # A directory from a leakpath without the record: only checkpoint records, recognised by
    # their checksums, are known to be leakpath's (and a different sweep needs them gone).
    out = tmp_path / "out"
    run_main(capsys, *RUN_1, "--out", str(out))
    (out / ".leakpath-outputs.json").unlink()
    first = files_in(out)
    add_user_files(out)
    err = run_main(capsys, *RUN_2, "--out", str(out), "--overwrite")
    assert_user_files_intact(out)
    old_checkpoints = {f for f in first if f.startswith("checkpoints/")}
    stays = (first - old_checkpoints) | set(USER_FILES)
    assert files_in(out) == run_2_files | stays
    assert "no record" in err


def test_overwrite_never_follows_a_record_out_of_the_directory(tmp_path, capsys):
    out = tmp_path / "out"
    run_main(capsys, *RUN_2, "--out", str(out))
    outside = tmp_path / "precious.txt"
    outside.write_text("outside the output directory")
    info = outside.stat()
    stamp = {"size": info.st_size, "mtime_ns": info.st_mtime_ns}
    record = json.loads((out / ".leakpath-outputs.json").read_text())
    record["files"]["../precious.txt"] = stamp
    record["files"][str(outside)] = stamp
    (out / ".leakpath-outputs.json").write_text(json.dumps(record))
    run_main(capsys, *RUN_2, "--out", str(out), "--overwrite")
    assert outside.read_text() == "outside the output directory"


def test_paper_overwrite_keeps_a_users_figure(tmp_path, capsys):
    out = tmp_path / "paper"
    run_main(capsys, "paper", "--no-flow", "--out", str(out))
    (out / "figures" / "fig_my_notes.pdf").write_text("my own figure")
    run_main(capsys, "paper", "--no-flow", "--out", str(out), "--overwrite")
    assert (out / "figures" / "fig_my_notes.pdf").read_text() == "my own figure"
    assert (out / "table.csv").is_file()
