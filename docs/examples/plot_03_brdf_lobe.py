"""
A BRDF lobe: anisotropic GGX
============================

The BRDF of a rough conductor (``sf.Conductor``: GGX microfacets, Smith masking, conductor Fresnel,
as Mitsuba evaluates it) for light from 40 deg zenith, over every outgoing direction of the
hemisphere. Rougher along y (``alpha_y`` 0.3) than along x (``alpha_x`` 0.08), its specular lobe is
stretched across the plane of incidence. Left: the hemisphere seen from above (each outgoing
direction projected on the surface); right: cuts through the specular direction along x and along y.
"""

import matplotlib.pyplot as plt
import numpy as np

import spacefit as sf

material = sf.Conductor(eta=1.5, k=3.0, alpha_x=0.08, alpha_y=0.3)
zenith_i = np.radians(40.0)
wi = np.array(
    [-np.sin(zenith_i), 0.0, np.cos(zenith_i)]
)  # towards the light, in the surface's frame

# outgoing directions: a grid over the unit disk (x, y; z from the hemisphere) ...
x, y = np.meshgrid(np.linspace(-1, 1, 161), np.linspace(-1, 1, 161))
disk = np.stack([x, y, np.sqrt(np.clip(1 - x**2 - y**2, 0, 1))], axis=-1).reshape(-1, 3)
# ... and two cuts through the specular direction, tilted from it along x and along y
offset = np.radians(np.linspace(-60, 60, 241))
along_x = np.stack(
    [np.sin(zenith_i + offset), 0 * offset, np.cos(zenith_i + offset)], axis=-1
)
along_y = np.stack(
    [
        np.sin(zenith_i) * np.cos(offset),
        np.sin(offset),
        np.cos(zenith_i) * np.cos(offset),
    ],
    axis=-1,
)
wo = np.concatenate([disk, along_x, along_y])
f = np.asarray(
    material.evaluate(np.broadcast_to(wi, wo.shape), wo)
)  # sr^-1, one call for all directions
f_disk = np.where(x**2 + y**2 < 0.999, f[: disk.shape[0]].reshape(x.shape), np.nan)
f_x, f_y = np.split(f[disk.shape[0] :], 2)

fig, (hemisphere, cuts) = plt.subplots(1, 2, figsize=(9, 4), layout="constrained")
shown = hemisphere.pcolormesh(x, y, np.log10(f_disk), cmap="magma", vmin=-2)
hemisphere.plot(
    -wi[0], -wi[1], "c+", markersize=14, markeredgewidth=2, label="specular direction"
)
hemisphere.set(
    aspect="equal",
    xlabel="outgoing x (tangent)",
    ylabel="outgoing y",
    title="light from 40 deg, at -x",
)
hemisphere.legend(loc="lower left", fontsize=9)
fig.colorbar(shown, ax=hemisphere, label="log$_{10}$ BRDF (sr$^{-1}$)")

cuts.semilogy(
    np.degrees(offset),
    np.where(along_x[:, 2] > 0, f_x, np.nan),
    label="along x (alpha_x 0.08)",
)
cuts.semilogy(np.degrees(offset), f_y, label="along y (alpha_y 0.3)")
cuts.set(
    xlabel="angle from the specular direction (deg)",
    ylabel="BRDF (sr$^{-1}$)",
    title="cuts through the peak",
)
cuts.legend(fontsize=9)
cuts.grid(alpha=0.3)
