"""Command-line interface: ``leakpath <command> ...`` (also ``python -m leakpath``).

Layout
------
:func:`build_parser` creates the top-level parser and one sub-parser per command. Each
command lives in its own ``_add_<name>_parser(subparsers)`` function, which registers its
arguments and sets ``func`` (a callable ``(argparse.Namespace) -> int``) with
``parser.set_defaults(func=...)``; :func:`main` dispatches to it. To add a command (e.g.
``paper``, ``sweep``, ``ensemble``), write ``_add_<name>_parser`` and call it from
:func:`build_parser` — nothing else changes.

Errors
------
Usage errors and every error leakpath raises on purpose (argparse errors, a
:class:`~leakpath.errors.LeakpathError` — a bad argument, a problem too large for memory,
a solver that did not converge —, any other ``ValueError``, a missing optional package,
refusing to overwrite a file) print one line ``leakpath: error: ...`` on stderr and exit
with status 2; I/O failures (``OSError``) exit with status 1; Ctrl-C exits with 130. An
unexpected error prints one line naming it and exits with status 1; ``--debug`` (anywhere
on the command line) adds the traceback. No traceback is shown otherwise. ``--json`` output
is strict JSON: non-finite numbers are written as ``null``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from . import _validate, leakage
from ._core import __version__  # leakage: --flow, --flow-axis, --flux-maps
from .errors import InvalidArgumentError, LeakpathError
from .generators import _shape_text, generate, parse_spec, rmd, spectral
from .moments import nayak_moments
from .surfaces import FILL_METHODS, Surface, load

__all__ = [
    "main",
    "build_parser",
    "surface_statistics",
    "format_table",
    "format_summary",
    "parse_surface_spec",
    "UsageError",
    "PAPER_SETUP",
]

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


_STAT_LABELS: tuple[tuple[str, str], ...] = (
    ("shape", "shape (ny x nx)"),
    ("dx", "dx"),
    ("height_range", "h_s (max - min)"),
    ("mean", "mean height"),
    ("rms_height", "rms height"),
    ("m0", "m0"),
    ("m2", "m2"),
    ("m4", "m4"),
    ("alpha", "alpha"),
)


def _report(surface: Surface, out: Path, *, as_json: bool) -> None:
    stats = surface_statistics(surface)
    if as_json:
        payload = {"path": str(out), **stats, "metadata": surface.metadata}
        _print_json(payload)
    else:
        rows = [("file", str(out))] + [(label, stats[key]) for key, label in _STAT_LABELS]
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


def _cmd_surface_rmd(args: argparse.Namespace) -> int:
    _check_out(args.out, args.overwrite)
    surface = rmd(args.m, args.D, seed=args.seed, sigma0=args.sigma0, length=args.length)
    return _write_and_report(surface, args)


def _cmd_surface_spectral(args: argparse.Namespace) -> int:
    _check_out(args.out, args.overwrite)
    surface = spectral(
        args.n,
        args.hurst,
        seed=args.seed,
        length=args.length,
        rms_height=args.rms_height,
        rms_slope=args.rms_slope,
        long_cutoff=args.long_cutoff,
        short_cutoff=args.short_cutoff,
    )
    return _write_and_report(surface, args)


def _add_surface_parser(subparsers: Any) -> None:
    """``leakpath surface {rmd,spectral}``: generate a surface, save it, print statistics."""
    p = subparsers.add_parser(
        "surface",
        help="generate a rough surface and save it",
        description="Generate a rough surface, write it as .npz and print its statistics.",
    )
    gens = p.add_subparsers(dest="generator", metavar="GENERATOR", required=True)

    r = gens.add_parser(
        "rmd",
        help="random midpoint displacement (the paper's generator)",
        description="Random midpoint displacement on a (2^m+1)^2 grid, H = 3 - D, min(h) = 0.",
    )
    r.add_argument("--m", type=int, required=True, help="levels: grid (2^m + 1)^2, 1 <= m <= 14")
    r.add_argument("--D", type=float, required=True, help="fractal dimension, 2 < D < 3")
    r.add_argument("--seed", type=int, required=True, help="random seed (non-negative integer)")
    r.add_argument(
        "--sigma0",
        type=float,
        default=1.0 / math.sqrt(0.09),
        help="std. deviation of the corner heights (default 1/sqrt(0.09))",
    )
    r.add_argument(
        "--length", type=float, default=1.0, help="side length; dx = length/2^m (default 1)"
    )
    _add_output_arguments(r)
    r.set_defaults(func=_cmd_surface_rmd)

    s = gens.add_parser(
        "spectral",
        help="periodic Fourier-filtered self-affine surface",
        description="Periodic self-affine surface, PSD ~ q^(-2(1+H)) between two cut-offs "
        "(given as wavelengths; q = 2 pi / wavelength).",
    )
    s.add_argument(
        "--n", type=_shape_arg, required=True, metavar="N|NYxNX", help="grid size, e.g. 256"
    )
    s.add_argument("--hurst", type=float, required=True, help="Hurst exponent, 0 < H < 1")
    s.add_argument("--seed", type=int, required=True, help="random seed (non-negative integer)")
    s.add_argument(
        "--length", type=float, default=1.0, help="size along x; dx = length/nx (default 1)"
    )
    scale = s.add_mutually_exclusive_group()
    scale.add_argument("--rms-height", type=float, help="rms height sqrt(m0) (default 1)")
    scale.add_argument("--rms-slope", type=float, help="rms slope sqrt(2 m2), forward differences")
    s.add_argument("--long-cutoff", type=float, help="longest wavelength (default: the box size)")
    s.add_argument(
        "--short-cutoff", type=float, help="shortest wavelength (default: 2 dx, Nyquist)"
    )
    _add_output_arguments(s)
    s.set_defaults(func=_cmd_surface_spectral)


# ---------------------------------------------------------------------------- sweep/paper
#: Files a sweep command writes into its output directory (besides figures/ and checkpoints/).
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
    path = Path(text)
    if not path.exists():
        raise UsageError(
            f"SURFACE {text!r} is neither an existing file nor a spec such as "
            "'rmd:m=7,D=2.1,seed=0' or 'spectral:n=256,hurst=0.8,seed=1'"
        )
    return load(path, dx=dx, fill=fill)


_OWN_PATTERNS = {
    CHECKPOINT_DIR: ("manifest.json", "level_*.json", "level_*.npz", ".*.tmp"),
    FIGURES_DIR: ("fig*.png", "fig*.pdf", "map_k*.png", "map_k*.pdf", ".*.tmp")
    + leakage.FIGURE_PATTERNS,
}


def _prepare_outdir(out: Path, *, overwrite: bool, resume: bool) -> None:
    """Refuse a non-empty output directory unless ``--overwrite``/``--resume``; create it.

    ``--overwrite`` deletes only the files a sweep writes (checkpoints, figures, table,
    metadata, surface, fields), nothing else in the directory.
    """
    if overwrite and resume:
        raise UsageError("--overwrite and --resume exclude each other")
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
    if overwrite and non_empty:
        for sub, patterns in _OWN_PATTERNS.items():
            for pattern in patterns:
                for f in (out / sub).glob(pattern):
                    if f.is_file():
                        f.unlink()
        for name in (TABLE_NAME, METADATA_NAME, SURFACE_NAME, FIELDS_NAME):
            if (out / name).is_file():
                (out / name).unlink()
    out.mkdir(parents=True, exist_ok=True)


def format_summary(rows: Sequence[dict[str, Any]]) -> str:
    """The summary table: k, Δ*, contact fraction, V*, V_pg*, ḡ*, m0*, m2* (4 decimals)."""
    header = [label for _, label in _SUMMARY_COLUMNS]
    body = []
    for row in rows:
        cells = []
        for key, _ in _SUMMARY_COLUMNS:
            v = row[key]
            if key == "K_star":  # leakpath.leakage: spans decades
                cells.append(f"{v:.3e}")
                continue
            cells.append(str(v) if isinstance(v, int) else f"{v:.4f}")
        body.append(cells)
    widths = [max(len(h), *(len(r[i]) for r in body)) for i, h in enumerate(header)]
    lines = ["  ".join(h.rjust(w) for h, w in zip(header, widths, strict=True))]
    lines += ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in body]
    return "\n".join(lines)


def _run_sweep(
    surface: Surface,
    args: argparse.Namespace,
    *,
    command: str,
    description: str,
    warm_start: bool,
    levels: int,
    axis: Any = 0,
    boundary: str = "free",
    E: float = 1.0,  # noqa: N803
    nu: float = 0.0,
    connectivity: int = 4,
    keep_fields: bool = False,
    mean_pressures: Sequence[float] | None = None,
    argv: Sequence[str] | None = None,
) -> int:
    """Run a sweep into ``args.out`` and print its summary (table or JSON)."""
    from ._checkpoint import CheckpointMismatch
    from ._sweep import _check_levels, sweep
    from .contact import contact_modulus

    out: Path = args.out
    contact_modulus(E, nu)  # validate before touching the output directory
    _check_levels(levels, surface.shape, keep_fields)
    if not surface.height_range > 0:
        raise UsageError(
            "SURFACE is flat (h_s = max h - min h = 0): the flat touches every point at once "
            "and there is no approach to sweep; check the file's heights"
        )
    _prepare_outdir(out, overwrite=args.overwrite, resume=args.resume)
    try:
        result = sweep(
            surface,
            levels=levels,
            mean_pressures=mean_pressures,
            solver=args.solver,
            warm_start=warm_start,
            axis=axis,
            connectivity=connectivity,
            E=E,
            nu=nu,
            boundary=boundary,
            keep_fields=keep_fields,
            progress=sys.stderr.isatty(),
            checkpoint_dir=out / CHECKPOINT_DIR,
            **leakage.sweep_flow_options(args),  # leakpath.leakage
        )
    except CheckpointMismatch as exc:
        raise UsageError(
            f"cannot resume in {str(out)!r}: its checkpoints are from a different sweep "
            f"({exc.field} differs); use --overwrite or another --out"
        ) from None
    files = {
        "table": out / TABLE_NAME,
        "metadata": out / METADATA_NAME,
        "surface": out / SURFACE_NAME,
    }
    surface.save(files["surface"], overwrite=True)
    result.to_csv(files["table"])
    if keep_fields:
        files["fields"] = result.save_fields(out / FIELDS_NAME)
    figures = result.plot(out / FIGURES_DIR)
    from .plotting.flow import save_flow_figures  # leak-rate figures (fig4, flux maps)

    figures += save_flow_figures(result, out / FIGURES_DIR, flux_levels=args.flux_maps)
    extra = {
        "command": command,
        "argv": list(argv) if argv is not None else sys.argv[1:],
        "description": description,
        "outputs": {
            **{k: str(v) for k, v in files.items()},
            "figures": [str(p) for p in figures],
            "checkpoints": str(out / CHECKPOINT_DIR),
        },
    }
    result.to_json(files["metadata"], extra=extra)
    summary = [{key: row[key] for key, _ in _SUMMARY_COLUMNS} for row in result.rows]
    if args.json:
        payload = {
            "command": command,
            "description": description,
            "out": str(out),
            "files": extra["outputs"],
            "resumed_levels": result.resumed,
            "seconds": result.total_seconds,
            "summary": summary,
        }
        _print_json(payload, default=_json_number)
    else:
        print(description)
        print(format_summary(summary))
        resumed = f" ({len(result.resumed)} levels from checkpoints)" if result.resumed else ""
        print(
            f"{len(result.rows)} levels in {result.total_seconds:.1f} s{resumed}; wrote "
            f"{files['table']}, {files['metadata']}, {len(figures)} figures in "
            f"{out / FIGURES_DIR}"
        )
    return 0


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
        help="replace the results in a non-empty --out directory",
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
    "<= 1e-12 h_s), polonsky-keer, active-set, or lawson-hanson (the paper's algorithm "
    "itself, slow)"
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
    from .contact import SOLVERS

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


#: The paper's setup (Cinat, Paggi, Borri): RMD surface, D = 2.1, m = 7, side 0.1 mm.
PAPER_SETUP: dict[str, Any] = {"m": 7, "D": 2.1, "length": 0.1, "unit": "mm", "levels": 20}


def _cmd_paper(args: argparse.Namespace) -> int:
    setup = PAPER_SETUP
    surface = rmd(setup["m"], setup["D"], seed=args.seed, length=setup["length"])
    surface.metadata["unit"] = setup["unit"]
    surface.metadata["experiment"] = (
        "Cinat, Paggi, Borri: Percolation properties of the free volume generated by two "
        "rough surfaces in contact"
    )
    n = 2 ** setup["m"] + 1
    mode = "cold (p = 0) per level" if args.cold else "warm start from the previous level"
    description = (
        f"leakpath paper: RMD surface D = {setup['D']}, m = {setup['m']} ({n} x {n}), side "
        f"{setup['length']} mm, seed {args.seed}; lengths in mm, pressures in units of E "
        f"(E = 1, nu = 0); {setup['levels']} levels Delta_k = k h_s/{setup['levels']}; "
        f"solver {args.solver}, {mode}"
    )
    return _run_sweep(
        surface,
        args,
        command="paper",
        description=description,
        warm_start=not args.cold,
        levels=setup["levels"],
    )


def _add_paper_parser(subparsers: Any) -> None:
    """``leakpath paper``: the paper's experiment (table, metadata and figures)."""
    p = subparsers.add_parser(
        "paper",
        help="run the paper's experiment (RMD D=2.1, m=7, 20 levels) and draw its figures",
        description=(
            "The experiment of Cinat, Paggi & Borri: an RMD surface (D = 2.1, m = 7, 129 x 129 "
            "points, side 0.1 mm; lengths in mm) pressed against a rigid flat at 20 equal "
            "approaches up to its height range. Writes table.csv, metadata.json, surface.npz "
            "and figures/ into --out and prints a summary."
        ),
    )
    p.add_argument("--seed", type=int, default=0, help="RMD seed (default 0)")
    _solver_arg(p, _SOLVER_HELP)
    warm = p.add_mutually_exclusive_group()
    warm.add_argument(
        "--cold",
        action="store_true",
        help="solve every level from p = 0, as in the paper (\"without warm starting\"); "
        "default: start each level from the previous one (the same minimiser, faster)",
    )
    warm.add_argument("--warm-start", action="store_true", help="the default; kept for scripts")
    leakage.add_flow_arguments(p)  # leakpath.leakage
    _add_sweep_output_arguments(p, "paper-results")
    p.set_defaults(func=_cmd_paper)


