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
