"""``leakpath paper`` and ``leakpath sweep``: a sweep into an output directory."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .. import leakage
from ..errors import InvalidArgumentError
from ..experiments import PAPER, paper_surface
from ..surfaces import FILL_METHODS, Surface
from ._common import (
    _PLASTIC_SUMMARY_COLUMNS,
    _SOLVER_HELP,
    _SUMMARY_COLUMNS,
    CHECKPOINT_DIR,
    FIELDS_NAME,
    FIGURES_DIR,
    METADATA_NAME,
    SURFACE_NAME,
    TABLE_NAME,
    UsageError,
    _add_sweep_output_arguments,
    _axis_arg,
    _json_number,
    _positive_int,
    _prepare_outdir,
    _pressure_list,
    _print_json,
    _solver_arg,
    _surface_from_arg,
    format_summary,
)


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
    hardness: float | None = None,
    unload: bool = False,
) -> int:
    """Run a sweep into ``args.out`` and print its summary (table or JSON)."""
    from .._checkpoint import CheckpointMismatch
    from .._sweep import _check_levels, _resolve_mean_pressures, sweep
    from ..contact import check_hardness, contact_modulus

    out: Path = args.out
    # Every option is checked before the output directory is touched or anything is solved.
    contact_modulus(E, nu)
    try:
        hardness = check_hardness(hardness)
    except InvalidArgumentError as exc:
        raise UsageError(f"--hardness: {str(exc).split(': ', 1)[-1]}") from None
    if hardness is not None and args.solver in ("active-set", "lawson-hanson"):
        raise UsageError(
            f"--solver {args.solver} cannot cap the pressure at a hardness; use --solver auto "
            "or polonsky-keer with --hardness"
        )
    if hardness is not None and mean_pressures and max(mean_pressures) > hardness:
        raise UsageError(
            f"--mean-pressures: {max(mean_pressures)!r} exceeds --hardness {hardness!r}; a "
            "perfectly plastic surface carries at most the hardness"
        )
    _check_levels(levels, surface.shape, keep_fields)
    n_rows = levels + 1
    if mean_pressures is not None:
        try:
            n_rows = len(_resolve_mean_pressures(mean_pressures))
        except InvalidArgumentError as exc:
            raise UsageError(f"--mean-pressures: {str(exc).split(': ', 1)[-1]}") from None
    _check_flux_maps(args.flux_maps, n_rows, leakage.flow_enabled(args.flow, surface.shape))
    if not surface.height_range > 0:
        raise UsageError(
            "SURFACE is flat (h_s = max h - min h = 0): the flat touches every point at once "
            "and there is no approach to sweep; check the file's heights"
        )
    record = _prepare_outdir(out, overwrite=args.overwrite, resume=args.resume)
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
            hardness=hardness,
            unload=unload,
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
    # Each file is recorded as soon as it is written, so that a later --overwrite removes
    # exactly this run's files even if the run stops part-way.
    record.add([surface.save(files["surface"], overwrite=True)])
    record.add([result.to_csv(files["table"])])
    if keep_fields:
        files["fields"] = result.save_fields(out / FIELDS_NAME)
        record.add([files["fields"]])
    # The files of result.plot(directory), in two steps so that each is recorded as written:
    # the paper's figures, then the leak-rate ones (fig4, flux maps) when there is flow.
    from ..plotting.flow import save_flow_figures
    from ..plotting.paper import save_paper_figures

    figures = save_paper_figures(result, out / FIGURES_DIR)
    record.add(figures)
    figures += save_flow_figures(result, out / FIGURES_DIR, flux_levels=args.flux_maps)
    record.add(figures)
    from ..plotting.plastic import save_plastic_figures

    figures += save_plastic_figures(result, out / FIGURES_DIR)
    record.add(figures)
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
    record.add([result.to_json(files["metadata"], extra=extra)])
    columns = _PLASTIC_SUMMARY_COLUMNS if (hardness is not None or unload) else _SUMMARY_COLUMNS
    summary = [{key: row[key] for key, _ in columns} for row in result.rows]
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
        print(format_summary(summary, columns))
        resumed = f" ({len(result.resumed)} levels from checkpoints)" if result.resumed else ""
        print(
            f"{len(result.rows)} levels in {result.total_seconds:.1f} s{resumed}; wrote "
            f"{files['table']}, {files['metadata']}, {len(figures)} figures in "
            f"{out / FIGURES_DIR}"
        )
    return 0


def _check_flux_maps(rows: Sequence[int] | None, n_rows: int, flow_on: bool) -> None:
    """Refuse ``--flux-maps`` rows the sweep will not have, before it runs."""
    if rows is None:
        return
    if not flow_on:
        raise UsageError(
            "--flux-maps: this sweep computes no leak rates (--no-flow, or the default above "
            "513 x 513 points); pass --flow, or drop --flux-maps"
        )
    bad = [k for k in rows if not 0 <= k < n_rows]
    if bad:
        raise UsageError(
            f"--flux-maps: row {bad[0]} does not exist, the sweep has rows 0 to {n_rows - 1}; "
            "give row indices in that range"
        )


def _cmd_paper(args: argparse.Namespace) -> int:
    setup = PAPER
    surface = paper_surface(args.seed, setup)
    n = setup.points
    mode = "cold (p = 0) per level" if args.cold else "warm start from the previous level"
    description = (
        f"leakpath paper: RMD surface D = {setup.D}, m = {setup.m} ({n} x {n}), side "
        f"{setup.side:g} {setup.unit}, seed {args.seed}; lengths and heights in {setup.unit}, "
        f"pressures in units of E (E = {setup.E:g}, nu = {setup.nu:g}); {setup.levels} levels "
        f"Delta_k = k h_s/{setup.levels}; solver {args.solver}, {mode}"
    )
    return _run_sweep(
        surface,
        args,
        command="paper",
        description=description,
        warm_start=not args.cold,
        levels=setup.levels,
        E=setup.E,
        nu=setup.nu,
    )


def _add_paper_parser(subparsers: Any) -> None:
    """``leakpath paper``: the paper's experiment (table, metadata and figures)."""
    p = subparsers.add_parser(
        "paper",
        help="run the paper's experiment (RMD D=2.1, m=7, 20 levels) and draw its figures",
        description=(
            "The experiment of Cinat, Paggi & Borri: an RMD surface (D = 2.1, m = 7, 129 x 129 "
            "points, side 100 µm; lengths and heights in µm) pressed against a rigid flat at "
            "20 equal approaches up to its height range. Writes table.csv, metadata.json, "
            "surface.npz and figures/ into --out and prints a summary."
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
        hardness=args.hardness,
        unload=args.unload,
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
    p.add_argument(
        "--hardness",
        type=float,
        default=None,
        metavar="H",
        help="cap the contact pressure at H (E's unit): elastic-perfectly-plastic contact "
        "(docs/plasticity.md); adds the plastic columns",
    )
    p.add_argument(
        "--unload",
        action="store_true",
        help="append an unloading branch (the loading rows in reverse, on the permanently "
        "deformed surface of the last loading row); best with --mean-pressures",
    )
    leakage.add_flow_arguments(p)  # leakpath.leakage
    _add_sweep_output_arguments(p, "sweep-results")
    p.set_defaults(func=_cmd_sweep)


# ---------------------------------------------------------------------------- flow
