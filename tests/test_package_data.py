"""The synthetic cases are package data: found through importlib.resources, declared in
pyproject.toml's package-data, and present in a built wheel installed away from the checkout."""

from __future__ import annotations

import fnmatch
import subprocess
import sys
import textwrap
import tomllib
from importlib.resources import files
from pathlib import Path

import pytest

import spacefit as sf
from spacefit.cases import CASES_DIR

ROOT = Path(__file__).resolve().parents[1]


def test_cases_are_found_as_package_data():
    """cases.toml and every scene file it names sit in spacefit's package data, and pyproject.toml's
    package-data patterns take each of them into a wheel (setuptools leaves out what they miss)."""
    assert CASES_DIR == files("spacefit") / "synthetic"
    listed = sorted(p.name for p in CASES_DIR.iterdir() if p.is_file())
    table = tomllib.loads((CASES_DIR / "cases.toml").read_text())
    scenes = {entry.get("scene", name) for name, entry in table.items()}
    assert listed == sorted({"cases.toml", *(f"{s}.toml" for s in scenes)})
    patterns = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["spacefit"]
    assert all(any(fnmatch.fnmatch(f"synthetic/{name}", p) for p in patterns) for name in listed)
    assert sf.case_names() == list(table)
    assert sf.load_case("panels").truth["parts.legs.kd"] == 0.5


@pytest.mark.slow
def test_an_installed_wheel_loads_and_renders_a_case(tmp_path):
    """pip wheel, install it into a folder (not editable) and, from another folder, load and render a case (about 15 s; pip builds it in an isolated environment, which fetches setuptools)."""
    run = [sys.executable, "-m", "pip"]
    subprocess.run([*run, "wheel", "--no-deps", "-q", "-w", str(tmp_path / "wheel"), str(ROOT)], check=True, capture_output=True)
    wheel = next((tmp_path / "wheel").glob("spacefit-*.whl"))
    subprocess.run([*run, "install", "--no-deps", "-q", "--target", str(tmp_path / "site"), str(wheel)], check=True,
                   capture_output=True)
    code = textwrap.dedent("""
        import spacefit as sf
        case = sf.load_case("panels").with_values({"render.resolution": [32, 32], "camera.pixel_pitch_mm": 75.0, "render.spp": 2})
        image, _ = case.reference()
        print(sf.__file__, image.shape, float(image.max()) > 0)
    """)
    away = tmp_path / "elsewhere"
    away.mkdir()
    out = subprocess.run([sys.executable, "-c", code], cwd=away, env={"PYTHONPATH": str(tmp_path / "site"), "PATH": "/usr/bin:/bin"},
                         check=True, capture_output=True, text=True).stdout.split()
    assert out == [str(tmp_path / "site" / "spacefit" / "__init__.py"), "(32,", "32,", "3)", "True"]
