"""Sweeps over the imposed approach: the paper's experiment as a table (``docs/conventions.md``).

A sweep presses one rough surface against the rigid flat at a sequence of increasing imposed
approaches ``Δ_0 < Δ_1 < …`` and records, per level, the contact, the free volume, its
percolation classes along both in-plane axes and Nayak's moments of the deformed surface.

Levels
------
By default ``Δ_k = k·Δ_max/levels``, ``k = 0 … levels`` (``levels + 1`` rows), where
``Δ_max = h_s = max h − min h`` for ``boundary="free"`` (the paper: ``k·h_s/20``) and
``Δ_max = max h − mean h`` (full contact) for ``boundary="periodic"``. Row ``k = 0`` is the
undeformed state (the flat just touches the highest point; ``p = 0``).

Columns (lengths ``L`` in the surface's unit, pressures in the unit of ``E``)
------------------------------------------------------------------------------
=====================  ================================================================  =====
column                 definition                                                        unit
=====================  ================================================================  =====
``k``                  level index
``approach``           imposed approach ``Δ``                                            L
``approach_star``      ``Δ* = Δ/h_s``
``n_contact``          ``#(p > 0)``
``contact_fraction``   ``a = #(p > 0)/N``
``contact_area``       ``A = #(p > 0)·dx²``                                              L²
``load``               ``F = dx² Σ p``                                                   E·L²
``mean_pressure``      ``p̄ = F/A0``, ``A0 = N·dx²``                                      E
``free_volume``        ``V = dx² Σ g``, gap ``g = max h − Δ − h + u``                    L³
``free_volume_star``   ``V* = V/(A0·σ)``, ``σ = √m0`` of the undeformed surface
``mean_gap``           ``ḡ = V/A0``                                                      L
``mean_gap_star``      ``ḡ* = ḡ/ḡ(Δ = 0)``
``V_pg``               percolating volume for the chosen ``axis``                        L³
``V_pg_star``          ``V_pg* = V_pg/V_pg(Δ = 0)`` (chosen ``axis``)
``V_pg_axis0``         volume of the free clusters spanning axis 0 (first to last row)   L³
``V_dead_axis0``       clusters touching the boundary without spanning axis 0            L³
``V_trapped_axis0``    clusters touching no boundary                                     L³
``n_spanning_axis0``   number of clusters spanning axis 0
``…_axis1``            the same for flow along axis 1 (first to last column)
``m0 m2 m4 alpha``     Nayak's moments of the deformed surface ``s = h − u``             L², 1,
                       (:func:`leakpath.moments.nayak_moments`, finite differences)      L⁻², 1
``m0_star`` …          each divided by its value for the undeformed surface
``solver``             the solver that ran (``"auto"``: ``polonsky-keer+active-set``)
``iterations``         solver iterations (summed over restarts)
``kkt_restarts``       exact re-solves from the returned contact set needed to reach the
                       KKT acceptance threshold :data:`KKT_ACCEPT` (normally 0)
``kkt``                KKT certificate of the accepted solution, relative to ``h_s``
``Q K K_star``         leak rate, permeability and ``K/K(Δ = 0)`` along ``flow_axis``     L³, L³,
                       (:mod:`leakpath.leakage`; NaN with ``flow=False``)                1
=====================  ================================================================  =====

``V = V_pg + V_dead + V_trapped`` for each axis (to round-off). Wall-clock ``seconds`` per
level are kept in :attr:`SweepResult.seconds` and in the JSON metadata, not in the CSV: the
CSV holds only numbers that a rerun reproduces bit for bit.

Warm starts and reproducibility
-------------------------------
``warm_start=True`` starts level ``k`` from the *contact mask* of level ``k − 1`` (passed as
``warm_start=mask`` to :meth:`leakpath.contact.ContactProblem.solve`, which rebuilds its
factor from that set). The numbers of level ``k`` are then a deterministic function of the
surface, ``Δ_k`` and the previous mask, so a sweep resumed from a checkpoint (which stores
the masks) produces a byte-identical CSV. ``warm_start=False`` solves every level from
``p = 0`` ("without warm starting", as in the paper). The Polonsky–Keer solver is always
started cold in a sweep (it would need the previous pressure field, not a mask).

Checkpoints
-----------
With ``checkpoint_dir``, a ``manifest.json`` records what the sweep is (surface hash,
approaches, solver options); each finished level is written atomically as
``level_KKKK.json`` (its row, its wall time, its contact mask and percolation class map, both
compressed) and, with ``keep_fields``, ``level_KKKK.npz`` (pressure, gap, labels). Rerunning
the same sweep with the same ``checkpoint_dir`` loads the finished levels instead of solving
them again; a different sweep in that directory is refused (``ValueError``).
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import io
import json
import math
import os
import platform
import secrets
import struct
import sys
import time
import warnings
import zlib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from . import __version__, _validate, leakage  # leakage: leak-rate columns Q, K, K_star
from .contact import AUTO_ACTIVE_SET_MAX_POINTS, SOLVERS, ContactProblem, ContactState
from .errors import InvalidArgumentError, NotConvergedError
from .moments import nayak_moments
from .surfaces import Surface

if TYPE_CHECKING:  # pragma: no cover
    from .percolation import Percolation

__all__ = [
    "sweep",
    "SweepResult",
    "CheckpointMismatch",
    "COLUMNS",
    "CSV_COLUMNS",
    "KKT_ACCEPT",
    "atomic_write_bytes",
    "atomic_write_text",
    "surface_sha256",
    "machine_info",
]

PathLike = str | os.PathLike[str]

#: Largest KKT certificate (relative to ``h_s``) a sweep accepts from a solve. A larger one
#: triggers an exact re-solve warm-started from the returned contact set; if that does not
#: reach it either, the sweep raises ``RuntimeError``.
KKT_ACCEPT = 1e-8

#: Axes accepted by ``axis`` (``docs/conventions.md``).
AXES: tuple[Any, ...] = (0, 1, "either", "both")

_CHECKPOINT_FORMAT = 3  # 2: bound to their run, checksummed, pressure fields; 3: Q and K

# (name, type) of every column, in CSV order. Types: "f" float, "i" int, "s" str.
_COLUMN_SPEC: tuple[tuple[str, str], ...] = (
    ("k", "i"),
    ("approach", "f"),
    ("approach_star", "f"),
    ("n_contact", "i"),
    ("contact_fraction", "f"),
    ("contact_area", "f"),
    ("load", "f"),
    ("mean_pressure", "f"),
    ("mean_pressure_star", "f"),
    ("free_volume", "f"),
    ("free_volume_star", "f"),
    ("mean_gap", "f"),
    ("mean_gap_star", "f"),
    ("V_pg", "f"),
    ("V_pg_star", "f"),
    ("V_pg_axis0", "f"),
    ("V_dead_axis0", "f"),
    ("V_trapped_axis0", "f"),
    ("n_spanning_axis0", "i"),
    ("V_pg_axis1", "f"),
    ("V_dead_axis1", "f"),
    ("V_trapped_axis1", "f"),
    ("n_spanning_axis1", "i"),
    ("m0", "f"),
    ("m2", "f"),
    ("m4", "f"),
    ("alpha", "f"),
    ("m0_star", "f"),
    ("m2_star", "f"),
    ("m4_star", "f"),
    ("alpha_star", "f"),
    ("solver", "s"),
    ("iterations", "i"),
    ("kkt_restarts", "i"),
    ("kkt", "f"),
) + leakage.FLOW_COLUMNS  # leak-rate columns (leakpath.leakage)

#: Every column of :attr:`SweepResult.rows`, in CSV order.
COLUMNS: tuple[str, ...] = tuple(name for name, _ in _COLUMN_SPEC)
#: The CSV columns (the same as :data:`COLUMNS`).
CSV_COLUMNS: tuple[str, ...] = COLUMNS
_TYPES: dict[str, str] = dict(_COLUMN_SPEC)
_STAR_COLUMNS = (
    "approach_star",
    "mean_pressure_star",
    "free_volume_star",
    "mean_gap_star",
    "V_pg_star",
    "m0_star",
    "m2_star",
    "m4_star",
    "alpha_star",
    "K_star",  # leakpath.leakage
)
#: Columns a level computes itself (the dimensionless ones follow from the reference).
_LEVEL_COLUMNS = tuple(c for c in COLUMNS if c not in _STAR_COLUMNS)


def _units(length: str, pressure: str) -> dict[str, str]:
    """Unit of every column, with ``length``/``pressure`` the surface's and E's unit names."""
    L, P = length, pressure  # noqa: N806
    units = {c: "1" for c in COLUMNS}
    units.update(
        approach=L,
        contact_area=f"{L}^2",
        load=f"{P}*{L}^2",
        mean_pressure=P,
        free_volume=f"{L}^3",
        mean_gap=L,
        m0=f"{L}^2",
        m4=f"{L}^-2",
        solver="",
    )
    for c in COLUMNS:
        if c.startswith(("V_pg", "V_dead", "V_trapped")) and not c.endswith("_star"):
            units[c] = f"{L}^3"
    units.update({c: u.format(L=L) for c, u in leakage.FLOW_UNITS.items()})  # leakage
    return units


# ---------------------------------------------------------------------------- file helpers
def atomic_write_bytes(path: PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically.

    The bytes go to a fresh hidden temporary file in the same directory, are flushed and
    fsync'ed, and the file is moved over ``path`` with :func:`os.replace`; a reader (or a run
    killed half-way) never sees a partial file. The directory must exist.
    """
    target = Path(path)
    directory = target.parent if str(target.parent) else Path(".")
    tmp = directory / f".{target.name}.{os.getpid()}.{secrets.token_hex(6)}.tmp"
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    finally:
        if tmp.exists():
            tmp.unlink()
    return target


