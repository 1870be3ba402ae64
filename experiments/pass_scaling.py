"""Time per fit step of a pass against dask workers: the batch of every frame's render and Jacobian
columns (what one Levenberg-Marquardt step evaluates), in this process and on local clusters of 1
to N single-threaded worker processes; parallel efficiency, memory per worker (and the loaded scenes
and frames each holds), and whether every worker count gives the same numbers as this process.

    python experiments/pass_scaling.py --out experiments/results/pass_scaling            # 24 and 100 frames, 0 to 4 workers
    python experiments/pass_scaling.py --frames 4 --workers 0 2 --size 16 --out /tmp/x  # a quick check

Each frame is the panels case seen from its own point of an arc (:func:`spacefit.arc_pass`), with
the three materials shared and its own target attitude about x free: per frame and step one primal
render, two finite-difference renders and three forward-mode AD renders. The first step (which
compiles) is timed apart from the following ones (scenes kept loaded); in this process (``--workers
0``) its JAX compilations (XLA programs and their trace, lowering and compile time) and Dr.Jit's
kernels (new to the process, and their compile time) are counted too.
Writes ``scaling.csv`` and ``scaling.png`` and prints the table with the machine's load average.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import psutil
from studyio import save_figure, write_csv

import spacefit as sf
from spacefit.fitting.frames import InProcess, executor_of, loaded_count
from spacefit.fitting.problem import setup
from spacefit.precision import float64
from spacefit.rendering.logs import kernel_log

# JAX's events (jax.monitoring) of one compilation: trace, lowering, XLA compilation.
COMPILE_EVENTS = ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration",
                  "/jax/core/compile/backend_compile_duration")

MATERIALS = ["parts.panels.alpha_x", "parts.panels.alpha_y", "parts.legs.kd"]


def observations(n: int, size: int) -> list[sf.Observation]:
    """n frames of the panels case along an arc; the references are black (time does not depend on them)."""
    base = sf.load_scene("spacefit/synthetic/panels.toml", {"render.resolution": [size, size], "camera.pixel_pitch_mm": 18.75 * 128 / size})
    frames = sf.Pass.from_columns({"file": [f"f{k}.exr" for k in range(n)], "time": [10.0 * k for k in range(n)],
                                   **_columns(sf.arc_pass(n))})
    return [sf.Observation(scene, np.zeros((size, size, 3), np.float32)) for scene in frames.scenes(base)]


def _columns(frames: list[dict[str, object]]) -> dict[str, list[object]]:
    return {key: [f[key] for f in frames] for key in frames[0]}


def worker_memory(executor: object) -> tuple[float, int, int]:
    """The mean resident memory of the workers (MiB), and the loaded scenes and frames each holds (the most)."""
    if isinstance(executor, InProcess):
        return psutil.Process().memory_info().rss / 2**20, len(executor.loaded.stages), len(executor.loaded.chains)
    rss = executor.client.run(lambda: psutil.Process().memory_info().rss)
    held = list(executor.client.run(loaded_count).values())
    return float(np.mean(list(rss.values()))) / 2**20, max(h[0] for h in held), max(h[1] for h in held)


@float64
def measure(n: int, workers: int, size: int, spp: int, repeats: int) -> tuple[dict[str, object], np.ndarray]:
    obs = observations(n, size)
    free = [*MATERIALS, *(f"target.attitude_x_deg@{k}" for k in range(n))]
    executor = InProcess() if workers == 0 else executor_of(workers)
    try:
        t0 = time.perf_counter()
        s = setup(obs, free, render=sf.FitRender(spp=spp), executor=executor)  # loads every frame's scene (part images)
        t_load = time.perf_counter() - t0
        x = jnp.asarray(s.x0)
        step = jax.jit(lambda y: (s.problem.residual_x(y), jax.jacfwd(s.problem.residual_x)(y)))
        compiles: list[tuple[str, float]] = []

        def listen(event: str, seconds: float, **_: object) -> None:
            if event in COMPILE_EVENTS:
                compiles.append((event, seconds))

        jax.monitoring.register_event_duration_secs_listener(listen)
        try:
            with kernel_log() as kernels:  # the renders of this process (--workers 0)
                t0 = time.perf_counter()
                J = step(x)[1].block_until_ready()
                times = [time.perf_counter() - t0]
        finally:
            jax.monitoring.unregister_event_duration_listener(listen)
        for k in range(repeats):  # each at its own point: a frame asked again at its last point reuses its Jacobian
            t0 = time.perf_counter()
            J = step(x * (1.0 + 1e-3 * (k + 1)))[1].block_until_ready()
            times.append(time.perf_counter() - t0)
        mem, scenes, held = worker_memory(executor)
    finally:
        executor.close()
    row = {"frames": n, "workers": workers, "load_s": round(t_load, 2), "first_step_s": round(times[0], 2),
           "first_step_xla_programs": sum(e == COMPILE_EVENTS[-1] for e, _ in compiles),
           "first_step_jax_compile_s": round(sum(secs for _, secs in compiles), 2),
           "first_step_drjit_kernels_new": kernels["new"] if not workers else "",
           "first_step_drjit_compile_s": round(kernels["compile_s"], 2) if not workers else "",
           "step_s": round(float(np.median(times[1:])), 3), "memory_per_worker_mib": round(mem, 0), "scenes_per_worker": scenes, "frames_per_worker": held,
           "load_average_1min": round(os.getloadavg()[0], 2)}
    return row, np.asarray(J)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, type=Path)
    p.add_argument("--frames", type=int, nargs="+", default=[24, 100])
    p.add_argument("--workers", type=int, nargs="+", default=[0, 1, 2, 3, 4], help="0: in this process")
    p.add_argument("--size", type=int, default=32)
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--repeats", type=int, default=2, help="steps timed after the first")
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"{platform.node()}: {psutil.cpu_count()} cores, {psutil.virtual_memory().total / 2**30:.0f} GiB; "
          f"load average {os.getloadavg()} at {time.strftime('%Y-%m-%d %H:%M:%S', time.gmtime())} UTC")
    rows = []
    for n in args.frames:
        reference = None
        for w in args.workers:
            row, J = measure(n, w, args.size, args.spp, args.repeats)
            reference = J if reference is None else reference
            row["same_as_first"] = bool(np.array_equal(J, reference))
            rows.append(row)
            print(row, flush=True)
            write_csv(args.out / "scaling.csv", rows)  # so far, should a later run be stopped
    for row in rows:  # parallel efficiency against one worker process: T1 / (w T_w)
        one = next((r["step_s"] for r in rows if r["frames"] == row["frames"] and r["workers"] == 1), None)
        row["speedup"] = round(one / row["step_s"], 2) if one and row["workers"] else ""
        row["efficiency"] = round(one / (row["workers"] * row["step_s"]), 2) if one and row["workers"] else ""
    write_csv(args.out / "scaling.csv", rows)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.5))
    for n in args.frames:
        mine = [r for r in rows if r["frames"] == n and r["workers"]]
        ax.plot([r["workers"] for r in mine], [r["step_s"] for r in mine], "o-", label=f"{n} frames")
        inproc = [r["step_s"] for r in rows if r["frames"] == n and not r["workers"]]
        if inproc:
            ax.axhline(inproc[0], ls=":", color=ax.lines[-1].get_color())
    ax.set_xlabel(f"dask workers (the machine has {psutil.cpu_count()} cores)")
    ax.set_ylabel("time per fit step [s]")
    ax.set_yscale("log")
    ax.legend(title="dotted: in this process")
    save_figure(fig, args.out / "scaling.png")
    print(f"load average {os.getloadavg()} at the end")


if __name__ == "__main__":
    main()
