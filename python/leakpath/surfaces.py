"""Rough surfaces: the :class:`Surface` container, generators and file I/O (``docs/surfaces.md``).

Conventions
-----------
``heights[i, j]`` is a 2-D float64 array: axis 0 = rows = y, axis 1 = columns = x, uniform
spacing ``dx`` in both directions (square pixels). Each grid point is the centre of a
``dx × dx`` element, so a ``(ny, nx)`` surface covers ``ny·dx × nx·dx`` and has nominal area
``A0 = ny·nx·dx²``. Units are the user's own; nothing assumes micrometres.

Generators
----------
:func:`rmd`
    Random midpoint displacement (Saupe's MidPointFM2D without "addition"), the paper's
    generator, on a ``(2^m + 1)²`` grid, shifted so that ``min(h) = 0``.
:func:`spectral`
    Periodic Fourier-filtered self-affine surface with PSD ``C(q) ∝ q^(−2(1+H))`` between
    two cut-offs, scaled to a requested rms height or rms slope.

Files
-----
:meth:`Surface.save` writes ``.npz`` atomically; :func:`load` reads ``.npz``, ``.npy``,
plain-text matrices (``.txt``, ``.csv``, ``.dat``, ``.asc``) and, with the optional
``leakpath[io]`` extra, every format SurfaceTopography can read.
"""

from __future__ import annotations

import json
import math
import os
import secrets
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
from . import moments as _moments
from .errors import InvalidArgumentError, LeakpathError
from .moments import Moments, nayak_moments

__all__ = ["Surface", "load", "rmd", "spectral", "RMD_MEMORY_LIMIT_BYTES", "TEXT_SUFFIXES"]

FloatArray = npt.NDArray[np.float64]
PathLike = str | os.PathLike[str]

#: File suffixes read as plain-text matrices (comma- or whitespace-separated).
TEXT_SUFFIXES: frozenset[str] = frozenset({".txt", ".csv", ".dat", ".asc"})

#: :func:`rmd` refuses grids whose estimated peak memory exceeds this (8 GiB).
#: The estimate is ``3 · 8 · (2^m + 1)²`` bytes: the height array plus the random normals
#: and temporaries of the finest level. m = 14 (≈ 6.0 GiB) is the largest accepted size.
RMD_MEMORY_LIMIT_BYTES: int = 8 * 2**30

_NPZ_FORMAT_VERSION = 1


def _check_positive_finite(name: str, value: Any) -> float:
    """Return ``float(value)`` or raise :class:`InvalidArgumentError` naming ``name``."""
    return _validate.positive(name, value)


def _check_seed(seed: Any) -> int:
    """Validate a seed; ``None`` draws fresh OS entropy (recorded in the metadata)."""
    if seed is None:
        return int(np.random.SeedSequence().entropy)  # type: ignore[arg-type]
    return _validate.integer(
        "seed", seed, low=0, high=2**256, what="a non-negative integer or None"
    )


class _Owned:
    """A freshly built height array handed to :class:`Surface` without a defensive copy."""

    __slots__ = ("array",)

    def __init__(self, array: FloatArray) -> None:
        self.array = array


#: Largest |height| a surface may hold: squares (moments, energies) stay finite.
MAX_ABS_HEIGHT = _validate.MAX_ABS_HEIGHT