def _cmd_sweep(args: argparse.Namespace) -> int:
    surface = _surface_from_arg(args.surface, args.dx, args.fill)
    if args.unit:
        surface.metadata["unit"] = args.unit
    unit = surface.metadata.get("unit", "the surface's length unit")
    ny, nx = surface.shape
    description = (
        f"leakpath sweep: {args.surface} ({ny} x {nx}, dx = {surface.dx:.6g}, lengths in "
        f"{unit}); "
        + (
            f"{len(args.mean_pressures)} imposed mean pressures"
            if args.mean_pressures
            else f"{args.levels} levels"
        )
        + f", boundary {args.boundary}, flow axis {args.axis}, "
        f"solver {args.solver}, {'cold' if args.no_warm_start else 'warm start'}"
    )
    return _run_sweep(
        surface,
        args,
        command="sweep",
        description=description,
        warm_start=not args.no_warm_start,
        levels=args.levels,
        axis=args.axis,
        boundary=args.boundary,
        E=args.E,
        nu=args.nu,
        connectivity=args.connectivity,
        keep_fields=args.keep_fields,
        mean_pressures=args.mean_pressures,
    )


def _add_sweep_parser(subparsers: Any) -> None:
    """``leakpath sweep SURFACE``: a sweep over the approach for any surface."""
    p = subparsers.add_parser(
        "sweep",
        help="sweep the approach for a surface file or generator spec",
        description=(
            "Press SURFACE against a rigid flat at LEVELS + 1 equal approaches from 0 to its "
            "height range (free boundary) or to full contact (periodic), and write table.csv, "
            "metadata.json, surface.npz and figures/ into --out. SURFACE is a file (.npz, "
            ".npy, .csv, .txt, ...; give --dx when the file has no spacing) or a spec such as "
            "rmd:m=8,D=2.3,seed=4 or spectral:n=256,hurst=0.8,seed=1,rms_height=1."
        ),
    )
    p.add_argument("surface", metavar="SURFACE", help="surface file or generator spec")
    p.add_argument("--dx", type=float, help="grid spacing for files that do not store it")
    p.add_argument(
        "--fill",
        choices=FILL_METHODS,
        default=None,
        help="fill a file's undefined (NaN or masked) points: nearest (mean of the nearest "
        "defined points) or mean (mean height); default: refuse such a file",
    )
    p.add_argument("--unit", help="name of the length unit, for labels and metadata")
    p.add_argument("--levels", type=_positive_int, default=20, help="number of steps (default 20)")
    _solver_arg(p, _SOLVER_HELP)
    p.add_argument(
        "--no-warm-start",
        "--cold",
        dest="no_warm_start",
        action="store_true",
        help="solve every level from p = 0 (default: start from the previous level)",
    )
    p.add_argument(
        "--mean-pressures",
        type=_pressure_list,
        default=None,
        metavar="P1,P2,...",
        help="load control: one row per imposed mean pressure p = F/A0 (increasing, in E's "
        "unit) instead of --levels equal approaches; the table carries p/E*",
    )
    p.add_argument(
        "--boundary",
        choices=("free", "periodic"),
        default="free",
        help="elastic boundary (default free)",
    )
    p.add_argument(
        "--axis",
        type=_axis_arg,
        default=0,
        metavar="{0,1,either,both}",
        help="flow direction for V_pg* and the maps (default 0)",
    )
    p.add_argument(
        "--connectivity",
        type=int,
        choices=(4, 8),
        default=4,
        help="free-cell neighbourhood (default 4)",
    )
    p.add_argument("--E", type=float, default=1.0, help="Young's modulus (default 1)")
    p.add_argument("--nu", type=float, default=0.0, help="Poisson's ratio (default 0)")
    p.add_argument(
        "--keep-fields",
        action="store_true",
        help="also write per-level pressure, gap and cluster labels to fields.npz",
    )
    leakage.add_flow_arguments(p)  # leakpath.leakage
    _add_sweep_output_arguments(p, "sweep-results")
    p.set_defaults(func=_cmd_sweep)


