"""Memory limits: one default from what the process may really allocate, refusals before
allocating, and failed allocations that raise ProblemTooLargeError instead of aborting.

The address-space cases run in subprocesses under ``RLIMIT_AS`` (``ulimit -v``): there a
failed allocation is real, and an abort would show as SIGABRT (return code −6).
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import leakpath
from leakpath import _memory
from leakpath.errors import InvalidArgumentError, ProblemTooLargeError

GIB = 1 << 30

posix_only = pytest.mark.skipif(
    not sys.platform.startswith("linux"), reason="RLIMIT_AS and /proc are Linux features"
)


def _run_capped(code: str, extra_bytes: int | None = None, cap: int | None = None):
    """Run ``code`` in a subprocess whose address space is capped at ``cap`` bytes, or at its
    own size after start-up plus ``extra_bytes``. Returns the CompletedProcess."""
    prelude = f"""
import resource, sys
import numpy as np
import leakpath
from leakpath.errors import ProblemTooLargeError
def _vm():
    for line in open("/proc/self/status"):
        if line.startswith("VmSize:"):
            return int(line.split()[1]) * 1024
cap = {cap!r} if {cap!r} is not None else _vm() + {extra_bytes!r}
resource.setrlimit(resource.RLIMIT_AS, (cap, resource.RLIM_INFINITY))
"""
    return subprocess.run(
        [sys.executable, "-c", prelude + textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=120,
    )


def _assert_refused(proc) -> None:
    assert proc.returncode == 0, (proc.returncode, proc.stdout, proc.stderr[-2000:])
    assert "refused" in proc.stdout, proc.stdout + proc.stderr[-2000:]


REFUSE = """
try:
    {call}
except ProblemTooLargeError as e:
    assert e.estimate > 0 and e.what, e
    print("refused:", e)
else:
    print("solved")
"""


# ---------------------------------------------------------------------------- the limit
def test_memory_limit_is_the_smallest_headroom_times_the_safety_fraction() -> None:
    terms = _memory.memory_headroom()
    limit = _memory.memory_limit()
    if terms:
        reserve = _memory.THREAD_RESERVE * ((os.cpu_count() or 1) + 1)
        assert limit == max(int(_memory.SAFETY * min(terms.values())) - reserve, 1)
    assert limit > 0
    assert leakpath.contact.default_memory_limit() <= limit * 1.5  # same definition, later


@posix_only
def test_memory_limit_follows_rlimit_as() -> None:
    proc = _run_capped(
        """
from leakpath import _memory
terms = _memory.memory_headroom()
print(terms["RLIMIT_AS"], _memory.memory_limit(), cap)
""",
        extra_bytes=GIB,
    )
    assert proc.returncode == 0, proc.stderr
    room, limit, _cap = map(int, proc.stdout.split())
    # What is left of the 1 GiB granted after start-up, times the safety fraction.
    assert 0 < room <= GIB
    assert limit <= _memory.SAFETY * room + 1


# ---------------------------------------------------------------------------- refusals
@posix_only
def test_large_problem_is_refused_under_an_address_space_cap() -> None:
    """8193² free-boundary problem under a 6 GiB cap: refused up front (it needs ~7 GiB)."""
    proc = _run_capped(
        REFUSE.format(
            call="leakpath.ContactProblem(leakpath.Surface(np.ones((8193, 8193)), 1.0))"
        ),
        cap=6 * GIB,
    )
    _assert_refused(proc)
    assert "more than the memory limit" in proc.stdout


@posix_only
def test_failed_allocation_raises_instead_of_aborting() -> None:
    """With the limit lifted, the allocation itself fails under the cap: still a refusal.

    The cap leaves room for the problem's copy of the heights (537 MB) but not for its
    kernel table as well, so the failure comes early and the test stays fast."""
    code = """
s = leakpath.Surface(np.ones((8193, 8193)), 1.0)
resource.setrlimit(resource.RLIMIT_AS, (_vm() + (800 << 20), resource.RLIM_INFINITY))
""" + REFUSE.format(call="leakpath.ContactProblem(s, memory_limit=1 << 50)")
    proc = _run_capped(code, cap=6 * GIB)
    _assert_refused(proc)
    assert "the system refused to allocate it" in proc.stdout


@posix_only
def test_active_set_factor_is_refused_under_an_address_space_cap() -> None:
    """The growing Cholesky factor meets the default limit under the cap: refused, no abort."""
    call = """
