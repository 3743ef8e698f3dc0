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
Usage errors (argparse errors, ``ValueError`` raised by the library for a bad argument,
refusing to overwrite a file) print one line ``leakpath: error: ...`` on stderr and exit
with status 2; other I/O failures (``OSError``) exit with status 1; Ctrl-C exits with 130.
No traceback is shown for any of them.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from . import __version__
from .moments import nayak_moments
from .surfaces import Surface, rmd, spectral

__all__ = ["main", "build_parser", "surface_statistics", "format_table", "UsageError"]

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
    if min(surface.shape) >= 3:
        mom = nayak_moments(surface)
        stats.update(m0=mom.m0, m2=mom.m2, m4=mom.m4, alpha=_finite_or_none(mom.alpha))
    else:
        stats.update(m0=None, m2=None, m4=None, alpha=None)
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
        print(json.dumps(payload, indent=2, default=str))
    else:
        rows = [("file", str(out))] + [(label, stats[key]) for key, label in _STAT_LABELS]
        print(format_table(rows))


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
    parts = text.lower().replace(",", "x").split("x")
    try:
        dims = [int(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected N or NYxNX, got {text!r}") from None
    if len(dims) == 1:
        return dims[0], dims[0]
    if len(dims) == 2:
        return dims[0], dims[1]
    raise argparse.ArgumentTypeError(f"expected N or NYxNX, got {text!r}")


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


# ---------------------------------------------------------------------------- entry point
def build_parser() -> argparse.ArgumentParser:
    """The ``leakpath`` argument parser with every registered command."""
    parser = _Parser(
        prog=PROG,
        description="Rough-surface contact mechanics and the percolating free volume.",
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    _add_surface_parser(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the process exit status."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help/--version (0) or a usage error (2)
        return int(exc.code) if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    func: Callable[[argparse.Namespace], int] = args.func
    try:
        return int(func(args))
    except (UsageError, ValueError) as exc:
        print(f"{PROG}: error: {_one_line(str(exc))}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"{PROG}: error: {_one_line(str(exc))}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