def _json_default(obj: Any) -> Any:
    """JSON encoder hook for numpy scalars/arrays and paths in metadata."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    raise TypeError(f"metadata value of type {type(obj).__name__} is not JSON-serialisable")


@dataclass(eq=False)
class Surface:
    """A rough surface sampled on a uniform square grid.

    Parameters
    ----------
    heights : (ny, nx) array_like
        Heights ``h[i, j]``; axis 0 = rows = y, axis 1 = columns = x. Stored as a C-contiguous
        float64 array (converted if needed). At least one point per axis; every value finite.
        (Nayak's moments need at least 3 points per axis.)
    dx : float
        Grid spacing (same in x and y), in the user's length unit; positive and finite.
    metadata : dict, optional
        Free-form, JSON-serialisable description (generator, parameters, source file, …).

    Raises
    ------
    InvalidArgumentError (a ``ValueError``)
        ``heights`` not a 2-D array of real numbers, empty, not finite or too large; ``dx``
        not a positive finite number or out of range; ``metadata`` not a mapping.
    """

    heights: FloatArray
    dx: float
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if isinstance(self.heights, _Owned):
            arr = self.heights.array  # built by leakpath itself: no copy needed
            if arr.ndim != 2 or arr.dtype != np.float64 or not arr.flags.c_contiguous:
                arr = _validate.real_array("heights", arr, finite=False)
        else:
            arr = _validate.real_array("heights", self.heights, finite=False)
        if arr.shape[0] < 1 or arr.shape[1] < 1:
            raise InvalidArgumentError(
                f"heights: must have at least one point per axis, got shape {arr.shape}"
            )
        finite = np.isfinite(arr)
        if not finite.all():
            bad = int(arr.size - np.count_nonzero(finite))
            raise InvalidArgumentError(
                f"heights: contains {bad} NaN or infinite value(s) of {arr.size}; fill or crop "
                "them first (leakpath.load(..., fill='nearest') fills undefined points of a file)"
            )
        peak = float(np.max(np.abs(arr)))
        if peak > MAX_ABS_HEIGHT:
            raise InvalidArgumentError(
                f"heights: values up to {peak:.3g} overflow when squared (moments, energies); "
                f"express them in a larger length unit so that |h| <= {MAX_ABS_HEIGHT:g}"
            )
        arr.flags.writeable = False
        self.heights = arr
        self.dx = _validate.spacing("dx", self.dx)
        if not isinstance(self.metadata, Mapping):
            raise InvalidArgumentError(
                f"metadata: must be a dict, got {type(self.metadata).__name__}"
            )
        self.metadata = dict(self.metadata)
        self.__dict__["_checked"] = True

    def __setattr__(self, name: str, value: Any) -> None:
        # Assigning new heights or a new dx later goes through the same checks (and copy).
        if name in ("heights", "dx") and self.__dict__.get("_checked"):
            heights = value if name == "heights" else _Owned(self.heights)
            dx = value if name == "dx" else self.dx
            checked = Surface(heights, dx)
            object.__setattr__(self, "heights", checked.heights)
            object.__setattr__(self, "dx", checked.dx)
            return
        object.__setattr__(self, name, value)

    def __repr__(self) -> str:
        gen = self.metadata.get("generator", self.metadata.get("source"))
        extra = f", generator={gen!r}" if gen is not None else ""
        return f"Surface(shape={self.shape}, dx={self.dx!r}{extra})"

    # ------------------------------------------------------------------ properties
    @property
    def shape(self) -> tuple[int, int]:
        """Grid size ``(ny, nx)``."""
        ny, nx = self.heights.shape
        return int(ny), int(nx)

    @property
    def length(self) -> tuple[float, float]:
        """Physical size ``(Ly, Lx) = (ny·dx, nx·dx)`` [length], in array-axis order."""
        ny, nx = self.shape
        return ny * self.dx, nx * self.dx

    @property
    def nominal_area(self) -> float:
        """Nominal area ``A0 = ny·nx·dx²`` [length²] (each point is a ``dx × dx`` element)."""
        ny, nx = self.shape
        return ny * nx * self.dx * self.dx

    @property
    def height_range(self) -> float:
        """Peak-to-valley height ``h_s = max h − min h`` [length]."""
        return float(np.max(self.heights) - np.min(self.heights))

    @property
    def mean_height(self) -> float:
        """Mean height ``h̄`` [length]."""
        return float(np.mean(self.heights))

    @property
    def rms_height(self) -> float:
        """Root-mean-square height about the mean, ``√(mean((h − h̄)²)) = √m0`` [length]."""
        d = self.heights - self.mean_height
        return float(np.sqrt(np.mean(d * d)))

    def moments(self, method: str = "fd") -> Moments:
        """Nayak's moments of the heights; see :func:`leakpath.moments.nayak_moments`."""
        return nayak_moments(self, method=method)  # type: ignore[arg-type]

    # ------------------------------------------------------------------ I/O
    def save(self, path: PathLike, *, overwrite: bool = True) -> Path:
        """Write the surface to a ``.npz`` file atomically.

        The archive holds ``heights`` (float64), ``dx`` (0-d float64), ``metadata`` (a JSON
        string) and ``format_version``. It is written to a temporary file in the target's
        directory and moved into place with :func:`os.replace`, so a reader never sees a
        half-written file and an existing file is never left truncated.

        Parameters
        ----------
        path : str or os.PathLike
            Destination; must end in ``.npz``.
        overwrite : bool
            If false, refuse (``FileExistsError``) when ``path`` already exists.

        Returns
        -------
        pathlib.Path
            The path written.

        Raises
        ------
        ValueError
            ``path`` does not end in ``.npz`` or the metadata is not JSON-serialisable.
        FileExistsError
            ``overwrite=False`` and ``path`` exists.
        FileNotFoundError
            The target directory does not exist.
        """
        if isinstance(path, (bytes, bool)) or not isinstance(path, (str, os.PathLike)):
            raise InvalidArgumentError(
                f"path: must be a file path (str or os.PathLike), got {_validate.describe(path)}"
            )
        overwrite = _validate.flag("overwrite", overwrite)
        target = Path(path)
        if target.suffix.lower() != ".npz":
            raise ValueError(f"path must end in '.npz' to save a surface, got {str(target)!r}")
        try:
            meta_json = json.dumps(self.metadata, default=_json_default, allow_nan=True)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"metadata cannot be stored as JSON: {exc}") from exc
        directory = target.parent if str(target.parent) else Path(".")
        if not directory.is_dir():
            raise FileNotFoundError(f"directory {str(directory)!r} for {str(target)!r} not found")
        if not overwrite and target.exists():
            raise FileExistsError(f"{str(target)!r} already exists (pass overwrite=True)")
        # A fresh hidden file next to the target; created with mode 0o666 & ~umask, like any
        # file the user writes (tempfile.mkstemp would leave it owner-only, 0o600).
        tmp = directory / f".{target.name}.{os.getpid()}.{secrets.token_hex(6)}.tmp"
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
        try:
            with os.fdopen(fd, "wb") as fh:
                np.savez(
                    fh,
                    heights=self.heights,
                    dx=np.float64(self.dx),
                    metadata=np.array(meta_json),
                    format_version=np.int64(_NPZ_FORMAT_VERSION),
                )
                fh.flush()
                os.fsync(fh.fileno())
            if overwrite:
                os.replace(tmp, target)
            else:
                try:
                    os.link(tmp, target)  # atomic; fails if the target appeared meanwhile
                except FileExistsError:
                    raise FileExistsError(
                        f"{str(target)!r} already exists (pass overwrite=True)"
                    ) from None
                except OSError:  # filesystem without hard links
                    if target.exists():
                        raise FileExistsError(
                            f"{str(target)!r} already exists (pass overwrite=True)"
                        ) from None
                    os.replace(tmp, target)
        finally:
            if tmp.exists():
                tmp.unlink()
        return target

    @classmethod
    def load(cls, path: PathLike, dx: float | None = None, fill: str | None = None) -> Surface:
        """Read a surface from ``path``; see :func:`leakpath.surfaces.load`."""
        return load(path, dx=dx, fill=fill)


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
    if isinstance(path, (bytes, bool)) or not isinstance(path, (str, os.PathLike)):
        raise InvalidArgumentError(
            f"path: must be a file path (str or os.PathLike), got {_validate.describe(path)}"
        )
    p = Path(path)
    try:
        info = os.stat(p)
    except FileNotFoundError:
        raise FileNotFoundError(f"surface file {str(p)!r} not found") from None
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