def atomic_write_text(path: PathLike, text: str) -> Path:
    """:func:`atomic_write_bytes` for UTF-8 text."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def _json_value(value: Any) -> Any:
    """JSON-safe value: non-finite floats become ``None``; numpy scalars become Python ones."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Mapping):
        return {str(k): _json_value(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_value(v) for v in value]
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    return value


def _dumps(obj: Any) -> str:
    return json.dumps(_json_value(obj), indent=1, allow_nan=False, ensure_ascii=False) + "\n"


def _pack(array: np.ndarray) -> str:
    """Compress an array's raw bytes (zlib) and encode them as base64 text."""
    return base64.b64encode(zlib.compress(np.ascontiguousarray(array).tobytes(), 6)).decode()


def _unpack(text: str, dtype: npt.DTypeLike, shape: tuple[int, ...]) -> np.ndarray:
    raw = zlib.decompress(base64.b64decode(text.encode()))
    return np.frombuffer(raw, dtype=dtype).reshape(shape).copy()


def _pack_mask(mask: np.ndarray) -> str:
    return _pack(np.packbits(mask.ravel()))


def _unpack_mask(text: str, shape: tuple[int, int]) -> np.ndarray:
    n = shape[0] * shape[1]
    bits = _unpack(text, np.uint8, (-1,))
    return np.unpackbits(bits, count=n).astype(bool).reshape(shape)


def surface_sha256(surface: Surface) -> str:
    """SHA-256 (hex) of the heights as little-endian float64 bytes (C order), then ``dx``.

    ``sha256(heights.astype('<f8').tobytes() + struct.pack('<d', dx))``; the shape is not
    hashed (record it next to the digest).
    """
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(surface.heights, dtype="<f8").tobytes())
    h.update(struct.pack("<d", float(surface.dx)))
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


