"""Memory limits: one default from what the process may really allocate, refusals before
allocating, and failed allocations that raise ProblemTooLargeError instead of aborting.

The address-space cases run in subprocesses under ``RLIMIT_AS`` (``ulimit -v``): there a
failed allocation is real, and an abort would show as SIGABRT (return code −6).
"""

from __future__ import annotations

import os
import shutil
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
    own size after start-up plus ``extra_bytes`` (neither: no cap). Returns the
    CompletedProcess."""
    capped = cap is not None or extra_bytes is not None
    prelude = f"""
import resource, sys
import numpy as np
import leakpath
from leakpath.errors import ProblemTooLargeError
def _vm():
    for line in open("/proc/self/status"):
        if line.startswith("VmSize:"):
            return int(line.split()[1]) * 1024
if {capped!r}:
    cap = {cap if cap is not None else 0!r} or _vm() + {extra_bytes or 0!r}
    # Under an outer hard cap (CI runs these tests under ``ulimit -v``) the soft cap can
    # only be lowered.
    hard = resource.getrlimit(resource.RLIMIT_AS)[1]
    if hard != resource.RLIM_INFINITY:
        cap = min(cap, hard)
    resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
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
def test_memory_limit_is_the_smallest_headroom_times_the_safety_fraction(monkeypatch) -> None:
    # The live terms move between two reads (MemAvailable follows the whole machine): the
    # formula is checked on fixed terms, the live limit only for being positive.
    assert _memory.memory_limit() > 0
    assert leakpath.contact.default_memory_limit() > 0
    terms = {"MemAvailable": 20 * GIB, "RLIMIT_AS": 3 * GIB}
    monkeypatch.setattr(_memory, "memory_headroom", lambda: dict(terms))
    reserve = _memory.THREAD_RESERVE * ((os.cpu_count() or 1) + 1)
    assert _memory.memory_limit() == int(_memory.SAFETY * 3 * GIB) - reserve
    terms["cgroup"] = 0
    assert _memory.memory_limit() == 1  # no room: every problem is refused


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
resource.setrlimit(resource.RLIMIT_AS, (min(_vm() + (800 << 20), cap), hard))
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
    assert k[0, 0] == pytest.approx(4 * 0.5 * np.log(1 + np.sqrt(2)) / np.pi, rel=1e-14, abs=0)


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
import os, resource, time
# Thread counts, not memory, are under test: lift a soft address-space cap inherited from
# the caller (each new thread reserves a stack and a malloc arena).
resource.setrlimit(resource.RLIMIT_AS, (resource.getrlimit(resource.RLIMIT_AS)[1],) * 2)
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


# ---------------------------------------------------------------------------- dense scratch
# faer's dense products allocate a packing buffer per thread sized from the CPU's reported
# last-level cache (2 × 32 MiB on a 2-core EPYC guest, 2 × 260 MiB on some Xeon guests). A
# larger reported cache is simulated by mounting a made-up cpu tree over
# /sys/devices/system/cpu in a private mount namespace (root only; skipped elsewhere).

VM_DELTA = """
import threading
from leakpath import _core
def solve_and_measure(problem, approach, out):
    # The thread and its pool exist before the measured solve (a first solve that needs no
    # dense product), so the growth is the dense products' own.
    problem.solve(approach, solver="polonsky-keer", threads=1)
    before = _vm()
    problem.solve(approach, solver="active-set", threads=1)
    out.append(_vm() - before)
s = leakpath.rmd(5, 2.2, seed=1)
out = []
t = threading.Thread(target=solve_and_measure,
                     args=(leakpath.ContactProblem(s), 0.6 * s.height_range, out))
t.start(); t.join()
print(_core.dense_scratch_bytes(), out[0])
"""


def _fake_cpu_tree(root, l3_size: str) -> None:
    """Per-CPU 32 KiB L1d/L1i and 1 MiB L2, one L3 of ``l3_size`` shared by every CPU."""
    n = os.cpu_count() or 1
    for cpu in range(n):
        for index, (kind, level, size, shared) in enumerate(
            [
                ("Data", 1, "32K", str(cpu)),
                ("Instruction", 1, "32K", str(cpu)),
                ("Unified", 2, "1024K", str(cpu)),
                ("Unified", 3, l3_size, f"0-{n - 1}"),
            ]
        ):
            d = root / f"cpu{cpu}" / "cache" / f"index{index}"
            d.mkdir(parents=True)
            for name, text in [("type", kind), ("level", level), ("size", size),
                               ("shared_cpu_list", shared), ("coherency_line_size", 64),
                               ("ways_of_associativity", 16)]:
                (d / name).write_text(f"{text}\n")


