"""Exceptions of leakpath.

Every error leakpath raises on purpose is a :class:`LeakpathError`, and each kind also
subclasses the builtin exception users already catch (``ValueError``, ``RuntimeError``,
``MemoryError``), so ``except ValueError`` keeps working. Messages follow one style:
``argument: what is wrong; what to do``. The Rust core raises the same types, with the
same attributes, through the bindings.
"""

from __future__ import annotations

__all__ = [
    "LeakpathError",
    "InvalidArgumentError",
    "NotConvergedError",
    "ProblemTooLargeError",
    "LeakpathWarning",
    "SlopeWarning",
]


class LeakpathError(Exception):
    """Base class of every error leakpath raises on purpose."""


class InvalidArgumentError(LeakpathError, ValueError):
    """An argument is out of its domain.

    Attributes
    ----------
    argument : str
        The argument as the API spells it (``"dx"``, ``"approach"``, ``"heights"`` …).
    """

    def __init__(self, message: str, *, argument: str | None = None) -> None:
        super().__init__(message)
        if argument is None:
            argument = message.split(":", 1)[0].strip() if ":" in message else ""
        self.argument = argument


class NotConvergedError(LeakpathError, RuntimeError):
    """An iterative method stopped before meeting its tolerance.

    Attributes
    ----------
    solver : str
        What did not converge (``"polonsky-keer"``, ``"active-set"`` …).
    iterations : int
        Iterations done.
    residual : float
        The last residual or KKT certificate (relative, as the solver reports it).
    """

    def __init__(
        self,
        message: str,
        *,
        solver: str = "",
        iterations: int = 0,
        residual: float = float("nan"),
    ) -> None:
        super().__init__(message)
        self.solver = solver
        self.iterations = int(iterations)
        self.residual = float(residual)


class ProblemTooLargeError(LeakpathError, MemoryError):
    """A problem would need more memory than allowed; refused before allocating.

    Attributes
    ----------
    estimate : int
        Bytes the problem would need (an estimate).
    limit : int
        Bytes allowed.
    what : str
        What was refused (``"Polonsky–Keer on 8193 × 8193"`` …).
    """

    def __init__(self, message: str, *, estimate: int = 0, limit: int = 0, what: str = "") -> None:
        super().__init__(message)
        self.estimate = int(estimate)
        self.limit = int(limit)
        self.what = what


class LeakpathWarning(UserWarning):
    """Base class of the warnings leakpath issues (``warnings.simplefilter("error",
    leakpath.errors.LeakpathWarning)`` turns them into errors)."""


class SlopeWarning(LeakpathWarning):
    """A surface's rms slope exceeds :data:`leakpath.surfaces.MAX_RMS_SLOPE` (0.3), beyond
    which the small-slope (half-space) contact and lubrication models lose accuracy (errors
    of order ``slope²/2``); usually heights and lateral lengths given in different units."""
