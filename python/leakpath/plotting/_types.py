"""What the figures read from a sweep result and a surface (structural types).

The figures take any object with these attributes, so the plotting package imports neither
the sweep nor the surface modules (they sit above it in the import order).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np


class SurfaceLike(Protocol):
    """A height map: :class:`leakpath.Surface` satisfies it."""

    heights: np.ndarray
    dx: float
    metadata: dict[str, Any]

    @property
    def length(self) -> tuple[float, float]: ...


class SweepLike(Protocol):
    """A sweep table: :class:`leakpath.SweepResult` satisfies it."""

    rows: list[dict[str, Any]]
    parameters: dict[str, Any]
    surface: Any
    fields: dict[str, np.ndarray] | None

    def column(self, name: str) -> np.ndarray: ...

    def class_map(self, k: int) -> np.ndarray: ...
