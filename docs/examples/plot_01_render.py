"""
The default render and its parts
================================

Render the default lander (the thesis's Table 4-2 scene) small, and ask which part each pixel's
centre sees. Its solar panels are seen edge-on, a line one pixel thin. Radiance is in W m^-2 sr^-1 at the camera's entrance pupil; the table gives each
part's pixels and mean radiance.
"""

import matplotlib.pyplot as plt
import numpy as np

import spacefit as sf

scene = sf.load_scene(
    None, {"render.resolution": [96, 96], "camera.pixel_pitch_mm": 8.0, "render.spp": 8}
)
renderer = sf.Renderer(scene)
radiance = renderer.render()  # (96, 96, 3) float32
parts = renderer.part_image()  # part index per pixel, -1 for space

fig, (left, right) = plt.subplots(1, 2, figsize=(8, 4), layout="constrained")
white = np.percentile(radiance[radiance > 0], 99.5)
left.imshow(np.clip(radiance / white, 0, 1))
left.set_title(f"radiance, linear (white: {white:.3g} W m$^{{-2}}$ sr$^{{-1}}$)")
colours = plt.get_cmap("tab10")
right.imshow(
    np.ma.masked_less(parts.ids, 0),
    cmap="tab10",
    vmin=0,
    vmax=9,
    interpolation="nearest",
)
right.set_title("the part each pixel sees")
right.legend(
    handles=[
        plt.Rectangle((0, 0), 1, 1, color=colours(i)) for i in range(len(parts.names))
    ],
    labels=list(parts.names),
    loc="upper right",
    fontsize=9,
)
for ax in (left, right):
    ax.set_axis_off()

# %%
# Each part's pixels and mean radiance (an xarray Dataset, printed as a table):
table = parts.table(radiance)
print(table[["pixels", "mean_radiance"]].to_dataframe().round(4).to_string())
