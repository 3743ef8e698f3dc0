"""Tests for :mod:`leakpath.ensemble`: executors, recovery, resume, statistics, CLI.

The ensembles are tiny (m = 4, 17² grids, 6 levels, 2 × 4 surfaces) so that process start-up,
not solving, dominates. Every run uses one rayon thread per task (the default), so the
per-surface tables — and hence the aggregates — are byte-identical across executors.
"""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

import leakpath
from leakpath import cli
from leakpath.ensemble import (
    QUANTITIES,
    OverwriteNote,
    aggregate,
    ensemble,
    param_key,
    regularized_incomplete_beta,
    student_t_ppf,
    t_critical,
    threshold_from_rows,
)

PARAMS = {"D": [2.2, 2.6], "m": [4]}
SURFACES = 4
LEVELS = 6
CLI_ARGS = ["--D", "2.2,2.6", "--m", "4", "--surfaces", str(SURFACES), "--levels", str(LEVELS)]
KEYS = ("D=2.2_m=4", "D=2.6_m=4")


def run_ensemble(out: Path, **kwargs):
    kwargs.setdefault("figures", False)
    return ensemble(
        params=PARAMS, surfaces=SURFACES, levels=LEVELS, out=out, progress=False, **kwargs
    )


def run_cli(*args: str, env: dict[str, str] | None = None, **kwargs):
    return subprocess.run(
        [sys.executable, "-m", "leakpath", "ensemble", *args],
        capture_output=True,
        text=True,
        timeout=180,
        env={**os.environ, **(env or {})},
        **kwargs,
    )


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def live_in_group(pgid: int) -> bool:
    """Whether a process of group ``pgid`` is still running.

    Exited workers are orphans, reaped by the init process whenever it gets to it (seconds
    later in some containers, never under a non-reaping init); until then ``killpg(pgid, 0)``
    still finds their zombies, so on Linux zombies are skipped.
    """
    proc = Path("/proc")
    if not (proc / "self" / "stat").exists():
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return False
        return True
    for entry in proc.iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:  # exited meanwhile
            continue
        # "pid (comm) state ppid pgrp ..."; comm may contain spaces, so split after ")".
        fields = stat[stat.rindex(")") + 2 :].split()
        if int(fields[2]) == pgid and fields[0] != "Z":
            return True
    return False


