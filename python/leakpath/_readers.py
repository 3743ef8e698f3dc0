"""Height-map file readers behind :func:`leakpath.load` (``docs/surfaces.md``, "Files").

Each reader returns the raw heights (any dtype, maybe with NaN), the spacing the file stores
(or ``None``) and metadata; :func:`leakpath.surfaces.load` validates them and builds the
:class:`~leakpath.Surface`. Formats: ``.npz`` (leakpath's own), ``.npy``, plain-text matrices
and, with the optional ``leakpath[io]`` extra, every format SurfaceTopography reads.
"""

from __future__ import annotations

import json
import math
import os
import stat
import warnings
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from . import _validate
from .errors import InvalidArgumentError, LeakpathError, ProblemTooLargeError

FloatArray = npt.NDArray[np.float64]

#: File suffixes read as plain-text matrices (comma- or whitespace-separated).
TEXT_SUFFIXES: frozenset[str] = frozenset({".txt", ".csv", ".dat", ".asc"})

# ---------------------------------------------------------------------------- loading
#: Ways :func:`load` can fill undefined (NaN or masked) points when asked to.
FILL_METHODS: tuple[str, ...] = ("nearest", "mean")

_NPY_MAGIC = b"\x93NUMPY"
_ZIP_MAGICS = (b"PK\x03\x04", b"PK\x05\x06")
#: Bytes read from the start of a file to recognise its format.
_SNIFF_BYTES = 4096


@dataclass
class _Raw:
    """What a reader found: heights (any dtype, maybe with NaN), the stored spacing, metadata."""

    heights: Any
    dx_file: float | None
    metadata: dict[str, Any] = field(default_factory=dict)


def _one_line(text: object) -> str:
    return " ".join(str(text).split())


def _resolve_dx(path: Path, dx_file: float | None, dx_arg: float | None) -> float:
    """Combine the file's spacing with the caller's (validated) ``dx``; both must agree."""
    if dx_file is None:
        if dx_arg is None:
            raise InvalidArgumentError(
                f"dx: required to read {str(path)!r}, the file does not store the grid "
                "spacing; pass dx=..."
            )
        return dx_arg
    try:
        dx_file = _validate.spacing("dx", dx_file)
    except InvalidArgumentError as exc:
        raise InvalidArgumentError(
            f"path: {str(path)!r} stores an invalid grid spacing ({exc})", argument="path"
        ) from None
    if dx_arg is not None and not math.isclose(dx_arg, dx_file, rel_tol=1e-12):
        raise InvalidArgumentError(
            f"dx: {dx_arg!r} differs from the spacing {dx_file!r} stored in {str(path)!r}; "
            "omit dx, or build Surface(heights, new_dx) to rescale"
        )
    return dx_file


def _check_path(path: Any) -> tuple[Path, os.stat_result]:
    """A path to an existing regular file (never a FIFO or device, which could block)."""
    p = _validate.path("path", path)  # NUL, too long, symlink loops: refused by name
    try:
        info = os.stat(p)
    except FileNotFoundError:
        raise FileNotFoundError(f"surface file {str(p)!r} not found") from None
    except OSError as exc:  # changed since the check above
        raise InvalidArgumentError(
            f"path: cannot read {_validate.show_path(p)} ({exc.strerror})", argument="path"
        ) from None
    if stat.S_ISDIR(info.st_mode):
        raise InvalidArgumentError(f"path: {str(p)!r} is a directory, not a surface file")
    if not stat.S_ISREG(info.st_mode):
        raise InvalidArgumentError(
            f"path: {str(p)!r} is not a regular file (a FIFO, socket or device); "
            "save the surface to a file first"
        )
    return p, info


def _check_file_size(path: Path, size: int, factor: int) -> None:
    """Refuse files whose contents could not fit in memory (``factor`` bytes per byte)."""
    limit = _validate.memory_budget()
    if size * factor > limit:
        raise _validate.too_large(
            "path",
            f"reading {str(path)!r} ({_validate.format_bytes(size)})",
            size * factor,
            limit,
            "crop or downsample the file first",
        )


#: Bytes per height point beyond the array as stored: the float64 copy of the heights and
#: one working copy (undefined points, fill) that :func:`leakpath.load` may make.
_WORK_BYTES_PER_POINT = 16


