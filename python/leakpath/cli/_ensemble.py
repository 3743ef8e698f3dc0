"""``leakpath ensemble``: many surfaces per parameter set, aggregated."""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .. import _validate
from ._common import (
    PROG,
    UsageError,
    _axis_arg,
    _one_line,
    _positive_int,
    _print_json,
    format_table,
)


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


#: API argument names as the command line spells them, for messages.
_FLAGS = {"out": "--out", "resume": "--resume", "overwrite": "--overwrite"}


def _as_flags(message: str) -> str:
    """A message in the API's words (``out: …``, ``resume=True``) in the CLI's (``--out``)."""
    head, sep, rest = message.partition(":")
    if sep and head in _FLAGS:
        message = _FLAGS[head] + sep + rest
    return (
        message.replace("resume=True (CLI --resume)", "--resume")
        .replace("overwrite=True (CLI --overwrite)", "--overwrite")
        .replace("resume=True", "--resume")
        .replace("overwrite=True", "--overwrite")
    )


def _print_warnings(caught: list[warnings.WarningMessage]) -> None:
    """Warnings of the run (tasks recomputed after failing their checks) and notes of
    ``--overwrite`` (files it kept), one line each."""
    from .._outputs import OverwriteNote

    for w in caught:
        kind = "note" if issubclass(w.category, OverwriteNote) else "warning"
        print(f"{PROG}: {kind}: {_one_line(_as_flags(str(w.message)))}", file=sys.stderr)


def _cmd_ensemble(args: argparse.Namespace) -> int:
    from ..ensemble import OverwriteNote, ensemble

    if args.workers is not None and args.scheduler:
        raise UsageError("--workers sizes local processes; with --scheduler size the cluster")
    if args.resume and args.overwrite:
        raise UsageError("--resume and --overwrite exclude each other")
    _validate.path("--out", args.out)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", RuntimeWarning)
            warnings.simplefilter("always", OverwriteNote)
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
        raise UsageError(_as_flags(str(exc))) from None
    except ValueError as exc:  # a bad argument or a damaged --out directory
        raise UsageError(_as_flags(str(exc))) from None
    except RuntimeError as exc:  # failed tasks; the finished ones are on disk
        _print_warnings(caught)
        print(f"{PROG}: error: {_one_line(_as_flags(str(exc)))}", file=sys.stderr)
        return 1
    _print_warnings(caught)
    if args.json:
        _print_json(result.summary())
    else:
        print(format_table(_ensemble_summary_rows(result)))
    return 0


def _add_ensemble_parser(subparsers: Any) -> None:
    """``leakpath ensemble``: many RMD surfaces per (D, m), in parallel, with error bands."""
    from ..contact import SOLVERS

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
        help="replace a previous ensemble in --out: delete the files its run wrote "
        "(as recorded in OUT/.leakpath-outputs.json) and its checksummed task files; "
        "files of your own stay",
    )
    p.add_argument("--no-figures", action="store_true", help="do not write OUT/figures")
    p.add_argument("--json", action="store_true", help="print ensemble.json instead of a table")
    p.set_defaults(func=_cmd_ensemble)


# ---------------------------------------------------------------------------- entry point