def _sniff(path: Path) -> bytes:
    with open(path, "rb") as fh:
        return fh.read(_SNIFF_BYTES)


def _read_npz(path: Path) -> _Raw:
    with zipfile.ZipFile(path) as archive:  # sizes before inflating anything
        _check_file_size(path, sum(info.file_size for info in archive.infolist()), 2)
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
        _check_file_size(path, size, 2)
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


def load(path: PathLike, *, dx: float | None = None, fill: str | None = None) -> Surface:
    """Read a surface from a file.

    ===================================  =====================================================
    suffix                               contents
    ===================================  =====================================================
    ``.npz``                             written by :meth:`Surface.save`: ``heights``, ``dx``
                                         and JSON ``metadata`` (an archive with a single array
                                         or a ``heights`` array but no ``dx`` needs ``dx=``)
    ``.npy``                             a 2-D array; ``dx`` required
    ``.txt`` ``.csv`` ``.asc``           a plain matrix, one grid row per line, comma-,
                                         semicolon- or whitespace-separated, ``#`` comments;
                                         ``dx`` required. Three columns ``x, y, z`` whose
                                         x, y form a complete grid (any row order) or are
                                         sorted are read as a point cloud: on a uniform
                                         square grid they become ``heights[iy, ix]`` with
                                         ``dx`` the grid step (missing points undefined);
                                         otherwise refused.
    ``.dat``                             a plain-text matrix as above; if that fails, a
                                         SurfaceTopography format (Zygo MetroPro binary …)
    anything else                        SurfaceTopography's readers (``pip install
                                         "leakpath[io]"``), chosen by the file's signature
                                         or, for formats without one, its extension; ``dx``
                                         from the file, or required if the file has no
                                         physical size. Heights are transposed to leakpath's
                                         axis 1 = x convention. A file that matches no
                                         format is refused (a ``.npy`` signature is read as
                                         ``.npy`` whatever the extension).
    ===================================  =====================================================

    Parameters
    ----------
    path : str or os.PathLike
        A regular file (a FIFO or device is refused, never waited on).
    dx : float, optional
        Grid spacing [length]. Required when the file does not store it; when it does, a
        different ``dx`` is an error (build ``Surface(s.heights, new_dx)`` to rescale).
    fill : {"nearest", "mean"}, optional
        What to do with undefined points (NaN, infinite, masked by the instrument, or grid
        points missing from a point cloud). ``None`` (default): refuse the file, reporting
        how many there are — heights are never invented silently. ``"nearest"``: each takes
        the mean of its nearest defined points in grid steps, filled layer by layer from the
        defined region inwards. ``"mean"``: the mean defined height. The count and method
        are recorded in ``metadata["filled"]``.

    Returns
    -------
    Surface
        With ``metadata["source"]`` set to the path.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    InvalidArgumentError (a ``ValueError``)
        ``path`` is not a regular file, cannot be parsed, matches no known format, holds
        complex or non-numeric data, not a 2-D matrix, or undefined points without
        ``fill``; ``dx`` missing, invalid or different from the file's; bad ``fill``.
    ProblemTooLargeError (a ``MemoryError``)
        A file too large to read into memory.
    ImportError
        A non-native format without the optional SurfaceTopography package.
    """
    dx_arg = None if dx is None else _validate.spacing("dx", dx)
    method = None if fill is None else _validate.choice("fill", fill, FILL_METHODS)
    p, info = _check_path(path)
    try:
        raw = _read_any(p, info.st_size, dx_arg)
    except (ImportError, FileNotFoundError, LeakpathError):
        raise
    except Exception as exc:  # corrupt archives, unreadable files, reader failures
        raise InvalidArgumentError(
            f"path: cannot read surface file {str(p)!r}: {_one_line(exc)}", argument="path"
        ) from exc
    try:
        heights = _validate.real_array("heights", raw.heights, finite=False)
    except InvalidArgumentError as exc:
        raise InvalidArgumentError(
            f"path: cannot read surface file {str(p)!r}: {exc}", argument="path"
        ) from None
    if heights.size == 0:
        raise InvalidArgumentError(
            f"path: {str(p)!r} holds an empty array {heights.shape}", argument="path"
        )
    undefined = int(heights.size - np.count_nonzero(np.isfinite(heights)))
    metadata = dict(raw.metadata)
    if undefined:
        if undefined == heights.size:
            raise InvalidArgumentError(
                f"path: all {heights.size} points of {str(p)!r} are undefined", argument="path"
            )
        if method is None:
            raise InvalidArgumentError(
                f"path: {undefined} of {heights.size} points of {str(p)!r} are undefined "
                "(NaN, infinite or masked); pass fill='nearest' or fill='mean' to fill them "
                "(--fill on the command line), or crop them from the file",
                argument="path",
            )
        _fill_undefined(heights, method)
        metadata["filled"] = {"method": method, "points": undefined}
    surface = Surface(_Owned(heights), _resolve_dx(p, raw.dx_file, dx_arg), metadata)
    surface.metadata.setdefault("source", str(p))
    return surface