def _npy_header(fh: Any) -> tuple[int, int] | None:
    """``(points, bytes)`` an ``.npy`` stream declares in its header (shape × dtype), read
    without reading the data; ``None`` when the header cannot be parsed (the reader that
    follows reports the file)."""
    fmt = np.lib.format
    try:
        version = fmt.read_magic(fh)
        if version == (1, 0):
            shape, _, dtype = fmt.read_array_header_1_0(fh)
        elif version == (2, 0):
            shape, _, dtype = fmt.read_array_header_2_0(fh)
        else:  # format 3.0 (UTF-8 field names) has no public reader
            shape, _, dtype = fmt._read_array_header(fh, version)
    except Exception:  # a damaged header is reported when the array itself is read
        return None
    points = math.prod(int(n) for n in shape)
    return points, points * max(int(dtype.itemsize), 1)


def _check_read_estimate(path: Path, estimate: int) -> None:
    """Refuse reading ``path`` when ``estimate`` bytes exceed the memory budget."""
    limit = _validate.memory_budget()
    if estimate > limit:
        size = _validate.format_bytes(path.stat().st_size)
        raise _validate.too_large(
            "path",
            f"reading {str(path)!r} ({size} on disk; its arrays as declared in their headers, "
            "then as float64)",
            estimate,
            limit,
            "crop or downsample the file first",
        )


def _npz_estimate(path: Path) -> int:
    """Bytes reading an ``.npz`` needs, from its members' headers alone: each member's
    uncompressed size (zip directory) or the shape × dtype its ``.npy`` header declares,
    whichever is larger, plus the float64 working copies of the largest one (the heights)."""
    total, largest = 0, 0
    with zipfile.ZipFile(path) as archive:
        for info in archive.infolist():
            size = int(info.file_size)
            if info.filename.endswith(".npy"):
                with archive.open(info) as fh:
                    declared = _npy_header(fh)
                if declared is not None:
                    points, nbytes = declared
                    size = max(size, nbytes)
                    largest = max(largest, points)
            total += size
    return total + _WORK_BYTES_PER_POINT * largest


def _npy_estimate(path: Path, size: int) -> int:
    """Bytes reading an ``.npy`` needs: its declared array and the float64 working copies."""
    with open(path, "rb") as fh:
        declared = _npy_header(fh)
    if declared is None:
        return 2 * size
    points, nbytes = declared
    return max(size, nbytes) + _WORK_BYTES_PER_POINT * points


def memory_error(path: Path, size: int) -> ProblemTooLargeError:
    """The error for a read of a ``size``-byte file that ran out of memory although its
    estimate fitted the budget."""
    limit = _validate.memory_budget()
    return ProblemTooLargeError(
        f"path: reading {str(path)!r} ({_validate.format_bytes(size)} on disk) ran out of "
        f"memory (limit {_validate.format_bytes(limit)}); crop or downsample the file first, "
        "or free memory",
        estimate=size,
        limit=limit,
        what=f"reading {str(path)!r}",
    )


def _sniff(path: Path) -> bytes:
    with open(path, "rb") as fh:
        return fh.read(_SNIFF_BYTES)


def _read_npz(path: Path) -> _Raw:
    _check_read_estimate(path, _npz_estimate(path))  # from the headers, before inflating
    with np.load(path, allow_pickle=False) as data:
        keys = list(data.files)
        if "heights" in keys:
            heights = data["heights"]
        elif len(keys) == 1:
            heights = data[keys[0]]
        else:
            raise ValueError(f"no 'heights' array (arrays: {keys})")
        dx_file = None
        if "dx" in keys:
            dx_arr = data["dx"]
            if dx_arr.shape != () or dx_arr.dtype.kind not in "fiu":
                raise ValueError(f"'dx' must be one real number, got {dx_arr.dtype} {dx_arr.shape}")
            dx_file = dx_arr[()]
        metadata: dict[str, Any] = {}
        if "metadata" in keys:
            loaded = json.loads(str(data["metadata"][()]))
            if isinstance(loaded, dict):
                metadata = loaded
    return _Raw(heights, dx_file, metadata)