s = leakpath.rmd(8, 2.2, seed=1)
p = leakpath.ContactProblem(s)
p.solve(0.6 * s.height_range, solver="active-set")
"""
    code = REFUSE.replace("    {call}", textwrap.indent(call.strip(), "    "))
    proc = _run_capped(code, extra_bytes=GIB)
    _assert_refused(proc)


def test_refusal_message_names_the_estimate_and_the_limit() -> None:
    s = leakpath.rmd(5, 2.2, seed=1)
    with pytest.raises(ProblemTooLargeError) as info:
        leakpath.ContactProblem(s, memory_limit=1000)
    e = info.value
    assert e.limit == 1000 and e.estimate > e.limit
    msg = str(e)
    assert "more than the memory limit" in msg and "33 × 33" in msg


def _readable(n: int) -> str:
    """``n`` bytes as the refusal messages must print them: the largest binary unit reached,
    three significant digits."""
    for unit, size in (("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n} bytes"


@pytest.mark.parametrize("limit", [10, 1000, 5 << 10])
def test_small_sizes_are_printed_in_readable_units(limit) -> None:
    """Not "needs 0.00 GiB … more than 0.00 GiB": bytes, KiB, MiB as the size calls for."""
    s = leakpath.rmd(5, 2.2, seed=1)
    for call in (
        lambda: leakpath.ContactProblem(s, memory_limit=limit),
        lambda: leakpath.solve(s, 0.1).flow(memory_limit=limit),
    ):
        with pytest.raises(ProblemTooLargeError) as info:
            call()
        e = info.value
        msg = str(e)
        assert e.limit == limit and e.estimate > limit
        assert "0.00 GiB" not in msg, msg
        assert f"needs about {_readable(e.estimate)}, more than the memory limit of " \
            f"{_readable(limit)} " in msg, msg


def test_growing_factor_refusal_is_consistent() -> None:
    """The factor's refusal reports the bytes it checked, which exceed the limit."""
    s = leakpath.rmd(6, 2.2, seed=1)
    limit = 2 << 20
    p = leakpath.ContactProblem(s, memory_limit=limit)
    # The operator fits; the contact block's factor does not.
    with pytest.raises(ProblemTooLargeError) as info:
        p.solve(s.height_range, solver="lawson-hanson")
    e = info.value
    assert e.limit == limit and e.estimate > limit
    assert "Cholesky factor" in str(e)


@pytest.mark.parametrize("shape", [(1, 2**62), (2**40, 2**40), (100_000, 100_000)])
def test_kernel_table_sizes_from_user_input_are_checked(shape) -> None:
    with pytest.raises(ProblemTooLargeError) as info:
        leakpath.kernel_table(shape, 1.0)
    assert "kernel table" in str(info.value)


def test_kernel_table_still_works() -> None:
    k = leakpath.kernel_table((3, 4), 0.5)
    assert k.shape == (3, 4)
    assert k[0, 0] == pytest.approx(4 * 0.5 * np.log(1 + np.sqrt(2)) / np.pi, rel=1e-14)


# ---------------------------------------------------------------------------- threads
def test_thread_count_is_capped() -> None:
    gap = np.ones((16, 16))
    with pytest.raises(InvalidArgumentError) as info:
        leakpath.percolation(gap, dx=1.0, threads=2**40)
    assert info.value.argument == "threads"


@posix_only
def test_pools_do_not_pile_up_threads() -> None:
    """64 calls with distinct thread counts leave a bounded number of OS threads."""
    code = """
import os, time
import numpy as np
import leakpath
from leakpath.errors import InvalidArgumentError
gap = np.random.default_rng(0).random((64, 64)) - 0.3
ref = leakpath.percolation(gap, dx=1.0).spanning_volume
ok = 0
for k in range(1, 65):
    try:
        r = leakpath.percolation(gap, dx=1.0, threads=k)
    except InvalidArgumentError as e:
        assert e.argument == "threads"
        continue
    assert r.spanning_volume == ref
    ok += 1
cap = 4 * len(os.sched_getaffinity(0))
for _ in range(50):  # dropped pools end their threads asynchronously
    n = len(os.listdir("/proc/self/task"))
    if n <= 2 * cap + os.cpu_count() + 8:
        break
    time.sleep(0.1)
print(ok, n, cap)
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    ok, n, cap = map(int, proc.stdout.split())
    assert ok == min(64, cap)
    # Main thread, rayon's global pool, at most two kept pools of ≤ cap threads, a few others.
    assert n <= 2 * cap + (os.cpu_count() or 1) + 8, n




def test_cgroup_headroom_follows_usage_at_every_call_and_limits_after_a_rescan(
    tmp_path, monkeypatch
):
    inner, outer = tmp_path / "inner", tmp_path / "outer"
    for d in (inner, outer):
        d.mkdir()
    (inner / "memory.max").write_text("max\n")  # no limit here
    (outer / "memory.max").write_text(str(8 << 30))
    (outer / "memory.current").write_text(str(3 << 30))
    monkeypatch.setattr(_memory, "_own_cgroup_dirs", lambda: [inner, outer])
    monkeypatch.setattr(_memory, "_limits_cache", None)
    assert _memory._cgroup_headroom() == 5 << 30
    (outer / "memory.current").write_text(str(6 << 30))
    assert _memory._cgroup_headroom() == 2 << 30  # usage: read at every call
    (inner / "memory.max").write_text(str(1 << 30))
    (inner / "memory.current").write_text(str(1 << 29))
    monkeypatch.setattr(_memory, "_RESCAN_SECONDS", 0.0)
    assert _memory._cgroup_headroom() == 1 << 29  # a new limit: seen at the next rescan
