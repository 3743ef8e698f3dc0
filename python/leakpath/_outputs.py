"""The record of the files a command-line run wrote into its output directory.

``--overwrite`` must replace a run's results without touching anything else a user keeps in
the same directory (notes, their own figures). A run therefore lists every file it writes in
``.leakpath-outputs.json`` (written atomically, updated after each group of files), with
each file's size and modification time; ``--overwrite`` removes exactly the listed files
that are still as the run left them. A file the run did not write, or one changed since, is
never deleted. Checkpoint records are recognised by their own checksums, so those of a run
killed before it recorded them are removed as well.
"""

from __future__ import annotations

import json
import os
import re
import stat
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from ._io import atomic_write_text, dumps

__all__ = ["RECORD_NAME", "OutputRecord", "OverwriteNote", "is_temporary", "prune_empty_dirs"]

#: The record's file name in the output directory.
RECORD_NAME = ".leakpath-outputs.json"
RECORD_FORMAT = 1

#: Hidden temporaries of :func:`leakpath._io.atomic_write_bytes`: ``.<name>.<pid>.<token>.tmp``.
_TEMPORARY = re.compile(r"^\..+\.\d+\.[0-9a-f]{12}\.tmp$")


def is_temporary(path: Path) -> bool:
    """Whether ``path`` is named like a temporary of leakpath's atomic writes."""
    return bool(_TEMPORARY.match(path.name))


class OverwriteNote(UserWarning):
    """What an overwrite left in place (a changed file, a directory without a record)."""


def _stamp(path: Path) -> dict[str, int] | None:
    """Size and modification time of a regular file (not followed through a link)."""
    try:
        info = os.lstat(path)
    except OSError:
        return None
    if not stat.S_ISREG(info.st_mode):
        return None
    return {"size": int(info.st_size), "mtime_ns": int(info.st_mtime_ns)}


class OutputRecord:
    """The files one run wrote into ``directory`` (paths relative to it)."""

    def __init__(self, directory: Path) -> None:
        self.dir = directory
        self.files: dict[str, dict[str, int]] = {}
        #: The files the last :meth:`remove_unchanged` deleted.
        self.removed: list[Path] = []

    @property
    def path(self) -> Path:
        return self.dir / RECORD_NAME

    def read(self) -> bool:
        """Load the record left by an earlier run; ``False`` when there is none (or it is
        unreadable: then nothing is known to be leakpath's)."""
        try:
            data = json.loads(self.path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return False
        files = data.get("files") if isinstance(data, dict) else None
        if not isinstance(files, dict):
            return False
        for rel, stamp in files.items():
            if (
                isinstance(rel, str)
                and isinstance(stamp, dict)
                and all(isinstance(stamp.get(k), int) for k in ("size", "mtime_ns"))
            ):
                self.files[rel] = {"size": stamp["size"], "mtime_ns": stamp["mtime_ns"]}
        return True

    def _inside(self, rel: str) -> Path | None:
        """``directory / rel`` when ``rel`` stays inside the directory, else ``None``."""
        parts = Path(rel).parts
        if not parts or Path(rel).is_absolute() or ".." in parts:
            return None
        path = self.dir / rel
        try:
            if not path.parent.resolve().is_relative_to(self.dir.resolve()):
                return None  # a linked sub-directory leading elsewhere
        except OSError:
            return None
        return path

    def add(self, paths: Iterable[Path], *, save: bool = True) -> None:
        """Record ``paths`` (files just written inside the directory) and save the record
        (``save=False`` defers that to a later :meth:`save`, for runs writing many files)."""
        root = self.dir.resolve()
        for p in paths:
            try:
                rel = Path(p).resolve().relative_to(root).as_posix()
            except (OSError, ValueError):
                continue  # not inside the output directory: not ours to remove later
            stamp = _stamp(Path(p))
            if stamp is not None:
                self.files[rel] = stamp
        if save:
            self.save()

    def save(self) -> None:
        body: dict[str, Any] = {
            "format": RECORD_FORMAT,
            "about": "files a leakpath run wrote here; --overwrite removes only these",
            "files": dict(sorted(self.files.items())),
        }
        atomic_write_text(self.path, dumps(body))

    def remove_unchanged(self) -> list[str]:
        """Delete the recorded files still as the run left them, and the record; return the
        recorded files kept because they changed since (or are no longer plain files)."""
        kept: list[str] = []
        self.removed = []
        for rel, stamp in sorted(self.files.items()):
            path = self._inside(rel)
            now = None if path is None else _stamp(path)
            if now is None:
                if path is not None and os.path.lexists(path):
                    kept.append(rel)  # replaced by a directory or a link: not ours now
                continue
            if now != stamp:
                kept.append(rel)
                continue
            path.unlink()
            self.removed.append(path)
        self.files.clear()
        try:
            self.path.unlink()
        except FileNotFoundError:
            pass
        return kept


def prune_empty_dirs(root: Path, removed: Iterable[Path]) -> None:
    """Remove the directories below ``root`` left empty by deleting ``removed``: the ones
    that held those files and their parents up to (not including) ``root``."""
    top = root.resolve()
    for path in sorted({Path(p).parent for p in removed}, key=lambda p: -len(p.parts)):
        while True:
            try:
                inside = path.resolve().is_relative_to(top) and path.resolve() != top
            except OSError:
                break
            if not inside or path.is_symlink():
                break
            try:
                path.rmdir()  # only succeeds when empty
            except OSError:
                break
            path = path.parent
