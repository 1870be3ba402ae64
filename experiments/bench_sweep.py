"""Sweep throughput (renders per second) of the default scene at a quarter of its resolution: in-process
with the loaded scene reused (a sun-elevation sweep, set in place), in-process with a reload per point
(the sun's direction as a scene-file key), and on local dask clusters of 1 and 2 workers (wall time,
the cluster's start and each worker's first scene load included).

Run: ``.venv/bin/python experiments/bench_sweep.py [--points N]``. States the machine and its load
average, since the figures depend on what else runs.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from studyio import machine

import spacefit as sf


def rate(scene: sf.Scene, axes: dict, **options: object) -> tuple[float, float]:
    """(renders per second, wall seconds) of one sweep in memory."""
    n = int(np.prod([len(next(iter(v.values()))) if isinstance(v, dict) else len(v) for v in axes.values()]))
    t0 = time.perf_counter()
    sf.sweep(scene, axes, quiet=True, **options)
    wall = time.perf_counter() - t0
    return n / wall, wall


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--points", type=int, default=60, help="points of each in-place and cluster sweep")
    p.add_argument("--reloads", type=int, default=10, help="points of the reloading sweep")
    args = p.parse_args()
    scene = sf.load_scene(None, ["render.resolution=[150, 150]", "camera.pixel_pitch_mm=16", "render.spp=4"])
    sf.render(scene)  # the meshes into the cache and the kernels compiled, for every case alike
    elevations = np.linspace(20.0, 89.0, args.points).tolist()
    directions = [[-float(np.cos(np.radians(e))), 0.0, -float(np.sin(np.radians(e)))]
                  for e in np.linspace(20.0, 89.0, args.reloads)]
    print(f"machine: {machine()}, load average at start {os.getloadavg()[0]:.1f}")
    print(f"scene: default (Table 4-2) at 150 x 150 px, 4 spp; {args.points} points per sweep, {args.reloads} with reloads")
    print(f"{'case':32s} {'renders/s':>10s} {'wall s':>8s}")
    cases = [("in-process, scene reused", {"sun.elevation_deg": elevations}, {}),
             ("in-process, reload per point", {"sun.direction": directions}, {}),
             ("local cluster, 1 worker", {"sun.elevation_deg": elevations}, {"workers": 1}),
             ("local cluster, 2 workers", {"sun.elevation_deg": elevations}, {"workers": 2})]
    for label, axes, options in cases:
        r, wall = rate(scene, axes, **options)
        print(f"{label:32s} {r:10.2f} {wall:8.1f}", flush=True)


if __name__ == "__main__":
    main()
