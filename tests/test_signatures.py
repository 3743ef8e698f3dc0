"""Public functions and methods take explicit keywords: no ``**kwargs`` to hide a typo."""

from __future__ import annotations

import inspect

import leakpath
from leakpath import experiments


def _public_callables():
    for name in leakpath.__all__:
        obj = getattr(leakpath, name)
        if inspect.isclass(obj):
            for attr, member in vars(obj).items():
                if not attr.startswith("_") and callable(member):
                    yield f"leakpath.{name}.{attr}", member
        elif callable(obj):
            yield f"leakpath.{name}", obj
    yield "leakpath.experiments.paper", experiments.paper


def test_no_public_api_takes_var_keywords() -> None:
    hidden = []
    for name, fn in _public_callables():
        fn = getattr(fn, "__func__", fn)
        try:
            params = inspect.signature(fn).parameters.values()
        except (TypeError, ValueError):  # compiled or builtin
            continue
        if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
            hidden.append(name)
    assert hidden == []


def test_state_flow_takes_the_flow_keywords() -> None:
    state_params = inspect.signature(leakpath.ContactState.flow).parameters
    flow_params = inspect.signature(leakpath.flow).parameters
    # Everything of leakpath.flow except what the state itself supplies.
    assert set(flow_params) - {"state_or_gap", "dx", "contact"} == set(state_params) - {"self"}
    for name, p in state_params.items():
        if name != "self":
            assert p.kind is inspect.Parameter.KEYWORD_ONLY
            assert p.default == flow_params[name].default, name
