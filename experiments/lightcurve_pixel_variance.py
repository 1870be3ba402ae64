"""Where a light-curve point's Monte Carlo error lives: the default lander at four phase angles, 16 renders
(16 spp, seeds 100 to 115) of the traced window; per pixel, the variance of its RGB-mean radiance over the
seeds. Prints each point's relative error of a render's total, how few pixels hold 90 % of the summed pixel
variance, and the gain in variance that allocating samples to pixels by their standard deviation (Neyman
1934) would bring over one count for all, from these estimates (the figures behind
``spacefit.studies.lightcurve_sizing``). Run: ``.venv/bin/python experiments/lightcurve_pixel_variance.py``.
"""

from __future__ import annotations

import os

import numpy as np
from studyio import machine

import spacefit as sf
from spacefit.studies.lightcurve import phase_plane_sun

PHASES_DEG = (120.0, 90.0, 60.0, 20.0)
SEEDS = range(100, 116)


def main() -> None:
    scene = sf.load_scene(None)
    renderer = sf.Renderer(scene)
    traced = renderer.traced.sum()
    print(f"machine: {machine()}; load {os.getloadavg()[0]:.1f}; default lander, {traced} traced pixels, 16 spp x {len(SEEDS)} seeds")
    for phase in PHASES_DEG:
        renderer.set_values({k: v[0] for k, v in phase_plane_sun(scene, np.array([phase])).items()})
        images = np.array([renderer.to_window(renderer.render(spp=16, seed=s)).mean(axis=-1) for s in SEEDS])
        totals = images.sum(axis=(1, 2))
        variance = images.var(axis=0, ddof=1)
        held = np.cumsum(np.sort(variance.ravel())[::-1]) / variance.sum()
        gain = traced * variance.sum() / np.sqrt(variance).sum() ** 2
        print(f"phase {phase:5.1f} deg: a render's total {totals.std(ddof=1) / totals.mean():.2%}; "
              f"{int(np.searchsorted(held, 0.9)) + 1} pixels hold 90 % of the pixel variance; Neyman gain {gain:.1f}x")


if __name__ == "__main__":
    main()