# ---------------------------------------------------------------------------- RMD
def generator_memory_limit() -> int:
    """Bytes a surface generator may use: :data:`RMD_MEMORY_LIMIT_BYTES` or 70 % of physical
    memory, whichever is smaller."""
    return min(RMD_MEMORY_LIMIT_BYTES, _validate.memory_budget())


def _rmd_bytes(m: int) -> int:
    """Estimated peak bytes of :func:`rmd`: ``3 · 8 · (2^m + 1)²``."""
    n = 2**m + 1
    return 3 * 8 * n * n


def _rmd_check_m(m: Any) -> int:
    m_int = _validate.integer(
        "m", m, low=1, high=2**1024, what="an integer ≥ 1 (grid (2^m + 1)²)"
    )
    limit = generator_memory_limit()
    largest = max((k for k in range(1, 40) if _rmd_bytes(k) <= limit), default=0)
    if m_int > largest:
        # 2^m itself is not computed for absurd m (2^(2^62) would never finish).
        estimate = _rmd_bytes(m_int) if m_int < 64 else 24 * 2**128  # a lower bound
        what = (
            f"an RMD surface with m = {m_int} ((2^{m_int} + 1)² points)"
            if m_int < 64
            else f"an RMD surface with m = {m_int} (more than 2^128 points)"
        )
        hint = f"use m <= {largest}" if largest else "free some memory"
        raise _validate.too_large("m", what, estimate, limit, hint)
    return m_int


