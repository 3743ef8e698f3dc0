"""Shared pieces of the command line: errors, output formatting, argument types, the
SURFACE argument and the output directory."""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from .. import _validate
from .._outputs import RECORD_NAME, OutputRecord
from ..errors import InvalidArgumentError
from ..generators import _shape_text, generate, parse_spec
from ..moments import nayak_moments
from ..surfaces import Surface, load

PROG = "leakpath"


class UsageError(Exception):
    """A bad command line detected after parsing; reported with exit status 2."""


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are a single ``leakpath: error: ...`` line (exit 2)."""

    def error(self, message: str) -> NoReturn:
        hint = f" (see '{self.prog} --help')"
        self.exit(2, f"{PROG}: error: {_one_line(message)}{hint}\n")


def _one_line(message: str) -> str:
    return " ".join(str(message).split())


# ---------------------------------------------------------------------------- output helpers
def surface_statistics(surface: Surface) -> dict[str, Any]:
    """Summary statistics of a surface as a JSON-serialisable dict.

    Keys: ``shape`` [ny, nx], ``dx``, ``length`` [Ly, Lx], ``height_range`` (h_s = max − min),
    ``mean``, ``rms_height`` (√m0), and Nayak's ``m0, m2, m4, alpha`` (finite differences,
    :func:`leakpath.moments.nayak_moments`; ``None`` when the grid has fewer than 3 points
    on an axis).
    """
    stats: dict[str, Any] = {
        "shape": list(surface.shape),
        "dx": surface.dx,
        "length": list(surface.length),
        "height_range": surface.height_range,
        "mean": surface.mean_height,
        "rms_height": surface.rms_height,
    }
    stats.update(m0=None, m2=None, m4=None, alpha=None)
    if min(surface.shape) >= 3:
        try:
            mom = nayak_moments(surface)
        except InvalidArgumentError:  # slopes or curvatures beyond the float range for dx
            stats["m0"] = surface.rms_height**2
            return stats
        stats.update(m0=mom.m0, m2=mom.m2, m4=mom.m4, alpha=_finite_or_none(mom.alpha))
    return stats


def _finite_or_none(x: float) -> float | None:
    return x if math.isfinite(x) else None


def _fmt(value: Any) -> str:
    if value is None:
        return "n/a"
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (list, tuple)):
        return " x ".join(_fmt(v) for v in value)
    return str(value)


def format_table(rows: Sequence[tuple[str, Any]]) -> str:
    """Two aligned columns ``name  value`` (floats with 6 significant digits)."""
    width = max((len(name) for name, _ in rows), default=0)
    return "\n".join(f"{name.ljust(width)}  {_fmt(value)}" for name, value in rows)


#: (statistic, label with its unit; ``{L}`` is the surface's length unit).
_STAT_LABELS: tuple[tuple[str, str], ...] = (
    ("shape", "shape (ny x nx)"),
    ("dx", "dx [{L}]"),
    ("height_range", "h_s (max - min) [{L}]"),
    ("mean", "mean height [{L}]"),
    ("rms_height", "rms height [{L}]"),
    ("m0", "m0 [{L}^2]"),
    ("m2", "m2 [1]"),
    ("m4", "m4 [{L}^-2]"),
    ("alpha", "alpha [1]"),
)


def _report(surface: Surface, out: Path, *, as_json: bool) -> None:
    stats = surface_statistics(surface)
    if as_json:
        payload = {"path": str(out), **stats, "metadata": surface.metadata}
        _print_json(payload)
    else:
        rows = [("file", str(out))] + [
            (label.format(L=surface.unit), stats[key]) for key, label in _STAT_LABELS
        ]
        print(format_table(rows))


def json_safe(obj: Any) -> Any:
    """``obj`` with every non-finite float replaced by ``None`` (JSON has no NaN or ∞)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if hasattr(obj, "item") and callable(obj.item) and getattr(obj, "ndim", 1) == 0:
        return json_safe(obj.item())  # numpy scalars
    if hasattr(obj, "tolist"):
        return json_safe(obj.tolist())  # numpy arrays
    return obj


def _print_json(payload: Any, default: Callable[[Any], Any] = str) -> None:
    """Print strict JSON (``null`` for NaN/∞; refuses to write invalid JSON)."""
    print(json.dumps(json_safe(payload), indent=2, default=default, allow_nan=False))