# ---------------------------------------------------------------------------- CSV
def _format_cell(name: str, value: Any) -> str:
    kind = _TYPES[name]
    if kind == "f":
        return repr(float(value))  # shortest string that round-trips exactly
    if kind == "i":
        return str(int(value))
    text = str(value)
    if any(c in text for c in ',"\n\r'):
        text = '"' + text.replace('"', '""') + '"'
    return text


def _csv_text(rows: Sequence[Mapping[str, Any]], columns: Sequence[str] = CSV_COLUMNS) -> str:
    lines = [",".join(columns)]
    lines += [",".join(_format_cell(c, row[c]) for c in columns) for row in rows]
    return "\n".join(lines) + "\n"


def _coerce_cell(name: str, value: Any) -> Any:
    kind = _TYPES[name]
    if kind == "f":
        return float("nan") if value is None else float(value)
    if kind == "i":
        return int(value)
    return str(value)


# ---------------------------------------------------------------------------- result
@dataclass(eq=False)
class SweepResult:
    """The table of a sweep, its parameters and the surface it was run on.

    Attributes
    ----------
    rows : list of dict
        One dict per level, keys :data:`COLUMNS` (floats, ints and the solver name).
    parameters : dict
        The arguments of :func:`sweep` (``approaches`` resolved to the list used).
    surface : Surface
        The undeformed surface.
    reference : dict
        Undeformed values the dimensionless columns divide by: ``h_s``, ``A0``, ``sigma``
        (√m0), ``mean_gap`` and ``V_pg`` at ``Δ = 0`` (chosen axis), ``m0 m2 m4 alpha``.
    seconds : list of float
        Wall time of each level's solve and analysis (as first computed, also when loaded
        from a checkpoint).
    resumed : list of int
        Levels loaded from a checkpoint instead of computed in this call.
    recomputed : list of int
        Levels whose checkpoint record failed its integrity check (another run's, edited,
        truncated) and were computed again.
    fields : dict or None
        With ``keep_fields``: ``pressure``, ``gap`` (float64) and ``labels`` (int32, cluster
        labels for the chosen axis), each ``(levels, ny, nx)``; otherwise ``None``.
    """

    rows: list[dict[str, Any]]
    parameters: dict[str, Any]
    surface: Surface
    reference: dict[str, float]
    seconds: list[float]
    resumed: list[int] = field(default_factory=list)
    recomputed: list[int] = field(default_factory=list)
    fields: dict[str, np.ndarray] | None = None
    total_seconds: float = 0.0
    _masks: list[str] = field(default_factory=list, repr=False)
    _classes: list[str] = field(default_factory=list, repr=False)

    def __len__(self) -> int:
        return len(self.rows)

    @property
    def columns(self) -> tuple[str, ...]:
        """Column names in CSV order."""
        return COLUMNS

    def column(self, name: str) -> np.ndarray:
        """One column as a numpy array (``float64``, ``int64`` or ``str``)."""
        if name not in _TYPES:
            raise KeyError(f"no column {name!r}; columns: {', '.join(COLUMNS)}")
        kind = _TYPES[name]
        dtype = {"f": np.float64, "i": np.int64, "s": str}[kind]
        return np.array([row[name] for row in self.rows], dtype=dtype)

    def to_array(self) -> np.ndarray:
        """The table as a numpy structured array (one record per level)."""
        width = max((len(str(r["solver"])) for r in self.rows), default=1)
        dtype = [(c, {"f": "<f8", "i": "<i8", "s": f"<U{width}"}[_TYPES[c]]) for c in COLUMNS]
        return np.array([tuple(r[c] for c in COLUMNS) for r in self.rows], dtype=dtype)

    def contact_mask(self, k: int) -> np.ndarray:
        """Boolean contact mask ``p > 0`` of row ``k``."""
        return _unpack_mask(self._masks[k], self.surface.shape)

    def class_map(self, k: int) -> np.ndarray:
        """Percolation classes of row ``k`` for the chosen axis (int8): 0 contact,
        1 spanning, 2 dead-end, 3 trapped (see :meth:`leakpath.percolation.Percolation.class_map`).
        """
        return _unpack(self._classes[k], np.int8, self.surface.shape)

    # ------------------------------------------------------------------ output
    def csv_text(self) -> str:
        """The CSV table: header + one line per level, floats as ``repr`` (exact round trip)."""
        return _csv_text(self.rows)

    def to_csv(self, path: PathLike) -> Path:
        """Write :meth:`csv_text` to ``path`` atomically; returns the path."""
        return atomic_write_text(path, self.csv_text())

    def metadata(self) -> dict[str, Any]:
        """Everything :meth:`to_json` writes, as a dict."""
        s = self.surface
        unit = s.metadata.get("unit", s.metadata.get("length_unit"))
        length_unit = str(unit) if unit else "L"
        rows = []
        for row, sec in zip(self.rows, self.seconds, strict=True):
            rows.append({**row, "seconds": sec})
        return {
            "leakpath_version": __version__,
            "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "parameters": dict(self.parameters),
            "surface": {
                "shape": list(s.shape),
                "dx": s.dx,
                "length": list(s.length),
                "unit": length_unit,
                "height_range": s.height_range,
                "sha256": surface_sha256(s),
                "sha256_of": "heights as little-endian float64 (C order) bytes, then dx as <f8",
                "seed": s.metadata.get("seed"),
                "generator": s.metadata.get("generator", s.metadata.get("source")),
                "metadata": dict(s.metadata),
            },
            "reference": dict(self.reference),
            "units": _units(length_unit, "E"),
            "columns": list(COLUMNS),
            "definitions": _DEFINITIONS,
            "machine": machine_info(),
            "total_seconds": self.total_seconds,
            "resumed_levels": list(self.resumed),
            "rows": rows,
        }

    def to_json(self, path: PathLike, extra: Mapping[str, Any] | None = None) -> Path:
        """Write :meth:`metadata` (parameters, versions, surface hash, machine, rows with
        their wall times) to ``path`` atomically as strict JSON (non-finite numbers → null).

        ``extra`` entries (e.g. the command line that ran) are added at the top level.
        """
        data = self.metadata()
        if extra:
            data = {**data, **dict(extra)}
        return atomic_write_text(path, _dumps(data))

    def save_fields(self, path: PathLike) -> Path:
        """Write the per-level fields to a compressed ``.npz`` atomically.

        Arrays: ``pressure``, ``gap`` (float64), ``labels`` (int32, cluster labels for the
        chosen axis), ``classes`` (int8 class maps), each ``(levels, ny, nx)``, plus
        ``approach`` (levels,) and ``dx``. Needs ``keep_fields=True`` in :func:`sweep`.
        """
        if self.fields is None:
            raise ValueError(
                "keep_fields: the sweep did not keep its fields; rerun with keep_fields=True"
            )
        classes = np.stack([self.class_map(k) for k in range(len(self.rows))])
        buf = io.BytesIO()
        np.savez_compressed(
            buf,
            approach=self.column("approach"),
            dx=np.float64(self.surface.dx),
            classes=classes,
            **self.fields,
        )
        return atomic_write_bytes(path, buf.getvalue())

    def plot(
        self,
        outdir: PathLike,
        formats: Sequence[str] = ("png", "pdf"),
        levels_to_map: Iterable[int] | None = None,
    ) -> list[Path]:
        """Write the paper's figures into ``outdir``; see
        :func:`leakpath.plots.save_paper_figures`."""
        from .plots import save_paper_figures

        return save_paper_figures(self, outdir, formats=formats, levels_to_map=levels_to_map)


