"""Studies on top of the renderer: sweeps of scene values into resumable Zarr stores, sensitivities
with Monte Carlo errors, light curves, and running sweeps on dask.distributed."""
