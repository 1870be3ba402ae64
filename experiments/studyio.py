"""Small helpers shared by the study and benchmark scripts: CSV and chart output, image error, machine name."""

from __future__ import annotations

import csv
import os
import subprocess
from collections.abc import Sequence
from pathlib import Path

import numpy as np


def write_csv(path: Path, rows: Sequence[dict[str, object]]) -> None:
    """Write dict rows (all with the first row's keys) as CSV with a header."""
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def save_figure(fig: object, path: Path, rect: tuple[float, float, float, float] | None = None) -> None:
    """Lay out a pyplot figure (within ``rect`` of the canvas, if given), write it as PNG at the
    studies' resolution (110 dpi) and close it."""
    import matplotlib.pyplot as plt  # here: each script chooses the Agg backend before pyplot loads

    fig.tight_layout(rect=rect)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def relative_rmse(image: np.ndarray, reference: np.ndarray) -> float:
    """RMSE over the reference's lit pixels (maximum channel > 0) divided by their mean radiance."""
    lit = reference.max(axis=-1) > 0
    return float(np.sqrt(np.mean((image[lit] - reference[lit]) ** 2)) / reference[lit].mean())


def machine() -> str:
    """CPU model and core count, for benchmark output."""
    cpu = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                if line.startswith("model name")), "unknown CPU")
    return f"{cpu}, {os.cpu_count()} cores"


def commit() -> str:
    """The checkout's short commit hash ("unknown" outside a git checkout), for benchmark output."""
    run = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=Path(__file__).parent, capture_output=True, text=True)
    return run.stdout.strip() or "unknown"
