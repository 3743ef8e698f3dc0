"""``leakpath surface {rmd,spectral}``: generate a surface, save it, print statistics."""

from __future__ import annotations

import argparse
import math
from typing import Any

from ..generators import DEFAULT_LENGTH, rmd, spectral
from ._common import (
    _add_output_arguments,
    _check_out,
    _shape_arg,
    _write_and_report,
)


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
        rolloff=args.rolloff,
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
        "--length",
        type=float,
        default=DEFAULT_LENGTH,
        help=f"side length in µm; dx = length/2^m (default {DEFAULT_LENGTH:g})",
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
        "--length",
        type=float,
        default=DEFAULT_LENGTH,
        help=f"size along x in µm; dx = length/nx (default {DEFAULT_LENGTH:g})",
    )
    scale = s.add_mutually_exclusive_group()
    scale.add_argument("--rms-height", type=float, help="rms height sqrt(m0) (default 1)")
    scale.add_argument("--rms-slope", type=float, help="rms slope sqrt(2 m2), forward differences")
    s.add_argument("--long-cutoff", type=float, help="longest wavelength (default: the box size)")
    s.add_argument(
        "--short-cutoff", type=float, help="shortest wavelength (default: 2 dx, Nyquist)"
    )
    s.add_argument(
        "--rolloff",
        type=float,
        help="roll-off wavelength: flat PSD between it and the long cut-off "
        "(default: the long cut-off, no plateau)",
    )
    _add_output_arguments(s)
    s.set_defaults(func=_cmd_surface_spectral)


# ---------------------------------------------------------------------------- sweep/paper
#: Files a sweep command writes into its output directory (besides figures/ and checkpoints/).
