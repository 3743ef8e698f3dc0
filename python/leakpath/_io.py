"""File helpers shared by sweeps, checkpoints, ensembles and figures (a leaf module).

* atomic writes: a reader, or a run killed half-way, never sees a partial file;
* JSON as leakpath writes it (non-finite floats become ``null``, numpy scalars plain numbers);
* CSV text (one writer; the cell format is the caller's);
* array packing for checkpoint records (zlib + base64 text);
* SHA-256 of a height map and the machine description recorded in metadata files.
"""

from __future__ import annotations

import base64
import hashlib
import json
import math
import os
import platform
import secrets
import struct
import sys
import zlib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from . import _validate
from ._core import __version__

PathLike = str | os.PathLike[str]

__all__ = [
    "atomic_write_bytes",
    "atomic_write_text",
    "json_value",
    "dumps",
    "csv_quote",
    "csv_text",
    "pack",
    "unpack",
    "pack_mask",
    "unpack_mask",
    "heights_sha256",
    "machine_info",
]


# ---------------------------------------------------------------------------- atomic writes
def atomic_write_bytes(path: PathLike, data: bytes, *, overwrite: bool = True) -> Path:
    """Write ``data`` to ``path`` atomically.

    The bytes go to a fresh hidden temporary file in the same directory (mode
    ``0o666 & ~umask``, like any file the user writes), are flushed and fsync'ed, and the file
    is moved over ``path`` with :func:`os.replace`; a reader (or a run killed half-way) never
    sees a partial file. The directory must exist. ``overwrite=False`` links the file into
    place instead, which fails with ``FileExistsError`` if ``path`` exists.
    """
    target = _validate.path("path", path)
    directory = target.parent if str(target.parent) else Path(".")
    # The name is cut so that a target name near the file system's limit still has a
    # temporary: ".<name>.<pid>.<token>.tmp" adds about 30 characters.
    tmp = directory / f".{target.name[:120]}.{os.getpid()}.{secrets.token_hex(6)}.tmp"
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        if overwrite:
            os.replace(tmp, target)
        else:
            _link_new(tmp, target)
    finally:
        if tmp.exists():
            tmp.unlink()
    return target


def _link_new(tmp: Path, target: Path) -> None:
    exists = FileExistsError(f"{str(target)!r} already exists (pass overwrite=True)")
    try:
        os.link(tmp, target)  # atomic; fails if the target appeared meanwhile
    except FileExistsError:
        raise exists from None
    except OSError:  # filesystem without hard links
        if target.exists():
            raise exists from None
        os.replace(tmp, target)


def atomic_write_text(path: PathLike, text: str) -> Path:
    """:func:`atomic_write_bytes` for UTF-8 text."""
    return atomic_write_bytes(path, text.encode("utf-8"))


# ---------------------------------------------------------------------------- JSON
def json_value(value: Any) -> Any:
    """JSON-safe value: non-finite floats become ``None``; numpy scalars become Python ones."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Mapping):
        return {str(k): json_value(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_value(v) for v in value]
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    return value


def dumps(obj: Any) -> str:
    """leakpath's JSON text: :func:`json_value` of ``obj``, indent 1, a final newline."""
    return json.dumps(json_value(obj), indent=1, allow_nan=False, ensure_ascii=False) + "\n"


# ---------------------------------------------------------------------------- CSV
def csv_quote(text: str) -> str:
    """RFC 4180 quoting of one cell's text (only when it holds ``,``, ``"`` or a newline)."""
    if any(c in text for c in ',"\n\r'):
        return '"' + text.replace('"', '""') + '"'
    return text


def csv_text(
    rows: Sequence[Mapping[str, Any]],
    columns: Sequence[str],
    cell: Callable[[str, Any], str],
) -> str:
    """CSV text: a header of ``columns``, then one line per row, ``cell(column, value)`` each."""
    lines = [",".join(columns)]
    lines += [",".join(cell(c, row.get(c, "")) for c in columns) for row in rows]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------- arrays as text
def pack(array: np.ndarray) -> str:
    """Compress an array's raw bytes (zlib) and encode them as base64 text."""
    return base64.b64encode(zlib.compress(np.ascontiguousarray(array).tobytes(), 6)).decode()


def unpack(text: str, dtype: npt.DTypeLike, shape: tuple[int, ...]) -> np.ndarray:
    """Inverse of :func:`pack`: a fresh, writable array of ``dtype`` and ``shape``."""
    raw = zlib.decompress(base64.b64decode(text.encode()))
    return np.frombuffer(raw, dtype=dtype).reshape(shape).copy()


def pack_mask(mask: np.ndarray) -> str:
    """:func:`pack` of a boolean mask stored as bits (``np.packbits`` of the C-order ravel)."""
    return pack(np.packbits(mask.ravel()))


def unpack_mask(text: str, shape: tuple[int, int]) -> np.ndarray:
    """Inverse of :func:`pack_mask`."""
    n = shape[0] * shape[1]
    bits = unpack(text, np.uint8, (-1,))
    return np.unpackbits(bits, count=n).astype(bool).reshape(shape)


# ---------------------------------------------------------------------------- identity
def heights_sha256(heights: np.ndarray, dx: float) -> str:
    """SHA-256 (hex) of the heights as little-endian float64 bytes (C order), then ``dx``.

    ``sha256(heights.astype('<f8').tobytes() + struct.pack('<d', dx))``; the shape is not
    hashed (record it next to the digest).
    """
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(heights, dtype="<f8").tobytes())
    h.update(struct.pack("<d", float(dx)))
    return h.hexdigest()


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _memory_bytes() -> int | None:
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        return None


def machine_info() -> dict[str, Any]:
    """Platform, CPU, memory and package versions of this process, for metadata files."""
    import matplotlib

    return {
        "platform": platform.platform(),
        "machine": platform.machine(),
        "cpu": _cpu_model(),
        "cpu_count": os.cpu_count(),
        "memory_bytes": _memory_bytes(),
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "matplotlib": matplotlib.__version__,
        "leakpath": __version__,
    }