def task_files(out: Path) -> dict[str, int]:
    """Relative path → mtime_ns of every finished task table."""
    return {
        str(p.relative_to(out)): p.stat().st_mtime_ns for p in sorted(out.glob("tasks/*/*.csv"))
    }


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The reference ensemble: local processes, 2 workers, figures on."""
    out = tmp_path_factory.mktemp("ensemble") / "reference"
    result = run_ensemble(out, workers=2, figures=True)
    return result


# ---------------------------------------------------------------------------- Student t
class TestStudentT:
    def test_against_scipy(self):
        stats = pytest.importorskip("scipy.stats")
        for df in (1, 2, 3, 4, 5, 9, 19, 49, 99, 250, 1000, 5000, 2.5, 0.7):
            for p in (0.6, 0.8, 0.9, 0.95, 0.975, 0.99, 0.995, 0.9995, 0.025, 0.1, 1e-6):
                expected = pytest.approx(stats.t.ppf(p, df), rel=1e-12, abs=0)
                assert student_t_ppf(p, df) == expected, (
                    p,
                    df,
                )
        for df in (2e5, 1e7):  # Cornish–Fisher branch
            assert student_t_ppf(0.975, df) == pytest.approx(stats.t.ppf(0.975, df), rel=1e-12)

    def test_closed_forms_and_known_values(self):
        for p in (0.9, 0.975, 0.999):
            exact1 = math.tan(math.pi * (p - 0.5))
            assert student_t_ppf(p, 1) == pytest.approx(exact1, rel=1e-13, abs=0)
            exact2 = (2 * p - 1) / math.sqrt(2 * p * (1 - p))
            assert student_t_ppf(p, 2) == pytest.approx(exact2, rel=1e-13, abs=0)
        assert t_critical(50) == pytest.approx(2.009575237129239, rel=1e-14, abs=0)
        assert t_critical(2) == pytest.approx(12.706204736174698, rel=1e-13)
        assert math.isnan(t_critical(1))
        assert student_t_ppf(0.5, 7) == 0.0
        assert student_t_ppf(0.1, 7) == -student_t_ppf(0.9, 7)

    def test_incomplete_beta_against_scipy(self):
        special = pytest.importorskip("scipy.special")
        for a in (0.5, 1.0, 3.5, 40.0, 2e3):
            for b in (0.5, 2.0, 30.0):
                for x in (1e-4, 0.2, 0.5, 0.8, 0.9999):
                    assert regularized_incomplete_beta(a, b, x) == pytest.approx(
                        special.betainc(a, b, x), rel=1e-12, abs=1e-300
                    )

    def test_bad_arguments(self):
        with pytest.raises(ValueError, match="p"):
            student_t_ppf(1.0, 3)
        with pytest.raises(ValueError, match="df"):
            student_t_ppf(0.9, 0)


# ---------------------------------------------------------------------------- threshold
def _rows(spans0, spans1=None, a=None, both=None):
    """Synthetic sweep rows; ``V_pg`` (axis "both") > 0 where ``both`` (default: 0 and 1)."""
    n = len(spans0)
    spans1 = spans0 if spans1 is None else spans1
    a = a or [k / (2 * n) for k in range(n)]
    return [
        {
            "contact_fraction": a[k],
            "approach_star": k / (n - 1),
            "n_spanning_axis0": int(spans0[k]),
            "n_spanning_axis1": int(spans1[k]),
            "V_pg": 1.0
            if (both is None and spans0[k] and spans1[k]) or (both and both[k])
            else 0.0,
        }
        for k in range(n)
    ]


class TestThresholdFromRows:
    def test_first_level_without_spanning(self):
        rows = _rows([1, 1, 2, 0, 0], a=[0.0, 0.1, 0.2, 0.3, 0.4])
        t = threshold_from_rows(rows, 0)
        assert t["found"] and t["k_c"] == 3
        assert t["contact_fraction_c"] == 0.3
        assert t["contact_fraction_below"] == 0.2
        assert t["contact_fraction_mid"] == pytest.approx(0.25)
        assert t["approach_star_c"] == 0.75 and t["approach_star_below"] == 0.5
        assert not t["respans"]

    def test_axes_not_found_and_respans(self):
        rows = _rows([1, 1, 0, 0], [1, 1, 1, 0])
        assert threshold_from_rows(rows, 0)["k_c"] == 2
        assert threshold_from_rows(rows, 1)["k_c"] == 3
        assert threshold_from_rows(rows, "either")["k_c"] == 3
        assert threshold_from_rows(rows, "both")["k_c"] == 2
        # "both" needs one cluster spanning both axes: only V_pg tells, not the two counts.
        crossing = _rows([1, 1, 1, 0], [1, 1, 1, 0], both=[1, 0, 0, 0])
        assert threshold_from_rows(crossing, "both")["k_c"] == 1
        assert threshold_from_rows(crossing, "either")["k_c"] == 3
        never = threshold_from_rows(_rows([1, 1, 1]), 0)
        assert not never["found"] and never["k_c"] == -1
        assert math.isnan(never["contact_fraction_c"])
        assert threshold_from_rows(_rows([1, 0, 1]), 0)["respans"]
        at_zero = threshold_from_rows(_rows([0, 0]), 0)
        assert at_zero["k_c"] == 0 and math.isnan(at_zero["contact_fraction_below"])

    def test_brackets_the_bisected_threshold(self, reference):
        """The exact threshold (bisection, leakpath.threshold) lies in [below, c]."""
        from leakpath.threshold import percolation_threshold

        checked = 0
        for row in reference.thresholds:
            if not row["found"] or row["k_c"] == 0:
                continue
            surface = leakpath.rmd(4, row["D"], seed=row["seed"])
            exact = percolation_threshold(surface, axis=0, atol=1e-9 * surface.height_range)
            d_star = exact.approach / surface.height_range
            assert row["approach_star_below"] - 1e-9 < d_star <= row["approach_star_c"] + 1e-9
            checked += 1
        assert checked >= 1


# ---------------------------------------------------------------------------- aggregation
class TestAggregate:
    def test_files_and_layout(self, reference):
        out = reference.directory
        for name in ("manifest.json", "aggregate.csv", "thresholds.csv", "ensemble.json"):
            assert (out / name).is_file()
        assert len(task_files(out)) == 2 * SURFACES
        assert len(list(out.glob("tasks/*/*.json"))) == 2 * SURFACES
        assert sorted(p.name for p in (out / "tasks").iterdir()) == list(KEYS)
        assert not list(out.rglob(".*.tmp"))
        for stem in ("fig2_vpg_volume_gap", "fig3_vpg_moments", "thresholds_hist"):
            for fmt in ("png", "pdf"):
                assert (out / "figures" / f"{stem}.{fmt}").stat().st_size > 1000
        meta = json.loads((out / "tasks" / KEYS[0] / "seed-1.json").read_text())
        assert meta["params"] == {"D": 2.2, "m": 4} and meta["seed"] == 1
        assert meta["worker"]["rayon_num_threads"] == "1"
        assert reference.run["executor"] == "processes" and reference.run["tasks_run"] == 8

    def test_against_direct_numpy(self, reference):
        """mean, std (ddof 1) and the t band, recomputed from the per-surface CSVs."""
        stats = pytest.importorskip("scipy.stats")
        out = reference.directory
        agg = read_csv(out / "aggregate.csv")
        assert [r["param_key"] for r in agg] == [KEYS[0]] * 7 + [KEYS[1]] * 7
        for key in KEYS:
            tables = [read_csv(out / "tasks" / key / f"seed-{s}.csv") for s in range(SURFACES)]
            rows = [r for r in agg if r["param_key"] == key]
            assert [int(r["k"]) for r in rows] == list(range(LEVELS + 1))
            n = len(tables)
            tq = stats.t.ppf(0.975, n - 1)
            for q in QUANTITIES:
                x = np.array([[float(r[q]) for r in t] for t in tables])  # (surfaces, levels)
                mean = np.mean(x, axis=0)
                std = np.std(x, axis=0, ddof=1)
                half = tq * std / np.sqrt(n)
                got = {
                    s: np.array([float(r[f"{q}_{s}"]) for r in rows])
                    for s in ("mean", "std", "ci_low", "ci_high")
                }
                np.testing.assert_allclose(got["mean"], mean, rtol=1e-14, atol=1e-300)
                np.testing.assert_allclose(got["std"], std, rtol=1e-12, atol=1e-15)
                np.testing.assert_allclose(got["ci_low"], mean - half, rtol=1e-12, atol=1e-14)
                np.testing.assert_allclose(got["ci_high"], mean + half, rtol=1e-12, atol=1e-14)
            # V_pg* starts at 1 and the contact fraction grows on average.
            assert float(rows[0]["V_pg_star_mean"]) == 1.0
            assert float(rows[-1]["contact_fraction_mean"]) > float(
                rows[1]["contact_fraction_mean"]
            )

    def test_thresholds_against_direct_computation(self, reference):
        out = reference.directory
        thr = read_csv(out / "thresholds.csv")
        summary = json.loads((out / "ensemble.json").read_text())["thresholds"]
        for key in KEYS:
            found = []
            for seed in range(SURFACES):
                table = read_csv(out / "tasks" / key / f"seed-{seed}.csv")
                k_c = next((k for k, r in enumerate(table) if int(r["n_spanning_axis0"]) == 0), -1)
                row = next(r for r in thr if r["param_key"] == key and int(r["seed"]) == seed)
                assert int(row["k_c"]) == k_c
                if k_c >= 0:
                    assert row["found"] == "true"
                    assert float(row["contact_fraction_c"]) == float(table[k_c]["contact_fraction"])
                    found.append(float(table[k_c]["contact_fraction"]))
                else:
                    assert row["found"] == "false" and row["contact_fraction_c"] == "nan"
            s = summary[key]
            assert s["n_found"] == len(found) and s["surfaces"] == SURFACES
            if found:
                assert s["contact_fraction"]["mean"] == pytest.approx(
                    np.mean(found), rel=1e-14, abs=0
                )
                assert s["contact_fraction"]["quantiles"]["0.5"] == pytest.approx(
                    np.median(found), rel=1e-14, abs=0
                )
            if len(found) > 1:
                assert s["contact_fraction"]["std"] == pytest.approx(
                    np.std(found, ddof=1), rel=1e-12, abs=0
                )

    def test_reaggregation_is_byte_identical(self, reference, tmp_path):
        """aggregate(DIR) again (other process state, other order on disk) → same bytes."""
        before = reference.aggregate_path.read_bytes()
        thr = reference.thresholds_path.read_bytes()
        again = aggregate(reference.directory, figures=False)
        assert again.aggregate_path.read_bytes() == before
        assert again.thresholds_path.read_bytes() == thr

    def test_missing_task_is_reported(self, reference, tmp_path):
        import shutil

        copy = tmp_path / "copy"
        shutil.copytree(reference.directory, copy)
        (copy / "tasks" / KEYS[1] / "seed-2.csv").unlink()
        with pytest.raises(ValueError, match="seed-2"):
            aggregate(copy, figures=False)


# ---------------------------------------------------------------------------- executors
class TestExecutors:
    def test_killed_worker_process_is_replaced(self, reference, tmp_path, monkeypatch):
        """A worker dies after its sweep (os._exit): the pool is rebuilt, lost tasks rerun."""
        marker = tmp_path / "kill-once"
        marker.touch()
        result = run_ensemble(tmp_path / "run", workers=2, _kill_once=str(marker))
        assert not marker.exists()  # a worker consumed it and died
        assert result.run["pool_restarts"] >= 1
        assert result.run["tasks_run"] == 2 * SURFACES
        assert result.aggregate_path.read_bytes() == reference.aggregate_path.read_bytes()
        assert result.thresholds_path.read_bytes() == reference.thresholds_path.read_bytes()

    def test_dask_local_cluster_matches_processes(self, reference, tmp_path, monkeypatch):
        distributed = pytest.importorskip("distributed")
        with (
            distributed.LocalCluster(
                n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
            ) as cluster,
            distributed.Client(cluster) as client,
        ):
            result = run_ensemble(tmp_path / "dask", executor=client)
            assert result.run["executor"] == "dask"
            assert result.aggregate_path.read_bytes() == reference.aggregate_path.read_bytes()

            # A worker process dies mid-run (same hook); the scheduler address as executor.
            marker = tmp_path / "kill-once"
            marker.touch()
            killed = run_ensemble(
                tmp_path / "dask-killed", executor=cluster.scheduler_address, _kill_once=str(marker)
            )
            assert not marker.exists()
            assert killed.run["tasks_run"] == 2 * SURFACES
            assert killed.aggregate_path.read_bytes() == reference.aggregate_path.read_bytes()
            assert killed.thresholds_path.read_bytes() == reference.thresholds_path.read_bytes()

    def test_local_processes_without_dask_installed(self, tmp_path):
        """The package imports and the default executor runs with dask unimportable."""
        code = (
            "import sys; sys.modules['dask'] = None; sys.modules['distributed'] = None\n"
            "from leakpath.ensemble import ensemble\n"
            f"r = ensemble(params={{'D': 2.3, 'm': 3}}, surfaces=2, levels=2, "
            f"out={str(tmp_path / 'nodask')!r}, workers=2, progress=False, figures=False)\n"
            "print(r.run['executor'], r.run['tasks_run'])\n"
            "try:\n"
            "    ensemble(params={'D': 2.3, 'm': 3}, surfaces=2, levels=2, executor='tcp://x:1',"
            f" out={str(tmp_path / 'nodask2')!r}, progress=False)\n"
            "except ImportError as e:\n"
            "    print('ImportError', 'leakpath[dask]' in str(e))\n"
            f"import os; print(os.path.exists({str(tmp_path / 'nodask2')!r}))\n"
        )
        proc = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, timeout=120
        )
        assert proc.returncode == 0, proc.stderr
        assert proc.stdout.split() == ["processes", "2", "ImportError", "True", "False"]


# ---------------------------------------------------------------------------- resume
class TestResume:
    def test_interrupted_driver_then_resume(self, reference, tmp_path):
        """The driver is SIGKILLed after 3 written tasks; --resume runs only the other 5."""
        out = tmp_path / "run"
        log = tmp_path / "driver.log"
        with open(log, "wb") as fh:
            # The command line, with the driver told to kill itself after 3 written tasks.
            argv = ["ensemble", *CLI_ARGS, "--out", str(out), "--workers", "2", "--no-figures"]
            code = (
                "import functools, sys\n"
                "import leakpath.ensemble as package\n"
                "package.ensemble = functools.partial(package.ensemble, _stop_after=3)\n"
                "from leakpath.cli import main\n"
                f"sys.exit(main({argv!r}))\n"
            )
            proc = subprocess.Popen(
                [sys.executable, "-c", code],
                stdout=fh,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
            try:
                proc.wait(timeout=180)
            finally:  # its pool processes exit by themselves within ~0.5 s; make sure
                deadline = time.monotonic() + 2.5
                while live_in_group(proc.pid) and time.monotonic() < deadline:
                    time.sleep(0.05)
                orphans = live_in_group(proc.pid)
                if orphans:
                    os.killpg(proc.pid, signal.SIGKILL)
        assert not orphans, "worker processes outlived the killed driver by 2.5 s"
        assert proc.returncode == -signal.SIGKILL
        before = task_files(out)
        assert len(before) == 3
        assert not (out / "aggregate.csv").exists()

        again = run_cli(*CLI_ARGS, "--out", str(out), "--workers", "2", "--no-figures")
        assert again.returncode == 2 and "--resume" in again.stderr  # refuses without it

        resumed = run_cli(
            *CLI_ARGS, "--out", str(out), "--workers", "2", "--no-figures", "--resume", "--json"
        )
        assert resumed.returncode == 0, resumed.stderr
        summary = json.loads(resumed.stdout)
        assert summary["run"]["tasks_run"] == 5 and summary["run"]["tasks_resumed"] == 3
        ran = {f"tasks/{k}/seed-{s}.csv" for k, s in summary["run"]["ran"]}
        assert ran.isdisjoint(before)
        after = task_files(out)
        assert len(after) == 8
        assert {p: after[p] for p in before} == before  # finished tasks were not redone
        assert (out / "aggregate.csv").read_bytes() == reference.aggregate_path.read_bytes()

    def test_resume_extends_the_seeds(self, reference, tmp_path):
        out = tmp_path / "grow"
        first = ensemble(
            params=PARAMS,
            surfaces=2,
            levels=LEVELS,
            out=out,
            workers=2,
            progress=False,
            figures=False,
        )
        assert first.run["tasks_run"] == 4
        before = task_files(out)
        grown = run_ensemble(out, workers=2, resume=True)
        assert grown.run["tasks_resumed"] == 4 and grown.run["tasks_run"] == 4
        assert sorted(s for _, s in grown.run["ran"]) == [2, 2, 3, 3]
        assert {p: task_files(out)[p] for p in before} == before
        assert grown.aggregate_path.read_bytes() == reference.aggregate_path.read_bytes()

        nothing = run_ensemble(out, workers=2, resume=True)
        assert nothing.run["tasks_run"] == 0 and nothing.run["tasks_resumed"] == 8

    def test_resume_refuses_a_different_ensemble(self, reference, tmp_path):
        import shutil

        copy = tmp_path / "copy"
        shutil.copytree(reference.directory, copy)
        with pytest.raises(ValueError, match="levels"):
            ensemble(
                params=PARAMS,
                surfaces=SURFACES,
                levels=LEVELS + 1,
                out=copy,
                resume=True,
                progress=False,
            )
        with pytest.raises(FileExistsError, match="not empty"):
            run_ensemble(copy)
        fresh = run_ensemble(copy, overwrite=True, workers=2)  # overwrite redoes everything
        assert fresh.run["tasks_run"] == 8
        assert fresh.aggregate_path.read_bytes() == reference.aggregate_path.read_bytes()


# ---------------------------------------------------------------------------- overwrite
#: An earlier, different ensemble (other D, m and levels): none of its task files is one the
#: runs under test write, so each must be deleted by --overwrite, not merely rewritten.
OLD_PARAMS = {"D": [2.4], "m": [3]}
OLD_KEY = "D=2.4_m=3"
OLD_CLI = ["--D", "2.4", "--m", "3", "--surfaces", "2", "--levels", "3"]
#: Files of the user's kept in the ensemble directory, some named like leakpath's.
USER_FILES = {
    "figures/my_notes.pdf": "my own figure",
    "figures/fig2_vpg_volume_gap_draft.png": "named like a figure of the run",
    "tasks/README.txt": "what these tasks are",
    f"tasks/{OLD_KEY}/seed-7.csv": "named like a task table, without its checksummed JSON",
    "notes.txt": "keep me",
    ".notes.tmp": "hidden, but not named like a temporary of leakpath's atomic writes",
}
RECORD = ".leakpath-outputs.json"


def files_in(directory: Path) -> set[str]:
    """Every file below ``directory``, relative, in POSIX form."""
    return {p.relative_to(directory).as_posix() for p in directory.rglob("*") if p.is_file()}


def add_user_files(out: Path) -> None:
    for rel, text in USER_FILES.items():
        (out / rel).parent.mkdir(parents=True, exist_ok=True)
        (out / rel).write_text(text)


def assert_user_files_intact(out: Path) -> None:
    for rel, text in USER_FILES.items():
        assert (out / rel).read_text() == text, rel


def run_old_ensemble(out: Path, figures: bool = False) -> set[str]:
    """The earlier ensemble in ``out``; returns its files."""
    ensemble(params=OLD_PARAMS, surfaces=2, levels=3, out=out, executor="serial",
             progress=False, figures=figures)
    return files_in(out)


class TestOverwrite:
    @staticmethod
    def fresh_files(reference) -> set[str]:
        """What a run without figures writes into an empty directory: the reference run's
        files (a fresh run into an empty directory) apart from its figures."""
        return {f for f in files_in(reference.directory) if not f.startswith("figures/")}

    def test_api_keeps_users_files_and_removes_the_earlier_runs(self, reference, tmp_path):
        out = tmp_path / "run"
        first = run_old_ensemble(out, figures=True)
        assert {"figures/thresholds_hist.png", f"tasks/{OLD_KEY}/seed-1.json"} <= first
        add_user_files(out)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result = run_ensemble(out, overwrite=True, workers=2)
        assert not [w for w in caught if issubclass(w.category, OverwriteNote)]
        assert_user_files_intact(out)
        # The earlier run's files are gone (its figures, its task files), nothing else is
        # left but the user's; the results equal those of a fresh, uninterrupted run.
        assert files_in(out) == self.fresh_files(reference) | set(USER_FILES)
        assert result.run["tasks_run"] == 2 * SURFACES
        assert result.aggregate_path.read_bytes() == reference.aggregate_path.read_bytes()
        assert result.thresholds_path.read_bytes() == reference.thresholds_path.read_bytes()
        # The record lists every file this run wrote and nothing of the user's.
        record = json.loads((out / RECORD).read_text())
        assert set(record["files"]) == files_in(out) - set(USER_FILES) - {RECORD}

    def test_cli_keeps_users_files_and_removes_the_earlier_runs(
        self, reference, tmp_path, capsys
    ):
        out = tmp_path / "run"
        old = ["ensemble", *OLD_CLI, "--out", str(out), "--workers", "1", "--no-figures"]
        assert cli.main(old) == 0
        assert f"tasks/{OLD_KEY}/seed-0.csv" in files_in(out)
        add_user_files(out)
        capsys.readouterr()
        new = ["ensemble", *CLI_ARGS, "--out", str(out), "--workers", "2", "--no-figures"]
        assert cli.main([*new, "--overwrite"]) == 0
        err = capsys.readouterr().err
        assert "note" not in err and "warning" not in err
        assert_user_files_intact(out)
        assert files_in(out) == self.fresh_files(reference) | set(USER_FILES)
        assert (out / "aggregate.csv").read_bytes() == reference.aggregate_path.read_bytes()
        # A second --overwrite replaces this run in turn, still keeping the user's files.
        assert cli.main([*new, "--overwrite"]) == 0
        assert_user_files_intact(out)
        assert files_in(out) == self.fresh_files(reference) | set(USER_FILES)

    def test_a_recorded_file_the_user_edited_is_kept_with_a_note(
        self, reference, tmp_path, capsys
    ):
        out = tmp_path / "run"
        run_old_ensemble(out)
        edited = f"tasks/{OLD_KEY}/seed-1.csv"
        with open(out / edited, "a", encoding="utf-8") as fh:  # no longer the run's table
            fh.write("my extra row\n")
        # Only touched, the same bytes: still recognised as leakpath's by its checksum.
        touched = out / "tasks" / OLD_KEY / "seed-0.json"
        os.utime(touched, ns=(touched.stat().st_atime_ns, touched.stat().st_mtime_ns + 10**9))
        argv = ["ensemble", *CLI_ARGS, "--out", str(out), "--workers", "2", "--no-figures"]
        assert cli.main([*argv, "--overwrite"]) == 0
        notes = [line for line in capsys.readouterr().err.splitlines() if "note" in line]
        assert len(notes) == 1
        assert notes[0].startswith("leakpath: note: --overwrite: kept 1 file(s)")
        assert edited in notes[0] and "changed" in notes[0]
        assert (out / edited).read_text(encoding="utf-8").endswith("my extra row\n")
        assert files_in(out) == self.fresh_files(reference) | {edited}
        assert (out / "aggregate.csv").read_bytes() == reference.aggregate_path.read_bytes()

    def test_without_a_record_only_checksummed_task_files_are_removed(
        self, reference, tmp_path
    ):
        # A directory from a leakpath that kept no record: only task files, recognised by
        # their checksums, are known to be leakpath's.
        out = tmp_path / "run"
        first = run_old_ensemble(out, figures=True)
        (out / RECORD).unlink()
        add_user_files(out)
        with pytest.warns(OverwriteNote, match="no record") as notes:
            result = run_ensemble(out, overwrite=True, workers=2)
        assert "task files" in str(notes[0].message)
        assert_user_files_intact(out)
        old_tasks = {f for f in first if f.startswith("tasks/")}
        assert len(old_tasks) == 4
        stays = first - old_tasks - {RECORD}  # its figures, rewritten tables, manifest
        assert files_in(out) == self.fresh_files(reference) | stays | set(USER_FILES)
        assert result.aggregate_path.read_bytes() == reference.aggregate_path.read_bytes()


# ---------------------------------------------------------------------------- API / CLI
def _tilted_rmd(*, seed, m, slope):
    """A picklable custom generator: an RMD surface plus a tilt along axis 1."""
    s = leakpath.rmd(m, 2.3, seed=seed)
    tilt = slope * np.arange(s.shape[1]) * s.dx
    return leakpath.Surface(s.heights + tilt[None, :], s.dx, {"generator": "tilted"})


class TestArguments:
    def test_param_keys_and_product(self, tmp_path):
        assert param_key({"m": 7, "D": 2.1}) == "D=2.1_m=7"
        assert param_key({"shape": [64, 32], "hurst": 0.8}) == "hurst=0.8_shape=64x32"
        with pytest.raises(ValueError, match="generator 'rmd' needs D"):
            ensemble(params={"m": [4]}, surfaces=1, out=tmp_path / "a", progress=False)
        with pytest.raises(ValueError, match="does not take"):
            ensemble(
                params={"m": 4, "D": 2.2, "H": 1}, surfaces=1, out=tmp_path / "a", progress=False
            )
        with pytest.raises(ValueError, match=r"\bD\b.*fractal dimension"):
            ensemble(
                params={"m": 4, "D": [2.2, 3.2]}, surfaces=1, out=tmp_path / "a", progress=False
            )
        with pytest.raises(ValueError, match="seeds"):
            ensemble(params={"m": 4, "D": 2.2}, seeds=[1, 1], out=tmp_path / "a", progress=False)
        with pytest.raises(ValueError, match="executor"):
            ensemble(
                params={"m": 4, "D": 2.2}, executor="threads", out=tmp_path / "a", progress=False
            )
        with pytest.raises(ValueError, match="workers"):
            ensemble(
                params={"m": 4, "D": 2.2},
                executor="serial",
                workers=2,
                out=tmp_path / "a",
                progress=False,
            )
        with pytest.raises(ValueError, match="picklable"):
            ensemble(
                generator=lambda seed, **kw: None,
                params={"x": 1},
                out=tmp_path / "a",
                progress=False,
            )
        assert not (tmp_path / "a").exists()  # nothing created for bad arguments

    def test_custom_generator(self, tmp_path):
        r = ensemble(
            generator=_tilted_rmd,
            params={"m": 3, "slope": [0.0, 0.5]},
            surfaces=2,
            levels=2,
            out=tmp_path / "g",
            workers=2,
            progress=False,
            figures=False,
        )
        assert r.keys == ["m=3_slope=0.0", "m=3_slope=0.5"]
        assert r.identity["generator"].endswith("_tilted_rmd")

    def test_serial_executor_and_explicit_seeds(self, tmp_path):
        r = ensemble(
            params=[{"m": 3, "D": 2.4}],
            seeds=[5, 2],
            levels=2,
            out=tmp_path / "s",
            executor="serial",
            progress=False,
            figures=False,
        )
        assert r.run["executor"] == "serial"
        assert r.param_sets[0].seeds == (2, 5)
        assert [row["seed"] for row in r.thresholds] == [2, 5]
        assert r.curve("D=2.4_m=3", "V_pg_star")["mean"][0] == 1.0

    @pytest.mark.parametrize(
        "argv, fragment",
        [
            (["--D", "2.2,abc", "--m", "4"], "comma-separated list of numbers"),
            (["--D", "3.4", "--m", "4"], "fractal dimension"),
            (["--D", "2.2", "--m", "4", "--surfaces", "0"], "positive integer"),
            (["--D", "2.2", "--m", "4", "--workers", "0"], "positive integer"),
            (
                ["--D", "2.2", "--m", "4", "--workers", "2", "--scheduler", "tcp://x:1"],
                "--scheduler",
            ),
            (["--D", "2.2", "--m", "4", "--resume", "--overwrite"], "exclude each other"),
            (["--D", "2.2", "--m", "4", "--axis", "2"], "either"),
        ],
    )
    def test_cli_usage_errors(self, argv, fragment, tmp_path, capsys):
        code = cli.main(["ensemble", *argv, "--out", str(tmp_path / "o")])
        err = capsys.readouterr().err
        assert code == 2
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("leakpath: error: ")
        assert fragment in lines[0]

    def test_cli_refuses_non_empty_out(self, tmp_path, capsys):
        (tmp_path / "o").mkdir()
        (tmp_path / "o" / "notes.txt").write_text("mine")
        code = cli.main(["ensemble", "--D", "2.2", "--m", "3", "--out", str(tmp_path / "o")])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and "--overwrite" in err[0]
        assert (tmp_path / "o" / "notes.txt").read_text() == "mine"


# ---------------------------------------------------------------------------- integrity
class DiesOnSeed:
    """A picklable rmd generator whose worker process dies on one seed while ``marker``
    exists (``os._exit(3)``, or SIGKILL with ``signal=True``); the same surfaces otherwise.
    One ``repr`` for every instance: runs with and without the marker are one ensemble."""

    def __init__(self, seed: int, marker: Path, signal: bool = False):
        self.seed, self.marker, self.signal = seed, str(marker), signal

    def __call__(self, *, seed, m, D):
        if seed == self.seed and os.path.exists(self.marker):
            if self.signal:
                os.kill(os.getpid(), signal.SIGKILL)
            os._exit(3)
        return leakpath.rmd(m, D, seed=seed)

    def __repr__(self) -> str:
        return "DiesOnSeed"


def copy_of(reference, tmp_path: Path) -> Path:
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(reference.directory, copy)
    return copy


class TestIntegrity:
    def test_edited_table_is_refused_then_recomputed(self, reference, tmp_path):
        """A task table edited after the run: aggregate refuses it (naming it); resume
        recomputes only that task and restores the reference table and aggregate."""
        copy = copy_of(reference, tmp_path)
        path = copy / "tasks" / KEYS[0] / "seed-1.csv"
        text = path.read_text()
        rows = read_csv(path)
        old = rows[2]["contact_fraction"]
        assert old in text
        path.write_text(text.replace(old, "0.5", 1))  # a plausible, wrong value
        with pytest.raises(ValueError, match="checksum") as info:
            aggregate(copy, figures=False)
        assert str(path) in str(info.value) and "resume" in str(info.value)

        with pytest.warns(RuntimeWarning, match=f"{KEYS[0]}/seed-1 .*checksum"):
            again = run_ensemble(copy, workers=2, resume=True)
        assert again.run["ran"] == [[KEYS[0], 1]]
        assert [r[:2] for r in again.run["recomputed"]] == [[KEYS[0], 1]]
        assert path.read_bytes() == (reference.directory / path.relative_to(copy)).read_bytes()
        assert again.aggregate_path.read_bytes() == reference.aggregate_path.read_bytes()

    def test_edited_metadata_and_swapped_tasks_are_recomputed(self, reference, tmp_path):
        copy = copy_of(reference, tmp_path)
        meta = copy / "tasks" / KEYS[1] / "seed-0.json"
        doc = json.loads(meta.read_text())
        doc["seed"] = 0 if doc["seed"] else 1  # anything but what was written
        meta.write_text(json.dumps(doc))
        for suffix in (".csv", ".json"):  # another task's files under this task's name
            src = copy / "tasks" / KEYS[0] / f"seed-2{suffix}"
            (copy / "tasks" / KEYS[0] / f"seed-3{suffix}").write_bytes(src.read_bytes())
        with pytest.warns(RuntimeWarning) as caught:
            again = run_ensemble(copy, workers=2, resume=True)
        message = str(caught[0].message)
        assert f"{KEYS[1]}/seed-0 (its metadata file seed-0.json does not match" in message
        assert f"{KEYS[0]}/seed-3 (it belongs to another task" in message
        assert sorted(map(tuple, again.run["ran"])) == [(KEYS[0], 3), (KEYS[1], 0)]
        assert again.aggregate_path.read_bytes() == reference.aggregate_path.read_bytes()

    def test_table_of_another_run_is_not_used(self, reference, tmp_path):
        """Task files copied in from an ensemble with other sweep options."""
        other = ensemble(params={"D": 2.2, "m": 4}, seeds=[1], levels=LEVELS, warm_start=False,
                         out=tmp_path / "other", executor="serial", progress=False, figures=False)
        copy = copy_of(reference, tmp_path)
        for suffix in (".csv", ".json"):
            name = f"seed-1{suffix}"
            (copy / "tasks" / KEYS[0] / name).write_bytes(
                (other.directory / "tasks" / KEYS[0] / name).read_bytes()
            )
        with pytest.raises(ValueError, match="another run"):
            aggregate(copy, figures=False)

    def test_garbage_table_named_by_aggregate_and_recomputed_by_cli(self, reference, tmp_path):
        copy = copy_of(reference, tmp_path)
        path = copy / "tasks" / KEYS[1] / "seed-3.csv"
        path.write_bytes(b"\xff\xfe\x00\x81garbage\x9c\n" * 40)
        with pytest.raises(ValueError) as info:
            aggregate(copy, figures=False)
        assert not isinstance(info.value, UnicodeDecodeError)
        assert str(path) in str(info.value) and "resume" in str(info.value)

        proc = run_cli(*CLI_ARGS, "--out", str(copy), "--workers", "2", "--no-figures",
                       "--resume", "--json")
        assert proc.returncode == 0, proc.stderr
        warning = [ln for ln in proc.stderr.splitlines() if ln.startswith("leakpath: warning:")]
        assert len(warning) == 1 and f"{KEYS[1]}/seed-3" in warning[0]
        assert "UnicodeDecodeError" not in proc.stderr
        assert json.loads(proc.stdout)["run"]["ran"] == [[KEYS[1], 3]]
        assert (copy / "aggregate.csv").read_bytes() == reference.aggregate_path.read_bytes()

    def test_garbage_manifest_is_named(self, reference, tmp_path):
        copy = copy_of(reference, tmp_path)
        manifest = copy / "manifest.json"
        manifest.write_bytes(b"\x89PNG\r\n\x1a\n\xff\xff")
        with pytest.raises(ValueError, match="manifest.json") as info:
            aggregate(copy, figures=False)
        assert not isinstance(info.value, UnicodeDecodeError)
        proc = run_cli(*CLI_ARGS, "--out", str(copy), "--no-figures", "--resume")
        assert proc.returncode == 2
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("leakpath: error: --out:")
        assert str(manifest) in lines[0] and "--overwrite" in lines[0]

    @pytest.mark.parametrize("key", ["../../..", "/etc", "..", "tasks/../.."])
    def test_manifest_keys_outside_the_directory_are_refused(self, reference, tmp_path, key):
        copy = copy_of(reference, tmp_path)
        manifest = copy / "manifest.json"
        doc = json.loads(manifest.read_text())
        doc["param_sets"][0]["key"] = key
        manifest.write_text(json.dumps(doc))
        with pytest.raises(ValueError) as info:
            aggregate(copy, figures=False)
        assert repr(key) in str(info.value) and str(manifest) in str(info.value)
        assert (copy / "aggregate.csv").read_bytes() == reference.aggregate_path.read_bytes()

    def test_result_table_takes_only_its_own_tasks(self, reference):
        with pytest.raises(KeyError):
            reference.table("../" + KEYS[0], 0)
        with pytest.raises(KeyError):
            reference.table(KEYS[0], SURFACES)
        rows = reference.table(KEYS[0], 0)
        assert len(rows) == LEVELS + 1


class TestDyingWorkers:
    def test_a_seed_that_kills_its_worker_fails_alone(self, reference, tmp_path):
        """Seed 2 ends its worker process (os._exit) in both parameter sets: every other task
        is saved as the reference computed it, the failure names seed 2 and the reason, and a
        resume (the generator healthy again) runs only the two seed-2 tasks."""
        marker = tmp_path / "sick"
        marker.touch()
        out = tmp_path / "run"
        gen = DiesOnSeed(2, marker)
        kwargs = dict(generator=gen, params=PARAMS, surfaces=SURFACES, levels=LEVELS, out=out,
                      workers=2, retries=1, progress=False, figures=False)
        with pytest.raises(RuntimeError) as info:
            ensemble(**kwargs)
        message = str(info.value)
        assert message.startswith(f"2 of {2 * SURFACES} task(s) failed")
        for key in KEYS:
            assert f"{key}/seed-2: its worker process exited with status 3" in message
        saved = task_files(out)
        expected = {f"tasks/{k}/seed-{s}.csv" for k in KEYS for s in range(SURFACES) if s != 2}
        assert set(saved) == expected
        for rel in expected:  # the same surfaces as the rmd generator's: the same tables
            assert (out / rel).read_bytes() == (reference.directory / rel).read_bytes()

        marker.unlink()
        resumed = ensemble(**kwargs, resume=True)
        assert sorted(map(tuple, resumed.run["ran"])) == [(k, 2) for k in KEYS]
        assert resumed.run["tasks_resumed"] == 2 * SURFACES - 2
        assert {p: task_files(out)[p] for p in saved} == saved  # untouched
        assert resumed.aggregate_path.read_bytes() == reference.aggregate_path.read_bytes()
        assert resumed.thresholds_path.read_bytes() == reference.thresholds_path.read_bytes()

    def test_a_seed_killed_by_a_signal_is_reported(self, tmp_path):
        marker = tmp_path / "sick"
        marker.touch()
        out = tmp_path / "run"
        with pytest.raises(RuntimeError, match=r"D=2.3_m=3/seed-1: .*killed by SIGKILL"):
            ensemble(generator=DiesOnSeed(1, marker, signal=True), params={"D": 2.3, "m": 3},
                     surfaces=3, levels=2, out=out, workers=2, retries=0, progress=False,
                     figures=False)
        assert set(task_files(out)) == {f"tasks/D=2.3_m=3/seed-{s}.csv" for s in (0, 2)}
