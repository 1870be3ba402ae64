"""Every code example of the docs runs as written: the README's and the docs pages' static Python blocks, with
``sf.`` names only. The tutorials' and how-to pages' code cells (MyST-NB ``{code-cell}``) and the gallery's scripts
run in the docs build itself (tests/test_docs.py), not here again; the gallery's scripts use ``sf.`` names only."""

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
def test_gallery_example_uses_public_names(script):
    """The gallery's scripts teach the public API: ``import spacefit as sf`` and ``sf.`` names only. They run in the
    docs build (tests/test_docs.py), which fails naming a script that raises and checks that each shows its figure;
    running them here as well cost the suite their whole time a second time."""
    code = script.read_text()
    assert "import spacefit as sf\n" in code and "sf." in code, script.name
    assert not re.search(r"from spacefit[.\w]* import|import spacefit\.", code), script.name
