"""Tests for the ``leakpath`` command line (run as ``python -m leakpath`` in a subprocess)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

import leakpath
from leakpath import cli
from leakpath.generators import rmd, spectral
from leakpath.surfaces import load


def run(command: str, *extra: str, cwd=None) -> subprocess.CompletedProcess[str]:
    """Run ``python -m leakpath`` with ``command.split()`` followed by ``extra`` arguments."""
    return subprocess.run(
        [sys.executable, "-m", "leakpath", *command.split(), *extra],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=120,
    )


def parse_table(stdout: str) -> dict[str, str]:
    """``name  value`` lines → dict (names may contain single spaces)."""
    rows = {}
    for line in stdout.strip().splitlines():
        name, _, value = line.partition("  ")
        rows[name.strip()] = value.strip()
    return rows


def assert_usage_error(proc: subprocess.CompletedProcess[str]) -> str:
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("leakpath: error: ")
    assert "Traceback" not in proc.stderr
    return lines[0]


class TestSurfaceRmd:
    def test_writes_loadable_file_and_prints_stats(self, tmp_path):
        out = tmp_path / "s.npz"
        proc = run("surface rmd --m 5 --D 2.2 --seed 3 --length 2 --out", str(out))
        assert proc.returncode == 0, proc.stderr
        s = load(out)
        assert s.dx == 2.0 / 32
        assert s.shape == (33, 33)
        assert np.array_equal(s.heights, rmd(5, 2.2, seed=3, length=2.0).heights)
        assert s.metadata["generator"] == "rmd" and s.metadata["seed"] == 3

        rows = parse_table(proc.stdout)
        h = s.heights
        assert float(rows["m0 [µm^2]"]) == pytest.approx(np.var(h), rel=1e-5)
        assert float(rows["rms height [µm]"]) == pytest.approx(np.std(h), rel=1e-5)
        assert float(rows["h_s (max - min) [µm]"]) == pytest.approx(np.ptp(h), rel=1e-5)
        assert float(rows["mean height [µm]"]) == pytest.approx(np.mean(h), rel=1e-5)
        assert float(rows["dx [µm]"]) == pytest.approx(2.0 / 32, rel=1e-6)
        m2 = 0.5 * (np.mean(np.diff(h, axis=1) ** 2) + np.mean(np.diff(h, axis=0) ** 2))
        m2 /= s.dx**2
        assert float(rows["m2 [1]"]) == pytest.approx(m2, rel=1e-5)
        assert {"m4 [µm^-2]", "alpha [1]", "shape (ny x nx)"} <= set(rows)
        assert rows["shape (ny x nx)"] == "33 x 33"

    def test_json(self, tmp_path):
        out = tmp_path / "s.npz"
        proc = run("surface rmd --m 4 --D 2.5 --seed 0 --sigma0 2 --out", str(out), "--json")
        assert proc.returncode == 0, proc.stderr
        data = json.loads(proc.stdout)
        h = load(out).heights
        assert data["shape"] == [17, 17]
        assert data["dx"] == pytest.approx(500 / 16)  # default side 500 µm
        assert data["m0"] == pytest.approx(np.var(h), rel=1e-12)
        assert data["height_range"] == pytest.approx(np.ptp(h), rel=1e-12)
        assert data["alpha"] == pytest.approx(data["m0"] * data["m4"] / data["m2"] ** 2)
        assert data["metadata"]["sigma0"] == 2.0

    def test_refuses_to_overwrite(self, tmp_path):
        out = tmp_path / "s.npz"
        assert run("surface rmd --m 3 --D 2.2 --seed 1 --out", str(out)).returncode == 0
        before = out.read_bytes()
        proc = run("surface rmd --m 3 --D 2.2 --seed 2 --out", str(out))
        line = assert_usage_error(proc)
        assert "--overwrite" in line and "s.npz" in line
        assert out.read_bytes() == before
        proc = run("surface rmd --m 3 --D 2.2 --seed 2 --out", str(out), "--overwrite")
        assert proc.returncode == 0, proc.stderr
        assert np.array_equal(load(out).heights, rmd(3, 2.2, seed=2).heights)


class TestSurfaceSpectral:
    def test_rms_slope(self, tmp_path):
        out = tmp_path / "p.npz"
        proc = run(
            "surface spectral --n 32x48 --hurst 0.8 --seed 0 --rms-slope 0.25 --json --out",
            str(out),
        )
        assert proc.returncode == 0, proc.stderr
        s = load(out)
        assert s.shape == (32, 48) and s.dx == pytest.approx(500 / 48)  # default 500 µm
        h = s.heights
        slope = math.sqrt(np.mean(np.diff(h, axis=1) ** 2) + np.mean(np.diff(h, axis=0) ** 2))
        assert slope / s.dx == pytest.approx(0.25, rel=1e-12, abs=0)
        assert json.loads(proc.stdout)["m2"] == pytest.approx(0.25**2 / 2, rel=1e-12, abs=0)

    def test_rms_height_default(self, tmp_path):
        out = tmp_path / "p.npz"
        proc = run("surface spectral --n 64 --hurst 0.5 --seed 4 --out", str(out))
        assert proc.returncode == 0, proc.stderr
        s = load(out)
        assert np.array_equal(s.heights, spectral(64, 0.5, seed=4).heights)
        assert float(parse_table(proc.stdout)["rms height [µm]"]) == pytest.approx(1.0, rel=1e-5)

    def test_rms_height_and_slope_exclusive(self, tmp_path):
        proc = run(
            "surface spectral --n 16 --hurst 0.5 --seed 0 --rms-height 1 --rms-slope 1 --out",
            str(tmp_path / "x.npz"),
        )
        assert_usage_error(proc)
        assert not (tmp_path / "x.npz").exists()


class TestTopLevel:
    def test_help(self):
        proc = run("--help")
        assert proc.returncode == 0
        assert "surface" in proc.stdout and "usage: leakpath" in proc.stdout

    def test_surface_rmd_help(self):
        proc = run("surface rmd --help")
        assert proc.returncode == 0
        assert "--D" in proc.stdout and "--overwrite" in proc.stdout

    def test_version(self):
        proc = run("--version")
        assert proc.returncode == 0
        assert proc.stdout.strip() == f"leakpath {leakpath.__version__}"

    @pytest.mark.parametrize(
        "args, needle",
        [
            ("surface rmd --m 5 --D 3.5 --seed 0 --out {o}", "D: must be a fractal"),
            ("surface rmd --m 5 --D 2.5 --seed 0", "--out"),
            ("surface rmd --m 2.5 --D 2.5 --seed 0 --out {o}", "--m"),
            ("surface rmd --m 0 --D 2.5 --seed 0 --out {o}", "m: must"),
            ("surface rmd --m 3 --D 2.5 --seed -4 --out {o}", "seed"),
            ("surface rmd --m 3 --D 2.5 --seed 0 --out {o}x", ".npz"),
            ("surface spectral --n 1 --hurst 0.5 --seed 0 --out {o}", "shape"),
            ("surface spectral --n 8 --hurst 1.2 --seed 0 --out {o}", "hurst"),
            ("surface spectral --n 8by8 --hurst 0.5 --seed 0 --out {o}", "--n"),
            ("surface bogus", "bogus"),
            ("frobnicate", "frobnicate"),
            ("", "required"),
            ("surface", "required"),
        ],
    )
    def test_bad_arguments_exit_2(self, tmp_path, args, needle):
        out = str(tmp_path / "o.npz")
        proc = run("", *[a.replace("{o}", out) for a in args.split()])
        line = assert_usage_error(proc)
        assert needle in line
        assert proc.stdout == ""
        assert not (tmp_path / "o.npz").exists()

    def test_missing_directory(self, tmp_path):
        proc = run(
            "surface rmd --m 3 --D 2.5 --seed 0 --out", str(tmp_path / "no" / "dir" / "s.npz")
        )
        assert_usage_error(proc)


class TestInProcess:
    def test_main_returns_status(self, tmp_path, capsys):
        out = tmp_path / "s.npz"
        assert (
            cli.main(["surface", "rmd", "--m", "3", "--D", "2.4", "--seed", "5", "--out", str(out)])
            == 0
        )
        assert "alpha" in capsys.readouterr().out
        assert (
            cli.main(["surface", "rmd", "--m", "3", "--D", "2.4", "--seed", "5", "--out", str(out)])
            == 2
        )
        err = capsys.readouterr().err
        assert err.startswith("leakpath: error: ") and err.count("\n") == 1
        assert cli.main(["--version"]) == 0
        assert capsys.readouterr().out.strip() == f"leakpath {leakpath.__version__}"

    def test_closed_stdout_is_not_an_error(self, tmp_path):
        # `leakpath ... | head -0`: the reader is gone before anything is written.
        read_end, write_end = os.pipe()
        os.close(read_end)
        out = tmp_path / "s.npz"
        try:
            proc = subprocess.run(
                [sys.executable, "-m", "leakpath", "surface", "rmd", "--m", "3", "--D", "2.4"]
                + ["--seed", "1", "--out", str(out)],
                stdout=write_end,
                stderr=subprocess.PIPE,
                text=True,
                timeout=120,
            )
        finally:
            os.close(write_end)
        assert proc.returncode == 141
        assert proc.stderr == ""
        assert load(out).shape == (9, 9)

    def test_format_table_aligned(self):
        text = cli.format_table([("a", 1.0), ("long name", 2.5e-9), ("shape", [3, 4])])
        lines = text.splitlines()
        assert lines == ["a          1", "long name  2.5e-09", "shape      3 x 4"]
