"""
A pass
======

A pass is a series of frames of one target as an observer flies by: here three frames of the
synthetic ``panels`` lander along ``sf.arc_pass`` (the observer crosses the panels' glint
half-way), each with its own small attitude error about x. One fit takes every frame: the panels'
roughness shared by all, each frame's attitude angle its own (``per_frame``). ``sf.frame_table`` gives
each frame's fitted values and goodness of fit, ``sf.plot_frames`` draws them against time.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import spacefit as sf

scene = (
    sf.load_case("panels")
    .scene()
    .with_values({"render.resolution": [24, 24], "camera.pixel_pitch_mm": 100.0})
)
errors = [0.2, -0.25, 0.1]  # deg, the attitude's error at each frame (the truth)
folder = Path(tempfile.mkdtemp()) / "pass"
frames = sf.simulate_pass(
    scene,
    sf.arc_pass(len(errors)),
    folder,
    spp=64,
    errors=[{"target.attitude_x_deg": e} for e in errors],
)
observation = sf.PassObservation.read(
    frames, scene, per_frame=["target.attitude_x_deg"]
)
result = sf.fit(
    observation,
    ["parts.panels.alpha_x"],
    start={"parts.panels.alpha_x": 0.1},
    render=sf.FitRender(spp=8),
    max_steps=8,
)
rows = sf.frame_table(result, frames)
for row, truth in zip(rows, errors):
    print(
        f"t = {row['time_s']:4.0f} s: attitude x {row['target.attitude_x_deg']:+.3f} "
        f"+- {row['target.attitude_x_deg.stderr']:.3f} deg (truth {truth:+.2f})"
    )
print(
    f"panels alpha_x {result.values['parts.panels.alpha_x']:.4f} "
    f"+- {result.stderr['parts.panels.alpha_x']:.4f} (truth 0.15)"
)

# %%
# The frames as observed (top), each frame's fitted attitude and its goodness of fit:
fig = plt.figure(figsize=(9, 7), layout="constrained")
top, bottom = fig.subfigures(2, 1, height_ratios=[1, 1.6])
white = max(float(np.percentile(image.reference, 99.5)) for image in observation.images)
for ax, image, row in zip(top.subplots(1, len(rows)), observation.images, rows):
    ax.imshow(np.clip(image.reference / white, 0, 1))
    ax.set_title(f"t = {row['time_s']:.0f} s")
    ax.set_axis_off()
axes = sf.plot_frames(rows, fig=bottom)
axes[0].plot([row["time_s"] for row in rows], errors, "kx", label="truth")
axes[0].legend(fontsize=9, loc="lower right")
