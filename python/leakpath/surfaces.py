"""Rough surfaces: the :class:`Surface` container, generators and file I/O (DESIGN §2).

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
import numbers
import os
import secrets
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from . import moments as _moments
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
    """Return ``float(value)`` or raise ``ValueError`` naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    out = float(value)
    if not (math.isfinite(out) and out > 0.0):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return out


def _check_seed(seed: Any) -> int:
    """Validate a seed; ``None`` draws fresh OS entropy (recorded in the metadata)."""
    if seed is None:
        return int(np.random.SeedSequence().entropy)  # type: ignore[arg-type]
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise ValueError(f"seed must be a non-negative integer or None, got {seed!r}")
    if int(seed) < 0:
        raise ValueError(f"seed must be a non-negative integer or None, got {seed!r}")
    return int(seed)


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
    ValueError
        ``heights`` not 2-D, empty or not finite; ``dx`` not a positive finite number;
        ``metadata`` not a mapping.
    """

    heights: FloatArray
    dx: float
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        try:
            arr = np.ascontiguousarray(self.heights, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"heights must be a 2-D array of numbers: {exc}") from exc
        if arr.ndim != 2:
            raise ValueError(f"heights must be a 2-D array (ny, nx), got {arr.ndim} dimension(s)")
        if arr.shape[0] < 1 or arr.shape[1] < 1:
            raise ValueError(f"heights must have at least one point per axis, got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            bad = int(arr.size - np.count_nonzero(np.isfinite(arr)))
            raise ValueError(
                f"heights contains {bad} NaN or infinite value(s); fill or crop them first"
            )
        self.heights = arr
        self.dx = _check_positive_finite("dx", self.dx)
        if not isinstance(self.metadata, Mapping):
            raise ValueError(f"metadata must be a dict, got {type(self.metadata).__name__}")
        self.metadata = dict(self.metadata)

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
    def load(cls, path: PathLike, dx: float | None = None) -> Surface:
        """Read a surface from ``path``; see :func:`leakpath.surfaces.load`."""
        return load(path, dx=dx)


# ---------------------------------------------------------------------------- loading
def _resolve_dx(path: Path, dx_file: float | None, dx_arg: float | None) -> float:
    """Combine the file's spacing with the caller's ``dx``; they must agree if both exist."""
    if dx_arg is not None:
        dx_arg = _check_positive_finite("dx", dx_arg)
    if dx_file is None:
        if dx_arg is None:
            raise ValueError(
                f"dx is required to read {str(path)!r}: the file does not store the grid spacing"
            )
        return dx_arg
    if dx_arg is not None and not math.isclose(dx_arg, dx_file, rel_tol=1e-12):
        raise ValueError(
            f"dx={dx_arg!r} differs from the spacing {dx_file!r} stored in {str(path)!r}; "
            "omit dx, or build Surface(heights, new_dx) to rescale"
        )
    return dx_file


def _load_npz(path: Path, dx: float | None) -> Surface:
    with np.load(path, allow_pickle=False) as data:
        keys = list(data.files)
        if "heights" in keys:
            heights = data["heights"]
        elif len(keys) == 1:
            heights = data[keys[0]]
        else:
            raise ValueError(f"{str(path)!r} has no 'heights' array (arrays: {keys})")
        dx_file = float(data["dx"]) if "dx" in keys else None
        metadata: dict[str, Any] = {}
        if "metadata" in keys:
            loaded = json.loads(str(data["metadata"][()]))
            if isinstance(loaded, dict):
                metadata = loaded
    return Surface(heights, _resolve_dx(path, dx_file, dx), metadata)


def _load_text(path: Path) -> FloatArray:
    with open(path, encoding="utf-8", errors="replace") as fh:
        sample = ""
        for line in fh:
            stripped = line.strip()
            if stripped and not stripped.startswith("#"):
                sample = stripped
                break
    delimiter = "," if "," in sample else (";" if ";" in sample else None)
    arr = np.loadtxt(path, delimiter=delimiter, comments="#", ndmin=2, dtype=np.float64)
    return np.asarray(arr, dtype=np.float64)


def _load_surface_topography(path: Path, dx: float | None) -> Surface:
    try:
        import SurfaceTopography as st  # noqa: N813
    except ImportError as exc:
        raise ImportError(
            f"reading {path.suffix or 'extension-less'!s} files such as {str(path)!r} needs the "
            'optional SurfaceTopography package: pip install "leakpath[io]" (or save the '
            "heights as .npy/.csv and pass dx)"
        ) from exc
    with st.open_topography(str(path)) as reader:
        channel = getattr(reader, "default_channel", None) or reader.channels[0]
        if getattr(channel, "dim", 2) != 2:
            raise ValueError(f"{str(path)!r} holds a line scan, not a 2-D topography map")
        kwargs: dict[str, Any] = {}
        if channel.physical_sizes is None:
            if dx is None:
                raise ValueError(
                    f"dx is required to read {str(path)!r}: the file has no physical size"
                )
            step = _check_positive_finite("dx", dx)
            kwargs["physical_sizes"] = tuple(float(n) * step for n in channel.nb_grid_pts)
        topo = channel.topography(**kwargs)
    # SurfaceTopography indexes heights[ix, iy] (axis 0 = x); leakpath uses axis 1 = x.
    heights = np.asarray(topo.heights(), dtype=np.float64).T
    nx, ny = (int(n) for n in topo.nb_grid_pts)
    sx, sy = (float(s) for s in topo.physical_sizes)
    dx_x, dx_y = sx / nx, sy / ny
    if not math.isclose(dx_x, dx_y, rel_tol=1e-9):
        raise ValueError(
            f"{str(path)!r} has non-square pixels ({dx_x!r} × {dx_y!r}); leakpath needs one "
            "spacing dx for both axes — resample the topography first"
        )
    dx_final = _resolve_dx(path, dx_x, dx)
    meta: dict[str, Any] = {"source": str(path), "reader": "SurfaceTopography"}
    info = getattr(topo, "info", None)
    if isinstance(info, Mapping) and "unit" in info:
        meta["unit"] = str(info["unit"])
    return Surface(heights, dx_final, meta)


def load(path: PathLike, *, dx: float | None = None) -> Surface:
    """Read a surface from a file.

    ===================================  =====================================================
    suffix                               contents
    ===================================  =====================================================
    ``.npz``                             written by :meth:`Surface.save`: ``heights``, ``dx``
                                         and JSON ``metadata`` (an archive with a single array
                                         or a ``heights`` array but no ``dx`` needs ``dx=``)
    ``.npy``                             a 2-D array; ``dx`` required
    ``.txt`` ``.csv`` ``.dat`` ``.asc``  a plain matrix, one grid row per line, comma-,
                                         semicolon- or whitespace-separated, ``#`` comments;
                                         ``dx`` required
    anything else                        SurfaceTopography's readers (``pip install
                                         "leakpath[io]"``); ``dx`` from the file, or required
                                         if the file has no physical size. Heights are
                                         transposed to leakpath's axis 1 = x convention.
    ===================================  =====================================================

    Parameters
    ----------
    path : str or os.PathLike
        File to read.
    dx : float, optional
        Grid spacing [length]. Required when the file does not store it; when it does, a
        different ``dx`` is an error (build ``Surface(s.heights, new_dx)`` to rescale).

    Returns
    -------
    Surface
        With ``metadata["source"]`` set to the path.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    ValueError
        The file cannot be parsed, is not a 2-D finite matrix, or ``dx`` is missing/invalid.
    ImportError
        A non-native format without the optional SurfaceTopography package.
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"surface file {str(p)!r} not found")
    if p.is_dir():
        raise ValueError(f"{str(p)!r} is a directory, not a surface file")
    suffix = p.suffix.lower()
    try:
        if suffix == ".npz":
            surface = _load_npz(p, dx)
        elif suffix == ".npy":
            heights = np.load(p, allow_pickle=False)
            surface = Surface(heights, _resolve_dx(p, None, dx))
        elif suffix in TEXT_SUFFIXES:
            surface = Surface(_load_text(p), _resolve_dx(p, None, dx))
        else:
            surface = _load_surface_topography(p, dx)
    except (ImportError, FileNotFoundError):
        raise
    except ValueError as exc:
        if str(p) in str(exc):
            raise
        raise ValueError(f"cannot read surface file {str(p)!r}: {exc}") from exc
    except Exception as exc:  # corrupt archives, unreadable files, reader failures
        raise ValueError(f"cannot read surface file {str(p)!r}: {exc}") from exc
    surface.metadata.setdefault("source", str(p))
    return surface


