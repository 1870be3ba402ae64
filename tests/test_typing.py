"""Names an editor can see: the type stub spacefit/__init__.pyi re-exports every public name from its
home module (tools/api_stub.py writes it from ``_EXPORTS``), the package ships it with a PEP 561
``py.typed`` marker, and mypy finds no error in the README's and the docs' examples but does in a misuse."""

from __future__ import annotations

import ast
import importlib
import re
import sys
import tomllib
from pathlib import Path

from mypy import api

import spacefit as sf

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import api_stub  # noqa: E402

MISUSE = '''import spacefit as sf
scene = sf.load_case("panels").scene()
image = sf.render("scene.toml")
sf.rendr(scene)
sf.Intrinsics(7.0, 4e-3, 600.5, 600)
'''


def test_the_stub_reexports_every_public_name_from_its_home():
    stub = (ROOT / "spacefit" / "__init__.pyi").read_text()
    assert stub == api_stub.stub_text(), "spacefit/__init__.pyi is stale: run python tools/api_stub.py"
    tree = ast.parse(stub)
    imported = {alias.asname: getattr(importlib.import_module(node.module), alias.name)
                for node in tree.body if isinstance(node, ast.ImportFrom) for alias in node.names}
    assert set(imported) == set(sf._EXPORTS) == set(sf.__all__)
    assert all(imported[name] is getattr(sf, name) for name in imported)
    listed = next(node.value for node in tree.body if isinstance(node, ast.Assign) and node.targets[0].id == "__all__")
    assert ast.literal_eval(listed) == sf.__all__


def test_the_stub_and_the_marker_are_package_data():
    patterns = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["spacefit"]
    for name in ("py.typed", "__init__.pyi"):
        assert name in patterns and (ROOT / "spacefit" / name).is_file()


def test_mypy_passes_the_readme_examples_and_catches_a_misuse(tmp_path):
    """One mypy run (a cold cache: about 8 s of CPU) over each Python block and code cell of the README and the docs'
    pages as a user script, and a misuse: a path for a scene, a misspelt name, a float image width."""
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    blocks = [b for page in pages for b in re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.DOTALL)]
    for page in pages:  # an executed page's code cells run in turn, as one script
        cells = re.findall(r"```\{code-cell\} ipython3\n(?::tags:[^\n]*\n)?(.*?)```", page.read_text(), flags=re.DOTALL)
        blocks += ["\n".join(cells)] if cells else []
    assert len(blocks) >= 1
    for i, block in enumerate(blocks):
        (tmp_path / f"readme_{i}.py").write_text(f'from pathlib import Path\nOUT = Path("out")\n{block}')
    (tmp_path / "misuse.py").write_text(MISUSE)
    out, err, status = api.run(["--config-file", str(ROOT / "pyproject.toml"), "--cache-dir", str(tmp_path / "cache"),
                                "--no-error-summary", "--hide-error-context", *map(str, sorted(tmp_path.glob("*.py")))])
    assert status == 1, (out, err)
    errors = [line.split(": error: ")[0].removeprefix(str(tmp_path) + "/") for line in out.splitlines() if ": error: " in line]
    assert errors == ["misuse.py:3", "misuse.py:4", "misuse.py:5"], out