# ---------------------------------------------------------------------------- flow
def _cmd_flow(args: argparse.Namespace) -> int:
    import numpy as np

    from . import _core
    from ._flow import flow
    from .contact import contact_modulus, default_memory_limit, solve

    surface = _surface_from_arg(args.surface, args.dx)
    e_star = contact_modulus(args.E, args.nu)
    if args.approach is not None:
        state = solve(
            surface, args.approach, E=args.E, nu=args.nu, boundary=args.boundary,
            solver="polonsky-keer",
        )
        gap, contact = np.maximum(state.gap, 0.0), state.contact
        approach, mean_pressure = state.approach, state.mean_pressure
    else:
        if not (math.isfinite(args.pressure) and args.pressure > 0):
            raise UsageError(f"--pressure must be a positive number, got {args.pressure!r}")
        out = _core.solve_polonsky_keer(
            np.ascontiguousarray(surface.heights, dtype=np.float64),
            surface.dx,
            e_star,
            args.boundary,
            mean_pressure=args.pressure,
            memory_limit=default_memory_limit(),
        )
        gap, contact = np.maximum(out["gap"], 0.0), out["pressure"] > 0
        approach, mean_pressure = float(out["approach"]), float(out["mean_pressure"])
    f = flow(
        gap,
        dx=surface.dx,
        contact=contact,
        axis=args.axis,
        viscosity=args.viscosity,
        pressure_drop=args.pressure_drop,
        periodic=args.boundary == "periodic",
    )
    result = {
        "surface": args.surface,
        "shape": list(surface.shape),
        "dx": surface.dx,
        "boundary": args.boundary,
        "approach": approach,
        "mean_pressure": mean_pressure,
        "contact_fraction": float(np.count_nonzero(contact) / contact.size),
        "axis": f.axis,
        "viscosity": f.viscosity,
        "pressure_drop": f.pressure_drop,
        "flow_rate": f.flow_rate,
        "inlet_flow_rate": f.inlet_flow_rate,
        "conductance": f.conductance,
        "permeability": f.permeability,
        "hydraulic_aperture": f.hydraulic_aperture,
        "n_unknowns": f.n_unknowns,
        "iterations": f.iterations,
        "residual": f.residual,
        "conservation": f.conservation,
        "seconds": f.seconds,
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        width = max(len(k) for k in result)
        for k, v in result.items():
            text = f"{v:.6g}" if isinstance(v, float) else str(v)
            print(f"{k:<{width}}  {text}")
    return 0


def _add_flow_parser(subparsers: Any) -> None:
    """``leakpath flow SURFACE``: the leak rate through the gap at one approach or load."""
    p = subparsers.add_parser(
        "flow",
        help="leak rate (Reynolds flow through the gap) at one approach or mean pressure",
        description=(
            "Press SURFACE against a rigid flat (Polonsky-Keer) at --approach A (length) or "
            "mean pressure --pressure P, then solve the steady Reynolds flow through the gap "
            "along --axis with inlet pressure --pressure-drop and outlet 0 (docs/flow.md). "
            "SURFACE is a file or a spec such as spectral:n=256,hurst=0.8,seed=1,rms_height=1."
        ),
    )
    p.add_argument("surface", metavar="SURFACE", help="surface file or generator spec")
    p.add_argument("--dx", type=float, help="grid spacing for files that do not store it")
    load = p.add_mutually_exclusive_group(required=True)
    load.add_argument("--approach", type=float, help="imposed approach (length)")
    load.add_argument("--pressure", type=float, help="mean contact pressure (load control)")
    p.add_argument("--axis", type=int, choices=(0, 1), default=0, help="flow axis (default 0)")
    p.add_argument("--viscosity", type=float, default=1.0, help="dynamic viscosity (default 1)")
    p.add_argument(
        "--pressure-drop", type=float, default=1.0, help="inlet minus outlet pressure (default 1)"
    )
    p.add_argument(
        "--boundary",
        choices=("free", "periodic"),
        default="free",
        help="elastic boundary; periodic also wraps the flow across the axis (default free)",
    )
    p.add_argument("--E", type=float, default=1.0, help="Young's modulus (default 1)")
    p.add_argument("--nu", type=float, default=0.0, help="Poisson's ratio (default 0)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=_cmd_flow)


# ---------------------------------------------------------------------------- ensemble
def _ensemble_list(kind: Callable[[str], Any], what: str) -> Callable[[str], list[Any]]:
    """argparse type: a comma-separated list of ``kind`` values (``2.1,2.3,2.5``)."""

    def parse(text: str) -> list[Any]:
        items = [t.strip() for t in text.split(",")]
        try:
            if not all(items):
                raise ValueError
            return [kind(t) for t in items]
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected a comma-separated list of {what}, got {text!r}"
            ) from None

    return parse


def _ensemble_summary_rows(result: Any) -> list[tuple[str, Any]]:
    run = result.run or {}
    rows: list[tuple[str, Any]] = [
        ("ensemble", str(result.directory)),
        (
            "tasks",
            f"{run.get('tasks_total')} (run {run.get('tasks_run')}, "
            f"resumed {run.get('tasks_resumed')})",
        ),
        ("executor", f"{run.get('executor')}, workers {run.get('workers')}"),
        ("wall time", f"{run.get('wall_seconds', float('nan')):.1f} s"),
    ]
    for ps in result.param_sets:
        s = result.threshold_summary[ps.key]
        a = s["contact_fraction"]
        half = (a["ci_high"] - a["ci_low"]) / 2
        rows.append(
            (
                f"a_c {ps.key}",
                f"mean {a['mean']:.4f} +/- {half:.4f} (95 % band), std {a['std']:.4f}, "
                f"median {a['quantiles']['0.5']:.4f}, found {s['n_found']}/{s['surfaces']}",
            )
        )
    rows.append(("aggregate", str(result.aggregate_path)))
    rows.append(("thresholds", str(result.thresholds_path)))
    rows.append(("summary", str(result.json_path)))
    if result.figures:
        rows.append(("figures", str(result.figures[0].parent)))
    return rows


def _cmd_ensemble(args: argparse.Namespace) -> int:
    from .ensemble import ensemble

    if args.workers is not None and args.scheduler:
        raise UsageError("--workers sizes local processes; with --scheduler size the cluster")
    if args.resume and args.overwrite:
        raise UsageError("--resume and --overwrite exclude each other")
    try:
        result = ensemble(
            generator="rmd",
            params={"D": args.D, "m": args.m},
            surfaces=args.surfaces,
            levels=args.levels,
            solver=args.solver,
            warm_start=not args.cold,
            axis=args.axis,
            out=args.out,
            executor=args.scheduler,
            workers=args.workers,
            resume=args.resume,
            overwrite=args.overwrite,
            progress=True,
            figures=not args.no_figures,
            E=args.E,
            nu=args.nu,
        )
    except (FileExistsError, ImportError) as exc:
        raise UsageError(str(exc)) from None
    except RuntimeError as exc:  # failed tasks; the finished ones are on disk
        print(f"{PROG}: error: {_one_line(str(exc))}", file=sys.stderr)
        return 1
    if args.json:
        _print_json(result.summary())
    else:
        print(format_table(_ensemble_summary_rows(result)))
    return 0


def _add_ensemble_parser(subparsers: Any) -> None:
    """``leakpath ensemble``: many RMD surfaces per (D, m), in parallel, with error bands."""
    from .contact import SOLVERS

    p = subparsers.add_parser(
        "ensemble",
        help="sweeps over many surfaces per parameter set, in parallel, aggregated",
        description="Run one sweep per (D, m, seed) on local processes or a Dask cluster, "
        "write each finished surface to OUT/tasks at once, then the mean curves with 95 % "
        "confidence bands (OUT/aggregate.csv), the percolation thresholds "
        "(OUT/thresholds.csv, OUT/ensemble.json) and figures (OUT/figures).",
    )
    p.add_argument(
        "--D",
        type=_ensemble_list(float, "numbers"),
        required=True,
        metavar="D[,D...]",
        help="fractal dimensions, 2 < D < 3 (e.g. 2.1,2.3,2.5)",
    )
    p.add_argument(
        "--m",
        type=_ensemble_list(int, "integers"),
        required=True,
        metavar="M[,M...]",
        help="RMD levels: grids (2^m + 1)^2 (e.g. 7)",
    )
    p.add_argument(
        "--surfaces",
        type=_positive_int,
        default=50,
        help="surfaces per parameter set, seeds 0..N-1 (default 50)",
    )
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory")
    p.add_argument(
        "--levels", type=_positive_int, default=20, help="approach steps per sweep (default 20)"
    )
    p.add_argument(
        "--solver", choices=SOLVERS, default="auto", help="contact solver (default auto)"
    )
    p.add_argument(
        "--axis",
        type=_axis_arg,
        default=0,
        help="flow axis for V_pg and the threshold: 0, 1, either, both (default 0)",
    )
    p.add_argument(
        "--cold", action="store_true", help="solve every level from p = 0 (no warm start)"
    )
    p.add_argument("--E", type=float, default=1.0, help="Young's modulus (default 1)")
    p.add_argument("--nu", type=float, default=0.0, help="Poisson's ratio (default 0)")
    p.add_argument(
        "--workers",
        type=_positive_int,
        default=None,
        help="local worker processes (default: all CPUs), one rayon thread each",
    )
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="run on a Dask cluster (e.g. tcp://host:8786; needs leakpath[dask])",
    )
    p.add_argument(
        "--resume", action="store_true", help="run only the tasks missing in a previous --out"
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="delete a previous ensemble's files in --out first",
    )
    p.add_argument("--no-figures", action="store_true", help="do not write OUT/figures")
    p.add_argument("--json", action="store_true", help="print ensemble.json instead of a table")
    p.set_defaults(func=_cmd_ensemble)


