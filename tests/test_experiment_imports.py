"""The scripts in experiments/ and the docs' examples name only spacefit names that exist.

They are run by hand (minutes to hours), not by the suite, so a rename in spacefit would break them
unseen; this reads their ``from spacefit... import`` lines (without running the scripts) and checks
that each module imports and holds each name.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted([*ROOT.glob("experiments/*.py"), *ROOT.glob("docs/examples/*.py"), *ROOT.glob("tools/*.py")])


def spacefit_imports(path: Path) -> list[tuple[str, str]]:
    """(module, name) of each ``from spacefit[.x] import name`` in the file."""
    tree = ast.parse(path.read_text(), filename=str(path))
    return [(node.module, alias.name) for node in ast.walk(tree)
            if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "spacefit"
            for alias in node.names]


def missing_names(path: Path) -> list[str]:
    """The names the file imports from spacefit that spacefit does not have (neither attribute nor submodule)."""
    def has(module: str, name: str) -> bool:
        found = importlib.import_module(module)
        return hasattr(found, name) or (hasattr(found, "__path__") and importlib.util.find_spec(f"{module}.{name}") is not None)

    return [f"{module}.{name}" for module, name in spacefit_imports(path) if not has(module, name)]


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: str(p.relative_to(ROOT)))
def test_a_script_imports_only_names_that_exist(path):
    assert not missing_names(path), f"{path.relative_to(ROOT)} imports names spacefit no longer has"


def test_the_check_sees_a_missing_name_and_a_submodule(tmp_path):
    script = tmp_path / "old.py"
    script.write_text("from spacefit.fitting.nuisance import image_model, split\nfrom spacefit import fitting, errors\n")
    assert missing_names(script) == ["spacefit.fitting.nuisance.split"]