def _read_npy(path: Path) -> _Raw:
    heights = np.load(path, allow_pickle=False)
    if not isinstance(heights, np.ndarray):  # pragma: no cover - np.load of .npy
        raise ValueError("not a numpy array file")
    return _Raw(heights, None)


def _read_text(path: Path) -> _Raw:
    """A plain-text matrix, or an x,y,z point cloud on a complete uniform grid."""
    if b"\x00" in _sniff(path):
        raise ValueError("it holds binary data (NUL bytes), not text")
    with open(path, encoding="utf-8", errors="replace") as fh:
        sample = ""
        for line in fh:
            stripped = line.strip()
            if stripped and not stripped.startswith("#"):
                sample = stripped
                break
    delimiter = "," if "," in sample else (";" if ";" in sample else None)
    with warnings.catch_warnings():  # an empty file is reported below, not warned about
        warnings.simplefilter("ignore", UserWarning)
        arr = np.loadtxt(path, delimiter=delimiter, comments="#", ndmin=2, dtype=np.float64)
    if arr.size == 0:
        raise ValueError("no numbers in the file")
    cloud = _grid_point_cloud(arr, path)
    if cloud is not None:
        return cloud
    return _Raw(arr, None)


def _uniform_steps(values: np.ndarray) -> float | None:
    """The common step of sorted unique ``values``, or ``None`` when they are not evenly spaced."""
    steps = np.diff(values)
    step = (values[-1] - values[0]) / (values.size - 1)
    if not step > 0 or not np.allclose(steps, step, rtol=1e-6, atol=0.0):
        return None
    return float(step)


def _monotone(col: np.ndarray) -> bool:
    d = np.diff(col)
    return bool(np.all(d >= 0) or np.all(d <= 0))


def _grid_point_cloud(arr: np.ndarray, path: Path) -> _Raw | None:
    """Three columns x, y, z whose (x, y) lie on a uniform square grid → heights[iy, ix].

    Returns ``None`` for an ordinary ``n × 3`` height map. A table that looks like a point
    cloud (x and y forming a complete grid in any order, or x or y sorted) but is not on a
    uniform square grid is refused.
    Grid points missing from the table become undefined points (see ``fill``).
    """
    rows = arr.shape[0]
    if arr.shape[1] != 3 or rows < 4:
        return None
    x, y, z = arr[:, 0], arr[:, 1], arr[:, 2]
    if not (np.isfinite(x).all() and np.isfinite(y).all()):
        return None
    ux, uy = np.unique(x), np.unique(y)
    sorted_xy = _monotone(x) or _monotone(y)
    repeated = ux.size < rows or uy.size < rows
    # Two columns whose values pair up into every point of a grid, in any order, are
    # coordinates; so is a sorted column, unless it is a short one without repeats (a sorted
    # column of 8 or more rough heights does not happen by chance).
    complete_grid = repeated and ux.size >= 2 and uy.size >= 2 and ux.size * uy.size == rows
    if not (complete_grid or (sorted_xy and (repeated or rows >= 8))):
        return None
    where = (
        f"{str(path)!r} looks like an x,y,z point cloud (3 columns, x and y on a grid or "
        "sorted; a 3-column height matrix can be read with numpy and passed to Surface)"
    )
    if ux.size < 2 or uy.size < 2:
        raise ValueError(f"{where} but all points share one x or one y: a line, not a surface")
    sx, sy = _uniform_steps(ux), _uniform_steps(uy)
    pairs = np.unique(arr[:, :2], axis=0).shape[0]
    if sx is None or sy is None or pairs != rows:
        raise ValueError(
            f"{where}, but its points are not on a uniform grid (uneven x or y steps, or "
            "repeated points); interpolate it onto a grid first, or save the height matrix "
            "itself (one grid row per line)"
        )
    if not math.isclose(sx, sy, rel_tol=1e-6):
        raise ValueError(
            f"{where} with x step {sx!r} and y step {sy!r}; leakpath needs square pixels "
            "(one dx), resample it first"
        )
    ix = np.rint((x - ux[0]) / sx).astype(np.intp)
    iy = np.rint((y - uy[0]) / sy).astype(np.intp)
    heights = np.full((uy.size, ux.size), np.nan)
    heights[iy, ix] = z
    meta = {"layout": "x,y,z point cloud on a uniform grid (y along axis 0, x along axis 1)"}
    return _Raw(heights, sx, meta)