# ---------------------------------------------------------------------------- entry point
def build_parser() -> argparse.ArgumentParser:
    """The ``leakpath`` argument parser with every registered command."""
    parser = _Parser(
        prog=PROG,
        description="Rough-surface contact mechanics and the percolating free volume.",
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    parser.add_argument(
        "--debug", action="store_true", help="show the traceback of an unexpected error"
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    _add_surface_parser(subparsers)
    _add_paper_parser(subparsers)
    _add_sweep_parser(subparsers)
    _add_ensemble_parser(subparsers)
    _add_flow_parser(subparsers)
    _add_debug_flags(parser)
    return parser


def _add_debug_flags(parser: argparse.ArgumentParser) -> None:
    """``--debug`` on the parser and on every sub-command, so it may go anywhere."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                sub.add_argument(
                    "--debug",
                    action="store_true",
                    default=argparse.SUPPRESS,
                    help="show the traceback of an unexpected error",
                )
                _add_debug_flags(sub)


def _fail(message: str, status: int) -> int:
    print(f"{PROG}: error: {_one_line(message)}", file=sys.stderr)
    return status


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the process exit status."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help/--version (0) or a usage error (2)
        return int(exc.code) if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    func: Callable[[argparse.Namespace], int] = args.func
    debug = bool(getattr(args, "debug", False))
    try:
        return int(func(args))
    except BrokenPipeError:
        # The reader went away (`leakpath ... | head`): stop quietly, with the status of a
        # process ended by SIGPIPE as other command-line tools do. Output files are written
        # atomically, so none is left half-written. Pointing stdout at /dev/null stops
        # Python's own flush at exit from reporting the same broken pipe.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        return 141  # 128 + SIGPIPE (13)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except (UsageError, LeakpathError, ValueError, ImportError) as exc:
        # Bad arguments, files leakpath cannot read, problems refused up front (too large
        # for memory), solvers that did not converge, a missing optional package.
        if debug:
            traceback.print_exc()
        return _fail(str(exc), 2)
    except OSError as exc:
        if debug:
            traceback.print_exc()
        return _fail(str(exc), 1)
    except Exception as exc:  # a defect or an environment failure: name it, one line
        if debug:
            traceback.print_exc()
            return _fail(f"unexpected {type(exc).__name__}: {exc}", 1)
        return _fail(
            f"unexpected {type(exc).__name__}: {exc} (run again with --debug to see the "
            "traceback)",
            1,
        )


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