_DEFINITIONS = {
    "approach_star": "Delta/h_s, h_s = max h - min h",
    "free_volume_star": "V/(A0*sigma), sigma = sqrt(m0) of the undeformed surface",
    "mean_gap_star": "mean_gap/mean_gap(Delta=0)",
    "V_pg_star": "V_pg/V_pg(Delta=0) for the chosen axis",
    **leakage.FLOW_DESCRIPTIONS,  # leakpath.leakage
    "m_star": "m_n/m_n(undeformed), alpha_star likewise",
    "gap": "g = max h - Delta - h + u",
    "moments": "finite differences on s = h - u (leakpath.moments.nayak_moments)",
}


# ---------------------------------------------------------------------------- validation
def _check_levels(levels: Any, shape: tuple[int, int], keep_fields: bool) -> int:
    n = _validate.integer("levels", levels, low=1, high=2**1024, what="an integer ≥ 1")
    # Each level keeps its row (~16 KiB with its approach), its packed contact mask and
    # class map (≤ 2 bytes per point compressed) and, with keep_fields, pressure, gap and
    # labels twice over (20 bytes per point, stacked at the end): refuse before solving.
    points = shape[0] * shape[1]
    per_level = 16 * 1024 + 2 * points + (40 * points if keep_fields else 0)
    limit = _validate.memory_budget()
    if (n + 1) * per_level > limit:
        raise _validate.too_large(
            "levels",
            f"a sweep of {n} levels on {shape[0]} × {shape[1]} points",
            (n + 1) * per_level,
            limit,
            f"use at most {max(limit // per_level - 1, 1)} levels",
        )
    return n


def _resolve_approaches(problem: ContactProblem, levels: int, approaches: Any) -> list[float]:
    limit = problem.max_approach
    if approaches is None:
        return [float(limit * k / levels) for k in range(levels + 1)]
    arr = _validate.real_array("approaches", approaches, ndim=1, finite=False)
    if arr.size == 0:
        raise InvalidArgumentError("approaches: must be a non-empty 1-D sequence of numbers")
    if not np.all(np.isfinite(arr)):
        raise InvalidArgumentError("approaches: every value must be finite")
    if np.any(arr < 0):
        raise InvalidArgumentError(f"approaches: must be ≥ 0, got min {arr.min()!r}")
    if np.any(np.diff(arr) <= 0):
        raise InvalidArgumentError("approaches: must be strictly increasing")
    if problem.boundary == "periodic" and arr[-1] > limit * (1 + 1e-12):
        raise InvalidArgumentError(
            f"approaches: {arr[-1]!r} exceeds full contact of a periodic surface, "
            f"max h − mean h = {limit!r}; give approaches ≤ that"
        )
    return [float(a) for a in arr]


def _resolve_mean_pressures(mean_pressures: Any) -> list[float]:
    arr = _validate.real_array("mean_pressures", mean_pressures, ndim=1, finite=False)
    if arr.size == 0:
        raise InvalidArgumentError("mean_pressures: must be a non-empty 1-D sequence of numbers")
    if not (np.all(np.isfinite(arr)) and np.all(arr > 0)):
        raise InvalidArgumentError("mean_pressures: every value must be finite and > 0")
    if np.any(np.diff(arr) <= 0):
        raise InvalidArgumentError("mean_pressures: must be strictly increasing")
    return [float(v) for v in arr]


def _check_axis(axis: Any) -> Any:
    return _validate.axis(axis)


def _check_connectivity(connectivity: Any) -> int:
    return _validate.connectivity(connectivity)


# ---------------------------------------------------------------------------- one level
@dataclass
class _Level:
    """Everything one level contributes: its row, timing, masks and optional fields."""

    row: dict[str, Any]
    seconds: float
    mask: str
    classes: str
    fields: dict[str, np.ndarray] | None = None
    #: The level's pressure field (float64, packed): the warm start of the next level, kept
    #: in checkpoints so that a resumed warm sweep repeats the same solves bit for bit.
    pressure: str | None = None


