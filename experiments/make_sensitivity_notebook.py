"""Build and execute ``experiments/sensitivity_lightcurve.ipynb``: a small sensitivity study, a sweep and
light curves of the lander, end to end, with ``sf.`` names only (issue 9).

Run: ``.venv/bin/python experiments/make_sensitivity_notebook.py`` (a few minutes on 2 cores; needs the
``notebook`` extra). Built as ``make_notebook.py`` builds the walkthrough.
"""

from __future__ import annotations

from make_notebook import HERE, build

CELLS: list[tuple[str, str]] = [
    ("md", """# A sensitivity study, a sweep and light curves of the lander

How the lander's image responds to its parameters, with the Monte Carlo error of every derivative,
a sweep of sun elevation and panel roughness, and what a telescope on the Earth sees of it: light
curves against the solar phase angle and under a spin. Only `sf.` names are used. Radiance is in
W m^-2 sr^-1, irradiance in W m^-2, angles in degrees at this edge."""),
    ("code", """import matplotlib.pyplot as plt
import numpy as np

import spacefit as sf

# the thesis's scene (Table 4-2) at 64 x 64 px, the lander filling a third of the frame, the sun off the axis
scene = sf.load_scene(None, {"render.resolution": [64, 64], "camera.pixel_pitch_mm": 12, "render.spp": 8,
                             "sun.direction": [-0.35, -0.6, -0.72]})
radiance = sf.render(scene)
plt.figure(figsize=(4, 4))
plt.imshow(np.clip(radiance / np.percentile(radiance[radiance > 0], 99), 0, 1))
plt.axis("off")
plt.title("radiance, 8 spp");"""),
    ("md", """## 1. Sensitivity, with errors

`sf.sensitivity` estimates each derivative with 4 independent seeds on one loaded scene: forward-mode
AD for the materials, central differences with common random numbers for the sun's elevation, the
attitude and the wrinkles' fractal dimension D. Each value comes with its standard error; one whose
95 % interval contains zero is flagged UNRESOLVED (it is noise at these samples per pixel), and a
region no pixel centre sees gives no number at all."""),
    ("code", """sens = sf.sensitivity(scene, ["parts.panels.alpha_x", "parts.body.alpha", "parts.legs.kd", "sun.elevation_deg",
                             "target.attitude_z_deg", "wrinkles.D"], seeds=4, quiet=True)
print(sens.table())"""),
    ("md", """The derivative images (pixels whose derivative is not resolved are grey) and the normalised
sensitivities of each part's mean radiance, relative change per relative change for the materials
and D, per radian for the angles, with 95 % intervals (hatched: unresolved)."""),
    ("code", """sens.figure()[0].figure"""),
    ("md", """## 2. A sweep

The sun's elevation and the panels' roughness on a grid, set in place on the loaded scene (no reload).
The Dataset is labelled: its dimensions are the swept keys, its coordinates carry their units."""),
    ("code", """ds = sf.sweep(scene, {"sun.elevation_deg": np.linspace(20, 85, 6).tolist(), "parts.panels.alpha_x": [0.05, 0.1, 0.2]})
print(ds.mean_radiance.dims, ds["sun.elevation_deg"].attrs["units"], ds.mean_radiance.attrs["units"])
fig, axes = plt.subplots(1, 3, figsize=(12, 3.2), sharex=True, constrained_layout=True)
for ax, region in zip(axes, ["body", "legs", "target"]):
    for alpha in ds["parts.panels.alpha_x"].values:
        ax.plot(ds["sun.elevation_deg"], ds.mean_radiance.sel({"region": region, "parts.panels.alpha_x": alpha}),
                "o-", label=f"panels alpha_x {alpha:g}")
    ax.set_title(region)
    ax.set_xlabel("sun elevation (deg)")
axes[0].set_ylabel("mean radiance (W m$^{-2}$ sr$^{-1}$)")
axes[0].legend(fontsize=8);"""),
    ("md", """## 3. Light curves

The irradiance at the observer is the image's radiance times each pixel's solid angle, summed; it is
rendered at the scene's 70 m and rescaled to the Moon's distance (3.844e8 m) by the inverse square
law. Magnitudes are in V with the sun's -26.74 (Cox 2000), target and observer at the same distance
from the sun. Against the solar phase angle (the sun turns away from the observer):"""),
    ("code", """phase = sf.light_curve(scene, phase_deg=np.arange(0, 151, 15), observer_range_m=3.844e8, quiet=True)
print("V magnitudes:", np.round(phase.magnitude, 2))
phase.figure()[0].figure"""),
    ("md", """And under a spin of 6 deg/s about the target's z axis for a minute, with the sun given as an
elevation and azimuth in the target's own frame:"""),
    ("code", """spin = sf.light_curve(scene, times_s=np.linspace(0, 60, 16), spin_rate_deg_s=6.0, axis="z", sun=(45.0, -120.0),
                      observer_range_m=3.844e8, quiet=True)
print(f"phase angle {spin.phase_angle_deg[0]:.1f} deg, magnitude {spin.magnitude.min():.2f} to {spin.magnitude.max():.2f}")
spin.figure()[0].figure"""),
]


if __name__ == "__main__":
    build(HERE / "sensitivity_lightcurve.ipynb", CELLS)
    print(f"wrote {HERE / 'sensitivity_lightcurve.ipynb'}")
