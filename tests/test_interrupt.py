"""Ctrl-C stops every long Rust computation within half a second, in the API and the CLI.

Each case runs a solve that takes well over ten seconds uninterrupted in a subprocess, sends a
real SIGINT a second into it and measures, from the signal, when the subprocess caught
KeyboardInterrupt (the child prints ``time.time()`` in its handler; both clocks are the same
wall clock) and when it exited.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

pytestmark = pytest.mark.skipif(os.name != "posix", reason="POSIX signals")

#: The promise: KeyboardInterrupt within this many seconds of the signal.
LATENCY = 0.5
#: Interpreter shutdown after the interrupt, on a loaded machine.
EXIT_SLACK = 5.0
#: When to interrupt, after the child says the solve starts.
DELAY = 1.0


@pytest.fixture(autouse=True)
def _python_sigint_handler():
    """Python's own Ctrl-C handler in this process while each test runs. A suite started with
    SIGINT ignored (a background job of a non-interactive shell) would otherwise pass the
    ignored disposition to its children and keep it itself, and these tests would measure
    nothing; a handler, unlike an ignored signal, is reset to the default at `exec`, so the
    children start as from a terminal."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


CHILD = """
import sys, time
import numpy as np
import leakpath
{setup}
print("ready", flush=True)
try:
    {call}
except KeyboardInterrupt:
    print("interrupted", repr(time.time()), flush=True)
    sys.exit(130)
print("finished", flush=True)
"""


def _interrupt(setup: str, call: str) -> tuple[float, float]:
    """Run the child, SIGINT it ``DELAY`` s after "ready"; (latency, exit time) from the signal."""
    code = CHILD.format(setup=textwrap.dedent(setup), call=call)
    proc = subprocess.Popen(
        [sys.executable, "-c", code],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = proc.stdout.readline()
        assert line.strip() == "ready", line + proc.stderr.read()
        time.sleep(DELAY)
        assert proc.poll() is None, "the solve finished before the signal: pick a larger one"
        sent = time.time()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
        exited = time.time() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, (proc.returncode, out, err)
    caught = [ln for ln in out.splitlines() if ln.startswith("interrupted")]
    assert caught, out + err
    latency = float(caught[0].split()[1]) - sent
    return latency, exited


CASES = {
    # Each takes ≥ 10 s uninterrupted on a 2-core machine.
    "lawson-hanson": (
        "s = leakpath.rmd(9, 2.2, seed=1)",
        "leakpath.solve(s, 0.5 * s.height_range, solver='lawson-hanson')",
    ),
    "active-set": (
        "s = leakpath.rmd(10, 2.2, seed=1)",
        "leakpath.solve(s, 0.5 * s.height_range, solver='active-set')",
    ),
    "polonsky-keer": (
        "s = leakpath.rmd(10, 2.2, seed=1)",
        "leakpath.solve(s, 0.5 * s.height_range, solver='polonsky-keer', tol=1e-300, "
        "max_iter=10**7)",
    ),
    "percolation_threshold": (
        "s = leakpath.rmd(9, 2.2, seed=1)",
        "leakpath.percolation_threshold(s, solver='active-set')",
    ),
    "percolation_threshold-auto": (
        "s = leakpath.rmd(9, 2.2, seed=1)",
        "leakpath.percolation_threshold(s)",
    ),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_sigint_stops_the_solve(case: str) -> None:
    latency, exited = _interrupt(*CASES[case])
    assert latency < LATENCY, f"{case}: KeyboardInterrupt {latency:.3f} s after SIGINT"
    assert exited < LATENCY + EXIT_SLACK


def test_sigint_stops_the_cli(tmp_path) -> None:
    """``leakpath sweep`` on a large surface exits with status 130 soon after Ctrl-C."""
    surface = tmp_path / "s.npz"
    subprocess.run(
        [sys.executable, "-m", "leakpath", "surface", "rmd", "--m", "9", "--D", "2.2",
         "--seed", "1", "--out", str(surface)],
        check=True,
        capture_output=True,
    )
    proc = subprocess.Popen(
        [sys.executable, "-m", "leakpath", "sweep", str(surface), "--out",
         str(tmp_path / "run"), "--solver", "lawson-hanson", "--no-warm-start", "--levels", "2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        time.sleep(4.0)  # start-up, surface load, then well into the first solves
        assert proc.poll() is None, proc.communicate()
        sent = time.time()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
        exited = time.time() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, (out, err)
    assert "interrupted" in err
    assert exited < LATENCY + EXIT_SLACK


def test_interrupted_problem_can_be_solved_again() -> None:
    """After Ctrl-C in the middle of a long solve the same ContactProblem still solves, from
    p = 0, and gives the numbers of a fresh problem."""
    import threading

    import numpy as np

    import leakpath

    s = leakpath.rmd(9, 2.2, seed=1)
    prob = leakpath.ContactProblem(s)
    timer = threading.Timer(0.5, os.kill, args=(os.getpid(), signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            prob.solve(0.5 * s.height_range, solver="active-set")
    finally:
        timer.cancel()
    a = 0.02 * s.height_range
    again = prob.solve(a, solver="active-set", warm_start=True)
    fresh = leakpath.ContactProblem(s).solve(a, solver="active-set")
    assert np.array_equal(again.pressure, fresh.pressure)
    assert np.array_equal(again.gap, fresh.gap)