def _st_module() -> Any:
    try:
        import SurfaceTopography as st  # noqa: N813
    except ImportError:
        return None
    return st


def _st_format_name(reader: Any) -> str:
    for attr in ("name", "format"):
        try:
            return str(getattr(reader, attr)())
        except Exception:  # a reader without that description
            continue
    return getattr(reader, "__name__", "reader")


class _NoReader(ValueError):
    """No reader matched or every matching reader failed; the message lists what was tried."""


def _st_open(st: Any, path: Path, tried: list[str]) -> Any:
    """Open ``path`` with the SurfaceTopography reader its signature or extension names.

    SurfaceTopography's own detection tries every reader, and some formats have no
    signature (an HGT elevation map is any file of 2·n² bytes), so random data can pass as a
    surface. Here a reader is tried only when the file's first bytes match its signature,
    or when they do not rule it out and the file has one of its extensions. ``tried``
    collects the formats tried and why they failed.
    """
    readers = getattr(getattr(st, "IO", None), "readers", None)
    if not readers:  # a SurfaceTopography without a reader registry: its own detection
        return st.open_topography(str(path))
    ext = path.suffix.lower().lstrip(".")
    magic = _sniff(path)[:512]
    ruled_out: list[str] = []  # formats of this extension whose signature is absent
    for reader in readers:
        verdict = "MAYBE"
        can_read = getattr(reader, "can_read", None)
        if can_read is not None:
            try:
                verdict = str(getattr(can_read(magic), "name", "MAYBE"))
            except Exception:  # a failing check decides nothing
                verdict = "MAYBE"
        try:
            extensions = [str(e).lower() for e in (reader.file_extensions() or [])]
        except Exception:  # a reader without registered extensions
            extensions = []
        if verdict == "NO":
            if ext in extensions:
                ruled_out.append(_st_format_name(reader))
            continue
        if verdict != "YES" and ext not in extensions:
            continue
        name = _st_format_name(reader)
        try:
            return reader(str(path))
        except Exception as exc:  # try the next matching reader
            tried.append(f"{name} ({_one_line(exc)[:120]})")
    if tried:
        raise _NoReader("tried " + "; ".join(tried))
    if ruled_out:
        raise _NoReader(
            f"its extension {path.suffix!r} names {' or '.join(ruled_out)}, but its first bytes "
            "do not carry that format's signature (a damaged file, or another format)"
        )
    raise _NoReader(
        f"it matches no known format: neither its first bytes nor its extension "
        f"{path.suffix or '(none)'!r} belong to a format leakpath or SurfaceTopography reads "
        "(leakpath itself reads .npz, .npy, .txt, .csv, .asc and .dat)"
    )


def _read_surface_topography(st: Any, path: Path, dx: float | None, tried: list[str]) -> _Raw:
    reader = _st_open(st, path, tried)
    name = _st_format_name(type(reader))
    try:
        channel = getattr(reader, "default_channel", None) or reader.channels[0]
        if getattr(channel, "dim", 2) != 2:
            raise ValueError("it holds a line scan, not a 2-D topography map")
        kwargs: dict[str, Any] = {}
        from_file = channel.physical_sizes is not None
        if not from_file:
            if dx is None:
                raise InvalidArgumentError(
                    f"dx: required to read {str(path)!r}, the file has no physical size; "
                    "pass dx=..."
                )
            kwargs["physical_sizes"] = tuple(float(n) * dx for n in channel.nb_grid_pts)
        try:
            topo = channel.topography(**kwargs)
            raw_heights = topo.heights()
            if np.ma.isMaskedArray(raw_heights):  # undefined points: NaN; load() decides
                raw_heights = np.ma.filled(np.ma.asarray(raw_heights, dtype=np.float64), np.nan)
            # A copy, and no reference kept to the topography: some readers map the file,
            # which is closed below.
            raw_heights = np.array(raw_heights)
            nx, ny = (int(n) for n in topo.nb_grid_pts)
            sx, sy = (float(s) for s in topo.physical_sizes)
            info = getattr(topo, "info", None)
            del topo
        except LeakpathError:
            raise
        except Exception as exc:
            failed = [*tried, f"{name} ({_one_line(exc)[:160]})"]
            raise _NoReader("tried " + "; ".join(failed)) from exc
    finally:
        close = getattr(reader, "close", None)
        if callable(close):
            with warnings.catch_warnings():  # a memory-mapped reader warns about its own views
                warnings.simplefilter("ignore", RuntimeWarning)
                close()
    # SurfaceTopography indexes heights[ix, iy] (axis 0 = x); leakpath uses axis 1 = x.
    heights = raw_heights.T
    dx_x, dx_y = sx / nx, sy / ny
    if not math.isclose(dx_x, dx_y, rel_tol=1e-9):
        raise InvalidArgumentError(
            f"path: {str(path)!r} has non-square pixels ({dx_x!r} × {dx_y!r}); leakpath needs "
            "one spacing dx for both axes — resample the topography first",
            argument="path",
        )
    meta: dict[str, Any] = {"reader": "SurfaceTopography"}
    if isinstance(info, Mapping) and "unit" in info:
        meta["unit"] = str(info["unit"])
    return _Raw(heights, dx_x if from_file else None, meta)


