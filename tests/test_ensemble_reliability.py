"""Ensembles under the ways users actually start and stop them.

* the default local-process executor from ``python -`` (a piped script), ``python -c`` and a
  script file without a ``__main__`` guard;
* a driver killed while its caller reads its output through a pipe leaves no process behind;
* bad elastic constants are refused before anything is started or written (API and CLI);
* ``--resume`` removes the temporaries a killed run left in ``figures/``;
* results have short reprs.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from leakpath.ensemble import ensemble
from leakpath.plotting import remove_stale_temporaries

SCRIPT = """
from leakpath.ensemble import ensemble
r = ensemble(params={{"m": 3, "D": 2.2}}, surfaces=2, levels=2, out={out!r}, workers=2,
             progress=False, figures=False)
print("rows", len(r.aggregate))
"""


@pytest.mark.parametrize("how", ["stdin", "-c", "file"])
def test_default_executor_from_any_entry_point(tmp_path: Path, how: str) -> None:
    code = SCRIPT.format(out=str(tmp_path / "run"))
    if how == "stdin":
        proc = subprocess.run([sys.executable, "-"], input=code, capture_output=True,
                              text=True, timeout=120, cwd=tmp_path)
    elif how == "-c":
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              timeout=120, cwd=tmp_path)
    else:
        script = tmp_path / "script.py"  # deliberately no `if __name__ == "__main__"` guard
        script.write_text(code)
        proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                              timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "rows 3" in proc.stdout  # levels + 1 rows for the one parameter set


def _session_members(sid: int) -> list[tuple[int, str]]:
    """(pid, state) of the processes in session ``sid``, zombies excluded."""
    out = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2 :].split()
        state, session = fields[0], int(fields[3])
        if session == sid and state != "Z":
            out.append((int(entry), state))
    return out


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc")
def test_killed_driver_under_a_piping_parent_leaves_nothing_alive(tmp_path: Path) -> None:
    """The driver SIGKILLs itself after its first task while this test reads its stdout
    through a pipe and does not reap it (a zombie). The pipe must reach end-of-file and
    every worker, the fork server and the resource tracker must be gone within 3 s."""
    code = """
from leakpath.ensemble import ensemble
ensemble(params={{"m": 5, "D": 2.2}}, surfaces=8, levels=6, out={!r}, workers=2,
         progress=False, figures=False, _stop_after=1)
""".format(str(tmp_path / "run"))
    env = dict(os.environ)
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=env, start_new_session=True)
    sid = proc.pid
    eof = threading.Event()

    def drain() -> None:
        while os.read(proc.stdout.fileno(), 4096):
            pass
        eof.set()

    reader = threading.Thread(target=drain, daemon=True)
    reader.start()
    try:
        # Wait for the driver to die (without reaping it: it stays a zombie).
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            state = Path(f"/proc/{proc.pid}/stat").read_text()
            if state[state.rindex(")") + 2] == "Z":
                break
            time.sleep(0.05)
        else:
            pytest.fail("the driver did not kill itself")
        died = time.monotonic()
        alive = _session_members(sid)
        while alive and time.monotonic() - died < 3.0:
            time.sleep(0.1)
            alive = _session_members(sid)
        assert not alive, f"still alive 3 s after the driver died: {alive}"
        assert eof.wait(1.0), "the driver's stdout pipe is still open"
    finally:
        for pid, _ in _session_members(sid):
            try:
                os.kill(pid, 9)
            except OSError:
                pass
        proc.kill()
        proc.wait()
        proc.stdout.close()
        proc.stderr.close()


def test_bad_elastic_constants_are_refused_before_anything_starts(tmp_path: Path) -> None:
    cases = ((-1.0, 0.3, "E"), (1.0, 0.7, "nu"), (float("nan"), 0.0, "E"), ("7", 0.3, "E"),
             (1.0, None, "nu"))
    for E, nu, name in cases:
        out = tmp_path / f"run-{name}-{E}"
        with pytest.raises(ValueError) as info:
            ensemble(params={"m": 3, "D": 2.2}, surfaces=2, levels=2, out=out, E=E, nu=nu,
                     progress=False, figures=False)
        assert str(info.value).startswith(f"{name}:")
        assert not out.exists()


def test_cli_ensemble_takes_elastic_constants(tmp_path: Path) -> None:
    bad = tmp_path / "bad"
    proc = subprocess.run(
        [sys.executable, "-m", "leakpath", "ensemble", "--D", "2.2", "--m", "3", "--surfaces",
         "2", "--levels", "2", "--out", str(bad), "--nu", "0.7", "--no-figures"],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 2, proc.stderr
    assert "nu:" in proc.stderr
    assert not bad.exists()
    good = tmp_path / "good"
    proc = subprocess.run(
        [sys.executable, "-m", "leakpath", "ensemble", "--D", "2.2", "--m", "3", "--surfaces",
         "2", "--levels", "2", "--out", str(good), "--E", "210", "--nu", "0.3",
         "--no-figures", "--workers", "1", "--json"],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    import json

    manifest = json.loads((good / "manifest.json").read_text())
    assert manifest["identity"]["E"] == 210.0 and manifest["identity"]["nu"] == 0.3


def test_resume_removes_stale_figure_temporaries(tmp_path: Path) -> None:
    out = tmp_path / "run"
    kwargs = dict(params={"m": 3, "D": 2.2}, surfaces=2, levels=2, out=out,
                  executor="serial", progress=False)
    first = ensemble(**kwargs)
    # What a run killed while writing its figures leaves behind.
    stale = out / "figures" / ".fig2_vpg_volume_gap.png.999999999.abcdef.tmp"
    stale.write_bytes(b"partial")
    top = out / ".aggregate.csv.999999999.abcdef.tmp"
    top.write_bytes(b"partial")
    again = ensemble(**kwargs, resume=True)
    assert not stale.exists() and not top.exists()
    assert again.aggregate_path.read_bytes() == first.aggregate_path.read_bytes()
    r = repr(again)
    assert len(r) < 300 and "D=2.2_m=3" in r and "surfaces=2" in r


def test_figure_writer_keeps_temporaries_of_live_writers(tmp_path: Path) -> None:
    dead = tmp_path / ".fig.png.999999999.abc.tmp"
    live = tmp_path / f".fig.png.{os.getppid()}.abc.tmp"
    other = tmp_path / "notes.tmp"
    for p in (dead, live, other):
        p.write_bytes(b"x")
    removed = remove_stale_temporaries(tmp_path)
    assert removed == [dead]
    assert live.exists() and other.exists()
