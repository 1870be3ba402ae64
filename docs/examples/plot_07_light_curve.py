"""
A light curve with error bars
=============================

The lander's brightness against the solar phase angle, seen from the Moon's distance: the
irradiance at the observer is each render's radiance times each pixel's solid angle, summed.
Three independent seeds at each phase give each point's Monte Carlo standard error, the error bars
(asymmetric in magnitude); ``seeds_for`` says how many seeds a wanted precision needs.
"""

import matplotlib.pyplot as plt
import numpy as np

import spacefit as sf

scene = sf.load_scene(
    None,
    {"render.resolution": [32, 32], "camera.pixel_pitch_mm": 37.5, "render.spp": 2},
)
curve = sf.light_curve(
    scene,
    phase_deg=np.arange(0, 151, 25),
    observer_range_m=3.844e8,
    seeds=[1, 2, 3],
    quiet=True,
)
for phase, m, se in zip(curve.phase_angle_deg, curve.magnitude, curve.magnitude_se):
    print(f"phase {phase:5.1f} deg: V = {m:6.3f} +- {se:.3f}")
print(f"seeds for 0.1 mag at every point: {curve.seeds_for(precision_mag=0.1)}")

# %%
# The light curve draws itself into a figure you give (or a new one): the irradiance,
# and the magnitude, brighter up.
fig = plt.figure(figsize=(9, 4), layout="constrained")
axes = curve.figure(fig=fig)
