"""Careless and hostile input, through every entry path: the Python API, files and the CLI.

Every refusal must be a leakpath error (:class:`leakpath.errors.LeakpathError`) that is also
the builtin it stands for (``ValueError`` for a bad argument, ``MemoryError`` for a problem
too large to allocate) and that names the argument (``.argument`` or the message prefix
``argument: ...``). The command line must answer with one line on stderr and exit status 2,
without a traceback, an abort or a hang. Nothing may come back as silent garbage: the last
part feeds random finite inputs to the solvers and accepts only a solution with a KKT
certificate within the tolerance or a leakpath error.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import leakpath
from leakpath import (
    ContactProblem,
    Surface,
    cli,
    kernel_table,
    load,
    nayak_moments,
    percolation,
    percolation_threshold,
    rmd,
    solve,
    spectral,
    sweep,
)
from leakpath.contact import contact_modulus
from leakpath.errors import (
    InvalidArgumentError,
    LeakpathError,
    NotConvergedError,
    ProblemTooLargeError,
)

try:
    import SurfaceTopography  # noqa: F401

    HAVE_ST = True
except ImportError:  # pragma: no cover - depends on the optional extra
    HAVE_ST = False


# ---------------------------------------------------------------------------- helpers
@contextlib.contextmanager
def deadline(seconds: float):
    """Fail instead of hanging: a Python-level loop that outlives ``seconds`` is stopped."""

    def expire(signum, frame):
        raise TimeoutError(f"still running after {seconds} s")

    old = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def named(err: BaseException) -> str:
    """The argument an error names: ``.argument`` if set, else the message prefix."""
    arg = getattr(err, "argument", "")
    return arg or str(err).split(":", 1)[0].strip()


def refused(call, argument: str, builtin: type[BaseException] = ValueError, seconds=20.0):
    """``call()`` raises a leakpath error that is a ``builtin`` and names ``argument``."""
    with deadline(seconds):
        with pytest.raises(LeakpathError) as info:
            call()
    err = info.value
    assert isinstance(err, builtin), (type(err).__mro__, err)
    assert named(err) == argument, (argument, str(err))
    assert str(err).startswith(f"{argument}:"), str(err)
    return err


def run_cli(*args: str, timeout: float = 60.0, cwd=None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "leakpath", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd,
    )


def cli_refused(proc: subprocess.CompletedProcess[str], needle: str) -> str:
    """Exit 2, one ``leakpath: error:`` line naming ``needle``, no traceback, no abort."""
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("leakpath: error: "), lines[0]
    assert needle in lines[0], lines[0]
    return lines[0]


def strict_json(text: str) -> Any:
    """Parse JSON refusing NaN/Infinity (which ``json.loads`` would accept by default)."""

    def bad(constant: str) -> Any:
        raise AssertionError(f"invalid JSON constant {constant}")

    return json.loads(text, parse_constant=bad)


@pytest.fixture(scope="module")
def small() -> Surface:
    return rmd(3, 2.3, seed=1)


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    """Surface files, good and bad, shared by the load and CLI probes."""
    d = tmp_path_factory.mktemp("files")
    rng = np.random.default_rng(7)
    h = rng.standard_normal((9, 9))
    out = {"dir": d}
    np.save(d / "good.npy", h)
    out["good"] = d / "good.npy"
    np.save(d / "complex.npy", h + 1j * h)
    out["complex"] = d / "complex.npy"
    np.save(d / "flat.npy", np.full((9, 9), 3.0))
    out["flat"] = d / "flat.npy"
    np.save(d / "strings.npy", np.array([["1", "2"], ["3", "4"]]))
    out["strings"] = d / "strings.npy"
    np.save(d / "bools.npy", np.ones((3, 3), bool))
    out["bools"] = d / "bools.npy"
    (d / "junk.bin").write_bytes(rng.bytes(5000))  # 2·50²: HGT-sized random bytes
    out["junk"] = d / "junk.bin"
    (d / "junk.dat").write_bytes(b"\x00" + rng.bytes(3000))
    out["junk_dat"] = d / "junk.dat"
    np.savetxt(d / "text.dat", h)
    out["text_dat"] = d / "text.dat"
    holes = h.copy()
    holes[4, 4] = np.nan
    np.savetxt(d / "holes.txt", holes)
    out["holes"] = d / "holes.txt"
    pts = rng.random((30, 2))
    pts = pts[np.argsort(pts[:, 0])]
    np.savetxt(d / "scattered.txt", np.column_stack([pts, rng.random(30)]))
    out["scattered"] = d / "scattered.txt"
    fifo = d / "pipe.npy"
    os.mkfifo(fifo)
    out["fifo"] = fifo
    return out


BOOLS = [True, False, np.True_]
STRINGS = ["0.5", "3", "1e-8", ""]
COMPLEX = [1 + 0j, 0.5 + 0.5j, np.complex128(2.0)]
NON_NUMBERS = [None, [1.0], (1.0,), {"x": 1}, object(), b"1"]
NON_FINITE = [float("nan"), float("inf"), -float("inf")]
NOT_REAL = BOOLS + STRINGS + COMPLEX + [v for v in NON_NUMBERS if v is not None] + NON_FINITE
NOT_INT = BOOLS + STRINGS + COMPLEX + [2.5, 3.0, float("nan"), [3], object()]


# ---------------------------------------------------------------------------- the probes
class TestWrongAnswers:
    def test_surface_copies_and_freezes_the_callers_array(self, small):
        h = small.heights.copy()
        s = Surface(h, small.dx)
        prob = ContactProblem(s)
        before = prob.solve(0.5 * s.height_range, solver="active-set")
        h *= 10.0  # the caller rescales its own array afterwards
        after = prob.solve(0.5 * s.height_range, solver="active-set")
        assert np.array_equal(before.pressure, after.pressure)
        assert np.array_equal(s.heights, small.heights)
        assert not s.heights.flags.writeable
        with pytest.raises(ValueError):
            s.heights[0, 0] = 1.0

    def test_assigning_heights_or_dx_later_is_checked_too(self, small):
        s = Surface(small.heights, small.dx)
        refused(lambda: setattr(s, "heights", small.heights + 1j), "heights")
        refused(lambda: setattr(s, "dx", True), "dx")
        refused(lambda: setattr(s, "dx", 1e-200), "dx")
        h = np.zeros((4, 4))
        s.heights = h
        h[0, 0] = 1.0
        assert s.heights[0, 0] == 0.0 and not s.heights.flags.writeable

    def test_bare_arrays_are_copied_by_solve_and_problem(self, small):
        h = small.heights.copy()
        prob = ContactProblem(h, dx=small.dx)
        h[:] = 0.0
        assert np.array_equal(prob.surface.heights, small.heights)

    @pytest.mark.parametrize("dx", [1e-200, 1e200, 1e-160, 1e160, 5e-324])
    def test_spacings_whose_square_is_not_normal(self, small, dx):
        refused(lambda: Surface(small.heights, dx), "dx")
        refused(lambda: solve(small.heights, 0.1, dx=dx), "dx")
        refused(lambda: nayak_moments(small.heights, dx), "dx")
        refused(lambda: percolation(np.ones((3, 3)), dx=dx), "dx")

    def test_surface_with_a_conflicting_dx(self, small):
        refused(lambda: ContactProblem(small, dx=2 * small.dx), "dx")
        refused(lambda: solve(small, 0.1, dx=2 * small.dx), "dx")
        refused(lambda: nayak_moments(small, 2 * small.dx), "dx")
        # The same dx is not a conflict.
        assert ContactProblem(small, dx=small.dx).surface is small

    def test_e_whose_compliance_overflows(self, small):
        refused(lambda: solve(small, 0.1, E=1e-320), "E")
        refused(lambda: solve(small, 0.1, E=1e308, nu=0.49), "E")

    def test_incompressible_and_auxetic_poisson_ratios(self, small):
        assert contact_modulus(3.0, 0.5) == 4.0
        assert contact_modulus(3.0, -0.5) == 4.0
        a = 0.4 * small.height_range
        ref = solve(small, a, E=4.0 / 3.0, nu=0.0, solver="active-set")
        for nu in (0.5, -0.5):  # 1 − ν² = 3/4 for both: E* = 4E/3
            st = solve(small, a, E=1.0, nu=nu, solver="active-set")
            np.testing.assert_allclose(st.pressure, ref.pressure, rtol=1e-12, atol=0)
        refused(lambda: contact_modulus(1.0, -1.0), "nu")
        refused(lambda: contact_modulus(1.0, 0.5000001), "nu")


class TestFiles:
    def test_fifo_is_refused_without_waiting(self, files):
        refused(lambda: load(files["fifo"], dx=1.0), "path", seconds=10)

    def test_random_bytes_with_an_unknown_extension(self, files):
        if HAVE_ST:
            err = refused(lambda: load(files["junk"], dx=1.0), "path")
            assert "matches no known format" in str(err)
        else:
            with pytest.raises(ImportError, match=r"leakpath\[io\]"):
                load(files["junk"], dx=1.0)

    def test_dat_tries_text_then_the_other_readers(self, files):
        s = load(files["text_dat"], dx=0.5)
        np.testing.assert_array_equal(s.heights, np.loadtxt(files["text_dat"]))
        err = refused(lambda: load(files["junk_dat"], dx=1.0), "path")
        assert "plain-text matrix" in str(err)

    @pytest.mark.parametrize(
        "key, word", [("complex", "complex"), ("strings", "dtype"), ("bools", "dtype")]
    )
    def test_non_real_arrays_in_files(self, files, key, word):
        err = refused(lambda: load(files[key], dx=1.0), "path")
        assert word in str(err)

    def test_undefined_points_are_counted_and_filled_only_on_request(self, files):
        err = refused(lambda: load(files["holes"], dx=1.0), "path")
        assert "1 of 81 points" in str(err) and "fill=" in str(err)
        h = np.loadtxt(files["holes"])
        mean = load(files["holes"], dx=1.0, fill="mean")
        assert mean.heights[4, 4] == pytest.approx(np.nanmean(h), rel=1e-15, abs=0)
        near = load(files["holes"], dx=1.0, fill="nearest")
        four = (h[3, 4] + h[5, 4] + h[4, 3] + h[4, 5]) / 4
        assert near.heights[4, 4] == pytest.approx(four, rel=1e-15, abs=0)
        assert near.metadata["filled"] == {"method": "nearest", "points": 1}
        refused(lambda: load(files["holes"], dx=1.0, fill="zero"), "fill")
        refused(lambda: load(files["holes"], dx=1.0, fill=True), "fill")

    def test_nearest_fill_reproduces_a_plane_and_fills_big_holes(self, tmp_path):
        y, x = np.mgrid[0:12, 0:10]
        plane = 0.3 * x - 0.7 * y + 2.0
        h = plane.copy()
        h[5, 5] = np.nan
        h[1, 7] = np.nan
        np.save(tmp_path / "p.npy", h)
        s = load(tmp_path / "p.npy", dx=1.0, fill="nearest")
        np.testing.assert_allclose(s.heights, plane, rtol=0, atol=1e-12)
        h = plane.copy()
        h[2:9, 1:8] = np.nan  # a 7 × 7 hole: filled layer by layer, within the data's range
        np.save(tmp_path / "q.npy", h)
        s = load(tmp_path / "q.npy", dx=1.0, fill="nearest")
        assert np.isfinite(s.heights).all()
        assert np.nanmin(h) <= s.heights.min() and s.heights.max() <= np.nanmax(h)

    def test_gridded_point_cloud_in_any_order(self, tmp_path):
        rng = np.random.default_rng(3)
        h = rng.standard_normal((5, 7))
        y, x = np.mgrid[0:5, 0:7] * 0.25 + 10.0
        table = np.column_stack([x.ravel(), y.ravel(), h.ravel()])
        for name, rows in (("sorted", table), ("shuffled", table[rng.permutation(35)])):
            np.savetxt(tmp_path / f"{name}.txt", rows)
            s = load(tmp_path / f"{name}.txt")
            assert s.dx == pytest.approx(0.25)
            np.testing.assert_array_equal(s.heights, h)
        # A missing grid point is an undefined point.
        np.savetxt(tmp_path / "missing.txt", table[1:])
        err = refused(lambda: load(tmp_path / "missing.txt"), "path")
        assert "1 of 35" in str(err)

    def test_scattered_point_cloud_is_refused(self, files):
        err = refused(lambda: load(files["scattered"], dx=1.0), "path")
        assert "point cloud" in str(err)

    def test_non_square_point_cloud_is_refused(self, tmp_path):
        y, x = np.mgrid[0:4, 0:5]
        np.savetxt(tmp_path / "r.txt", np.column_stack([x.ravel() * 0.5, y.ravel(), x.ravel()]))
        err = refused(lambda: load(tmp_path / "r.txt"), "path")
        assert "square" in str(err)

    @pytest.mark.parametrize("path", [None, 3, b"x.npy", True, ["x.npy"]])
    def test_path_must_be_a_path(self, path):
        refused(lambda: load(path, dx=1.0), "path")

    def test_save_checks_its_arguments(self, small, tmp_path):
        refused(lambda: small.save(3), "path")
        refused(lambda: small.save(tmp_path / "x.npz", overwrite="no"), "overwrite")

    def test_directory_and_wrong_signatures(self, tmp_path):
        refused(lambda: load(tmp_path, dx=1.0), "path")
        (tmp_path / "fake.npy").write_text("1 2\n3 4\n")
        refused(lambda: load(tmp_path / "fake.npy", dx=1.0), "path")
        (tmp_path / "fake.npz").write_bytes(b"\x93NUMPY not a zip")
        refused(lambda: load(tmp_path / "fake.npz"), "path")
        (tmp_path / "bin.txt").write_bytes(b"\x00\x01\x02 3 4")
        refused(lambda: load(tmp_path / "bin.txt", dx=1.0), "path")

    @pytest.mark.skipif(not HAVE_ST, reason="needs the optional SurfaceTopography")
    def test_masked_points_of_a_measured_file(self, tmp_path):
        import SurfaceTopography as st  # noqa: N813

        h = np.random.default_rng(0).standard_normal((8, 10))
        mask = np.zeros_like(h, bool)
        mask[2:4, 3:5] = True
        st.Topography(np.ma.masked_array(h, mask), (8.0, 10.0)).to_netcdf(tmp_path / "m.nc")
        err = refused(lambda: load(tmp_path / "m.nc"), "path")
        assert "4 of 80 points" in str(err)
        s = load(tmp_path / "m.nc", fill="mean")
        assert s.heights[3, 2] == pytest.approx(h[~mask].mean(), rel=1e-12)  # transposed
        np.testing.assert_array_equal(s.heights.T[~mask], h[~mask])


class TestMemoryGuards:
    @pytest.mark.parametrize("shape", [30000, (30000, 30000), (2, 10**9), 2**40])
    def test_spectral(self, shape):
        err = refused(lambda: spectral(shape, 0.8, seed=1), "shape", MemoryError)
        assert isinstance(err, ProblemTooLargeError) and err.estimate > err.limit > 0

    @pytest.mark.parametrize("m", [15, 64, 1000, 2**62, 10**30])
    def test_rmd(self, m):
        refused(lambda: rmd(m, 2.2, seed=0), "m", MemoryError, seconds=5)

    def test_levels(self, small):
        refused(lambda: sweep(small, levels=10**12), "levels", MemoryError, seconds=5)
        refused(lambda: sweep(small, levels=2**80), "levels", MemoryError, seconds=5)

    def test_kernel_table(self):
        refused(lambda: kernel_table((10**6, 10**6), 1.0), "shape", MemoryError)

    def test_files_larger_than_memory(self, tmp_path, monkeypatch, small):
        small.save(tmp_path / "s.npz")
        np.save(tmp_path / "s.npy", small.heights)
        np.savetxt(tmp_path / "s.txt", small.heights)
        monkeypatch.setattr(leakpath._validate, "memory_budget", lambda: 1000)
        for name in ("s.npz", "s.npy", "s.txt"):  # npz: its uncompressed size counts
            refused(lambda n=name: load(tmp_path / n, dx=small.dx), "path", MemoryError)

    def test_compressed_npz_is_sized_by_what_it_expands_to(self, tmp_path, monkeypatch):
        # A million int8 zeros compress to about a kilobyte (several hundred times smaller).
        # Loaded, they are 1 MB as stored plus 8 MB as float64 heights at the very least.
        path = tmp_path / "zeros.npz"
        points = 1000 * 1000
        np.savez_compressed(path, heights=np.zeros((1000, 1000), np.int8), dx=np.float64(1.0))
        assert path.stat().st_size * 200 < points
        monkeypatch.setattr(leakpath._validate, "memory_budget", lambda: 4 * points)
        err = refused(lambda: load(path), "path", MemoryError)
        assert isinstance(err, ProblemTooLargeError)
        assert err.estimate >= 9 * points > err.limit and "zeros.npz" in str(err)
        # With room for those copies the same file loads.
        monkeypatch.setattr(leakpath._validate, "memory_budget", lambda: 100 * points)
        assert load(path).shape == (1000, 1000)

    def test_npz_member_header_declaring_more_than_the_archive_holds(self, tmp_path, monkeypatch):
        # The zip directory says a few hundred bytes; the .npy header inside declares a
        # 2000 x 2000 float64 array (32 MB) that reading it would allocate first.
        import io
        import zipfile

        header = io.BytesIO()
        np.lib.format.write_array_header_1_0(
            header, {"descr": "<f8", "fortran_order": False, "shape": (2000, 2000)}
        )
        path = tmp_path / "liar.npz"
        with zipfile.ZipFile(path, "w") as archive:
            archive.writestr("heights.npy", header.getvalue() + bytes(64))
        monkeypatch.setattr(leakpath._validate, "memory_budget", lambda: 10 * 2**20)
        err = refused(lambda: load(path, dx=1.0), "path", MemoryError)
        assert err.estimate >= 8 * 2000 * 2000

    def test_npy_header_sizes_the_read(self, tmp_path, monkeypatch):
        path = tmp_path / "bytes.npy"
        np.save(path, np.zeros((1000, 1000), np.uint8))  # 1 MB on disk, 8 MB as float64
        monkeypatch.setattr(leakpath._validate, "memory_budget", lambda: 4 * 10**6)
        refused(lambda: load(path, dx=1.0), "path", MemoryError)

    @pytest.mark.parametrize("where", ["_read_npz", "real_array"])
    def test_memory_error_while_reading_is_a_problem_too_large(
        self, tmp_path, monkeypatch, small, where
    ):
        # The estimate fits, the allocation fails anyway (other processes took the memory).
        small.save(tmp_path / "s.npz")

        def out_of_memory(*args, **kwargs):
            raise MemoryError

        target = leakpath._readers if where == "_read_npz" else leakpath._validate
        monkeypatch.setattr(target, where, out_of_memory)
        err = refused(lambda: load(tmp_path / "s.npz"), "path", MemoryError)
        assert isinstance(err, ProblemTooLargeError) and "s.npz" in str(err)

    def test_huge_arrays_that_cost_nothing_until_copied(self):
        # Zero-stride views: 80 GB of heights that occupy 8 bytes until someone copies them.
        huge = np.broadcast_to(1.0, (100_000, 100_000))
        refused(lambda: Surface(huge, 1.0), "heights", MemoryError)
        refused(lambda: solve(huge, 0.0, dx=1.0), "heights", MemoryError)
        refused(lambda: nayak_moments(huge, 1.0), "heights", MemoryError)
        refused(lambda: percolation(huge, dx=1.0), "gap")


def _api_cases(small: Surface) -> list[tuple[str, str, Any, Any]]:
    """(function, argument, bad value, call) for every numeric and flag argument."""
    h, hs = small.heights, small.height_range
    gap = np.ones((4, 4))
    flat = Surface(np.zeros((5, 5)), 1.0)
    calls = {
        "rmd.m": lambda v: rmd(v, 2.2, seed=0),
        "rmd.D": lambda v: rmd(3, v, seed=0),
        "rmd.seed": lambda v: rmd(3, 2.2, seed=v),
        "rmd.sigma0": lambda v: rmd(3, 2.2, seed=0, sigma0=v),
        "rmd.length": lambda v: rmd(3, 2.2, seed=0, length=v),
        "spectral.shape": lambda v: spectral(v, 0.8, seed=0),
        "spectral.hurst": lambda v: spectral(8, v, seed=0),
        "spectral.length": lambda v: spectral(8, 0.8, seed=0, length=v),
        "spectral.rms_height": lambda v: spectral(8, 0.8, seed=0, rms_height=v),
        "spectral.rms_slope": lambda v: spectral(8, 0.8, seed=0, rms_slope=v),
        "spectral.long_cutoff": lambda v: spectral(8, 0.8, seed=0, long_cutoff=v),
        "spectral.short_cutoff": lambda v: spectral(8, 0.8, seed=0, short_cutoff=v),
        "spectral.rolloff": lambda v: spectral(8, 0.8, seed=0, rolloff=v),
        "Surface.dx": lambda v: Surface(h, v),
        "ContactProblem.E": lambda v: ContactProblem(small, E=v),
        "ContactProblem.nu": lambda v: ContactProblem(small, nu=v),
        "ContactProblem.memory_limit": lambda v: ContactProblem(small, memory_limit=v),
        "solve.dx": lambda v: solve(h, 0.1, dx=v),
        "solve.approach": lambda v: solve(small, v, boundary="periodic"),
        "solve.tol": lambda v: solve(small, 0.1 * hs, tol=v),
        "solve.max_iter": lambda v: solve(small, 0.1 * hs, max_iter=v),
        "solve.memory_limit": lambda v: solve(small, 0.1 * hs, memory_limit=v),
        "solve.mean_pressure": lambda v: solve(small, mean_pressure=v),
        "flow.memory_limit": lambda v: leakpath.flow(gap, dx=1.0, memory_limit=v),
        "flow.max_iter": lambda v: leakpath.flow(gap, dx=1.0, max_iter=v),
        "flow.viscosity": lambda v: leakpath.flow(gap, dx=1.0, viscosity=v),
        "flow.tol": lambda v: leakpath.flow(gap, dx=1.0, tol=v),
        "sweep.levels": lambda v: sweep(small, levels=v),
        "sweep.E": lambda v: sweep(small, levels=2, E=v),
        "sweep.nu": lambda v: sweep(small, levels=2, nu=v),
        "sweep.warm_start": lambda v: sweep(small, levels=2, warm_start=v),
        "sweep.keep_fields": lambda v: sweep(small, levels=2, keep_fields=v),
        "sweep.axis": lambda v: sweep(small, levels=2, axis=v),
        "sweep.connectivity": lambda v: sweep(small, levels=2, connectivity=v),
        "percolation.dx": lambda v: percolation(gap, dx=v),
        "percolation.threads": lambda v: percolation(gap, dx=1.0, threads=v),
        "percolation.axis": lambda v: percolation(gap, dx=1.0, axis=v),
        "percolation.connectivity": lambda v: percolation(gap, dx=1.0, connectivity=v),
        "percolation_threshold.atol": lambda v: percolation_threshold(small, atol=v),
        "percolation_threshold.max_solves": lambda v: percolation_threshold(small, max_solves=v),
        "percolation_threshold.axis": lambda v: percolation_threshold(small, axis=v),
        "nayak_moments.dx": lambda v: nayak_moments(h, v),
        "kernel_table.shape": lambda v: kernel_table(v, 1.0),
        "kernel_table.dx": lambda v: kernel_table((3, 3), v),
        "kernel_table.e_star": lambda v: kernel_table((3, 3), 1.0, v),
        "load.dx": lambda v: load("/nonexistent-never-read.npy", dx=v),
    }
    ints = {"rmd.m", "rmd.seed", "solve.max_iter", "sweep.levels", "percolation.threads",
            "percolation_threshold.max_solves", "ContactProblem.memory_limit",
            "solve.memory_limit", "flow.memory_limit", "flow.max_iter"}
    shapes = {"spectral.shape", "kernel_table.shape"}
    choices = {"sweep.axis", "percolation.axis", "percolation_threshold.axis",
               "sweep.connectivity", "percolation.connectivity"}
    flags = {"sweep.warm_start", "sweep.keep_fields"}
    cases = []
    for key, call in calls.items():
        arg = key.split(".", 1)[1]
        if key in ints:
            bad = NOT_INT + [-1, 0 if "seed" not in key else -5]
            if key in ("solve.max_iter", "percolation.threads", "ContactProblem.memory_limit",
                       "percolation_threshold.max_solves", "solve.memory_limit",
                       "flow.memory_limit", "flow.max_iter"):
                bad = bad + [2**70, 10**400, "big"]
        elif key in shapes:
            bad = [(2.5, 3), ("3", "3"), (-1, 5), (True, 3), (3, 3, 3), "8", 2.5, None, (0, 4)]
        elif key in choices:
            bad = [True, 2, -1, 4.0, "x", None, [0], 0.0] + (["3"] if "axis" in key else [6])
        elif key in flags:
            bad = [1, 0, "yes", None, 1.0]
        else:
            bad = list(NOT_REAL) + [10**400]
            if arg not in ("approach",):
                bad += [0, -1.0, -1e-300]
            else:
                bad += [-1.0, 10 * hs]
            if arg == "nu":
                bad = [v for v in bad if v not in (0, -1e-300)] + [0.6, -1.0, -3.0]
            if arg == "hurst":
                bad += [1.0, 1.5]
            if arg == "D":
                bad += [2.0, 3.0, 3.5]
            if arg in ("rms_height", "rms_slope", "long_cutoff", "short_cutoff", "rolloff"):
                bad = [v for v in bad if v is not None]
            if arg == "dx":
                bad += [1e-200, 1e200]
            if arg == "mean_pressure":
                bad += [1e300, 1e-300]  # beyond the solvers' floating-point range
        for v in bad:
            if v is None and arg in ("rms_height", "rms_slope", "long_cutoff", "short_cutoff",
                                      "rolloff", "tol", "max_iter", "atol", "threads",
                                      "memory_limit", "seed", "dx"):
                continue  # None means "the default" there
            cases.append((key, arg, v, call))
    # Flat surfaces: refused, not solved to garbage.
    cases.append(("percolation_threshold.flat", "surface", None,
                  lambda v: percolation_threshold(flat)))
    cases.append(("sweep.flat", "surface", None, lambda v: sweep(flat)))
    return cases


@pytest.fixture(scope="module")
def api_cases():
    return _api_cases(rmd(3, 2.3, seed=1))


def test_every_bad_argument_is_refused_by_name(api_cases):
    failures = []
    for key, arg, value, call in api_cases:
        try:
            with deadline(20):
                call(value)
        except LeakpathError as exc:
            builtin = MemoryError if isinstance(exc, ProblemTooLargeError) else ValueError
            if not isinstance(exc, builtin) or named(exc) != arg:
                failures.append(f"{key}={value!r}: {type(exc).__name__}: {exc}")
        except Exception as exc:  # noqa: BLE001 - any other exception is a defect
            failures.append(f"{key}={value!r}: raw {type(exc).__name__}: {exc}")
        else:
            failures.append(f"{key}={value!r}: accepted")
    assert not failures, "\n".join(failures)
    assert len(api_cases) > 400


def test_complex_heights_are_refused_everywhere(small):
    hc = small.heights + 1j
    refused(lambda: Surface(hc, 1.0), "heights")
    refused(lambda: solve(hc, 0.1, dx=1.0), "heights")
    refused(lambda: nayak_moments(hc, 1.0), "heights")
    refused(lambda: percolation(hc, dx=1.0), "gap")
    refused(lambda: Surface(small.heights.astype(str), 1.0), "heights")
    refused(lambda: Surface([[1, 2], [3]], 1.0), "heights")
    refused(lambda: Surface(np.ones(5), 1.0), "heights")
    refused(lambda: Surface(np.full((3, 3), 1e200), 1.0), "heights")


def test_the_probes_of_the_report(small, files):
    """The probe list itself, one call each (a regression index for the report)."""
    hs = small.height_range
    refused(lambda: solve(small, "0.5"), "approach")
    refused(lambda: solve(small, True), "approach")
    refused(lambda: solve(small, 0.1 * hs, tol="1e-8"), "tol")
    refused(lambda: Surface(small.heights, True), "dx")
    refused(lambda: kernel_table((2.5, 3), 1.0), "shape")
    refused(lambda: kernel_table(("3", "3"), 1.0), "shape")
    refused(lambda: kernel_table((-1, 5), 1.0), "shape")
    refused(lambda: ContactProblem(small, memory_limit=0), "memory_limit")
    refused(lambda: ContactProblem(small, memory_limit=-1), "memory_limit")
    refused(lambda: ContactProblem(small, memory_limit="big"), "memory_limit")
    refused(lambda: solve(small, 0.1, nu="0.3"), "nu")
    refused(lambda: solve(small, 0.1 * hs, max_iter=-1), "max_iter")
    refused(lambda: solve(small, 0.1 * hs, max_iter=2**70), "max_iter")
    refused(lambda: percolation_threshold(small, max_solves=None), "max_solves")
    refused(lambda: percolation_threshold(Surface(np.ones((5, 5)), 1.0)), "surface")
    refused(lambda: solve(small, 0.1, E=1e-320), "E")
    refused(lambda: load(files["complex"], dx=1.0), "path")
    refused(lambda: Surface(small.heights + 0j, 1.0), "heights")
    # memory_limit, max_iter and numbers as huge ints or non-numbers, wherever they are taken.
    state = solve(small, 0.3 * hs)
    for bad in (-1, 0, float("nan"), float("inf"), "8", 10**400, 1.5):
        refused(lambda b=bad: state.flow(memory_limit=b), "memory_limit")
        refused(lambda b=bad: solve(small, 0.1 * hs, memory_limit=b), "memory_limit")
    refused(lambda: state.flow(max_iter=10**400), "max_iter")
    refused(lambda: state.flow(viscosity=10**400), "viscosity")
    refused(lambda: solve(small, 0.1 * hs, max_iter=10**400), "max_iter")
    # Ragged lists and duck-typed states with strings.
    refused(lambda: solve([[1, 2], [3]], 0.1, dx=1.0), "heights")
    refused(lambda: solve(small, 0.1 * hs, warm_start=[[1.0, 2.0], [3.0]]), "warm_start")

    class Duck:
        gap = [["a", "b"], ["c", "d"]]
        contact = np.zeros((2, 2), bool)
        dx = 1.0

    refused(lambda: leakpath.flow(Duck()), "gap")
    refused(lambda: percolation(Duck()), "gap")
    duck = Duck()
    duck.gap, duck.dx = np.ones((2, 2)), "1.0"
    refused(lambda: leakpath.flow(duck), "dx")
    refused(lambda: solve(small, 0.1 * hs, warm_start=duck), "warm_start")
    # An absurd warm start is refused, not reported as non-convergence.
    refused(lambda: solve(small, 0.1 * hs, warm_start=np.full(small.shape, 1e300)), "warm_start")
    # Loads far past full contact are solved (not "did not converge"); beyond the
    # floating-point range of the solvers they are refused by name.
    assert solve(small, mean_pressure=1e6).contact_fraction == 1.0
    refused(lambda: solve(small, mean_pressure=1e300), "mean_pressure")
    refused(lambda: sweep(small, mean_pressures=[1.0, 1e300]), "mean_pressures")


# ---------------------------------------------------------------------------- unusable paths
@pytest.fixture
def bad_paths(tmp_path) -> dict[str, str]:
    """Paths no file can be read from or written to, each for its own reason."""
    loop = tmp_path / "loop"
    loop.symlink_to(loop)  # a link to itself: every lookup through it fails with ELOOP
    a_file = tmp_path / "plain.txt"
    a_file.write_text("x")
    return {
        "5000 characters": str(tmp_path / ("a" * 5000)),
        "a 300-character name": str(tmp_path / ("b" * 300 + ".npz")),
        "NUL": str(tmp_path / "x\x00y.npz"),
        "symlink loop": str(loop),
        "inside a symlink loop": str(loop / "x.npz"),
        "below a file": str(a_file / "x.npz"),
    }


PATH_WORDS = {
    "5000 characters": "too long",
    "a 300-character name": "too long",
    "NUL": "NUL",
    "symlink loop": "loop of symbolic links",
    "inside a symlink loop": "loop of symbolic links",
    "below a file": "through a file",
}


@pytest.mark.parametrize("kind", list(PATH_WORDS))
def test_unusable_paths_are_refused_by_name_in_the_api(small, bad_paths, kind):
    from leakpath.plotting.flow import save_flow_figures

    bad = bad_paths[kind]
    result = sweep(small, levels=2)
    calls = {
        "path": [
            lambda: load(bad, dx=1.0),
            lambda: small.save(bad),  # the path is refused before its suffix is looked at
            lambda: result.to_csv(bad),
            lambda: result.to_json(bad),
        ],
        "outdir": [lambda: result.plot(bad), lambda: save_flow_figures(result, bad)],
        "checkpoint_dir": [lambda: sweep(small, levels=2, checkpoint_dir=bad)],
    }
    for argument, group in calls.items():
        for call in group:
            err = refused(call, argument)
            assert PATH_WORDS[kind] in str(err)
            assert len(str(err)) < 400  # a long path is shortened in the message


def test_a_file_name_near_the_limit_is_still_written_atomically(tmp_path, small):
    # The hidden temporary beside the target must not exceed the name limit itself.
    path = tmp_path / ("c" * 250 + ".npz")
    small.save(path)
    assert np.array_equal(load(path).heights, small.heights)
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


@pytest.mark.parametrize("kind", list(PATH_WORDS))
def test_unusable_paths_are_refused_by_flag_in_the_cli(tmp_path, capsys, bad_paths, kind):
    from leakpath import cli

    bad = bad_paths[kind]
    spec = "rmd:m=3,D=2.2,seed=0"
    for argv, flag in [
        (["sweep", bad, "--dx", "1", "--out", str(tmp_path / "o")], "SURFACE:"),
        (["sweep", spec, "--out", bad], "--out:"),
        (["surface", "rmd", "--m", "3", "--D", "2.2", "--seed", "0", "--out", bad], "--out:"),
        (["ensemble", "--D", "2.2", "--m", "3", "--surfaces", "1", "--out", bad], "--out:"),
    ]:
        assert cli.main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith(f"leakpath: error: {flag}"), err
        assert PATH_WORDS[kind] in err and len(err) < 400 and "Traceback" not in err


def test_a_5000_character_path_in_a_subprocess(tmp_path):
    proc = run_cli("sweep", str(tmp_path / ("a" * 5000)), "--dx", "1")
    line = cli_refused(proc, "SURFACE")
    assert "too long" in line and len(line) < 400


def test_other_os_errors_are_one_short_line():
    from leakpath.cli import _os_error_text

    text = _os_error_text(PermissionError(13, "Permission denied", "/d/" + "a" * 5000))
    assert text.startswith("Permission denied: '/d/aaa") and "5003 characters" in text
    assert len(text) < 200


# ---------------------------------------------------------------------------- the CLI
class TestCLI:
    @pytest.mark.parametrize(
        "args, needle",
        [
            ("surface spectral --n 30000 --hurst 0.8 --seed 1 --out {d}/x.npz", "shape:"),
            ("surface rmd --m 1000 --D 2.2 --seed 1 --out {d}/x.npz", "m:"),
            ("sweep rmd:m=1000,D=2.2,seed=1 --out {d}/o", "m:"),
            ("sweep rmd:m=3,D=2.2,seed=1 --levels 1000000000000 --out {d}/o", "levels:"),
            ("ensemble --D 2.2 --m 1000 --surfaces 1 --workers 1 --out {d}/e", "m:"),
            ("sweep {junk} --dx 1 --out {d}/o", "path:"),
            ("sweep {fifo} --dx 1 --out {d}/o", "path:"),
            ("sweep {flat} --dx 1 --out {d}/o", "flat"),
            ("sweep {good} --dx 1e-200 --out {d}/o", "dx:"),
            ("sweep {good} --dx 1e200 --out {d}/o", "dx:"),
            ("sweep {good} --dx 1 --E 1e-320 --out {d}/o", "E:"),
            ("sweep {good} --dx 1 --nu 0.7 --out {d}/o", "nu:"),
            ("sweep {complex} --dx 1 --out {d}/o", "path:"),
            ("sweep {holes} --dx 1 --out {d}/o", "undefined"),
            ("sweep {scattered} --dx 1 --out {d}/o", "point cloud"),
            ("sweep {junk_dat} --dx 1 --out {d}/o", "plain-text"),
            ("sweep {good} --dx 1 --fill mean --levels 0 --out {d}/o", "--levels"),
            ("flow rmd:m=3,D=2.2,seed=1 --pressure 1e300", "--pressure:"),
            ("sweep rmd:m=3,D=2.2,seed=1 --mean-pressures 1,1e300 --out {d}/o",
             "mean_pressures:"),
        ],
    )
    def test_refusals_are_one_line_exit_2(self, files, tmp_path, args, needle):
        subst = {k: str(v) for k, v in files.items()} | {"d": str(tmp_path)}
        proc = run_cli(*args.format(**subst).split(), timeout=60)
        cli_refused(proc, needle)
        assert not (tmp_path / "o" / "table.csv").exists()

    def test_loads_far_past_full_contact_are_solved(self, tmp_path):
        """p̄ = 1e30 E* (flow) and 1e6 E* (sweep): the whole patch in contact, no flow."""
        proc = run_cli("flow", "rmd:m=5,D=2.2,seed=1", "--pressure", "1e30", "--json")
        assert proc.returncode == 0, proc.stderr
        data = strict_json(proc.stdout)
        assert data["contact_fraction"] == 1.0 and data["flow_rate"] == 0.0
        assert data["mean_pressure"] == pytest.approx(1e30, rel=1e-12)
        proc = run_cli(
            "sweep", "rmd:m=5,D=2.2,seed=1", "--mean-pressures", "0.1,1e6", "--json",
            "--out", str(tmp_path / "o"),
        )
        assert proc.returncode == 0, proc.stderr

    def test_unknown_extension_without_the_extra(self, files, monkeypatch, capsys):
        monkeypatch.setitem(sys.modules, "SurfaceTopography", None)
        rc = cli.main(["sweep", str(files["junk"]), "--dx", "1", "--out", "unused-dir"])
        err = capsys.readouterr().err
        assert rc == 2 and len(err.strip().splitlines()) == 1
        assert "leakpath[io]" in err and "Traceback" not in err

    def test_leakpaths_own_memory_refusal_is_one_line(self, tmp_path, monkeypatch, capsys):
        import leakpath.contact

        monkeypatch.setattr(leakpath.contact, "default_memory_limit", lambda: 1 << 16)
        rc = cli.main(["sweep", "rmd:m=6,D=2.2,seed=0", "--out", str(tmp_path / "o")])
        err = capsys.readouterr().err
        assert rc == 2, err
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err

    def test_unexpected_errors_point_to_debug(self, tmp_path, monkeypatch, capsys):
        def boom(*args, **kwargs):
            raise OverflowError("math range error")

        from leakpath.cli import _surface

        monkeypatch.setattr(_surface, "rmd", boom)
        argv = ["surface", "rmd", "--m", "3", "--D", "2.2", "--seed", "0"]
        rc = cli.main([*argv, "--out", str(tmp_path / "a.npz")])
        err = capsys.readouterr().err
        assert rc == 1
        assert err.strip().count("\n") == 0 and "Traceback" not in err
        assert "OverflowError" in err and "--debug" in err
        rc = cli.main([*argv, "--out", str(tmp_path / "b.npz"), "--debug"])
        err = capsys.readouterr().err
        assert rc == 1 and "Traceback" in err and "OverflowError" in err
        rc = cli.main(["--debug", *argv, "--out", str(tmp_path / "c.npz")])
        assert rc == 1 and "Traceback" in capsys.readouterr().err

    def test_json_is_strict(self, capsys):
        cli._print_json({"a": float("nan"), "b": [1.0, float("inf")], "c": np.float64("nan")})
        assert strict_json(capsys.readouterr().out) == {"a": None, "b": [1.0, None], "c": None}

    def test_sweep_json_and_incompressible_nu(self, files, tmp_path):
        proc = run_cli(
            "sweep", str(files["holes"]), "--dx", "1", "--fill", "nearest", "--nu", "0.5",
            "--levels", "3", "--json", "--out", str(tmp_path / "o"),
        )
        assert proc.returncode == 0, proc.stderr
        data = strict_json(proc.stdout)
        assert len(data["summary"]) == 4

    def test_surface_json_with_unrepresentable_moments(self, tmp_path):
        # dx = 1e-100 with heights of order 1: m4 ~ 1e400 does not fit a double → null.
        proc = run_cli(
            "surface", "rmd", "--m", "3", "--D", "2.2", "--seed", "0", "--length", "1e-99",
            "--json", "--out", str(tmp_path / "s.npz"),
        )
        assert proc.returncode == 0, proc.stderr
        data = strict_json(proc.stdout)
        assert data["m2"] is None and data["m4"] is None and data["alpha"] is None
        assert data["m0"] == pytest.approx(np.var(load(tmp_path / "s.npz").heights), rel=1e-12)


# ---------------------------------------------------------------------------- property
def _random_case(rng: np.random.Generator) -> dict[str, Any]:
    ny, nx = (int(n) for n in rng.integers(3, 11, size=2))
    kind = rng.integers(5)
    if kind == 0:
        h = rng.standard_normal((ny, nx))
    elif kind == 1:  # one spike
        h = np.zeros((ny, nx))
        h[rng.integers(ny), rng.integers(nx)] = 1.0
    elif kind == 2:  # integers with ties at the top
        h = rng.integers(0, 3, size=(ny, nx)).astype(float)
    elif kind == 3:  # a plane
        h = np.add.outer(np.arange(ny) * rng.normal(), np.arange(nx) * rng.normal())
    else:  # heavy tails
        h = rng.standard_cauchy((ny, nx))
    # Half the cases in everyday units, half anywhere in the floating-point range.
    decades = (20, 20, 20) if rng.random() < 0.5 else (120, 140, 250)
    return {
        "heights": h * 10.0 ** rng.uniform(-decades[0], decades[0]),
        "dx": 10.0 ** rng.uniform(-decades[1], decades[1]),
        "E": 10.0 ** rng.uniform(-decades[2], decades[2]),
        "nu": float(rng.uniform(-0.99, 0.5)),
        "fraction": float(rng.choice([0.0, 1.0, rng.uniform()])),
        "boundary": str(rng.choice(["free", "periodic"])),
        "solver": str(rng.choice(["auto", "active-set", "lawson-hanson", "polonsky-keer"])),
    }


def test_random_finite_inputs_solve_or_are_refused():
    """300 random small problems, in everyday units and across the whole floating-point
    range: each is solved with a KKT certificate within the tolerance or refused."""
    rng = np.random.default_rng(20261123)
    tol = 1e-9
    solved = refused_count = 0
    for i in range(300):
        case = _random_case(rng)
        try:
            with deadline(30):
                prob = ContactProblem(
                    case["heights"], dx=case["dx"], E=case["E"], nu=case["nu"],
                    boundary=case["boundary"],
                )
                approach = case["fraction"] * prob.max_approach
                st = prob.solve(approach, solver=case["solver"], tol=tol)
                perc = st.percolation()
        except LeakpathError:
            refused_count += 1
            continue
        except Exception as exc:  # noqa: BLE001
            raise AssertionError(f"case {i} {case}: raw {type(exc).__name__}: {exc}") from exc
        solved += 1
        hs = float(np.ptp(case["heights"]))
        assert st.kkt <= tol, (i, case, st.kkt)
        assert np.all(st.pressure >= 0) and np.isfinite(st.pressure).all(), (i, case)
        assert np.isfinite(st.gap).all() and st.gap.min() >= -tol * max(hs, 1e-300), (i, case)
        assert math.isfinite(st.load) and math.isfinite(st.free_volume), (i, case)
        assert 0.0 <= st.contact_fraction <= 1.0
        total = perc.spanning_volume + perc.dead_end_volume + perc.trapped_volume
        assert total == pytest.approx(perc.free_volume, rel=1e-9, abs=1e-300), (i, case)
    assert solved >= 150, (solved, refused_count)
    assert refused_count >= 50, (solved, refused_count)


def test_nonconvergence_is_a_leakpath_error(small):
    with pytest.raises(NotConvergedError) as info:
        solve(small, 0.9 * small.height_range, solver="polonsky-keer", max_iter=1)
    assert isinstance(info.value, RuntimeError) and isinstance(info.value, LeakpathError)


def test_invalid_argument_error_is_a_value_error():
    assert issubclass(InvalidArgumentError, ValueError)
    assert leakpath.errors.ProblemTooLargeError.__mro__[1:3] == (LeakpathError, MemoryError)
