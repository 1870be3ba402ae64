"""Whether two checkouts fit :mod:`bench_pass`'s pass the same, bit for bit: the pass (the panels case, 3 materials and
the PSF width shared, 5 own values a frame, each frame's pixel grid) simulated at 64 spp and fitted, 2 LM steps at
8 spp, its values, standard errors and the pixel grid's step and remainder written to a JSON file; given the file of
another checkout's run, each figure's largest relative difference from it printed ("bit for bit" where none).
Run in each checkout (``PYTHONPATH`` its own): ``python experiments/pass_same_bits.py SIZE_PX FRAMES OUT.json [OTHER.json]``.
Figures: docs/measurements/performance-history.md, "A regression in memory at 48 frames".
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from bench_pass import MATERIALS, PER_FRAME, SENSOR, START, base
from studyio import commit

import spacefit as sf

FIGURES = {"values": lambda r: r.values, "stderr": lambda r: r.stderr, "pixel_grid_error": lambda r: r.extras.get("pixel_grid_error", {}),
           "pixel_grid_remainder": lambda r: r.extras.get("pixel_grid_remainder", {})}


def fitted(size: int, n: int) -> dict[str, dict[str, float]]:
    """The pass of ``n`` frames of ``size`` x ``size`` px fitted: each of :data:`FIGURES` by parameter."""
    rng = np.random.default_rng(3)
    with tempfile.TemporaryDirectory() as tmp:
        errors = [{"target.attitude_x_deg": float(a), "target.attitude_z_deg": float(b)} for a, b in rng.uniform(-0.3, 0.3, (n, 2))]
        frames = sf.simulate_pass(base(size), sf.arc_pass(n), Path(tmp) / "pass", errors=errors, sensor=SENSOR, spp=64)
        obs = [sf.Observation.from_file(f.file, s) for f, s in zip(frames.frames, frames.scenes(base(size)))]
        free = [*MATERIALS, "image.blur_sigma_px", *[f"{name}@{k}" for k in range(n) for name in PER_FRAME]]
        result = sf.fit(obs, free, start=START, render=sf.FitRender(spp=8), max_steps=2)
    return {name: dict(figure(result)) for name, figure in FIGURES.items()}


def main() -> None:
    size, n, out = int(sys.argv[1]), int(sys.argv[2]), Path(sys.argv[3])
    figures = fitted(size, n)
    out.write_text(json.dumps({"commit": commit(), **figures}))
    if len(sys.argv) > 4:
        other = json.loads(Path(sys.argv[4]).read_text())
        print(f"commit {commit()} against {other['commit']}; {size} x {size} px, {n} frames")
        for name in FIGURES:
            a, b = figures[name], other[name]
            worst = max((abs(a[k] - b[k]) / max(abs(b[k]), 1e-300) for k in b), default=0.0)
            print(f"  {name}: {len(b)} parameters, " + ("bit for bit" if a == b else f"largest relative difference {worst:.3g}"))


if __name__ == "__main__":
    main()
