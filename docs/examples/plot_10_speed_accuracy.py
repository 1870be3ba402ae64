"""
Speed against accuracy: samples per pixel
=========================================

A render's Monte Carlo noise falls with the samples per pixel (spp), as 1 / sqrt(spp) for
independent samples and faster here, where the default sampler (``multijitter``) stratifies each
pixel's samples; its cost grows with them, once they outweigh each render's fixed overhead.
Measured here, while these pages were built, on the default lander at 64 x 64 px: the wall time of one render (the best of three, the scene loaded once) and its noise,
the rms difference of two renders with independent seeds over the target's pixels divided by
sqrt(2), relative to the target's mean radiance. Times are the build machine's: run the script to
measure yours.
"""

import os
import time

import matplotlib.pyplot as plt
import numpy as np

import spacefit as sf

scene = sf.load_scene(
    None, {"render.resolution": [64, 64], "camera.pixel_pitch_mm": 12.0}
)
renderer = sf.Renderer(scene)  # load once, render many times
target = renderer.part_image().ids >= 0
renderer.render(spp=1, seed=0)  # the first render compiles Mitsuba's kernels: not timed
spp = np.array([1, 4, 16, 64, 256])
seconds, error = [], []
for n in spp:
    times = []
    for seed in (1, 2, 3):
        start = time.perf_counter()
        images = renderer.render(spp=int(n), seed=seed)
        times.append(time.perf_counter() - start)
        if seed == 1:
            first = images
    difference = (first - images)[target]  # seeds 1 and 3: independent
    error.append(np.sqrt(np.mean(difference**2) / 2) / first[target].mean())
    seconds.append(min(times))
    print(f"{n:3d} spp: {1e3 * seconds[-1]:6.1f} ms, noise {100 * error[-1]:5.1f} %")

fig, ax = plt.subplots(figsize=(7, 4.5), layout="constrained")
ax.loglog(seconds, 100 * np.array(error), "o-")
for n, t, e in zip(spp, seconds, error):
    ax.annotate(
        f"{n} spp", (t, 100 * e), textcoords="offset points", xytext=(6, 4), fontsize=9
    )
ax.loglog(
    seconds,
    100 * error[0] / np.sqrt(spp),
    "k--",
    lw=0.8,
    label="1 / sqrt(spp) (independent samples)",
)
ax.set(
    xlabel="wall time of one render (s)",
    ylabel="noise per pixel (% of the target's mean)",
    title=f"64 x 64 px, measured on the build machine ({os.cpu_count()} CPUs)",
)
ax.legend(fontsize=9)
ax.grid(alpha=0.3, which="both")
