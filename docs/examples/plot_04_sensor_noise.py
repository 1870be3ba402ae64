"""
A sensor's noise
================

From radiance to counts: ``sf.observe`` turns a render into one exposure in DN (digital numbers)
with Poisson shot noise, Gaussian read noise, the full well and the ADC's rounding;
``sf.expected_dn`` is the noise-free mean and ``sf.noise_variance_dn`` the variance the fits use.
Here a 14-bit camera's exposure is chosen to put the lander's bright pixels at 80 % of full scale
(``sf.choose_exposure``), then 24 exposures with independent seeds measure each pixel's variance
against the model: a photon transfer curve.
"""

import matplotlib.pyplot as plt
import numpy as np

import spacefit as sf

scene = sf.load_scene(
    None,
    {"render.resolution": [64, 64], "camera.pixel_pitch_mm": 12.0, "render.spp": 16},
)
radiance = sf.render(scene)  # W m^-2 sr^-1
camera = sf.Intrinsics.from_scene(scene)  # focal length, pixel pitch (m)
sensor = sf.choose_exposure(radiance, sf.Sensor(), camera)
print(
    f"exposure {1e3 * sensor.exposure_time_s:.3g} ms, "
    f"saturation at {sensor.saturation_dn:.0f} DN"
)

mean = np.asarray(sf.expected_dn(radiance, sensor, camera))[..., 1]  # green channel, DN
exposures = np.stack(
    [sf.observe(radiance, sensor, camera, seed=s)[..., 1] for s in range(24)]
).astype(float)
measured = exposures.var(axis=0, ddof=1)

fig, (image, transfer) = plt.subplots(1, 2, figsize=(9, 4), layout="constrained")
shown = image.imshow(exposures[0], cmap="gray")
image.set_title("one exposure (green channel)")
image.set_axis_off()
fig.colorbar(shown, ax=image, label="DN")
order = np.argsort(mean.ravel())
transfer.loglog(
    mean.ravel() - sensor.bias_dn,
    measured.ravel(),
    ".",
    alpha=0.4,
    label="measured, 24 exposures",
)
transfer.loglog(
    mean.ravel()[order] - sensor.bias_dn,
    np.asarray(sf.noise_variance_dn(mean, sensor)).ravel()[order],
    "k-",
    label="sf.noise_variance_dn",
)
transfer.set(
    xlabel="mean signal above the bias (DN)",
    ylabel="variance (DN$^2$)",
    title="photon transfer curve",
)
transfer.legend(fontsize=9)
transfer.grid(alpha=0.3, which="both")