# ---------------------------------------------------------------------------- RMD
def _rmd_check_m(m: Any) -> int:
    if isinstance(m, bool) or not isinstance(m, numbers.Integral):
        raise ValueError(f"m must be an integer (grid (2^m + 1)²), got {m!r}")
    m_int = int(m)
    if m_int < 1:
        raise ValueError(f"m must be >= 1 (grid (2^m + 1)²), got {m_int}")
    n = 2**m_int + 1
    estimate = 3 * 8 * n * n
    if estimate > RMD_MEMORY_LIMIT_BYTES:
        raise ValueError(
            f"m={m_int} is too large: a {n}×{n} grid needs about {estimate / 2**30:.1f} GiB "
            f"(limit {RMD_MEMORY_LIMIT_BYTES / 2**30:.0f} GiB); use m <= 14"
        )
    return m_int


def _check_fractal_dimension(D: Any) -> float:  # noqa: N803
    if isinstance(D, bool) or not isinstance(D, numbers.Real):
        raise ValueError(f"D (fractal dimension) must be a number in (2, 3), got {D!r}")
    d = float(D)
    if not (math.isfinite(d) and 2.0 < d < 3.0):
        raise ValueError(f"D (fractal dimension) must lie in the open interval (2, 3), got {D!r}")
    return d


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
        peak memory ``3·8·(2^m + 1)²`` bytes must not exceed 8 GiB).
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
    ValueError
        Invalid ``m``, ``D``, ``seed``, ``sigma0`` or ``length`` (the message names it).
    """
    m_int = _rmd_check_m(m)
    d_frac = _check_fractal_dimension(D)
    sigma0_f = _check_positive_finite("sigma0", sigma0)
    length_f = _check_positive_finite("length", length)
    seed_i = _check_seed(seed)
    hurst = 3.0 - d_frac

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
    metadata = {
        "generator": "rmd",
        "m": m_int,
        "D": d_frac,
        "H": hurst,
        "seed": seed_i,
        "sigma0": sigma0_f,
        "length": length_f,
    }
    return Surface(h, length_f / big_n, metadata)


# ---------------------------------------------------------------------------- spectral
def _check_shape(shape: Any) -> tuple[int, int]:
    if isinstance(shape, numbers.Integral) and not isinstance(shape, bool):
        dims: tuple[Any, ...] = (shape, shape)
    elif isinstance(shape, (tuple, list)) and len(shape) == 2:
        dims = tuple(shape)
    else:
        raise ValueError(f"shape must be an int or a pair (ny, nx), got {shape!r}")
    out = []
    for n in dims:
        if isinstance(n, bool) or not isinstance(n, numbers.Integral) or int(n) < 2:
            raise ValueError(f"shape must have integer sizes >= 2 per axis, got {shape!r}")
        out.append(int(n))
    return out[0], out[1]


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
    ValueError
        ``hurst`` outside (0, 1); ``shape`` < 2 on an axis; both ``rms_height`` and
        ``rms_slope`` given; non-positive values; ``short_cutoff >= long_cutoff``; a band
        that contains no Fourier mode of the grid.
    """
    ny, nx = _check_shape(shape)
    if isinstance(hurst, bool) or not isinstance(hurst, numbers.Real):
        raise ValueError(f"hurst must be a number in (0, 1), got {hurst!r}")
    hurst_f = float(hurst)
    if not (math.isfinite(hurst_f) and 0.0 < hurst_f < 1.0):
        raise ValueError(f"hurst must lie in the open interval (0, 1), got {hurst!r}")
    length_f = _check_positive_finite("length", length)
    seed_i = _check_seed(seed)
    if rms_height is not None and rms_slope is not None:
        raise ValueError("give either rms_height or rms_slope, not both")
    target_height = None
    target_slope = None
    if rms_slope is not None:
        target_slope = _check_positive_finite("rms_slope", rms_slope)
    else:
        target_height = _check_positive_finite(
            "rms_height", 1.0 if rms_height is None else rms_height
        )
    dx = length_f / nx
    lam_long = (
        max(ny, nx) * dx
        if long_cutoff is None
        else _check_positive_finite("long_cutoff", long_cutoff)
    )
    lam_short = (
        2.0 * dx if short_cutoff is None else _check_positive_finite("short_cutoff", short_cutoff)
    )
    if not lam_short < lam_long:
        raise ValueError(
            f"short_cutoff ({lam_short!r}) must be smaller than long_cutoff ({lam_long!r})"
        )
    q_long = 2.0 * math.pi / lam_long
    q_short = 2.0 * math.pi / lam_short

    qy = 2.0 * np.pi * np.fft.fftfreq(ny, dx)
    qx = 2.0 * np.pi * np.fft.rfftfreq(nx, dx)
    q = np.hypot(qy[:, None], qx[None, :])
    band = (q >= q_long * (1.0 - 1e-12)) & (q <= q_short * (1.0 + 1e-12))
    if not np.any(band):
        raise ValueError(
            f"no Fourier mode of the {ny}×{nx} grid (dx={dx!r}) lies between long_cutoff="
            f"{lam_long!r} and short_cutoff={lam_short!r}; widen the band"
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
        raise ValueError(
            "the band-limited surface is flat on this grid (only Nyquist modes in the band?); "
            "widen the band between long_cutoff and short_cutoff"
        )
    h *= target / current
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
    return Surface(h, dx, metadata)
