"""The README's Python examples run as written: each ```python block, in order, in one
namespace, in an empty working directory (they write files)."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

README = Path(__file__).resolve().parents[1] / "README.md"


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


def test_readme_has_python_examples() -> None:
    assert len(_python_blocks(README.read_text(encoding="utf-8"))) >= 3


def test_readme_python_examples_run(tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__readme__"}
    out = io.StringIO()
    for i, block in enumerate(_python_blocks(README.read_text(encoding="utf-8"))):
        with contextlib.redirect_stdout(out):
            exec(compile(block, f"README.md python block {i + 1}", "exec"), namespace)
    # The sweep example wrote its table and figures where it said.
    assert (tmp_path / "table.csv").stat().st_size > 0
    assert any((tmp_path / "figures").iterdir())
    assert out.getvalue().strip()


def test_docs_name_only_modules_that_exist() -> None:
    """Every ``leakpath.x.y`` the docs and the README name imports (modules) or resolves
    (attributes), so a reader who follows them does not hit ModuleNotFoundError."""
    import importlib

    root = README.parent
    names: set[str] = set()
    for page in [README, *sorted((root / "docs").glob("*.md"))]:
        names |= set(re.findall(r"`(leakpath(?:\.[A-Za-z_][A-Za-z0-9_]*)+)", page.read_text()))
    missing = []
    for name in sorted(names):
        parts = name.split(".")
        for cut in range(len(parts), 0, -1):
            try:
                obj = importlib.import_module(".".join(parts[:cut]))
            except ModuleNotFoundError:
                continue
            try:
                for attr in parts[cut:]:
                    obj = getattr(obj, attr)
            except AttributeError:
                missing.append(name)
            break
        else:
            missing.append(name)
    assert not missing, missing