def _check_fractal_dimension(D: Any) -> float:  # noqa: N803
    return _validate.real(
        "D", D, low=2.0, high=3.0, low_open=True, high_open=True,
        what="a fractal dimension in the open interval (2, 3)",
    )


def _check_height_scale(h: FloatArray, name: str) -> None:
    """Refuse generated heights that overflowed or exceed :data:`MAX_ABS_HEIGHT`."""
    peak = float(np.max(np.abs(h)))
    if not peak <= MAX_ABS_HEIGHT:
        raise InvalidArgumentError(
            f"{name}: too large, the heights reach {peak:.3g} (limit {MAX_ABS_HEIGHT:g}); "
            "express them in a larger length unit"
        )


def rmd(
    m: int,
    D: float,  # noqa: N803 - the paper's symbol
    *,
    seed: int | None,
    sigma0: float = 1.0 / math.sqrt(0.09),
    length: float = 1.0,
) -> Surface:
    """Random-midpoint-displacement surface (Saupe's MidPointFM2D without addition).

    Builds heights on a ``(2^m + 1) × (2^m + 1)`` grid with Hurst exponent ``H = 3 − D``,
    then shifts them so that ``min(h) = 0``. Grid spacing ``dx = length / 2^m``.

    Algorithm (``N = 2^m``, ``G`` standard normals, ``δ`` a standard deviation)::

        δ = σ0;  f = 2^(−H/2)
        h[0,0], h[0,N], h[N,0], h[N,N] = σ0·G           (4 draws, in this order)
        for level = 1 … m:                              (D_ = N/2^(level−1), d = D_/2)
            δ ← f·δ
            centres   h[d::D_, d::D_]  = mean of the 4 diagonal corners + δ·G
            δ ← f·δ
            edge mid. h[0::D_, d::D_]  = mean of the axis neighbours + δ·G   (on rows)
                      h[d::D_, 0::D_]  = mean of the axis neighbours + δ·G   (on columns)
        h ← h − min(h)

    A point's "axis neighbours" are the ``d``-distant points along both axes: 4 inside the
    grid, 3 on its boundary. The corner mean is summed in the order
    ``h[i−d,j−d] + h[i−d,j+d] + h[i+d,j−d] + h[i+d,j+d]`` and divided by 4; an edge midpoint
    sums its two neighbours along its own edge (lower index first) and then the existing
    ones across it (lower index first), and divides by their count (4 or 3).

    **Draw order** (``rng = numpy.random.default_rng(seed)``; every draw is one call to
    ``rng.standard_normal``; arrays fill in row-major order):

    1. ``rng.standard_normal(4)`` for the corners ``(0,0), (0,N), (N,0), (N,N)``;
    2. per level, ``rng.standard_normal((k, k))`` with ``k = 2^(level−1)`` for the square
       centres ``h[d::D_, d::D_]``;
    3. then one ``rng.standard_normal(2·k·(k+1))``: its first ``(k+1)·k`` values, reshaped to
       ``(k+1, k)``, go to the midpoints on grid rows ``h[0::D_, d::D_]``; the remaining
       ``k·(k+1)``, reshaped to ``(k, k+1)``, go to the midpoints on grid columns
       ``h[d::D_, 0::D_]``.

    Each level is vectorised with numpy slicing (m = 12, a 4097² grid, takes well under 2 s).

    **Reading of the paper's variance.** The paper writes "variance σ1² = σ0²/2^((3−D)/2)".
    Read literally as a variance, it would halve the Hurst exponent. Following Saupe, the
    factor ``2^(−H/2)`` is applied to the *standard deviation* ``δ`` before each of the two
    half-steps of a level (so δ falls by ``2^(−H)`` per halving of the spacing, as
    self-affinity with exponent H requires). Midpoint displacement without addition is known
    to bias the measured Hurst exponent low for smooth surfaces (H near 1); see
    ``docs/surfaces.md`` for the measured values.

    Parameters
    ----------
    m : int
        Number of refinement levels, ``1 ≤ m ≤ 14`` (grid ``(2^m + 1)²``; the estimated
        peak memory ``3·8·(2^m + 1)²`` bytes must not exceed :func:`generator_memory_limit`,
        8 GiB or 70 % of physical memory, whichever is smaller).
    D : float
        Fractal dimension, ``2 < D < 3``; Hurst exponent ``H = 3 − D``.
    seed : int or None
        Seed for ``numpy.random.default_rng``; the same seed gives the same surface bit for
        bit. ``None`` draws fresh entropy, which is recorded in ``metadata["seed"]``.
    sigma0 : float
        Standard deviation of the corner heights (and the initial ``δ``) [length]; default
        ``1/√0.09``.
    length : float
        Physical size of the square (``2^m·dx``) [length]; default 1.

    Returns
    -------
    Surface
        ``metadata`` records ``generator="rmd"``, ``m``, ``D``, ``H``, ``seed``, ``sigma0``,
        ``length``.

    Raises
    ------
    InvalidArgumentError (a ``ValueError``)
        Invalid ``m``, ``D``, ``seed``, ``sigma0`` or ``length`` (the message names it).
    ProblemTooLargeError (a ``MemoryError``)
        ``m`` so large that the estimated peak memory ``3·8·(2^m + 1)²`` bytes exceeds
        :func:`generator_memory_limit` (checked before anything is allocated).
    """
    m_int = _rmd_check_m(m)
    d_frac = _check_fractal_dimension(D)
    sigma0_f = _check_positive_finite("sigma0", sigma0)
    length_f = _check_positive_finite("length", length)
    seed_i = _check_seed(seed)
    hurst = 3.0 - d_frac
    dx = length_f / 2**m_int
    try:
        _validate.spacing("dx", dx)
    except InvalidArgumentError:
        raise InvalidArgumentError(
            f"length: {length_f!r} gives a grid spacing dx = length/2^m = {dx!r} out of range "
            "(dx² must be a normal double); express lengths in another unit"
        ) from None

    rng = np.random.default_rng(seed_i)
    big_n = 2**m_int
    h = np.zeros((big_n + 1, big_n + 1), dtype=np.float64)
    corners = rng.standard_normal(4)
    h[0, 0], h[0, big_n], h[big_n, 0], h[big_n, big_n] = sigma0_f * corners
    factor = 2.0 ** (-0.5 * hurst)
    delta = sigma0_f
    step = big_n  # D_ in the docstring: spacing of the already-known lattice
    for level in range(1, m_int + 1):
        half = step // 2
        k = 2 ** (level - 1)
        # --- square centres: mean of the 4 diagonal neighbours
        delta *= factor
        c = h[0:big_n:step, 0:big_n:step] + h[0:big_n:step, step::step]
        c += h[step::step, 0:big_n:step]
        c += h[step::step, step::step]
        c /= 4.0
        c += delta * rng.standard_normal((k, k))
        h[half::step, half::step] = c
        # --- edge midpoints
        delta *= factor
        g = rng.standard_normal(2 * k * (k + 1))
        centres = h[half::step, half::step]  # (k, k), just computed
        # on grid rows: (k+1, k); along-edge neighbours are lattice points left/right,
        # across-edge neighbours are the centres above/below (absent on rows 0 and N).
        s = h[0::step, 0:big_n:step] + h[0::step, step::step]
        s[1:, :] += centres
        s[:-1, :] += centres
        s[1:-1, :] /= 4.0
        s[0, :] /= 3.0
        s[-1, :] /= 3.0
        s += delta * g[: (k + 1) * k].reshape(k + 1, k)
        h[0::step, half::step] = s
        # on grid columns: (k, k+1); along-edge neighbours above/below, centres left/right.
        t = h[0:big_n:step, 0::step] + h[step::step, 0::step]
        t[:, 1:] += centres
        t[:, :-1] += centres
        t[:, 1:-1] /= 4.0
        t[:, 0] /= 3.0
        t[:, -1] /= 3.0
        t += delta * g[(k + 1) * k :].reshape(k, k + 1)
        h[half::step, 0::step] = t
        step = half
    h -= h.min()
    _check_height_scale(h, "sigma0")
    metadata = {
        "generator": "rmd",
        "m": m_int,
        "D": d_frac,
        "H": hurst,
        "seed": seed_i,
        "sigma0": sigma0_f,
        "length": length_f,
    }
    return Surface(_Owned(h), dx, metadata)


