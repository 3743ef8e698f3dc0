"""Sweep checkpoints: a directory of finished levels, each record bound to its run.

A record is the level's table row, its wall time, its contact mask and percolation classes
(and, for warm-started sweeps, its pressure field). Arrays live in memory as arrays; they are
encoded (zlib + base64 text) only here, when a record is written.
"""

from __future__ import annotations

import binascii
import hashlib
import io
import json
import math
import os
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import _validate, leakage
from ._io import atomic_write_bytes, atomic_write_text, dumps, pack, pack_mask, unpack, unpack_mask
from ._table import _LEVEL_COLUMNS, _TYPES, _coerce_cell
from .errors import InvalidArgumentError

__all__ = ["CheckpointMismatch", "CHECKPOINT_FORMAT"]

PathLike = str | os.PathLike[str]

#: Record format: 2 bound records to their run, checksummed, with pressure fields; 3 added
#: the leak-rate columns Q and K; 4 the branch and plastic columns and the plastic
#: displacement of the last loading level of an unloading sweep.
CHECKPOINT_FORMAT = 4


@dataclass
class _Level:
    """Everything one level contributes: its row, timing, masks and optional fields."""

    row: dict[str, Any]
    seconds: float
    mask: np.ndarray  # contact mask as bits (np.packbits of the C-order ravel)
    classes: np.ndarray  # int8 class map
    fields: dict[str, np.ndarray] | None = None
    #: The level's pressure field (float64): the warm start of the next level, kept in
    #: checkpoints so that a resumed warm sweep repeats the same solves bit for bit.
    pressure: np.ndarray | None = None
    #: The plastic displacement (float64) of the last loading level of an unloading sweep:
    #: the permanent surface the unloading levels are solved on.
    plastic: np.ndarray | None = None

    def contact_mask(self, shape: tuple[int, int]) -> np.ndarray:
        """The contact mask as a boolean array of ``shape``."""
        return np.unpackbits(self.mask, count=shape[0] * shape[1]).astype(bool).reshape(shape)



class CheckpointMismatch(ValueError):
    """``checkpoint_dir`` holds the checkpoints of a different sweep (``field`` differs)."""

    def __init__(self, directory: Path, field: str) -> None:
        self.directory = directory
        self.field = field
        super().__init__(
            f"checkpoint_dir: {str(directory)!r} holds a different sweep ({field} differs); "
            "use another directory or delete it to start afresh"
        )


