"""Studies on top of the renderer: sweeps of scene values into resumable Zarr stores, sensitivities
with Monte Carlo errors, light curves with theirs, running sweeps on dask.distributed, a fit's
outcome against known truth (failures) and render cost against accuracy (costs)."""
