"""Parameter sets of an ensemble: their keys, their expansion from lists, the generator
that turns one set and a seed into a surface (the registry of :mod:`leakpath.generators`)."""

from __future__ import annotations

import itertools
import json
import numbers
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..generators import GENERATORS, generate
from ..surfaces import Surface

PathLike = str | os.PathLike[str]


def _format_value(value: Any) -> str:
    """Text of a parameter value in keys and CSV cells (floats as ``repr``)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        return repr(float(value))
    if isinstance(value, (list, tuple)):
        return "x".join(_format_value(v) for v in value)
    if value is None:
        return "none"
    return str(value)


def _safe(text: str) -> str:
    return "".join(ch if (ch.isascii() and (ch.isalnum() or ch in "._+-")) else "-" for ch in text)


def param_key(params: Mapping[str, Any]) -> str:
    """Directory-safe key of a parameter set: ``name=value`` over sorted names, joined by ``_``.

    ``param_key({"m": 7, "D": 2.1}) == "D=2.1_m=7"``; floats as ``repr``, sequences joined by
    ``x``; characters other than letters, digits and ``. _ + -`` become ``-``.
    """
    return "_".join(f"{_safe(str(k))}={_safe(_format_value(params[k]))}" for k in sorted(params))


def _sort_token(value: Any) -> tuple[Any, ...]:
    if isinstance(value, bool):
        return (1, int(value))
    if isinstance(value, numbers.Real):
        return (0, float(value))
    if isinstance(value, (list, tuple)):
        return (2, tuple(_sort_token(v) for v in value))
    return (3, str(value))


def _natural_order(params: Mapping[str, Any]) -> tuple[Any, ...]:
    """Sort key of a parameter set: numeric values compare as numbers (m=7 before m=10)."""
    return tuple((k, _sort_token(params[k])) for k in sorted(params))


@dataclass(frozen=True)
class ParamSet:
    """One parameter set of an ensemble: its key, generator arguments and seeds."""

    key: str
    params: dict[str, Any]
    seeds: tuple[int, ...]

    def label(self, names: Sequence[str] | None = None) -> str:
        """``"D = 2.1, m = 7"`` over ``names`` (default: all)."""
        names = sorted(self.params) if names is None else list(names)
        return ", ".join(f"{n} = {_format_value(self.params[n])}" for n in names)


def _json_roundtrip(value: Any) -> Any:
    """JSON-normalised value (tuples → lists); raises ``ValueError`` if not serialisable."""
    try:
        return json.loads(json.dumps(value, allow_nan=False))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"params: values must be JSON numbers, strings or lists ({exc})") from None


def _plain(value: Any) -> Any:
    """numpy scalars/arrays → Python numbers/lists, recursively (tuples stay tuples)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (list, tuple)):
        return type(value)(_plain(v) for v in value)
    return value


def _expand_params(params: Any) -> list[dict[str, Any]]:
    """A dict of lists → its Cartesian product; a list of dicts → itself (validated).

    In a dict, a list (or numpy array) holds the values of that parameter; anything else —
    a number, a string, a tuple such as ``shape=(64, 64)`` — is one value.
    """
    if isinstance(params, Mapping):
        if not params:
            raise ValueError("params: must name at least one parameter")
        names = list(params)
        values = []
        for name in names:
            v = _plain(params[name])
            if isinstance(v, list):
                if not v:
                    raise ValueError(f"params: the list for {name!r} is empty")
            else:
                v = [v]
            values.append(v)
        sets = [dict(zip(names, combo, strict=True)) for combo in itertools.product(*values)]
    elif isinstance(params, Sequence) and not isinstance(params, (str, bytes)):
        sets = []
        for i, item in enumerate(params):
            if not isinstance(item, Mapping):
                raise ValueError(f"params: item {i} must be a dict, got {type(item).__name__}")
            sets.append({k: _plain(v) for k, v in item.items()})
        if not sets:
            raise ValueError("params: the list of parameter sets is empty")
    else:
        raise ValueError(
            "params: expected a dict of lists (e.g. {'D': [2.1, 2.3], 'm': [7]}) or a list of "
            f"dicts, got {type(params).__name__}"
        )
    out = []
    for s in sets:
        for name in s:
            if not isinstance(name, str) or not name:
                raise ValueError(f"params: parameter names must be strings, got {name!r}")
            if name == "seed":
                raise ValueError("params: 'seed' is not a parameter; use surfaces= or seeds=")
        out.append(_json_roundtrip(s))
    return out


def _generator_name(generator: Any) -> str:
    if isinstance(generator, str):
        return generator
    module = getattr(generator, "__module__", "?")
    return f"{module}.{getattr(generator, '__qualname__', repr(generator))}"


def _check_generator(generator: Any, sets: list[dict[str, Any]]) -> None:
    if callable(generator) and not isinstance(generator, str):
        return
    if generator not in GENERATORS:
        raise ValueError(
            f"generator: must be one of {', '.join(GENERATORS)} or a callable, got {generator!r}"
        )
    gen = GENERATORS[generator]
    required, allowed = frozenset(gen.required), frozenset(gen.parameters)
    for s in sets:
        missing = sorted(required - set(s))
        unknown = sorted(set(s) - allowed)
        if missing:
            raise ValueError(f"params: generator {generator!r} needs {', '.join(missing)}")
        if unknown:
            raise ValueError(
                f"params: generator {generator!r} does not take {', '.join(unknown)} "
                f"(allowed: {', '.join(sorted(allowed))})"
            )


def _generate(generator: Any, params: Mapping[str, Any], seed: int) -> Surface:
    """The surface of one task: ``generator(**params, seed=seed)``."""
    if isinstance(generator, str):
        return generate(generator, params, seed)
    surface = generator(seed=seed, **dict(params))
    if not isinstance(surface, Surface):
        raise ValueError(f"generator: must return a leakpath Surface, got {type(surface).__name__}")
    return surface