def _namespaces_usable() -> bool:
    if not sys.platform.startswith("linux") or os.geteuid() != 0 or not shutil.which("unshare"):
        return False
    probe = subprocess.run(["unshare", "-m", "true"], capture_output=True)
    return probe.returncode == 0


large_cache = pytest.mark.skipif(
    not _namespaces_usable(), reason="needs root and mount namespaces (unshare -m)"
)


def _run_with_cache(tmp_path, l3_size: str, code: str, extra_bytes: int | None):
    """``_run_capped(code, extra_bytes)`` on a CPU that reports an L3 cache of ``l3_size``
    (no cap when ``extra_bytes`` is None)."""
    tree = tmp_path / "cpu"
    _fake_cpu_tree(tree, l3_size)
    script = tmp_path / "run.py"
    cap_line = (
        "hard = resource.getrlimit(resource.RLIMIT_AS)[1]\n"
        f"cap = _vm() + {extra_bytes}\n"
        "resource.setrlimit(resource.RLIMIT_AS, "
        "(cap if hard == resource.RLIM_INFINITY else min(cap, hard), hard))"
        if extra_bytes is not None
        else ""
    )
    script.write_text(
        textwrap.dedent(
            """
            import resource, sys
            import numpy as np
            import leakpath
            from leakpath.errors import ProblemTooLargeError
            def _vm():
                for line in open("/proc/self/status"):
                    if line.startswith("VmSize:"):
                        return int(line.split()[1]) * 1024
            """
        )
        + cap_line
        + "\n"
        + textwrap.dedent(code)
    )
    return subprocess.run(
        ["unshare", "-m", "sh", "-c",
         f'mount --bind "{tree}" /sys/devices/system/cpu && exec "{sys.executable}" "{script}"'],
        capture_output=True,
        text=True,
        timeout=300,
    )


@posix_only
def test_dense_scratch_is_what_the_first_dense_products_allocate() -> None:
    proc = _run_capped(VM_DELTA, cap=None)
    assert proc.returncode == 0, proc.stderr[-2000:]
    scratch, grown = map(int, proc.stdout.split())
    assert scratch >= 2 * (2 << 20)  # the product library's floor: a 2 MiB L3
    assert scratch - (1 << 20) <= grown <= scratch + (32 << 20), (scratch, grown)


@large_cache
def test_dense_scratch_follows_a_large_reported_cache(tmp_path) -> None:
    proc = _run_with_cache(tmp_path, "266240K", VM_DELTA, extra_bytes=None)
    assert proc.returncode == 0, proc.stderr[-2000:]
    scratch, grown = map(int, proc.stdout.split())
    # 260 MiB shared by all CPUs, then scaled by the library to at least one CPU's share.
    assert scratch >= 2 * (260 << 20) // (os.cpu_count() or 1)
    assert scratch - (1 << 20) <= grown <= scratch + (32 << 20), (scratch, grown)


@large_cache
@pytest.mark.parametrize(
    "call",
    [
        # The paper's grid, exact solver: its products run on the solver pool's threads.
        "s = leakpath.rmd(6, 2.2, seed=1)\n"
        "leakpath.ContactProblem(s).solve(0.6 * s.height_range, solver='active-set')",
        # The flow's sparse factor (solver="auto" would fall back to multigrid): its
        # supernodes' products run on the calling thread.
        "g = np.random.default_rng(0).random((96, 96)) + 0.1\n"
        "leakpath.flow(g, dx=1.0, solver='cholesky')",
    ],
    ids=["active-set", "flow"],
)
def test_a_large_reported_cache_is_refused_not_aborted(tmp_path, call) -> None:
    """2 × 2 GiB of scratch per thread under 1 GiB of address space: a refusal naming the
    scratch, where the product library alone would abort the process."""
    code = REFUSE.replace("    {call}", textwrap.indent(call, "    "))
    proc = _run_with_cache(tmp_path, "2G", code, extra_bytes=GIB)
    _assert_refused(proc)
    assert "packing scratch" in proc.stdout, proc.stdout


@large_cache
def test_memory_refusals_hold_on_a_cpu_reporting_a_large_cache(tmp_path) -> None:
    """The refusal tests above, rerun where the CPU reports a 260 MiB L3 cache."""
    tree = tmp_path / "cpu"
    _fake_cpu_tree(tree, "266240K")
    here = os.path.abspath(__file__)
    proc = subprocess.run(
        ["unshare", "-m", "sh", "-c",
         f'mount --bind "{tree}" /sys/devices/system/cpu && exec "{sys.executable}" -m pytest '
         f'-q -p no:cacheprovider "{here}" -k "refused or aborting or rlimit"'],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
    assert " passed" in proc.stdout
