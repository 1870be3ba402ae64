"""The planted bugs of ``make mutants`` (tools/mutants.py) stay plantable: each one's snippet is in its
file exactly once and each test it names exists. Edits that move a line made two mutants stale
unnoticed (they plant nothing, so they prove nothing) until the whole run was repeated."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def load_mutants() -> tuple:
    spec = importlib.util.spec_from_file_location("mutants", ROOT / "tools" / "mutants.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["mutants"] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module.MUTANTS


def test_every_mutant_plants_its_bug_in_one_place_and_names_tests_that_exist():
    mutants = load_mutants()
    assert len({m.name for m in mutants}) == len(mutants), "two mutants share a name"
    stale = [(m.name, (ROOT / m.path).read_text().count(m.original)) for m in mutants
             if (ROOT / m.path).read_text().count(m.original) != 1]
    assert stale == [], f"(mutant, times its snippet is found): {stale}"
    missing = []
    for m in mutants:
        for test in m.tests:
            path, _, name = test.partition("::")
            if not (ROOT / path).is_file() or (name and f"def {name.split('[')[0]}(" not in (ROOT / path).read_text()):
                missing.append((m.name, test))
    assert missing == []
