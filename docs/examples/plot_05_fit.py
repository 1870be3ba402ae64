"""
A fit and its residuals
=======================

Recover the legs' albedo (``parts.legs.kd``) and the panels' roughness (``parts.panels.alpha_x``)
of the synthetic ``panels`` case from a render with many samples, starting far off. The report
gives each value with its standard error and the verdict on the fit; the figure, the loss and the
values per step (truth dashed), then the reference, the fitted render and their difference.
"""

import textwrap

import matplotlib.pyplot as plt

import spacefit as sf

case = sf.load_case("panels")
scene = case.truth_scene.with_values(
    {"render.resolution": [32, 32], "camera.pixel_pitch_mm": 75.0}
)
reference = sf.render(scene.with_values({"render.spp": 256}))
free = ["parts.legs.kd", "parts.panels.alpha_x"]
result = sf.fit(
    sf.Observation(scene, reference),
    free,
    start={"parts.legs.kd": 0.3, "parts.panels.alpha_x": 0.1},
)
report = sf.format_result(result)
print(
    "\n".join(
        textwrap.fill(line, 88, subsequent_indent="      ")
        for line in report.splitlines()
    )
)  # wrapped for the page

# %%
# spacefit's plot functions draw into a figure or subfigure you give (``fig=``)
# and return their axes:
fig = plt.figure(figsize=(9, 7.5), layout="constrained")
top, bottom = fig.subfigures(2, 1, height_ratios=[1, 1.1])
convergence = sf.plot_convergence(
    result, truths={name: case.truth[name] for name in free}, fig=top
)
comparison = sf.plot_comparison(result, [reference], fig=bottom)
