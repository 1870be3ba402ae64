"""Issue 33's light-curve figure: a 24-point light curve of the default lander over the solar phase angle
(5 to 120 deg) at 0.5 % precision per point (the Monte Carlo standard error of each point's irradiance,
measured from four seeds), target at most 10 s a call to ``sf.light_curve`` on a quiet 2-core machine.
A pilot call at 16 spp measures the worst point's relative error (from 4 seeds: 2 seeds' error is itself
too uncertain to size a run by); the samples per pixel that reach 0.5 % follow from the error's
1 / sqrt(samples) law, and that call is timed (set-up included), with the precision it reached. Run: ``.venv/bin/python experiments/bench_light_curve.py``.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np
from studyio import machine

import spacefit as sf

PHASES_DEG = np.linspace(5.0, 120.0, 24)
TARGET_PRECISION = 0.005
PILOT_SPP = 16
SEEDS = (0, 1, 2, 3)


def timed(spp: int) -> tuple[float, float]:
    """A call's wall time (s) and its worst point's relative standard error at ``spp``."""
    scene = sf.load_scene(None, {"render.spp": spp})
    t0 = time.perf_counter()
    curve = sf.light_curve(scene, phase_deg=PHASES_DEG, seeds=list(SEEDS), quiet=True)
    wall = time.perf_counter() - t0
    return wall, float(np.nanmax(curve.irradiance_se_w_m2 / curve.irradiance_w_m2))


def main() -> None:
    print(f"machine: {machine()}; default lander, {len(PHASES_DEG)} phases, {len(SEEDS)} seeds a point; load {os.getloadavg()[0]:.1f}")
    wall, worst = timed(PILOT_SPP)
    print(f"pilot at {PILOT_SPP} spp: {wall:.1f} s a call, worst point {worst:.2%}")
    spp = max(1, math.ceil(PILOT_SPP * (worst / TARGET_PRECISION) ** 2))
    wall, reached = timed(spp)
    print(f"24-point light curve at {TARGET_PRECISION:.1%} per point: {wall:.1f} s a call (target 10 s) at {spp} spp x {len(SEEDS)} seeds, "
          f"worst point {reached:.2%}; load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
