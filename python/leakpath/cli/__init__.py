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

Modules: ``_common`` (errors, formatting, argument types), one module per command
(``_surface``, ``_sweep`` for ``paper``/``sweep``, ``_flow``, ``_ensemble``,
``_seal``); this module builds
the parser and dispatches.
"""

from __future__ import annotations

import argparse
import os
import sys
import traceback
from collections.abc import Callable, Sequence

from .._core import __version__
from .._validate import show_path
from ..errors import LeakpathError
from ._common import (
    PROG,
    UsageError,
    _one_line,
    _Parser,
    _print_json,
    format_summary,
    format_table,
    parse_surface_spec,
    surface_statistics,
)
from ._ensemble import _add_ensemble_parser
from ._flow import _add_flow_parser
from ._seal import _add_seal_parser
from ._surface import _add_surface_parser
from ._sweep import _add_paper_parser, _add_sweep_parser

__all__ = [
    "main",
    "build_parser",
    "surface_statistics",
    "format_table",
    "format_summary",
    "parse_surface_spec",
    "UsageError",
    "_print_json",
]


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
    _add_seal_parser(subparsers)
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


def _os_error_text(exc: OSError) -> str:
    """An ``OSError`` as one readable line: a long file name is shortened in the middle."""
    if exc.strerror and exc.filename is not None:
        names = [exc.filename] + ([exc.filename2] if exc.filename2 is not None else [])
        shown = " -> ".join(show_path(os.fsdecode(n)) for n in names)
        return f"{exc.strerror}: {shown}"
    return str(exc)


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
        return _fail(_os_error_text(exc), 1)
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