def _check_out(path: Path, overwrite: bool) -> None:
    _validate.path("--out", path)
    if path.suffix.lower() != ".npz":
        raise UsageError(f"--out must end in '.npz', got {str(path)!r}")
    if path.exists() and not overwrite:
        raise UsageError(f"{str(path)!r} already exists; pass --overwrite to replace it")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise UsageError(f"directory {str(parent)!r} for --out does not exist")


def _write_and_report(surface: Surface, args: argparse.Namespace) -> int:
    try:
        surface.save(args.out, overwrite=args.overwrite)
    except FileExistsError as exc:
        raise UsageError(f"{exc}; pass --overwrite to replace it") from None
    _report(surface, args.out, as_json=args.json)
    return 0


# ---------------------------------------------------------------------------- surface
def _add_output_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", type=Path, required=True, metavar="PATH", help="output file (.npz)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    p.add_argument(
        "--json", action="store_true", help="print the statistics as JSON instead of a table"
    )


def _shape_arg(text: str) -> tuple[int, int]:
    """Parse ``N`` or ``NYxNX`` (also ``NY,NX``)."""
    try:
        return _shape_text(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


TABLE_NAME = "table.csv"
METADATA_NAME = "metadata.json"
SURFACE_NAME = "surface.npz"
FIELDS_NAME = "fields.npz"
FIGURES_DIR = "figures"
CHECKPOINT_DIR = "checkpoints"

_SUMMARY_COLUMNS: tuple[tuple[str, str], ...] = (
    ("k", "k"),
    ("approach_star", "Delta*"),
    ("contact_fraction", "contact"),
    ("free_volume_star", "V*"),
    ("V_pg_star", "V_pg*"),
    ("mean_gap_star", "gbar*"),
    ("m0_star", "m0*"),
    ("m2_star", "m2*"),
    ("K_star", "K*"),  # leakpath.leakage
)

#: The summary of a sweep with a hardness or an unloading branch (units in the labels).
_PLASTIC_SUMMARY_COLUMNS: tuple[tuple[str, str], ...] = (
    ("k", "k"),
    ("branch", "branch"),
    ("mean_pressure_star", "pbar/E*"),
    ("contact_fraction", "contact"),
    ("plastic_fraction", "plastic"),
    ("plastic_volume", "V_pl[L^3]"),
    ("K_star", "K*"),  # leakpath.leakage
)

def parse_surface_spec(text: str) -> tuple[str, dict[str, Any], int] | None:
    """:func:`leakpath.generators.parse_spec`: ``(generator, parameters, seed)`` or ``None``."""
    return parse_spec(text)


def _surface_from_arg(text: str, dx: float | None, fill: str | None = None) -> Surface:
    spec = parse_surface_spec(text)
    if spec is not None:
        gen, params, seed = spec
        if dx is not None:
            raise UsageError("--dx applies to surface files only, not to a generator spec")
        if fill is not None:
            raise UsageError("--fill applies to surface files only, not to a generator spec")
        return generate(gen, params, seed)
    path = _validate.path("SURFACE", text)
    if not path.exists():
        raise UsageError(
            f"SURFACE {text!r} is neither an existing file nor a spec such as "
            "'rmd:m=7,D=2.1,seed=0' or 'spectral:n=256,hurst=0.8,seed=1'"
        )
    return load(path, dx=dx, fill=fill)


def _prepare_outdir(out: Path, *, overwrite: bool, resume: bool) -> OutputRecord:
    """Refuse a non-empty output directory unless ``--overwrite``/``--resume``; create it.

    Returns the record of the files this run writes (:mod:`leakpath._outputs`); with
    ``--resume`` it keeps the earlier run's entries. ``--overwrite`` deletes only the files
    an earlier run recorded there and left unchanged, and checkpoint files recognised by
    their checksums; anything else stays, and a note on stderr says so.
    """
    if overwrite and resume:
        raise UsageError("--overwrite and --resume exclude each other")
    _validate.path("--out", out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {str(out)!r} exists and is not a directory")
    non_empty = out.is_dir() and any(out.iterdir())
    if non_empty and not (overwrite or resume):
        raise UsageError(
            f"output directory {str(out)!r} is not empty; pass --resume to continue its sweep "
            "or --overwrite to replace its results"
        )
    if resume and non_empty and not (out / CHECKPOINT_DIR).is_dir():
        raise UsageError(
            f"nothing to resume in {str(out)!r} (no {CHECKPOINT_DIR}/ directory); "
            "run without --resume, or with --overwrite"
        )
    record = OutputRecord(out)
    if overwrite and non_empty:
        _clear_earlier_run(out, record)
    elif resume:
        record.read()  # the resumed run adds to the earlier run's files
    _validate.make_directory("--out", out)
    return record


def _clear_earlier_run(out: Path, record: OutputRecord) -> None:
    """Delete what an earlier run in ``out`` provably wrote; note on stderr what stays."""
    from .._checkpoint import own_files
    from ..plotting.paper import remove_stale_temporaries

    had_record = record.read()
    changed = record.remove_unchanged() if had_record else []
    for f in own_files(out / CHECKPOINT_DIR):
        f.unlink()
    for directory in (out, out / FIGURES_DIR):
        if directory.is_dir():
            remove_stale_temporaries(directory)
    left = sorted(
        p.relative_to(out).as_posix()
        for p in out.rglob("*")
        if p.is_file() or p.is_symlink()
    )
    if changed:
        _note(
            f"--overwrite kept {len(changed)} file(s) in {str(out)!r} that changed since the "
            f"earlier run wrote them: {_listing(changed)}"
        )
    if not had_record and left:
        _note(
            f"--overwrite: {str(out)!r} holds no record of the files an earlier run wrote "
            f"({RECORD_NAME}), so only its checkpoints were removed; {len(left)} other "
            f"file(s) stay unless this run rewrites them: {_listing(left)}"
        )


def _listing(names: Sequence[str], limit: int = 5) -> str:
    shown = ", ".join(names[:limit])
    return shown + (f" and {len(names) - limit} more" if len(names) > limit else "")


def _note(message: str) -> None:
    print(f"{PROG}: note: {_one_line(message)}", file=sys.stderr)


def format_summary(
    rows: Sequence[dict[str, Any]],
    columns: Sequence[tuple[str, str]] = _SUMMARY_COLUMNS,
) -> str:
    """The summary table: k, Δ*, contact fraction, V*, V_pg*, ḡ*, m0*, m2* (4 decimals)."""
    header = [label for _, label in columns]
    body = []
    for row in rows:
        cells = []
        for key, _ in columns:
            v = row[key]
            if isinstance(v, str):
                cells.append(v)
                continue
            if key in ("K_star", "plastic_volume"):  # leakpath.leakage: spans decades
                cells.append(f"{v:.3e}")
                continue
            cells.append(str(v) if isinstance(v, int) else f"{v:.4f}")
        body.append(cells)
    widths = [max(len(h), *(len(r[i]) for r in body)) for i, h in enumerate(header)]
    lines = ["  ".join(h.rjust(w) for h, w in zip(header, widths, strict=True))]
    lines += ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in body]
    return "\n".join(lines)


def _json_number(obj: Any) -> Any:
    return obj.item() if hasattr(obj, "item") else str(obj)


def _add_sweep_output_arguments(p: argparse.ArgumentParser, default_out: str) -> None:
    p.add_argument(
        "--out",
        type=Path,
        default=Path(default_out),
        metavar="DIR",
        help=f"output directory (default: {default_out})",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an earlier run's results in a non-empty --out directory (only the "
        "files it recorded writing, unchanged since; nothing else is deleted)",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue an interrupted run in --out from its checkpoints (same final table)",
    )
    p.add_argument("--json", action="store_true", help="print the summary as JSON")


_SOLVER_HELP = (
    "contact solver: auto (default; Polonsky–Keer with an FFT preconditioner on grids above "
    "32 x 32 points, the exact active set below: the same unique minimiser, KKT certificate "
    "<= 1e-12 h_s, <= 1e-10 h_s on a sweep's levels), polonsky-keer, active-set, or "
    "lawson-hanson (the paper's algorithm itself, slow)"
)


def _pressure_list(text: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated numbers such as 0.001,0.01, got {text!r}"
        ) from None
    if not values:
        raise argparse.ArgumentTypeError("expected at least one mean pressure")
    return values


def _solver_arg(p: argparse.ArgumentParser, help_text: str) -> None:
    from ..contact import SOLVERS

    p.add_argument("--solver", choices=SOLVERS, default="auto", help=help_text)


def _positive_int(text: str) -> int:
    try:
        return _validate.integer("value", int(text), low=1, high=2**1024)
    except (ValueError, InvalidArgumentError):
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None


def _axis_arg(text: str) -> int | str:
    try:
        return _validate.axis(text)
    except InvalidArgumentError:
        raise argparse.ArgumentTypeError(f"expected 0, 1, either or both, got {text!r}") from None