def _solve_accepted(
    problem: ContactProblem,
    level: tuple[str, float],
    solver: str,
    warm: bool | np.ndarray,
) -> tuple[ContactState, int, int]:
    """Solve one level (``("approach", Δ)`` or ``("mean_pressure", p̄)``), and re-solve
    exactly from the returned contact set while ``kkt > KKT_ACCEPT``.

    Returns the state, the iterations summed over the solves and the number of re-solves.
    """
    kind, value = level
    state = problem.solve(**{kind: value}, solver=solver, warm_start=warm)  # type: ignore[arg-type]
    approach = state.approach
    iterations = state.iterations
    restarts = 0
    while not (state.kkt <= KKT_ACCEPT):
        if restarts >= 2:
            raise NotConvergedError(
                f"solver: {solver!r} did not reach the KKT threshold {KKT_ACCEPT:g} at "
                f"approach {approach!r} (certificate {state.kkt:.3g} after {restarts} "
                "exact restarts); check the surface's units, or try solver='active-set'",
                solver=solver,
                iterations=iterations,
                residual=state.kkt,
            )
        restart_solver = "active-set" if solver in ("polonsky-keer", "auto") else solver
        state = problem.solve(approach, solver=restart_solver, warm_start=state.contact)  # type: ignore[arg-type]
        iterations += state.iterations
        restarts += 1
    return state, iterations, restarts


def _warm_start_for(
    done: Sequence[_Level], level_list: Sequence[tuple[str, float]], k: int, shape: Any
) -> np.ndarray:
    """Start of level ``k`` from the levels before it.

    With pressure fields (Polonsky–Keer): the linear extrapolation of the last two in the
    imposed value ``v`` (approach or mean pressure), clipped at 0,
    ``p = max(p₁ + (v_k − v₁)/(v₁ − v₀)·(p₁ − p₀), 0)`` — measured on the paper's sweep it
    saves about a fifth of the iterations over starting from ``p₁`` alone. Otherwise the
    previous contact mask (exact solvers). Only recorded fields enter, so a resumed sweep
    starts each level exactly as an uninterrupted one.
    """
    last = done[-1]
    if last.pressure is None:
        return _unpack_mask(last.mask, shape)
    p1 = _unpack(last.pressure, "<f8", shape)
    if len(done) < 2 or done[-2].pressure is None or k < 2:
        return p1
    v0, v1, vk = level_list[k - 2][1], level_list[k - 1][1], level_list[k][1]
    if not (v1 > v0 and v0 > 0):  # the Δ = 0 level carries no information on the slope
        return p1
    p0 = _unpack(done[-2].pressure, "<f8", shape)
    return np.maximum(p1 + (vk - v1) / (v1 - v0) * (p1 - p0), 0.0)


def _percolation_columns(perc: Percolation, suffix: str) -> dict[str, Any]:
    return {
        f"V_pg{suffix}": float(perc.spanning_volume),
        f"V_dead{suffix}": float(perc.dead_end_volume),
        f"V_trapped{suffix}": float(perc.trapped_volume),
        f"n_spanning{suffix}": int(perc.n_spanning),
    }


def _analyse(
    k: int,
    state: ContactState,
    *,
    iterations: int,
    restarts: int,
    axis: Any,
    connectivity: int,
    keep_fields: bool,
    t_start: float,
    keep_pressure: bool = False,
    flow_axis: int = 0,
    flow_on: bool = False,
) -> _Level:
    """Row, masks and fields of a solved level (``t_start``: when its solve began)."""
    p0 = state.percolation(axis=0, connectivity=connectivity)
    p1 = state.percolation(axis=1, connectivity=connectivity)
    pa = state.percolation(axis=axis, connectivity=connectivity)
    mom = nayak_moments(state.deformed, state.dx)
    n_contact = int(np.count_nonzero(state.contact))
    row: dict[str, Any] = {
        "k": k,
        "approach": float(state.approach),
        "n_contact": n_contact,
        "contact_fraction": state.contact_fraction,
        "contact_area": state.contact_area,
        "load": state.load,
        "mean_pressure": state.mean_pressure,
        "free_volume": state.free_volume,
        "mean_gap": state.mean_gap,
        "V_pg": float(pa.spanning_volume),
        **_percolation_columns(p0, "_axis0"),
        **_percolation_columns(p1, "_axis1"),
        "m0": mom.m0,
        "m2": mom.m2,
        "m4": mom.m4,
        "alpha": mom.alpha,
        "solver": state.solver,
        "iterations": int(iterations),
        "kkt_restarts": int(restarts),
        "kkt": float(state.kkt),
    }
    row.update(leakage.flow_columns(state, flow_axis, flow_on))  # Q, K (leakpath.leakage)
    classes = np.asarray(pa.class_map(), dtype=np.int8)
    fields = None
    if keep_fields:
        fields = {
            "pressure": np.array(state.pressure, dtype=np.float64),
            "gap": np.array(state.gap, dtype=np.float64),
            "labels": np.asarray(pa.labels, dtype=np.int32),
        }
    return _Level(
        row=row,
        seconds=time.perf_counter() - t_start,
        mask=_pack_mask(state.contact),
        classes=_pack(classes),
        fields=fields,
        pressure=_pack(np.asarray(state.pressure, dtype="<f8")) if keep_pressure else None,
    )


# ---------------------------------------------------------------------------- checkpoints
class CheckpointMismatch(ValueError):
    """``checkpoint_dir`` holds the checkpoints of a different sweep (``field`` differs)."""

    def __init__(self, directory: Path, field: str) -> None:
        self.directory = directory
        self.field = field
        super().__init__(
            f"checkpoint_dir: {str(directory)!r} holds a different sweep ({field} differs); "
            "use another directory or delete it to start afresh"
        )


