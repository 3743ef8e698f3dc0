"""The sweep table: its columns, their units and definitions, and :class:`SweepResult`.

Column definitions (lengths ``L`` in the surface's unit, pressures in the unit of ``E``) are
listed in the documentation of :func:`leakpath.sweep` and in ``docs/conventions.md``.
"""

from __future__ import annotations

import io
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any, overload

import numpy as np

from . import _validate, leakage  # leakage: leak-rate columns Q, K, K_star
from ._core import __version__
from ._io import (
    atomic_write_bytes,
    atomic_write_text,
    csv_quote,
    csv_text,
    dumps,
    heights_sha256,
    machine_info,
)

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

    from .surfaces import Surface

__all__ = ["SweepResult", "COLUMNS", "CSV_COLUMNS", "surface_sha256"]

PathLike = str | os.PathLike[str]

KKT_ACCEPT = 1e-8

#: Axes accepted by ``axis`` (``docs/conventions.md``).
AXES: tuple[Any, ...] = (0, 1, "either", "both")

# (name, type) of every column, in CSV order. Types: "f" float, "i" int, "s" str.
_COLUMN_SPEC: tuple[tuple[str, str], ...] = (
    ("k", "i"),
    ("branch", "s"),
    ("approach", "f"),
    ("approach_star", "f"),
    ("n_contact", "i"),
    ("contact_fraction", "f"),
    ("contact_area", "f"),
    ("load", "f"),
    ("mean_pressure", "f"),
    ("mean_pressure_star", "f"),
    ("plastic_fraction", "f"),
    ("plastic_volume", "f"),
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
        plastic_volume=f"{L}^3",
        m0=f"{L}^2",
        m4=f"{L}^-2",
        solver="",
        branch="",
    )
    for c in COLUMNS:
        if c.startswith(("V_pg", "V_dead", "V_trapped")) and not c.endswith("_star"):
            units[c] = f"{L}^3"
    units.update({c: u.format(L=L) for c, u in leakage.FLOW_UNITS.items()})  # leakage
    return units



def surface_sha256(surface: Surface) -> str:
    """SHA-256 (hex) of a surface's heights and ``dx`` (:func:`leakpath._io.heights_sha256`)."""
    return heights_sha256(surface.heights, surface.dx)


# ---------------------------------------------------------------------------- CSV
def _format_cell(name: str, value: Any) -> str:
    kind = _TYPES[name]
    if kind == "f":
        return repr(float(value))  # shortest string that round-trips exactly
    if kind == "i":
        return str(int(value))
    return csv_quote(str(value))


def _csv_text(rows: Sequence[Mapping[str, Any]], columns: Sequence[str] = CSV_COLUMNS) -> str:
    return csv_text(rows, columns, _format_cell)


def _coerce_cell(name: str, value: Any) -> Any:
    kind = _TYPES[name]
    if kind == "f":
        return float("nan") if value is None else float(value)
    if kind == "i":
        return int(value)
    return str(value)



