"""Every code example of the docs runs as written: the README's and the docs pages' static Python blocks and the
gallery's scripts (``make docs`` runs the gallery again and shows its figures), with ``sf.`` names only. The
tutorials' and how-to pages' code cells (MyST-NB ``{code-cell}``) run in the docs build itself (tests/test_docs.py),
not here again."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def markdown_python_blocks() -> list[tuple[str, str]]:
    """Every static ```python block of the README and the docs' Markdown pages, as (where, code) (a ``{code-cell}`` is
    executed by the docs build)."""
    blocks = []
    for path in [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]:
        if "_build" in path.parts:
            continue
        for i, code in enumerate(re.findall(r"```python\n(.*?)```", path.read_text(), flags=re.DOTALL)):
            blocks.append((f"{path.relative_to(ROOT)} python block {i}", code))
    return blocks


@pytest.mark.parametrize("where,code", markdown_python_blocks(), ids=[w for w, _ in markdown_python_blocks()])
def test_docs_python_block_runs(where, code, tmp_path, monkeypatch):
    """Every Python block of the docs runs as written (from the repository root), so the docs cannot rot; they use
    ``sf.`` names only."""
    monkeypatch.chdir(ROOT)
    assert "sf." in code and "from spacefit." not in code and "import spacefit." not in code, where
    exec(compile(code, where, "exec"), {"__name__": "docs", "OUT": tmp_path})


GALLERY = sorted((DOCS / "examples").glob("plot_*.py"))


@pytest.mark.parametrize("script", GALLERY, ids=[p.name for p in GALLERY])
def test_gallery_example_runs(script, tmp_path, monkeypatch):
    """The gallery's scripts run (``make docs`` runs them again and shows their figures), with ``sf.`` names only."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    code = script.read_text()
    assert "from spacefit." not in code and "import spacefit." not in code
    monkeypatch.syspath_prepend(str(DOCS / "_ext"))
    from gallery_figures import figures_in

    monkeypatch.chdir(tmp_path)
    variables = {"__name__": "__main__"}
    exec(compile(code, str(script), "exec"), variables)
    made = plt.get_fignums() or figures_in(variables)
    assert made, f"{script.name} made no figure"
    plt.close("all")
