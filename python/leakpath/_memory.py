"""How much memory this process may still allocate: the one default for every memory limit.

leakpath refuses a problem before allocating it when its estimated size exceeds the
``memory_limit`` (bytes) of the call. When none is given, the limit is::

    SAFETY × min(cgroup memory.max − memory.current,      (cgroup v2; v1: limit_in_bytes − usage)
                 RLIMIT_AS − current address space,        (``ulimit -v``)
                 RLIMIT_DATA − current data segment,       (``ulimit -d``)
                 MemAvailable)                             (/proc/meminfo)
    − THREAD_RESERVE × (CPUs + 1)

``THREAD_RESERVE`` (64 MiB a thread) covers what each computing thread allocates besides a
problem's own buffers: its stack, its allocator arena and small per-call buffers.

The packing scratch of the dense matrix products (``_core.dense_scratch_bytes()``: twice the
last-level cache the CPU reports, from 2 × 2 MiB to 2 × 260 MiB and more on some server CPUs,
allocated once per thread that runs the active-set or flow factorisations) is not part of
this limit: it depends on the CPU, not on the problem, and the Rust core reserves it
fallibly before a thread's first such product, so a machine without room for it refuses
with :class:`~leakpath.errors.ProblemTooLargeError` instead of aborting.

Each term that does not apply (no cgroup limit, unlimited rlimit, not Linux) is left out;
without any, 70 % of physical memory. The limit is computed at each call, so it follows what
the process and its neighbours already use (which cgroup limits exist is rescanned at most
once a second).
"""

from __future__ import annotations

import os
import resource
import time
from pathlib import Path

__all__ = ["SAFETY", "THREAD_RESERVE", "memory_limit", "memory_headroom"]

#: Fraction of the headroom a single problem may take: the estimates leave out small buffers,
#: and the rest of the program (and numpy's copies of the results) needs room too.
SAFETY = 0.8

#: Bytes each computing thread may allocate besides the problem's own buffers (stack,
#: allocator arena, small buffers); the dense products' CPU-sized scratch is checked apart.
THREAD_RESERVE = 64 << 20

_UNLIMITED = 1 << 62


def _read_int(path: Path) -> int | None:
    try:
        text = path.read_text().strip()
    except (OSError, ValueError):
        return None
    if not text or text == "max":
        return None
    try:
        value = int(text)
    except ValueError:
        return None
    # cgroup v1 reports "no limit" as a huge page-aligned number.
    return value if 0 < value < _UNLIMITED else None


def _own_cgroup_dirs() -> list[Path]:
    """Directories of this process's cgroups (v2 unified and v1 memory), innermost first."""
    dirs: list[Path] = []
    try:
        lines = Path("/proc/self/cgroup").read_text().splitlines()
    except OSError:
        return dirs
    for line in lines:
        parts = line.split(":", 2)
        if len(parts) != 3:
            continue
        _, controllers, rel = parts
        rel = rel.lstrip("/")
        if controllers == "":
            base = Path("/sys/fs/cgroup")
        elif "memory" in controllers.split(","):
            base = Path("/sys/fs/cgroup/memory")
        else:
            continue
        d = base / rel
        # A limit on any ancestor applies too; inside a container the path may not resolve,
        # then the mount's root is the container's own cgroup.
        while True:
            dirs.append(d)
            if d == base:
                break
            d = d.parent
        if base not in dirs:
            dirs.append(base)
    return dirs


#: Seconds between rescans of which cgroup memory limits apply (the usages are read at every
#: call): listing the cgroups and probing every limit file costs ~0.15 ms, several times per
#: level of a sweep, while a limit is set or lifted rarely.
_RESCAN_SECONDS = 1.0

_limits_cache: tuple[float, list[tuple[Path, Path]]] | None = None


def _limit_files() -> list[tuple[Path, Path]]:
    """(limit, usage) file pairs of this process's cgroups that set a limit, rescanned at
    most every :data:`_RESCAN_SECONDS`."""
    global _limits_cache
    now = time.monotonic()
    if _limits_cache is not None and now - _limits_cache[0] < _RESCAN_SECONDS:
        return _limits_cache[1]
    pairs = []
    for d in _own_cgroup_dirs():
        for limit_name, usage_name in (
            ("memory.max", "memory.current"),
            ("memory.limit_in_bytes", "memory.usage_in_bytes"),
        ):
            if _read_int(d / limit_name) is not None:
                pairs.append((d / limit_name, d / usage_name))
    _limits_cache = (now, pairs)
    return pairs


def _cgroup_headroom() -> int | None:
    best: int | None = None
    for limit_path, usage_path in _limit_files():
        limit = _read_int(limit_path)
        if limit is None:
            continue
        usage = _read_int(usage_path) or 0
        room = max(limit - usage, 0)
        best = room if best is None else min(best, room)
    return best


def _status_bytes(field: str) -> int | None:
    """A ``kB`` field of /proc/self/status (VmSize, VmData) in bytes."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _rlimit_headroom(which: int, usage_field: str) -> int | None:
    try:
        soft, _hard = resource.getrlimit(which)
    except (OSError, ValueError):
        return None
    if soft == resource.RLIM_INFINITY or soft < 0 or soft >= _UNLIMITED:
        return None
    used = _status_bytes(usage_field) or 0
    return max(soft - used, 0)


def _mem_available() -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _physical() -> int:
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        return 8 << 30


def memory_headroom() -> dict[str, int]:
    """The terms of :func:`memory_limit` that apply here, in bytes, by name."""
    terms = {
        "cgroup": _cgroup_headroom(),
        "RLIMIT_AS": _rlimit_headroom(resource.RLIMIT_AS, "VmSize"),
        "RLIMIT_DATA": _rlimit_headroom(resource.RLIMIT_DATA, "VmData"),
        "MemAvailable": _mem_available(),
    }
    return {k: v for k, v in terms.items() if v is not None}


def memory_limit() -> int:
    """Default ``memory_limit`` in bytes: ``SAFETY`` × the smallest headroom, less the
    per-thread reserve (see the module); at least 1 byte, so that any problem is refused."""
    terms = memory_headroom()
    room = int(0.7 * _physical()) if not terms else int(SAFETY * min(terms.values()))
    return max(room - _thread_reserve(), 1)


def _thread_reserve() -> int:
    return THREAD_RESERVE * ((os.cpu_count() or 1) + 1)