# ---------------------------------------------------------------------------- result
@dataclass(frozen=True, eq=False)
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
    #: Contact masks as bits (``np.packbits`` of the C-order ravel), one per level.
    _masks: list[np.ndarray] = field(default_factory=list, repr=False)
    #: Percolation class maps (int8), one per level.
    _classes: list[np.ndarray] = field(default_factory=list, repr=False)

    def __len__(self) -> int:
        return len(self.rows)

    def __repr__(self) -> str:
        # The rows, fields and masks are tables and grids: summarise them in two lines.
        ny, nx = self.surface.shape
        u = f" {self.surface.unit}"
        head = (
            f"SweepResult({len(self.rows)} levels on a {ny}x{nx} surface, "
            f"dx={self.surface.dx:.6g}{u}, boundary={self.parameters.get('boundary')!r}, "
            f"axis={self.parameters.get('axis', 0)!r}"
        )
        if not self.rows:
            return head + ")"

        def span(name: str, fmt: str = ".4g") -> str:
            col = self.column(name)
            return f"{col[0]:{fmt}} … {col[-1]:{fmt}}"

        has_flow = bool(np.isfinite(self.column("K")).any())
        return (
            f"{head},\n  approach {span('approach')}{u}, contact_fraction "
            f"{span('contact_fraction')}, V_pg* {span('V_pg_star')}"
            + (f", K* {span('K_star')}" if has_flow else ", no leak-rate columns")
            + f", {self.total_seconds:.3g} s)"
        )

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
        n = self.surface.shape[0] * self.surface.shape[1]
        return np.unpackbits(self._masks[k], count=n).astype(bool).reshape(self.surface.shape)

    def class_map(self, k: int) -> np.ndarray:
        """Percolation classes of row ``k`` for the chosen axis (int8): 0 contact,
        1 spanning, 2 dead-end, 3 trapped (see :meth:`leakpath.percolation.Percolation.class_map`).
        """
        return self._classes[k].copy()

    # ------------------------------------------------------------------ output
    def csv_text(self) -> str:
        """The CSV table: header + one line per level, floats as ``repr`` (exact round trip)."""
        return _csv_text(self.rows)

    @property
    def units(self) -> dict[str, str]:
        """Unit of every column: lengths ``L`` in the surface's unit
        (:attr:`leakpath.Surface.unit`), pressures in units of ``E`` (``"E"``), ``"1"`` for
        dimensionless columns, ``""`` for text."""
        return _units(self.surface.unit, "E")

    def headers(self) -> list[str]:
        """Column headers with their units, ``"approach [µm]"``, ``"V_pg_star [1]"``, in CSV
        order (text columns bare)."""
        units = self.units
        return [f"{c} [{units[c]}]" if units.get(c) else c for c in CSV_COLUMNS]

    def to_csv(self, path: PathLike, *, units: bool = False) -> Path:
        """Write :meth:`csv_text` to ``path`` atomically; returns the path. ``units=True``
        writes :meth:`headers` (``"approach [µm]"``) as the header line instead of the bare
        column names (which tables read back by name, e.g. the paper's, keep)."""
        text = self.csv_text()
        if _validate.flag("units", units):
            _, _, body = text.partition("\n")
            text = ",".join(csv_quote(h) for h in self.headers()) + "\n" + body
        return atomic_write_text(path, text)

    def metadata(self) -> dict[str, Any]:
        """Everything :meth:`to_json` writes, as a dict."""
        s = self.surface
        length_unit = s.unit
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
        return atomic_write_text(path, dumps(data))

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

    @overload
    def plot(
        self,
        outdir: None = None,
        formats: Sequence[str] = ...,
        levels_to_map: Iterable[int] | None = ...,
        flux_levels: Iterable[int] | None = ...,
    ) -> dict[str, Figure]: ...

    @overload
    def plot(
        self,
        outdir: PathLike,
        formats: Sequence[str] = ...,
        levels_to_map: Iterable[int] | None = ...,
        flux_levels: Iterable[int] | None = ...,
    ) -> list[Path]: ...

    def plot(
        self,
        outdir: PathLike | None = None,
        formats: Sequence[str] = ("png", "pdf"),
        levels_to_map: Iterable[int] | None = None,
        flux_levels: Iterable[int] | None = None,
    ) -> dict[str, Figure] | list[Path]:
        """The figures of the sweep, every one ``leakpath sweep`` writes: Figs. 1–3, one
        class map per row in ``levels_to_map`` (default
        :func:`leakpath.plotting.default_map_levels`) and, when the table has leak-rate
        columns, ``fig4_leak_rate`` and one flux map per row in ``flux_levels`` (default:
        the last leaking row); for a sweep with a hardness or an unloading branch also
        ``fig5_plastic_leak_rate`` (leak rate against nominal pressure, both branches) and
        ``fig6_plastic_area`` (contact and plastic area fractions,
        :mod:`leakpath.plotting.plastic`).

        Without ``outdir`` nothing is written: returns a dict file stem → matplotlib
        :class:`~matplotlib.figure.Figure` (``"fig1_topography_moments"``, …,
        ``"map_k05"``, ``"fig4_leak_rate"``, ``"flux_k07"``), which a notebook shows with
        ``display(fig)``. With ``outdir`` (created) each figure is written there as
        ``<stem>.<format>`` for every format in ``formats`` ⊆ {"png", "pdf", "svg"},
        atomically, the same files as the command line's ``figures/``; returns the paths
        written (see :func:`leakpath.plotting.save_paper_figures` and
        :func:`leakpath.plotting.save_flow_figures`).
        """
        from .plotting.flow import flow_figures, save_flow_figures
        from .plotting.paper import paper_figures, save_paper_figures
        from .plotting.plastic import plastic_figures, save_plastic_figures

        if outdir is None:
            return {
                **paper_figures(self, levels_to_map=levels_to_map),
                **flow_figures(self, flux_levels=flux_levels),
                **plastic_figures(self),
            }
        paths = save_paper_figures(self, outdir, formats=formats, levels_to_map=levels_to_map)
        paths += save_flow_figures(self, outdir, formats=formats, flux_levels=flux_levels)
        return paths + save_plastic_figures(self, outdir, formats=formats)


_DEFINITIONS = {
    "approach_star": "Delta/h_s, h_s = max h - min h",
    "free_volume_star": "V/(A0*sigma), sigma = sqrt(m0) of the undeformed surface",
    "mean_gap_star": "mean_gap/mean_gap(Delta=0)",
    "V_pg_star": "V_pg/V_pg(Delta=0) for the chosen axis",
    **leakage.FLOW_DESCRIPTIONS,  # leakpath.leakage
    "m_star": "m_n/m_n(undeformed), alpha_star likewise",
    "gap": "g = max h - Delta - h + w_p + u (w_p: plastic displacement, 0 without hardness)",
    "branch": "loading, or unloading from the last loading row (sweep(unload=True))",
    "plastic_fraction": "#(w_p > 0)/N, area fraction deformed plastically (hardness)",
    "plastic_volume": "dx^2 sum w_p, volume displaced plastically (hardness)",
    "moments": "finite differences on s = h - u (leakpath.moments.nayak_moments)",
}



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