def _needs_io(path: Path) -> ImportError:
    return ImportError(
        f"path: reading {path.suffix or 'extension-less'!s} files such as {str(path)!r} needs "
        'the optional SurfaceTopography package: pip install "leakpath[io]" (or save the '
        "heights as .npy/.csv and pass dx)"
    )


def _read_any(path: Path, size: int, dx: float | None) -> _Raw:
    """Pick the reader by extension and content signature; refuse what matches none."""
    suffix = path.suffix.lower()
    head = _sniff(path)
    if suffix == ".npz":
        if not head.startswith(_ZIP_MAGICS):
            raise ValueError("it is not an .npz archive (no zip signature)")
        return _read_npz(path)
    if suffix == ".npy" or (suffix not in TEXT_SUFFIXES and head.startswith(_NPY_MAGIC)):
        if not head.startswith(_NPY_MAGIC):
            raise ValueError("it is not a .npy array file (no NUMPY signature)")
        _check_read_estimate(path, _npy_estimate(path, size))
        return _read_npy(path)
    if suffix in (".txt", ".csv", ".asc"):
        _check_file_size(path, size, 2)
        return _read_text(path)
    tried: list[str] = []
    if suffix == ".dat":  # plain text, or Zygo MetroPro binary (and others) via SurfaceTopography
        _check_file_size(path, size, 2)
        try:
            return _read_text(path)
        except ValueError as exc:
            tried.append(f"plain-text matrix ({_one_line(exc)[:120]})")
        st = _st_module()
        if st is None:
            raise ValueError(
                f"tried: {tried[0]}; binary .dat files (Zygo MetroPro …) need the optional "
                'SurfaceTopography package: pip install "leakpath[io]"'
            )
    else:
        st = _st_module()
        if st is None:
            raise _needs_io(path)
    return _read_surface_topography(st, path, dx, tried)


def _fill_undefined(h: FloatArray, method: str) -> None:
    """Fill the non-finite points of ``h`` in place.

    ``"mean"``: the mean of the defined points. ``"nearest"``: layer by layer from the
    defined region inwards, each undefined point takes the mean of its already defined
    edge neighbours (the nearest defined points in grid steps; ties averaged).
    """
    known = np.isfinite(h)
    if method == "mean":
        h[~known] = float(np.mean(h[known]))
        return
    h[~known] = 0.0
    while not known.all():
        total = np.zeros_like(h)
        count = np.zeros(h.shape, dtype=np.int8)
        val = np.where(known, h, 0.0)
        k8 = known.astype(np.int8)
        total[1:, :] += val[:-1, :]
        count[1:, :] += k8[:-1, :]
        total[:-1, :] += val[1:, :]
        count[:-1, :] += k8[1:, :]
        total[:, 1:] += val[:, :-1]
        count[:, 1:] += k8[:, :-1]
        total[:, :-1] += val[:, 1:]
        count[:, :-1] += k8[:, 1:]
        front = ~known & (count > 0)
        h[front] = total[front] / count[front]
        known |= front

