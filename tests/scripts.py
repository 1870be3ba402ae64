"""The experiments' scripts run as a user runs them, in a subprocess (tests import nothing from
experiments/), and their CSV output read back."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import spacefit

ROOT = Path(__file__).resolve().parents[1]


def run_script(name: str, *args: str) -> str:
    """Run ``experiments/<name>.py`` with ``args`` from the repository root with this Python and this
    spacefit (the one the tests import); its stdout. A failure shows the script's stderr."""
    here = str(Path(spacefit.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([here, os.environ.get("PYTHONPATH", "")])}
    out = subprocess.run([sys.executable, str(ROOT / "experiments" / f"{name}.py"), *args], cwd=ROOT, env=env,
                         capture_output=True, text=True)
    assert out.returncode == 0, f"experiments/{name}.py {' '.join(args)} failed:\n{out.stderr[-4000:]}"
    return out.stdout


def read_csv(path: Path) -> list[dict[str, str]]:
    """A CSV file's rows (every value a string, as written)."""
    with open(path, newline="") as f:
        return list(csv.DictReader(f))