# ---------------------------------------------------------------------------- spectral
def _check_shape(shape: Any) -> tuple[int, int]:
    return _validate.shape_pair("shape", shape, low=2)


#: Bytes :func:`spectral` needs per grid point at its peak (white noise, its half spectrum,
#: the wavevector magnitudes and filter, the filtered spectrum, the result and the FFT's
#: work space: 48.5 measured with tracemalloc, rounded up).
SPECTRAL_BYTES_PER_POINT = 56


def _check_spectral_size(ny: int, nx: int) -> None:
    limit = generator_memory_limit()
    estimate = SPECTRAL_BYTES_PER_POINT * ny * nx
    if estimate > limit:
        side = math.isqrt(limit // SPECTRAL_BYTES_PER_POINT)
        raise _validate.too_large(
            "shape",
            f"a spectral surface of {ny} × {nx} points",
            estimate,
            limit,
            f"use at most about {side} × {side} points",
        )


def spectral(
    shape: int | tuple[int, int],
    hurst: float,
    *,
    seed: int | None,
    length: float = 1.0,
    rms_height: float | None = None,
    rms_slope: float | None = None,
    long_cutoff: float | None = None,
    short_cutoff: float | None = None,
) -> Surface:
    """Periodic self-affine surface by Fourier filtering of white noise.

    With ``w`` a ``(ny, nx)`` array of standard normals from
    ``numpy.random.default_rng(seed).standard_normal((ny, nx))`` (one call)::

        h = irfft2( A(q) · rfft2(w) ),   A(q) = |q|^(−(1+H))  for q_L ≤ |q| ≤ q_s, else 0

    so the power spectrum is ``C(q) ∝ A² = |q|^(−2(1+H))`` inside the band and exactly zero
    outside (including ``q = 0``, so the mean height is zero). Filtering real white noise
    gives a Gaussian field with uniformly random phases whose spectrum is Hermitian by
    construction: the result is exactly real and exactly periodic (a finite sum of the
    grid's Fourier modes). It is then scaled by one constant to the requested rms height or
    rms slope.

    **Wavevectors** are angular: ``q = 2π/λ`` in radians per length unit, with
    ``q_x = 2π·fftfreq(nx, dx)``, ``q_y = 2π·fftfreq(ny, dx)``; the cut-offs are given as
    wavelengths, ``q_L = 2π/long_cutoff``, ``q_s = 2π/short_cutoff`` (the band edges are
    inclusive, with a relative tolerance of 1e-12).

    **Grid:** square pixels, ``dx = length / nx``; ``length`` is the size along x (axis 1)
    and the size along y is ``ny·dx``.

    Parameters
    ----------
    shape : int or (int, int)
        ``n`` for an ``n × n`` grid or ``(ny, nx)``; at least 2 per axis.
    hurst : float
        Hurst exponent ``0 < H < 1``.
    seed : int or None
        Seed for ``numpy.random.default_rng``; ``None`` draws fresh entropy (recorded).
    length : float
        Size along x, ``nx·dx`` [length]; default 1.
    rms_height : float, optional
        Requested ``√m0 = √(mean((h − h̄)²))`` [length]. Default 1 when neither rms value is
        given.
    rms_slope : float, optional
        Requested ``√(⟨h_x²⟩ + ⟨h_y²⟩) = √(2·m2)`` with the *same non-periodic forward
        differences* as :func:`leakpath.moments.nayak_moments` (so ``nayak_moments`` reports
        exactly ``m2 = rms_slope²/2``). Mutually exclusive with ``rms_height``.
    long_cutoff : float, optional
        Longest wavelength ``λ_L`` [length]; default the box size ``max(ny, nx)·dx`` (the
        lowest non-zero mode).
    short_cutoff : float, optional
        Shortest wavelength ``λ_s`` [length]; default ``2·dx`` (the Nyquist wavelength).

    Returns
    -------
    Surface
        Zero-mean heights; ``metadata`` records the generator and all parameters.

    Raises
    ------
    InvalidArgumentError (a ``ValueError``)
        ``hurst`` outside (0, 1); ``shape`` < 2 on an axis; both ``rms_height`` and
        ``rms_slope`` given; non-positive values; ``short_cutoff >= long_cutoff``; a band
        that contains no Fourier mode of the grid.
    ProblemTooLargeError (a ``MemoryError``)
        A grid whose estimated peak memory (:data:`SPECTRAL_BYTES_PER_POINT` bytes per
        point) exceeds :func:`generator_memory_limit`, refused before allocating.
    """
    ny, nx = _check_shape(shape)
    hurst_f = _validate.real(
        "hurst", hurst, low=0.0, high=1.0, low_open=True, high_open=True,
        what="a Hurst exponent in the open interval (0, 1)",
    )
    length_f = _check_positive_finite("length", length)
    seed_i = _check_seed(seed)
    if rms_height is not None and rms_slope is not None:
        raise InvalidArgumentError(
            "rms_height: give either rms_height or rms_slope, not both", argument="rms_height"
        )
    target_height = None
    target_slope = None
    if rms_slope is not None:
        target_slope = _check_positive_finite("rms_slope", rms_slope)
    else:
        target_height = _check_positive_finite(
            "rms_height", 1.0 if rms_height is None else rms_height
        )
    dx = length_f / nx
    try:
        _validate.spacing("dx", dx)
    except InvalidArgumentError:
        raise InvalidArgumentError(
            f"length: {length_f!r} gives a grid spacing dx = length/nx = {dx!r} out of range "
            "(dx² must be a normal double); express lengths in another unit"
        ) from None
    _check_spectral_size(ny, nx)
    lam_long = (
        max(ny, nx) * dx
        if long_cutoff is None
        else _check_positive_finite("long_cutoff", long_cutoff)
    )
    lam_short = (
        2.0 * dx if short_cutoff is None else _check_positive_finite("short_cutoff", short_cutoff)
    )
    if not lam_short < lam_long:
        raise InvalidArgumentError(
            f"short_cutoff: {lam_short!r} must be smaller than long_cutoff ({lam_long!r})"
        )
    q_long = 2.0 * math.pi / lam_long
    q_short = 2.0 * math.pi / lam_short

    qy = 2.0 * np.pi * np.fft.fftfreq(ny, dx)
    qx = 2.0 * np.pi * np.fft.rfftfreq(nx, dx)
    q = np.hypot(qy[:, None], qx[None, :])
    band = (q >= q_long * (1.0 - 1e-12)) & (q <= q_short * (1.0 + 1e-12))
    if not np.any(band):
        raise InvalidArgumentError(
            f"short_cutoff: no Fourier mode of the {ny}×{nx} grid (dx={dx!r}) lies between "
            f"long_cutoff={lam_long!r} and short_cutoff={lam_short!r}; widen the band"
        )
    amplitude = np.zeros_like(q)
    amplitude[band] = q[band] ** (-(1.0 + hurst_f))

    rng = np.random.default_rng(seed_i)
    white = rng.standard_normal((ny, nx))
    h = np.fft.irfft2(np.fft.rfft2(white) * amplitude, s=(ny, nx))
    h -= h.mean()
    if target_slope is not None:
        current = _moments.rms_slope(h, dx)
        target = target_slope
    else:
        current = float(np.sqrt(np.mean(h * h)))
        target = target_height  # type: ignore[assignment]
    if not current > 0.0:
        raise InvalidArgumentError(
            "short_cutoff: the band-limited surface is flat on this grid (only Nyquist modes "
            "in the band?); widen the band between long_cutoff and short_cutoff"
        )
    h *= target / current
    _check_height_scale(h, "rms_height" if target_slope is None else "rms_slope")
    metadata = {
        "generator": "spectral",
        "shape": [ny, nx],
        "hurst": hurst_f,
        "seed": seed_i,
        "length": length_f,
        "long_cutoff": lam_long,
        "short_cutoff": lam_short,
        "rms_height": target_height,
        "rms_slope": target_slope,
        "wavevector": "q = 2*pi/lambda [rad/length]",
    }
    return Surface(_Owned(h), dx, metadata)
