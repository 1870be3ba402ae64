"""A render inside a long-running process against one in a fresh process (issue 33: 52-59 ms against
24-39 ms seen in a harness). In one process: the default scene's 16-spp window render timed (median of
``--repeats`` after a compiling one) fresh, then after a fit (the panels case at 64 x 64, 8 spp, LM),
then after ``gc.collect()``, each with the CPU time of all the process's threads (threads spinning while
they wait would show there), the process's thread count, Dr.Jit's thread pool size and the
number of live Python objects, so that a slowdown can be told apart from its suspects (threads left by
JAX or the fit, garbage, Dr.Jit's kernel cache and recorded frozen functions).
Run: ``.venv/bin/python experiments/bench_long_process.py [--repeats N]``.
"""

from __future__ import annotations

import argparse
import gc
import os
import statistics
import threading
import time

from studyio import machine

import spacefit as sf
from spacefit.rendering.backend import dr


def timed_renders(renderer: sf.Renderer, repeats: int) -> str:
    """The median and spread of ``repeats`` renders (ms), after one that compiles, and the process's state."""
    renderer.render(seed=0)
    times, cpu = [], []
    for seed in range(1, repeats + 1):
        t0, c0 = time.perf_counter(), time.process_time()
        renderer.render(seed=seed)
        times.append(1e3 * (time.perf_counter() - t0))
        cpu.append(1e3 * (time.process_time() - c0))
    return (f"median {statistics.median(times):.1f} ms (min {min(times):.1f}, max {max(times):.1f}), CPU of all the "
            f"process's threads median {statistics.median(cpu):.1f} ms; "
            f"{threading.active_count()} Python threads, {len(os.listdir('/proc/self/task'))} OS threads, "
            f"Dr.Jit pool {dr.thread_count()}, {len(gc.get_objects())} objects; load {os.getloadavg()[0]:.1f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=15)
    args = p.parse_args()
    print(f"machine: {machine()}; default scene, 16 spp")
    renderer = sf.Renderer(sf.load_scene(None, {"render.spp": 16}))
    print(f"fresh process:      {timed_renders(renderer, args.repeats)}")
    case = sf.load_case("panels")
    scene = case.truth_scene.with_values({"render.resolution": [64, 64], "camera.pixel_pitch_mm": 37.5, "render.spp": 8})
    result = sf.fit(sf.Observation(scene, sf.Renderer(scene).render(seed=7)), list(case.free), start=case.start, max_steps=10)
    print(f"(a fit: {result.steps} steps, {result.wall_time_s:.1f} s)")
    print(f"after a fit:        {timed_renders(renderer, args.repeats)}")
    fresh = sf.Renderer(sf.load_scene(None, {"render.spp": 16}))
    print(f"a new Renderer:     {timed_renders(fresh, args.repeats)}")
    gc.collect()
    print(f"after gc.collect(): {timed_renders(renderer, args.repeats)}")


if __name__ == "__main__":
    main()
