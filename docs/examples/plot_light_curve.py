"""
A light curve
=============

The lander's apparent V magnitude against the solar phase angle, seen from the Moon's distance:
the irradiance at the observer is the image's radiance times each pixel's solid angle, summed.
"""

import numpy as np

import spacefit as sf

scene = sf.load_scene(None, {"render.resolution": [48, 48], "camera.pixel_pitch_mm": 25.0, "render.spp": 4})
curve = sf.light_curve(scene, phase_deg=np.arange(0, 151, 30), observer_range_m=3.844e8, quiet=True)
print(np.round(curve.magnitude, 2))
axes = curve.figure()                 # irradiance and magnitude panels
