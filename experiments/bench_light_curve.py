"""Issue 33's light-curve figure: a 24-point light curve of the default lander over the solar phase angle
(5 to 120 deg) at 0.5 % precision per point (the Monte Carlo standard error of each point's irradiance,
measured from two seeds), target at most 10 s a call to ``sf.light_curve`` on a quiet 2-core machine.
Calls at 4 and 16 spp are timed (set-up included; the first is a fresh process's first call) with their
worst point's relative error; the samples per pixel that reach 0.5 % follow from the error's 1 / sqrt(samples)
law, and the time of a call at that spp is extrapolated from the two calls' (set-up plus a time per spp):
the default lander needs well over a thousand, whose call would take many minutes on 2 cores. Run: ``.venv/bin/python experiments/bench_light_curve.py``.
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
PILOT_SPP = 4


def timed(spp: int) -> tuple[float, float]:
    """A call's wall time (s) and its worst point's relative standard error at ``spp``."""
    scene = sf.load_scene(None, {"render.spp": spp})
    t0 = time.perf_counter()
    curve = sf.light_curve(scene, phase_deg=PHASES_DEG, seeds=[0, 1], quiet=True)
    wall = time.perf_counter() - t0
    return wall, float(np.nanmax(curve.irradiance_se_w_m2 / curve.irradiance_w_m2))


def main() -> None:
    print(f"machine: {machine()}; default lander, {len(PHASES_DEG)} phases, 2 seeds a point; load {os.getloadavg()[0]:.1f}")
    runs = {spp: timed(spp) for spp in (PILOT_SPP, 4 * PILOT_SPP)}
    for spp, (wall, worst) in runs.items():
        print(f"at {spp} spp: {wall:.1f} s a call, worst point {worst:.2%}")
    (spp0, (wall0, _)), (spp1, (wall1, worst1)) = runs.items()
    needed = max(1, math.ceil(spp1 * (worst1 / TARGET_PRECISION) ** 2))  # two seeds a point at either spp
    per_spp = (wall1 - wall0) / (spp1 - spp0)
    print(f"24-point light curve at {TARGET_PRECISION:.1%} per point: {needed} spp x 2 seeds, extrapolated {wall0 + per_spp * (needed - spp0):.0f} s "
          f"a call (target 10 s; {wall0 - per_spp * spp0:.1f} s of set-up and {per_spp:.2f} s per spp, from the two calls); "
          f"load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
