"""
A sensitivity chart
===================

Which parameter moves which part of the image, and by how much? ``sf.sensitivity`` renders the
derivative of every pixel's radiance with respect to each parameter (forward-mode automatic
differentiation through the path tracer) with three independent seeds, so that each derivative
carries its Monte Carlo standard error: pixels where it is not resolved from the noise are grey.
Below, each region's relative change of mean radiance for a step of each parameter (hatched where
the noise cannot tell it from zero).
"""

import matplotlib.pyplot as plt

import spacefit as sf

scene = (
    sf.load_case("panels")
    .scene()
    .with_values(
        {"render.resolution": [32, 32], "camera.pixel_pitch_mm": 75.0, "render.spp": 8}
    )
)
names = ["parts.panels.alpha_x", "parts.legs.kd"]
sens = sf.sensitivity(scene, names, seeds=3, quiet=True)
for row in sens.rows():
    if row["region"] == "target":
        print(f"{row['parameter']:22s} normalised {row['normalised']}")

fig = plt.figure(figsize=(9, 7), layout="constrained")
axes = sens.figure(fig=fig, crop=False)
