"""
A render and its parts
======================

Render the default lander (the thesis's Table 4-2 scene) small, and the part each pixel's centre
sees. Radiance is in W m^-2 sr^-1 at the camera's entrance pupil.
"""

import matplotlib.pyplot as plt
import numpy as np

import spacefit as sf

scene = sf.load_scene(None, {"render.resolution": [96, 96], "camera.pixel_pitch_mm": 12.5, "render.spp": 8})
renderer = sf.Renderer(scene)
radiance = renderer.render()
parts = renderer.part_image()

fig, (left, right) = plt.subplots(1, 2, figsize=(7, 3.4))
left.imshow(np.clip(radiance / np.percentile(radiance[radiance > 0], 99.5), 0, 1))
left.set_title("radiance (linear, 99.5th percentile white)", fontsize=9)
shown = right.imshow(np.ma.masked_less(parts.ids, 0), cmap="tab10", vmin=0, vmax=9)
right.set_title("parts: " + ", ".join(f"{i} {n}" for i, n in enumerate(parts.names)), fontsize=9)
for ax in (left, right):
    ax.set_axis_off()
fig.tight_layout()

print(parts.table(radiance))