class _Checkpoint:
    """A directory of finished levels: ``manifest.json`` + ``level_KKKK.json`` (+ ``.npz``).

    Every level record is bound to its run and to its own content: it carries the SHA-256 of
    the manifest (surface hash, parameters), its level index, and the SHA-256 of its own
    canonical JSON (and of its ``.npz`` fields file). A record that fails any check — another
    run's, edited, truncated, non-finite where a number is required — is not used: the level
    is computed again, and :attr:`recomputed` names it with the reason.
    """

    def __init__(self, directory: PathLike, manifest: dict[str, Any], keep_fields: bool):
        self.dir = Path(directory)
        self.keep_fields = keep_fields
        self.recomputed: list[tuple[int, str]] = []
        if self.dir.exists() and not self.dir.is_dir():
            raise InvalidArgumentError(
                f"checkpoint_dir: {str(self.dir)!r} exists and is not a directory",
                argument="checkpoint_dir",
            )
        self.dir.mkdir(parents=True, exist_ok=True)
        for stale in self.dir.glob(".*.tmp"):  # left by a run killed while writing
            try:
                stale.unlink()
            except OSError:
                pass
        path = self.dir / "manifest.json"
        text = _dumps(manifest)
        wanted = json.loads(text)
        self.run = hashlib.sha256(text.encode("utf-8")).hexdigest()
        if path.exists():
            try:
                found = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError) as exc:
                raise InvalidArgumentError(
                    f"checkpoint_dir: cannot read {str(path)!r} ({exc}); delete it to restart",
                    argument="checkpoint_dir",
                ) from None
            if isinstance(found, dict) and found.get("format") != wanted["format"]:
                raise CheckpointMismatch(
                    self.dir,
                    f"checkpoint format {found.get('format')!r}, this leakpath reads "
                    f"{wanted['format']} (format 3 adds the leak-rate columns Q, K)",
                )
            for key in _differences(found, wanted):
                raise CheckpointMismatch(self.dir, key)
        else:
            atomic_write_text(path, text)

    def _json(self, k: int) -> Path:
        return self.dir / f"level_{k:04d}.json"

    def _npz(self, k: int) -> Path:
        return self.dir / f"level_{k:04d}.npz"

    def load(self, k: int, shape: tuple[int, int], need_pressure: bool) -> _Level | None:
        """The checked level ``k``, or ``None`` (absent, or failed a check: see
        :attr:`recomputed`)."""
        path = self._json(k)
        if not path.exists():
            return None
        try:
            return self._load_checked(k, shape, need_pressure)
        except _BadCheckpoint as exc:
            self.recomputed.append((k, str(exc)))
            return None

    def _load_checked(self, k: int, shape: tuple[int, int], need_pressure: bool) -> _Level:
        try:
            data = json.loads(self._json(k).read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise _BadCheckpoint(f"unreadable ({exc.__class__.__name__})") from None
        if not isinstance(data, dict):
            raise _BadCheckpoint("not a level record")
        digest = data.pop("sha256", None)
        if digest != _record_digest(data):
            raise _BadCheckpoint("its content does not match its checksum")
        if data.get("run") != self.run:
            raise _BadCheckpoint("it belongs to another run (surface or parameters differ)")
        if data.get("k") != k or list(data.get("shape", [])) != list(shape):
            raise _BadCheckpoint("level index or shape differs")
        try:
            row = {c: _coerce_cell(c, data["row"][c]) for c in _LEVEL_COLUMNS}
            seconds = float(data["seconds"])
            mask, classes = str(data["mask"]), str(data["classes"])
            _unpack_mask(mask, shape)
            _unpack(classes, np.int8, shape)
            pressure = data.get("pressure")
            if need_pressure:
                if not isinstance(pressure, str):
                    raise _BadCheckpoint("no pressure field to warm-start the next level")
                if not np.all(np.isfinite(_unpack(pressure, "<f8", shape))):
                    raise _BadCheckpoint("non-finite pressure")
        except _BadCheckpoint:
            raise
        except (KeyError, TypeError, ValueError, zlib.error, binascii.Error) as exc:
            raise _BadCheckpoint(f"malformed ({exc.__class__.__name__}: {exc})") from None
        for c in _LEVEL_COLUMNS:
            v = row[c]
            nan_ok = ("kkt",) + leakage.FLOW_LEVEL_COLUMNS  # NaN: flow switched off
            if _TYPES[c] == "f" and c not in nan_ok and not math.isfinite(v):
                raise _BadCheckpoint(f"{c} is not finite")
            if _TYPES[c] == "i" and v < 0:
                raise _BadCheckpoint(f"{c} is negative")
        fields = None
        if self.keep_fields:
            try:
                raw = self._npz(k).read_bytes()
            except OSError:
                raise _BadCheckpoint("its fields file is missing") from None
            if hashlib.sha256(raw).hexdigest() != data.get("fields_sha256"):
                raise _BadCheckpoint("its fields file does not match its checksum")
            with np.load(io.BytesIO(raw), allow_pickle=False) as z:
                fields = {name: z[name] for name in ("pressure", "gap", "labels")}
        return _Level(row, seconds, mask, classes, fields, pressure)

    def save(self, k: int, level: _Level, shape: tuple[int, int]) -> None:
        record: dict[str, Any] = {
            "run": self.run,
            "k": k,
            "shape": list(shape),
            "row": {c: level.row[c] for c in _LEVEL_COLUMNS},
            "seconds": level.seconds,
            "mask": level.mask,
            "classes": level.classes,
        }
        if level.pressure is not None:
            record["pressure"] = level.pressure
        if level.fields is not None:
            buf = io.BytesIO()
            np.savez_compressed(buf, **level.fields)
            raw = buf.getvalue()
            atomic_write_bytes(self._npz(k), raw)
            record["fields_sha256"] = hashlib.sha256(raw).hexdigest()
        record = json.loads(_dumps(record))  # the JSON form that is hashed and read back
        record["sha256"] = _record_digest(record)
        atomic_write_text(self._json(k), _dumps(record))


class _BadCheckpoint(Exception):
    """A level record that must not be used (the message says why)."""


def _record_digest(record: Mapping[str, Any]) -> str:
    """SHA-256 of a record's canonical JSON (sorted keys, no ``sha256`` entry)."""
    body = {k: v for k, v in record.items() if k != "sha256"}
    text = json.dumps(body, sort_keys=True, allow_nan=False, ensure_ascii=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _differences(found: Any, wanted: Any, prefix: str = "") -> list[str]:
    """Dotted names of the entries where two JSON-like manifests differ."""
    if isinstance(found, dict) and isinstance(wanted, dict):
        out: list[str] = []
        for key in wanted:
            out += _differences(found.get(key), wanted[key], f"{prefix}{key}.")
        return out
    return [] if found == wanted else [prefix.rstrip(".") or "manifest"]


# ---------------------------------------------------------------------------- sweep
def _ratio(a: float, b: float) -> float:
    return a / b if (b != 0 and math.isfinite(b)) else float("nan")


def _finish_row(row: dict[str, Any], ref: Mapping[str, float], area: float) -> dict[str, Any]:
    out = dict(row)
    out["approach_star"] = _ratio(row["approach"], ref["h_s"])
    out["mean_pressure_star"] = _ratio(row["mean_pressure"], ref["e_star"])
    out["free_volume_star"] = _ratio(row["free_volume"], area * ref["sigma"])
    out["mean_gap_star"] = _ratio(row["mean_gap"], ref["mean_gap"])
    out["V_pg_star"] = _ratio(row["V_pg"], ref["V_pg"])
    for name in ("m0", "m2", "m4", "alpha"):
        out[f"{name}_star"] = _ratio(row[name], ref[name])
    out["K_star"] = leakage.flow_star(row, ref["K"])  # leakpath.leakage
    return {c: out[c] for c in COLUMNS}


def sweep(
    surface: Surface,
    *,
    levels: int = 20,
    approaches: Sequence[float] | np.ndarray | None = None,
    mean_pressures: Sequence[float] | np.ndarray | None = None,
    solver: str = "auto",
    warm_start: bool = True,
    axis: int | str = 0,
    connectivity: int = 4,
    E: float = 1.0,  # noqa: N803 - Young's modulus
    nu: float = 0.0,
    boundary: str = "free",
    keep_fields: bool = False,
    progress: bool = False,
    checkpoint_dir: PathLike | None = None,
    flow: bool | None = None,
    flow_axis: int | None = None,
) -> SweepResult:
    """Solve the contact of ``surface`` at increasing approaches and tabulate each level.

    Parameters
    ----------
    surface : Surface
        The undeformed rough surface (heights and ``dx`` in one length unit).
    levels : int
        Number of equal steps: ``Δ_k = k·Δ_max/levels``, ``k = 0 … levels``, with
        ``Δ_max = h_s`` (free) or ``max h − mean h`` (periodic). Ignored with ``approaches``.
    approaches : sequence of float, optional
        Explicit approaches [length]: strictly increasing, ``≥ 0`` (periodic: ``≤`` full
        contact, :attr:`ContactProblem.max_approach`).
    mean_pressures : sequence of float, optional
        Load control instead: strictly increasing mean pressures ``p̄ = F/A0 > 0`` [E's
        unit], one row each; the approach of each row is then the solver's output. The seal
        engineer's curve against nominal pressure (``mean_pressure_star = p̄/E*``).
    solver : str
        ``"auto"`` (default: Polonsky–Keer above a few thousand points, the exact active set
        below; see :meth:`ContactProblem.solve`), ``"polonsky-keer"``, ``"active-set"`` or
        ``"lawson-hanson"`` (the paper's one-point-per-iteration algorithm).
    warm_start : bool
        Start level ``k`` from level ``k − 1`` (default: Polonsky–Keer from its pressure
        field, the exact solvers from its contact set), or every level from ``p = 0``
        (``False``, the paper's "without warm starting").
    axis : 0, 1, "either" or "both"
        Flow direction for ``V_pg``/``V_pg_star`` and the maps (both axes are always
        tabulated in ``*_axis0``/``*_axis1``).
    connectivity : 4 or 8
        Neighbourhood of free cells in a cluster.
    E, nu : float
        Young's modulus and Poisson's ratio, ``E* = E/(1 − ν²)`` (pressures in E's unit).
    boundary : "free" or "periodic"
        Elastic boundary condition (``docs/conventions.md``).
    keep_fields : bool
        Keep pressure, gap and cluster labels of every level (:meth:`SweepResult.save_fields`).
    progress : bool
        Show a tqdm progress bar (one step per level) on stderr.
    checkpoint_dir : path, optional
        Write each finished level there and reuse the levels found there (module docstring).
    flow : bool, optional
        Leak-rate columns ``Q``, ``K``, ``K_star`` (:mod:`leakpath.leakage`): ``True``,
        ``False`` (NaN columns), or ``None`` (default: on up to 513² points).
    flow_axis : 0 or 1, optional
        Direction of the leak (default: ``axis`` when it is 0 or 1, else 0).

    Returns
    -------
    SweepResult

    Raises
    ------
    ValueError
        A bad argument (the message names it) or a checkpoint of a different sweep.
    RuntimeError
        A solve that does not reach the KKT threshold :data:`KKT_ACCEPT`.
    """
    if not isinstance(surface, Surface):
        raise InvalidArgumentError(
            f"surface: expected a leakpath Surface, got {type(surface).__name__}"
        )
    if min(surface.shape) < 3:
        raise InvalidArgumentError(
            f"surface: needs at least 3 points per axis, got {surface.shape}"
        )
    if not surface.height_range > 0:
        raise InvalidArgumentError(
            "surface: flat (h_s = max h − min h = 0): the flat touches every point at once "
            "and there is no approach to sweep; check the heights (units, a constant file)"
        )
    _validate.choice("solver", solver, SOLVERS)
    warm_start = _validate.flag("warm_start", warm_start)
    keep_fields = _validate.flag("keep_fields", keep_fields)
    n_levels = _check_levels(levels, surface.shape, keep_fields)
    axis = _check_axis(axis)
    connectivity = _check_connectivity(connectivity)
    flow_on = leakage.flow_enabled(flow, surface.shape)  # leakpath.leakage
    flow_axis = leakage.flow_axis_for(flow_axis, axis)
    problem = ContactProblem(surface, E=E, nu=nu, boundary=boundary)  # type: ignore[arg-type]
    if approaches is not None and mean_pressures is not None:
        raise InvalidArgumentError(
            "mean_pressures: give approaches= or mean_pressures=, not both",
            argument="mean_pressures",
        )
    if mean_pressures is not None:
        pressure_list = _resolve_mean_pressures(mean_pressures)
        level_list = [("mean_pressure", v) for v in pressure_list]
        approach_list = None
    else:
        approach_list = _resolve_approaches(problem, n_levels, approaches)
        level_list = [("approach", v) for v in approach_list]
        pressure_list = None
    run_solver = solver
    # Polonsky–Keer warm-starts from the previous pressure field, which checkpoints keep.
    uses_pk = solver == "polonsky-keer" or (
        solver == "auto" and surface.heights.size > AUTO_ACTIVE_SET_MAX_POINTS
    )
    keep_pressure = bool(warm_start) and (uses_pk or mean_pressures is not None)
    t_total = time.perf_counter()

    parameters: dict[str, Any] = {
        "levels": (
            len(approach_list) - 1
            if approach_list is not None and approaches is None
            else None
        ),
        "approaches": approach_list,
        "mean_pressures": pressure_list,
        "solver": solver,
        "warm_start": bool(warm_start),
        "axis": axis,
        "connectivity": connectivity,
        "E": float(E),
        "nu": float(nu),
        "e_star": problem.e_star,
        "boundary": boundary,
        "kkt_accept": KKT_ACCEPT,
        "keep_fields": bool(keep_fields),
        "flow": flow_on,  # leakpath.leakage
        "flow_axis": flow_axis,
    }

    # Undeformed reference (Δ = 0: p = 0, u = 0, the whole interface is free).
    ref_state = problem.solve(0.0, solver=run_solver, warm_start=False)  # type: ignore[arg-type]
    ref_mom = nayak_moments(surface.heights, surface.dx)
    reference = {
        "h_s": surface.height_range,
        "e_star": problem.e_star,
        "A0": surface.nominal_area,
        "sigma": math.sqrt(ref_mom.m0),
        "free_volume": ref_state.free_volume,
        "mean_gap": ref_state.mean_gap,
        "V_pg": float(ref_state.percolation(axis=axis, connectivity=connectivity).spanning_volume),
        "m0": ref_mom.m0,
        "m2": ref_mom.m2,
        "m4": ref_mom.m4,
        "alpha": ref_mom.alpha,
        "K": leakage.reference_permeability(ref_state, flow_axis, flow_on),  # leakage
    }

    checkpoint = None
    if checkpoint_dir is not None:
        identity = {k: v for k, v in parameters.items() if k not in ("keep_fields",)}
        manifest = {
            "format": _CHECKPOINT_FORMAT,
            "leakpath_version": __version__,
            "surface_sha256": surface_sha256(surface),
            "shape": list(surface.shape),
            "parameters": identity,
        }
        checkpoint = _Checkpoint(checkpoint_dir, manifest, keep_fields)

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(
            total=len(level_list), desc="sweep", unit="level", file=sys.stderr, leave=False
        )
    shape = surface.shape
    done: list[_Level] = []
    resumed: list[int] = []
    try:
        for k, target in enumerate(level_list):
            level = None
            if checkpoint is not None:
                level = checkpoint.load(k, shape, need_pressure=keep_pressure)
            if level is not None:
                resumed.append(k)
            else:
                warm: bool | np.ndarray = False
                if warm_start and done:
                    warm = _warm_start_for(done, level_list, k, shape)
                t0 = time.perf_counter()
                state, iterations, restarts = _solve_accepted(problem, target, run_solver, warm)
                level = _analyse(
                    k,
                    state,
                    iterations=iterations,
                    restarts=restarts,
                    axis=axis,
                    connectivity=connectivity,
                    keep_fields=keep_fields,
                    t_start=t0,
                    keep_pressure=keep_pressure,
                    flow_axis=flow_axis,  # leakpath.leakage
                    flow_on=flow_on,
                )
                if checkpoint is not None:
                    checkpoint.save(k, level, shape)
            done.append(level)
            if bar is not None:
                bar.update(1)
                bar.set_postfix(contact=f"{level.row['contact_fraction']:.3f}")
    finally:
        if bar is not None:
            bar.close()

    rows = [_finish_row(lv.row, reference, surface.nominal_area) for lv in done]
    fields = None
    if keep_fields:
        fields = {
            name: np.stack([lv.fields[name] for lv in done])  # type: ignore[index]
            for name in ("pressure", "gap", "labels")
        }
    if checkpoint is not None and checkpoint.recomputed:
        warnings.warn(
            "checkpoint_dir: recomputed "
            + "; ".join(f"level {k} ({why})" for k, why in checkpoint.recomputed)
            + " — their records failed the integrity check and were not used",
            stacklevel=2,
        )
    return SweepResult(
        rows=rows,
        parameters=parameters,
        surface=surface,
        reference=reference,
        seconds=[lv.seconds for lv in done],
        resumed=resumed,
        recomputed=[k for k, _ in checkpoint.recomputed] if checkpoint is not None else [],
        fields=fields,
        total_seconds=time.perf_counter() - t_total,
        _masks=[lv.mask for lv in done],
        _classes=[lv.classes for lv in done],
    )
