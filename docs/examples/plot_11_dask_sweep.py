"""
A sweep on a Dask cluster
=========================

``sf.sweep`` renders a scene at every point of a grid of values and returns a labelled xarray
Dataset: each region's pixels, mean radiance (W m^-2 sr^-1) and irradiance. ``cluster=`` says where
the points render: this process (None), a new local cluster of N worker processes (an int), a
running scheduler's address or a ``distributed.Client``. Here a client of a tiny cluster started in
this process (one worker thread) stands in for a real one; on several machines you would give the
address ``dask scheduler`` prints.
"""

import matplotlib.pyplot as plt
from distributed import Client, LocalCluster

import spacefit as sf

scene = (
    sf.load_case("panels")
    .scene()
    .with_values(
        {"render.resolution": [32, 32], "camera.pixel_pitch_mm": 75.0, "render.spp": 4}
    )
)
axes = {
    "sun.elevation_deg": [15, 30, 45, 60, 75, 90],
    "parts.panels.alpha_x": [0.05, 0.3],
}
# one worker thread: Dr.Jit renders on one thread per process (two threads crashed it)
local = LocalCluster(
    n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0"
)
with local, Client(local) as client:
    ds = sf.sweep(scene, axes, cluster=client, quiet=True).compute()
print("the target's mean radiance (W m^-2 sr^-1):")
print(ds.mean_radiance.sel(region="target").to_pandas().round(3))

fig, ax = plt.subplots(figsize=(7, 4.2), layout="constrained")
elevation = ds["sun.elevation_deg"].values
for i, alpha in enumerate(ds["parts.panels.alpha_x"].values):
    for region, style in (("panels", "o-"), ("body", "s--")):
        radiance = ds.mean_radiance.sel(region=region).isel({"parts.panels.alpha_x": i})
        ax.plot(
            elevation,
            radiance,
            style,
            color=f"C{i}",
            label=f"{region}, panels' alpha_x {alpha}",
        )
ax.set(
    yscale="log",
    xlabel="sun elevation (deg)",
    ylabel="mean radiance (W m$^{-2}$ sr$^{-1}$)",
    title="a 6 x 2 sweep, rendered on the cluster",
)
ax.legend(fontsize=9)
ax.grid(alpha=0.3)
