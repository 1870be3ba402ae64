"""
Wrinkles: the fractal dimension D and the height scale G
========================================================

The body's foil carries Weierstrass-Mandelbrot wrinkles (thesis eq. 2-1): ``wrinkles.D`` sets how
the height spreads over the scales (a larger D: more of it in the short wrinkles), ``wrinkles.G``
how tall they are. Rendered as displaced geometry (``wrinkles.model = "geometry"``), four
combinations side by side; each title gives the expected rms height and slope
(``sf.wm_rms``, ``sf.wm_rms_slope``).
"""

import matplotlib.pyplot as plt
import numpy as np

import spacefit as sf

# the body up close, the sun off to one side (no mirror glint back into the camera)
scene = sf.load_scene(
    None,
    {
        "render.resolution": [64, 64],
        "camera.pixel_pitch_mm": 5.0,
        "render.spp": 4,
        "wrinkles.model": "geometry",
        "sun.direction": [0.6, 0.3, -1.0],
    },
)
w = scene.wrinkles
fig, axes = plt.subplots(2, 2, figsize=(7, 7.4), layout="constrained")
fig.suptitle(
    "the lander's body up close (radiance, linear; white: 3 W m$^{-2}$ sr$^{-1}$)"
)
for row, D in zip(axes, (2.3, 2.5)):
    for ax, G in zip(row, (1e-6, 1e-4)):
        radiance = sf.render(scene.with_values({"wrinkles.D": D, "wrinkles.G": G}))
        ax.imshow(np.clip(radiance / 3.0, 0, 1))
        height = sf.wm_rms(D, G, gamma=w.gamma, M=w.M, L=w.L, Ls=w.Ls)
        slope = sf.wm_rms_slope(D, G, gamma=w.gamma, M=w.M, L=w.L, Ls=w.Ls)
        ax.set_title(
            f"D = {D}, G = {G:g} m\nrms height {1e3 * height:.2g} mm, slope {slope:.2f}"
        )
        ax.set_axis_off()