class _Checkpoint:
    """A directory of finished levels: ``manifest.json`` + ``level_KKKK.json`` (+ ``.npz``).

    Every level record is bound to its run and to its own content: it carries the SHA-256 of
    the manifest (surface hash, parameters), its level index, and the SHA-256 of its own
    canonical JSON (and of its ``.npz`` fields file). A record that fails any check — another
    run's, edited, truncated, non-finite where a number is required — is not used: the level
    is computed again, and :attr:`recomputed` names it with the reason.
    """

    def __init__(self, directory: PathLike, manifest: dict[str, Any], keep_fields: bool):
        self.dir = _validate.path("checkpoint_dir", directory)
        self.keep_fields = keep_fields
        self.recomputed: list[tuple[int, str]] = []
        if self.dir.exists() and not self.dir.is_dir():
            raise InvalidArgumentError(
                f"checkpoint_dir: {str(self.dir)!r} exists and is not a directory",
                argument="checkpoint_dir",
            )
        _validate.make_directory("checkpoint_dir", self.dir)
        for stale in self.dir.glob(".*.tmp"):  # left by a run killed while writing
            try:
                stale.unlink()
            except OSError:
                pass
        path = self.dir / "manifest.json"
        text = dumps(manifest)
        wanted = json.loads(text)
        self.run = hashlib.sha256(text.encode("utf-8")).hexdigest()
        if path.exists():
            try:
                found = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError) as exc:
                raise InvalidArgumentError(
                    f"checkpoint_dir: cannot read {str(path)!r} ({exc}); delete it to restart",
                    argument="checkpoint_dir",
                ) from None
            if isinstance(found, dict) and found.get("format") != wanted["format"]:
                raise CheckpointMismatch(
                    self.dir,
                    f"checkpoint format {found.get('format')!r}, this leakpath reads "
                    f"{wanted['format']} (format 4 adds the branch and plastic columns)",
                )
            for key in _differences(found, wanted):
                raise CheckpointMismatch(self.dir, key)
        else:
            atomic_write_text(path, text)

    def _json(self, k: int) -> Path:
        return self.dir / f"level_{k:04d}.json"

    def _npz(self, k: int) -> Path:
        return self.dir / f"level_{k:04d}.npz"

    def load(
        self, k: int, shape: tuple[int, int], need_pressure: bool, need_plastic: bool = False
    ) -> _Level | None:
        """The checked level ``k``, or ``None`` (absent, or failed a check: see
        :attr:`recomputed`)."""
        path = self._json(k)
        if not path.exists():
            return None
        try:
            return self._load_checked(k, shape, need_pressure, need_plastic)
        except _BadCheckpoint as exc:
            self.recomputed.append((k, str(exc)))
            return None

    def _load_checked(
        self, k: int, shape: tuple[int, int], need_pressure: bool, need_plastic: bool
    ) -> _Level:
        try:
            data = json.loads(self._json(k).read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise _BadCheckpoint(f"unreadable ({exc.__class__.__name__})") from None
        if not isinstance(data, dict):
            raise _BadCheckpoint("not a level record")
        digest = data.pop("sha256", None)
        if digest != _record_digest(data):
            raise _BadCheckpoint("its content does not match its checksum")
        if data.get("run") != self.run:
            raise _BadCheckpoint("it belongs to another run (surface or parameters differ)")
        if data.get("k") != k or list(data.get("shape", [])) != list(shape):
            raise _BadCheckpoint("level index or shape differs")
        try:
            row = {c: _coerce_cell(c, data["row"][c]) for c in _LEVEL_COLUMNS}
            seconds = float(data["seconds"])
            mask = np.packbits(unpack_mask(str(data["mask"]), shape).ravel())
            classes = unpack(str(data["classes"]), np.int8, shape)
            packed = data.get("pressure")
            pressure = None
            if need_pressure:
                if not isinstance(packed, str):
                    raise _BadCheckpoint("no pressure field to warm-start the next level")
                pressure = unpack(packed, "<f8", shape)
                if not np.all(np.isfinite(pressure)):
                    raise _BadCheckpoint("non-finite pressure")
            plastic = None
            if need_plastic:
                packed_w = data.get("plastic")
                if not isinstance(packed_w, str):
                    raise _BadCheckpoint("no plastic displacement to unload from")
                plastic = unpack(packed_w, "<f8", shape)
                if not (np.all(np.isfinite(plastic)) and np.all(plastic >= 0)):
                    raise _BadCheckpoint("non-finite or negative plastic displacement")
        except _BadCheckpoint:
            raise
        except (KeyError, TypeError, ValueError, zlib.error, binascii.Error) as exc:
            raise _BadCheckpoint(f"malformed ({exc.__class__.__name__}: {exc})") from None
        for c in _LEVEL_COLUMNS:
            v = row[c]
            nan_ok = ("kkt",) + leakage.FLOW_LEVEL_COLUMNS  # NaN: flow switched off
            if _TYPES[c] == "f" and c not in nan_ok and not math.isfinite(v):
                raise _BadCheckpoint(f"{c} is not finite")
            if _TYPES[c] == "i" and v < 0:
                raise _BadCheckpoint(f"{c} is negative")
        fields = None
        if self.keep_fields:
            try:
                raw = self._npz(k).read_bytes()
            except OSError:
                raise _BadCheckpoint("its fields file is missing") from None
            if hashlib.sha256(raw).hexdigest() != data.get("fields_sha256"):
                raise _BadCheckpoint("its fields file does not match its checksum")
            with np.load(io.BytesIO(raw), allow_pickle=False) as z:
                fields = {name: z[name] for name in ("pressure", "gap", "labels")}
        return _Level(row, seconds, mask, classes, fields, pressure, plastic)

    def save(self, k: int, level: _Level, shape: tuple[int, int]) -> None:
        record: dict[str, Any] = {
            "run": self.run,
            "k": k,
            "shape": list(shape),
            "row": {c: level.row[c] for c in _LEVEL_COLUMNS},
            "seconds": level.seconds,
            "mask": pack_mask(level.contact_mask(shape)),
            "classes": pack(level.classes),
        }
        if level.pressure is not None:
            record["pressure"] = pack(np.asarray(level.pressure, dtype="<f8"))
        if level.plastic is not None:
            record["plastic"] = pack(np.asarray(level.plastic, dtype="<f8"))
        if level.fields is not None:
            buf = io.BytesIO()
            np.savez_compressed(buf, **level.fields)
            raw = buf.getvalue()
            atomic_write_bytes(self._npz(k), raw)
            record["fields_sha256"] = hashlib.sha256(raw).hexdigest()
        record = json.loads(dumps(record))  # the JSON form that is hashed and read back
        record["sha256"] = _record_digest(record)
        atomic_write_text(self._json(k), dumps(record))


class _BadCheckpoint(Exception):
    """A level record that must not be used (the message says why)."""


def _record_digest(record: Mapping[str, Any]) -> str:
    """SHA-256 of a record's canonical JSON (sorted keys, no ``sha256`` entry)."""
    body = {k: v for k, v in record.items() if k != "sha256"}
    text = json.dumps(body, sort_keys=True, allow_nan=False, ensure_ascii=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _differences(found: Any, wanted: Any, prefix: str = "") -> list[str]:
    """Dotted names of the entries where two JSON-like manifests differ."""
    if isinstance(found, dict) and isinstance(wanted, dict):
        out: list[str] = []
        for key in wanted:
            out += _differences(found.get(key), wanted[key], f"{prefix}{key}.")
        return out
    return [] if found == wanted else [prefix.rstrip(".") or "manifest"]




_MANIFEST_KEYS = frozenset({"format", "leakpath_version", "surface_sha256", "shape", "parameters"})


def own_files(directory: Path) -> list[Path]:
    """The files in ``directory`` that leakpath's checkpoints wrote, recognised by content.

    The manifest (its keys), each level record whose checksum matches its content, the
    fields file whose SHA-256 its level record carries, and leftover temporaries of atomic
    writes. Anything else — a user's file, an edited record — is not listed.
    """
    from ._outputs import is_temporary

    if not directory.is_dir():
        return []
    own: list[Path] = []
    manifest = directory / "manifest.json"
    try:
        found = json.loads(manifest.read_text(encoding="utf-8"))
        if isinstance(found, dict) and _MANIFEST_KEYS <= found.keys():
            own.append(manifest)
    except (OSError, ValueError):
        pass
    for record in sorted(directory.glob("level_*.json")):
        try:
            data = json.loads(record.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if not isinstance(data, dict) or data.get("sha256") != _record_digest(data):
            continue
        own.append(record)
        fields = record.with_suffix(".npz")
        try:
            if hashlib.sha256(fields.read_bytes()).hexdigest() == data.get("fields_sha256"):
                own.append(fields)
        except OSError:
            pass
    own += [p for p in directory.glob(".*.tmp") if is_temporary(p) and p.is_file()]
    return own
