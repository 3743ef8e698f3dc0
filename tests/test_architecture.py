"""The package's layout: no import circles, no public name hiding a submodule.

The import graph is read from the source (every ``import`` statement, also those inside
functions and ``if TYPE_CHECKING:`` blocks), so a circle cannot hide behind a lazy import.
"""

from __future__ import annotations

import ast
import importlib
import pkgutil
from pathlib import Path

import pytest

import leakpath

ROOT = Path(leakpath.__file__).parent


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _resolve(module: str, is_package: bool, level: int, target: str | None) -> str:
    base = module.split(".")
    if not is_package:
        base = base[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join(base + ([target] if target else []))


def _import_graph() -> dict[str, set[str]]:
    modules = {_module_name(p): p for p in ROOT.rglob("*.py")}
    # The compiled core is a leaf: its stub stands for it.
    modules["leakpath._core"] = ROOT / "_core.pyi"
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for name, path in modules.items():
        if name == "leakpath._core":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        is_package = path.name == "__init__.py"
        for node in ast.walk(tree):
            targets: list[str] = []
            if isinstance(node, ast.ImportFrom):
                if node.level == 0:
                    base = node.module or ""
                else:
                    base = _resolve(name, is_package, node.level, node.module)
                # `from . import x` imports the submodule x when it is one; any other name
                # comes from the module (or the package face) ``base`` itself.
                for a in node.names:
                    sub = f"{base}.{a.name}"
                    targets.append(sub if sub in modules else base)
            elif isinstance(node, ast.Import):
                targets += [a.name for a in node.names]
            for t in targets:
                if t in modules and t != name:
                    graph[name].add(t)
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles() -> None:
    # A package face re-exports its submodules, so a submodule that imports the face (e.g.
    # ``from . import __version__``) closes a circle and is caught here too.
    assert _cycles(_import_graph()) == []


def test_cycle_detector_finds_a_planted_circle() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycles(graph) == [["a", "b", "c"]]


def test_graph_sees_lazy_imports_and_the_package_face() -> None:
    graph = _import_graph()
    # A contact state imports the flow lazily inside ContactState.flow().
    assert "leakpath._flow" in graph["leakpath._contact_state"]
    assert "leakpath.contact" in graph["leakpath"]


@pytest.mark.parametrize(
    "info", list(pkgutil.walk_packages(leakpath.__path__, "leakpath.")), ids=lambda i: i.name
)
def test_no_public_name_hides_a_submodule(info: pkgutil.ModuleInfo) -> None:
    """``import leakpath.x`` must give the module ``x``, not a function of the same name."""
    parent_name, _, child = info.name.rpartition(".")
    if info.name == "leakpath._core":
        return
    importlib.import_module(info.name)
    parent = importlib.import_module(parent_name)
    attr = getattr(parent, child, None)
    assert attr is None or getattr(attr, "__name__", None) == info.name, (
        f"{parent_name}.{child} is {attr!r}, not the submodule {info.name}"
    )
