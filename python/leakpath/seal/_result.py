"""The result of a seal run: column tables, CSV, metadata and figures.

Column names carry their unit as a suffix (``_Pa``, ``_m``, ``_m3``, ``_m3_per_s``,
``_kg_per_s``, ``_s``); the few dimensionless columns (fractions, counts, flags, indices)
are listed in :data:`DIMENSIONLESS`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._io import atomic_write_text, csv_text, dumps

__all__ = ["Table", "SealResult", "UNIT_SUFFIXES", "DIMENSIONLESS"]

PathLike = str | os.PathLike[str]

#: Unit suffixes of dimensional columns, longest first.
UNIT_SUFFIXES = ("_m3_per_s", "_kg_per_s", "_m3", "_Pa", "_m", "_s")

#: Columns without a unit: fractions of the nominal area or of the realisations, counts,
#: flags, indices, relative changes.
DIMENSIONLESS = frozenset({
    "realisation", "axis", "contact_fraction", "contact_fraction_std",
    "persson_contact_fraction", "percolates", "leaks", "leak_fraction", "n_realisations",
    "n_leaking", "n_patches", "contact_iterations", "grid_check_relative_change", "converged",
    "refine",
})


def unit_of(column: str) -> str:
    """The unit a column name carries (``"1"`` for the dimensionless ones)."""
    if column in DIMENSIONLESS:
        return "1"
    for suffix in UNIT_SUFFIXES:
        if column.endswith(suffix):
            return {"_m3_per_s": "m^3/s", "_kg_per_s": "kg/s", "_m3": "m^3", "_Pa": "Pa",
                    "_m": "m", "_s": "s"}[suffix]
    raise KeyError(f"column {column!r} carries no unit")


def _cell(value: Any) -> str:
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    x = float(value)
    if math.isnan(x):
        return "nan"
    return repr(x)  # shortest text that reads back to the same double


class Table:
    """A small column table: ordered columns of equal length (numpy arrays).

    ``table.column("permeability_m3")`` (or ``table["permeability_m3"]``) is a column,
    ``table.rows()`` a list of dicts, ``table.columns`` the names, ``len(table)`` the rows.
    """

    def __init__(self, rows: Sequence[Mapping[str, Any]], columns: Sequence[str]) -> None:
        self.columns: tuple[str, ...] = tuple(columns)
        self._data: dict[str, np.ndarray] = {}
        for c in self.columns:
            values = [r[c] for r in rows]
            if values and all(isinstance(v, (bool, np.bool_)) for v in values):
                arr = np.asarray(values, dtype=bool)
            elif values and all(isinstance(v, (int, np.integer)) and not isinstance(v, bool)
                                for v in values):
                arr = np.asarray(values, dtype=np.int64)
            else:
                arr = np.asarray(values, dtype=np.float64)
            self._data[c] = arr
        self._n = len(rows)

    def column(self, name: str) -> np.ndarray:
        """A copy of column ``name``."""
        if name not in self._data:
            raise KeyError(f"no column {name!r}; columns: {', '.join(self.columns)}")
        return self._data[name].copy()

    __getitem__ = column

    def __len__(self) -> int:
        return self._n

    def rows(self) -> list[dict[str, Any]]:
        """The rows as dicts of Python scalars."""
        return [{c: self._data[c][i].item() for c in self.columns} for i in range(self._n)]

    def units(self) -> dict[str, str]:
        """Column name → unit."""
        return {c: unit_of(c) for c in self.columns}

    def csv_text(self) -> str:
        """CSV with a header of the column names; floats written exactly (``repr``)."""
        return csv_text(self.rows(), self.columns, lambda _c, v: _cell(v))

    def __repr__(self) -> str:
        return f"Table({self._n} rows × {len(self.columns)} columns: {', '.join(self.columns)})"


class SealResult:
    """The outcome of :func:`leakpath.seal_leakage`.

    Attributes
    ----------
    config : SealConfig
    summary : Table
        One row per nominal pressure (``docs/seal.md``, "Outputs").
    realisations : Table
        One row per (realisation, axis, pressure).
    check : Table or None
        The convergence check's rows (refined grid), as ``realisations``.
    metadata : dict
        Inputs with units, versions, patch, surface SHA-256 per realisation, the
        convergence check, executor and wall time (written as ``metadata.json``).
    """

    def __init__(self, config: Any, summary: Table, realisations: Table,
                 check: Table | None, metadata: dict[str, Any]) -> None:
        self.config = config
        self.summary = summary
        self.realisations = realisations
        self.check = check
        self.metadata = metadata

    @property
    def gas(self) -> bool:
        return bool(self.config.fluid.gas)

    @property
    def rate_column(self) -> str:
        """``leak_rate_m3_per_s`` (liquid) or ``mass_flow_kg_per_s`` (gas)."""
        return "mass_flow_kg_per_s" if self.gas else "leak_rate_m3_per_s"

    @property
    def converged(self) -> bool:
        """Whether every pressure passed the convergence check (True when none was run)."""
        return bool(np.all(self.summary.column("converged")))

    def __repr__(self) -> str:
        cfg = self.config
        rate = self.summary.column(self.rate_column)
        unit = "kg/s" if self.gas else "m³/s"
        p = self.summary.column("mean_pressure_Pa")
        what = "mass flow" if self.gas else "leak rate"
        return (
            f"SealResult({cfg.realisations} realisations × {len(p)} pressures × "
            f"{len(cfg.axes)} axes; {what} {rate[0]:.3g} {unit} at "
            f"{p[0]:.3g} Pa … {rate[-1]:.3g} {unit} at {p[-1]:.3g} Pa"
            f"{'' if self.converged else '; convergence check FAILED'})"
        )

    # ------------------------------------------------------------------ files
    def to_csv(self, directory: PathLike) -> list[Path]:
        """Write ``summary.csv`` and ``realisations.csv`` (and ``check.csv`` when a
        convergence check ran) into ``directory`` (created), atomically. Returns the paths."""
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        paths = [
            atomic_write_text(d / "summary.csv", self.summary.csv_text()),
            atomic_write_text(d / "realisations.csv", self.realisations.csv_text()),
        ]
        if self.check is not None:
            paths.append(atomic_write_text(d / "check.csv", self.check.csv_text()))
        return paths

    def plot(self) -> Any:
        """A matplotlib Figure: leak rate against nominal pressure (log scale, with its
        interval band and the Bruggeman estimate), contact fraction against pressure with
        Persson's theory, and the distribution of K. Needs no directory."""
        from ._figures import seal_figure

        return seal_figure(self)

    def save(self, directory: PathLike) -> list[Path]:
        """Write the CSVs, ``metadata.json`` and ``figures/seal.png`` / ``.pdf`` into
        ``directory`` (atomically); returns the paths written."""
        d = Path(directory)
        paths = self.to_csv(d)
        paths.append(atomic_write_text(d / "metadata.json", dumps(self.metadata)))
        fig_dir = d / "figures"
        fig_dir.mkdir(exist_ok=True)
        from ..plotting.paper import save_figure

        paths += save_figure(self.plot(), fig_dir / "seal", ("png", "pdf"), 150)
        return paths
