"""Rough surfaces: the :class:`Surface` container and its files (``docs/surfaces.md``).

Conventions
-----------
``heights[i, j]`` is a 2-D float64 array: axis 0 = rows = y, axis 1 = columns = x, uniform
spacing ``dx`` in both directions (square pixels). Each grid point is the centre of a
``dx × dx`` element, so a ``(ny, nx)`` surface covers ``ny·dx × nx·dx`` and has nominal area
``A0 = ny·nx·dx²``.

Units
-----
Lengths and heights share one length unit, :attr:`Surface.unit` (a name such as ``"µm"``
or ``"m"``, kept in ``metadata["unit"]``); areas are in ``unit²``, volumes in ``unit³``.
The default is :data:`DEFAULT_UNIT` (micrometres): the generators make surfaces in µm
(a 500 µm square with heights of about 1 µm), files without a unit are read as µm unless
``load(..., unit=...)`` says otherwise. The unit only names the numbers (tables, metadata,
figure labels); leakpath never converts them.

Slopes
------
Contact and flow use the small-slope (half-space, lubrication) model, which is accurate to
about ``h'_rms²/2``; :func:`check_slope` warns with :class:`leakpath.errors.SlopeWarning`
above :data:`MAX_RMS_SLOPE` (``docs/conventions.md``).

Generators (:func:`leakpath.rmd`, :func:`leakpath.spectral`) live in
:mod:`leakpath.generators`; the file readers behind :func:`load` in ``leakpath._readers``.

Files
-----
:meth:`Surface.save` writes ``.npz`` atomically; :func:`load` reads ``.npz``, ``.npy``,
plain-text matrices (``.txt``, ``.csv``, ``.dat``, ``.asc``) and, with the optional
``leakpath[io]`` extra, every format SurfaceTopography can read.
"""

from __future__ import annotations

import io
import json
import math
import os
import sys
import warnings
from collections.abc import Mapping
from dataclasses import InitVar, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from . import _validate
from ._io import atomic_write_bytes
from ._readers import (
    FILL_METHODS,
    TEXT_SUFFIXES,
    _check_path,
    _fill_undefined,
    _one_line,
    _read_any,
    _resolve_dx,
    memory_error,
)
from .errors import InvalidArgumentError, LeakpathError, ProblemTooLargeError, SlopeWarning
from .moments import Moments, nayak_moments

__all__ = [
    "Surface",
    "load",
    "check_slope",
    "DEFAULT_UNIT",
    "MAX_RMS_SLOPE",
    "FILL_METHODS",
    "TEXT_SUFFIXES",
]

#: Length unit of a surface that names none: the micrometre.
DEFAULT_UNIT = "µm"

#: Largest rms slope ``h'_rms = √(2 m2)`` the small-slope model is trusted for without a
#: warning: it replaces the surface normal by the vertical and the surface by its
#: projection, errors of order ``1 − cos θ ≈ θ²/2``: 4.5 % at 0.3 (docs/conventions.md).
MAX_RMS_SLOPE = 0.3


def check_unit(value: Any, name: str = "unit") -> str:
    """A length unit's name: a non-empty string of at most 32 printable characters."""
    if not isinstance(value, str) or not value.strip() or len(value) > 32:
        raise InvalidArgumentError(
            f"{name}: must be the name of a length unit such as 'µm' or 'm' (a non-empty "
            f"string of at most 32 characters), got {_validate.describe(value)}",
            argument=name,
        )
    if not value.isprintable():
        raise InvalidArgumentError(
            f"{name}: must be printable (no newlines or control characters), got {value!r}",
            argument=name,
        )
    return value.strip()


def check_slope(surface: Surface, *, stacklevel: int = 2) -> float:
    """The surface's rms slope ``h'_rms``; warns (:class:`leakpath.errors.SlopeWarning`),
    once per surface, when it exceeds :data:`MAX_RMS_SLOPE`, the small-slope model's limit.
    """
    slope = surface.rms_slope
    if slope > MAX_RMS_SLOPE and not surface.__dict__.get("_slope_warned"):
        surface.__dict__["_slope_warned"] = True
        warnings.warn(
            f"surface: rms slope {slope:.3g} exceeds {MAX_RMS_SLOPE:g}, where the small-slope "
            f"(half-space) contact and lubrication models stop being accurate (errors of "
            "order slope²/2); check the units of dx and "
            f"the heights (both in {surface.unit}), or use a coarser grid or a longer "
            "lateral size",
            SlopeWarning,
            stacklevel=max(stacklevel + 1, _caller_level()),
        )
    return slope


_PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__))


def _caller_level() -> int:
    """``stacklevel`` of the first frame outside the leakpath package, seen from
    :func:`warnings.warn` called in this module's caller (a warning points at user code,
    not at the sweep or generator that raised it)."""
    frame = sys._getframe(2)  # the caller of check_slope
    level = 2
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(
        _PACKAGE_DIR + os.sep
    ):
        frame = frame.f_back
        level += 1
    return level

FloatArray = npt.NDArray[np.float64]
PathLike = str | os.PathLike[str]


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
        Grid spacing (same in x and y), in ``unit``; positive and finite.
    metadata : dict, optional
        Free-form, JSON-serialisable description (generator, parameters, source file, …).
    unit : str, optional
        Length unit of ``dx`` and the heights (``"µm"``, ``"m"``, …), kept in
        ``metadata["unit"]``. Default: ``metadata["unit"]`` when present, else
        :data:`DEFAULT_UNIT` (``"µm"``).

    Raises
    ------
    InvalidArgumentError (a ``ValueError``)
        ``heights`` not a 2-D array of real numbers, empty, not finite or too large; ``dx``
        not a positive finite number or out of range; ``metadata`` not a mapping.
    """

    heights: FloatArray
    dx: float
    metadata: dict[str, Any] = field(default_factory=dict)
    unit: InitVar[str | None] = None

    def __post_init__(self, unit: str | None) -> None:
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
        if unit is None:
            unit = self.metadata.get("unit", self.metadata.get("length_unit", DEFAULT_UNIT))
        self.metadata["unit"] = check_unit(unit)
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
        return f"Surface(shape={self.shape}, dx={self.dx!r}, unit={self.unit!r}{extra})"

    # ------------------------------------------------------------------ properties
    @property
    def shape(self) -> tuple[int, int]:
        """Grid size ``(ny, nx)``."""
        ny, nx = self.heights.shape
        return int(ny), int(nx)

    @property
    def rms_slope(self) -> float:
        """Root-mean-square slope ``h'_rms = √(⟨h_x²⟩ + ⟨h_y²⟩) = √(2 m2)`` with forward
        differences (dimensionless; :func:`leakpath.moments.rms_slope` to round-off), summed
        over blocks of rows so that it needs a few MiB whatever the grid. 0 for a surface
        with one point along both axes (an axis with one point has no differences)."""
        h = self.heights
        ny, nx = h.shape
        rows = max(1, (1 << 20) // max(nx, 1))  # ~8 MiB of differences per block
        sx = sy = 0.0
        for i in range(0, ny, rows):
            d = np.diff(h[i : i + rows], axis=1)
            sx += float(np.einsum("ij,ij->", d, d))
            d = np.diff(h[i : min(i + rows + 1, ny)], axis=0)
            sy += float(np.einsum("ij,ij->", d, d))
        mx = sx / (ny * (nx - 1)) if nx > 1 else 0.0
        my = sy / ((ny - 1) * nx) if ny > 1 else 0.0
        return math.sqrt(mx + my) / self.dx

    @property
    def length(self) -> tuple[float, float]:
        """Physical size ``(Ly, Lx) = (ny·dx, nx·dx)`` [unit], in array-axis order."""
        ny, nx = self.shape
        return ny * self.dx, nx * self.dx

    @property
    def nominal_area(self) -> float:
        """Nominal area ``A0 = ny·nx·dx²`` [unit²] (each point is a ``dx × dx`` element)."""
        ny, nx = self.shape
        return ny * nx * self.dx * self.dx

    @property
    def height_range(self) -> float:
        """Peak-to-valley height ``h_s = max h − min h`` [unit]."""
        return float(np.max(self.heights) - np.min(self.heights))

    @property
    def mean_height(self) -> float:
        """Mean height ``h̄`` [unit]."""
        return float(np.mean(self.heights))

    @property
    def rms_height(self) -> float:
        """Root-mean-square height about the mean, ``√(mean((h − h̄)²)) = √m0`` [unit]."""
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
        target = _validate.path("path", path)
        overwrite = _validate.flag("overwrite", overwrite)
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
        buf = io.BytesIO()
        np.savez(
            buf,
            heights=self.heights,
            dx=np.float64(self.dx),
            metadata=np.array(meta_json),
            format_version=np.int64(_NPZ_FORMAT_VERSION),
        )
        return atomic_write_bytes(target, buf.getvalue(), overwrite=overwrite)

    @classmethod
    def load(
        cls,
        path: PathLike,
        dx: float | None = None,
        fill: str | None = None,
        unit: str | None = None,
    ) -> Surface:
        """Read a surface from ``path``; see :func:`leakpath.surfaces.load`."""
        return load(path, dx=dx, fill=fill, unit=unit)


def _get_unit(self: Surface) -> str:
    return str(self.metadata.get("unit", DEFAULT_UNIT))


def _set_unit(self: Surface, value: str) -> None:
    self.metadata["unit"] = check_unit(value)


# The unit lives in the metadata (saved with it); the attribute reads and checks it.
Surface.unit = property(  # type: ignore[assignment,method-assign]
    _get_unit, _set_unit, doc="Length unit of ``dx`` and the heights (``metadata['unit']``)."
)


# ---------------------------------------------------------------------------- loading
def load(
    path: PathLike, *, dx: float | None = None, fill: str | None = None, unit: str | None = None
) -> Surface:
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
        Grid spacing [unit]. Required when the file does not store it; when it does, a
        different ``dx`` is an error (build ``Surface(s.heights, new_dx)`` to rescale).
    fill : {"nearest", "mean"}, optional
        What to do with undefined points (NaN, infinite, masked by the instrument, or grid
        points missing from a point cloud). ``None`` (default): refuse the file, reporting
        how many there are — heights are never invented silently. ``"nearest"``: each takes
        the mean of its nearest defined points in grid steps, filled layer by layer from the
        defined region inwards. ``"mean"``: the mean defined height. The count and method
        are recorded in ``metadata["filled"]``.
    unit : str, optional
        Length unit of the file's heights and spacing. Default: the unit the file records
        (a saved surface, SurfaceTopography's formats), else :data:`DEFAULT_UNIT` (µm). A
        unit different from the file's own is an error.

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
        A file too large to read into memory: sized before reading from the shapes and
        dtypes its ``.npy`` headers declare (an ``.npz`` by its members' uncompressed sizes
        too) plus the float64 copies, or a read that ran out of memory anyway.
    ImportError
        A non-native format without the optional SurfaceTopography package.
    """
    dx_arg = None if dx is None else _validate.spacing("dx", dx)
    method = None if fill is None else _validate.choice("fill", fill, FILL_METHODS)
    unit_arg = None if unit is None else check_unit(unit)
    p, info = _check_path(path)
    try:
        return _load_checked(p, info.st_size, dx_arg, method, unit_arg)
    except ProblemTooLargeError:
        raise
    except MemoryError:  # the estimate fitted, the allocation did not
        raise memory_error(p, info.st_size) from None


def _load_checked(
    p: Path, size: int, dx_arg: float | None, method: str | None, unit_arg: str | None = None
) -> Surface:
    """:func:`load` of a checked path and arguments."""
    try:
        raw = _read_any(p, size, dx_arg)
    except (ImportError, FileNotFoundError, LeakpathError, MemoryError):
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
    if unit_arg is not None:
        stored = metadata.get("unit", metadata.get("length_unit"))
        if stored is not None and str(stored) != unit_arg:
            raise InvalidArgumentError(
                f"unit: {unit_arg!r} differs from the file's own unit {str(stored)!r}; omit "
                "unit, or convert the heights and dx yourself",
                argument="unit",
            )
        metadata["unit"] = unit_arg
    surface = Surface(_Owned(heights), _resolve_dx(p, raw.dx_file, dx_arg), metadata)
    surface.metadata.setdefault("source", str(p))
    return surface


