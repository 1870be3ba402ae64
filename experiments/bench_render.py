"""Render-time benchmark of the default scene (Table 4-2: 600 x 600, 20 spp, depth 2) and depths 3-5.

Prints, per depth and thread mode: scene load, first render (includes kernel compilation), the
median of repeated renders after it, and camera samples traced per second (the rendered window
around the target times spp). Run: ``.venv/bin/python experiments/bench_render.py``.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import time

from studyio import machine

from spacefit.rendering.renderer import Renderer
from spacefit.scene.assembly import assemble
from spacefit.scene.toml import load_scene


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--depths", type=int, nargs="+", default=[2, 3, 4, 5])
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    args = p.parse_args()
    t0 = time.perf_counter()
    base = load_scene(None, args.overrides)
    assembly = assemble(base)
    t_assemble = time.perf_counter() - t0
    r = base.render
    print(f"machine: {machine()}")
    print(f"scene: {r.resolution[0]}x{r.resolution[1]}, {r.spp} spp, {assembly.triangle_count():,} triangles; "
          f"assembly (W-M refinement) {t_assemble:.2f} s")
    print(f"{'depth':>5} {'threads':>7} {'load s':>7} {'first s':>8} {'median s':>9} {'min s':>7} {'Msamples/s':>11}")
    for depth in args.depths:
        for deterministic in (True, False):
            settings = dataclasses.replace(base.render, depth=depth, deterministic=deterministic)
            t0 = time.perf_counter()
            renderer = Renderer(assemble(base.replace(render=settings)))
            t_load = time.perf_counter() - t0
            samples = renderer.window[2] * renderer.window[3] * r.spp
            t0 = time.perf_counter()
            renderer.render(seed=0)
            t_first = time.perf_counter() - t0
            times = []
            for i in range(args.repeats):
                t0 = time.perf_counter()
                renderer.render(seed=i + 1)
                times.append(time.perf_counter() - t0)
            med = statistics.median(times)
            threads = "1" if deterministic else str(os.cpu_count())
            print(f"{depth:>5} {threads:>7} {t_load:>7.2f} {t_first:>8.2f} {med:>9.3f} {min(times):>7.3f} {samples / med / 1e6:>11.1f}")
    x0, y0, w, h = renderer.window
    print(f"rendered window {w}x{h} px at ({x0}, {y0}), {w * h / (r.resolution[0] * r.resolution[1]):.1%} of the film")
    print("threads 1 = render.deterministic (bitwise-reproducible); load includes W-M displacement and BVH build")


if __name__ == "__main__":
    main()
