"""``leakpath seal CONFIG.toml --out DIR``: a seal's leak rate with its interval, in SI units."""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from pathlib import Path
from typing import Any

from .. import _validate
from ._common import PROG, UsageError, _note, _one_line, _positive_int

#: API argument names as the command line spells them, for messages.
_FLAGS = {
    "out": "--out",
    "resume": "--resume",
    "overwrite": "--overwrite",
    "scheduler": "--scheduler",
    "workers": "--workers",
    "config": "CONFIG",
}


def _as_flags(message: str) -> str:
    """A message in the API's words (``out: …``, ``resume=True``) in the CLI's."""
    head, sep, rest = message.partition(":")
    if sep and head in _FLAGS:
        message = _FLAGS[head] + sep + rest
    return message.replace("resume=True", "--resume").replace("overwrite=True", "--overwrite")


def _num(value: float, unit: str, digits: int = 3) -> str:
    if isinstance(value, float) and math.isnan(value):
        return "n/a"
    return f"{value:.{digits}g} {unit}".rstrip()


def format_seal_summary(result: Any) -> str:
    """The summary as an aligned text table, every number with its unit."""
    s = result.summary
    gas = result.gas
    stem, unit = ("mass_flow", "kg/s") if gas else ("leak_rate", "m3/s")
    suffix = "_kg_per_s" if gas else "_m3_per_s"
    header = ["p_nominal", "contact A/A0", "Persson A/A0", "K_eff", "K_eff 95% interval",
              "leaking patches", "mass flow" if gas else "leak rate Q", "Q interval",
              "Q Bruggeman", "grid check dK/K"]
    body = []
    for r in s.rows():
        change = r["grid_check_relative_change"]
        check = "n/a" if math.isnan(change) else f"{change:.1%}" + (
            "" if r["converged"] else " (!)")
        body.append([
            _num(r["mean_pressure_Pa"], "Pa"),
            f"{r['contact_fraction']:.3f} ± {r['contact_fraction_std']:.3f}",
            f"{r['persson_contact_fraction']:.3f}",
            _num(r["permeability_m3"], "m3"),
            f"[{r['permeability_low_m3']:.3g}, {r['permeability_high_m3']:.3g}] m3",
            f"{r['n_leaking']}/{r['n_patches']}",
            _num(r[stem + suffix], unit),
            f"[{r[stem + '_low' + suffix]:.3g}, {r[stem + '_high' + suffix]:.3g}] {unit}",
            _num(r[stem + "_bruggeman" + suffix], unit),
            check,
        ])
    widths = [max(len(h), *(len(row[i]) for row in body)) for i, h in enumerate(header)]
    lines = ["  ".join(h.rjust(w) for h, w in zip(header, widths, strict=True))]
    lines += ["  ".join(c.rjust(w) for c, w in zip(row, widths, strict=True)) for row in body]
    meta = result.metadata
    patch = meta["patch"]
    lines.append(
        f"E* = {meta['E_star_Pa']:.4g} Pa, composite rms slope {meta['composite_rms_slope']:.3g}, "
        f"patch {patch['n']}^2 points, {patch['length_m']:.4g} m side (dx {patch['dx_m']:.3g} m), "
        f"{result.config.realisations} realisations, axes {result.config.axis}, "
        f"wall time {meta['run']['wall_seconds']:.1f} s"
    )
    return "\n".join(lines)


def _cmd_seal(args: argparse.Namespace) -> int:
    from ..seal import SealConvergenceWarning, SealValidityWarning, load_config, seal_leakage

    if args.workers is not None and args.scheduler:
        raise UsageError("--workers sizes local processes; with --scheduler size the cluster")
    if args.resume and args.overwrite:
        raise UsageError("--resume and --overwrite exclude each other")
    _validate.path("--out", args.out)
    if not args.config.is_file():
        raise UsageError(f"CONFIG {str(args.config)!r} is not a file")
    config = load_config(args.config)  # errors name the config key (load.mean_pressure: …)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            result = seal_leakage(
                config,
                out=args.out,
                resume=args.resume,
                overwrite=args.overwrite,
                scheduler=args.scheduler,
                workers=args.workers,
                progress=True,
            )
        except (ValueError, FileExistsError, ImportError) as exc:
            raise UsageError(_as_flags(str(exc))) from None
        finally:
            for w in caught:
                if issubclass(w.category, (SealValidityWarning, SealConvergenceWarning,
                                           RuntimeWarning)):
                    print(f"{PROG}: warning: {_one_line(_as_flags(str(w.message)))}",
                          file=sys.stderr)
    kept = result.metadata.get("overwrite_kept")
    if kept:
        _note(f"--overwrite kept {len(kept)} file(s) changed since the earlier run: "
              + ", ".join(kept[:5]))
    print(format_seal_summary(result))
    print(f"results: {args.out}/summary.csv, realisations.csv, metadata.json, figures/seal.png")
    return 0


def _add_seal_parser(subparsers: Any) -> None:
    """``leakpath seal``: leak rate of a seal from a TOML configuration."""
    p = subparsers.add_parser(
        "seal",
        help="leak rate of a seal (two rough bodies, SI units) with its confidence interval",
        description="Read CONFIG.toml (docs/seal.md: bodies, materials, nominal pressures, "
        "fluid, seal geometry), run N realisations on local processes or a Dask cluster "
        "(one checkpoint per realisation in DIR/checkpoints), and write DIR/summary.csv, "
        "DIR/realisations.csv, DIR/metadata.json and DIR/figures/seal.png/.pdf.",
    )
    p.add_argument("config", type=Path, metavar="CONFIG.toml", help="the seal configuration")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory")
    p.add_argument(
        "--resume", action="store_true",
        help="continue an interrupted run in --out from its checkpoints (same tables)",
    )
    p.add_argument(
        "--overwrite", action="store_true",
        help="replace an earlier run's results in --out (only the files it recorded writing, "
        "unchanged since; nothing else is deleted)",
    )
    p.add_argument(
        "--scheduler", default=None, metavar="ADDRESS",
        help="run on a Dask cluster (e.g. tcp://host:8786; needs leakpath[dask])",
    )
    p.add_argument(
        "--workers", type=_positive_int, default=None,
        help="local worker processes (default: all CPUs; 1 runs in this process)",
    )
    p.set_defaults(func=_cmd_seal)
