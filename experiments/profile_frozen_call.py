"""Where a frozen render call's time goes outside its kernels, on a loaded machine too: the panels case at
128 x 128 px, 32 spp (bench_fixed_cost.py's calls), its primal render and a forward-mode column re-run step
by step as :meth:`~spacefit.rendering.renderer.Renderer.radiance` and
:meth:`~spacefit.rendering.drjit_scene.DrJitScene._render_forward` run them, each step timed in wall time and in
the Dr.Jit thread's CPU time. A step's CPU time is what it costs on a quiet machine (a loaded one delays it,
but does not make it use more), so the CPU time of the steps outside the kernels estimates the quiet fixed
cost per call whatever the load. The steps marked K run or wait for kernels. Each call's image is checked
equal, bit for bit, to the real call's, so that these steps stay the renderer's.
Run: ``.venv/bin/python experiments/profile_frozen_call.py [--calls N]``.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable

import jax.numpy as jnp
import numpy as np
from studyio import commit, machine

import spacefit as sf
from spacefit.rendering.backend import dr, mi, on_drjit_thread, variant_scope
from spacefit.rendering.drjit_scene import DrJitScene
from spacefit.rendering.derivatives import render_chain
from spacefit.rendering.drjit_values import to_value
from spacefit.rendering.logs import errors_only
from spacefit.rendering.sample_passes import pass_seeds, render_threads

SPP = 32


class Steps:
    """Wall and thread CPU time (ms) of named steps, per call."""

    def __init__(self) -> None:
        self.times: dict[str, list[list[float]]] = {}

    def start(self) -> None:
        """Begin a call."""
        self.wall, self.cpu = time.perf_counter(), time.thread_time()
        for rows in self.times.values():
            rows.append([0.0, 0.0])

    def __call__(self, name: str) -> None:
        """End step ``name`` (its time adds to the step's in this call)."""
        wall, cpu = time.perf_counter(), time.thread_time()
        rows = self.times.setdefault(name, [[0.0, 0.0] for _ in range(len(next(iter(self.times.values()), [[0, 0]])))])
        rows[-1][0] += (wall - self.wall) * 1e3
        rows[-1][1] += (cpu - self.cpu) * 1e3
        self.wall, self.cpu = wall, cpu


def primal(ds: DrJitScene, values: dict[str, np.ndarray], seed: int, step: Steps) -> np.ndarray:
    """``ds.render_primal(values, seed)`` step by step."""
    r = ds.renderer
    r.set_params(values)
    step("set the values")
    passes = pass_seeds(seed, ds.spp, len(r._pixels), r.assembly.scene.render.sampler)
    film = r.scene.sensors()[0].film()
    film.prepare([])
    block = film.create_block()
    block.set_offset(film.crop_offset())
    step("set up the film")
    for seed_i, spp_i, start, count in passes:
        camera, _, _ = r.frozen.functions(r.geometry)
        position, rgb = camera(r.scene, r._pixels, dr.opaque(mi.UInt32, seed_i), spp_i, start, count, r.window[2])
        dr.eval(position, rgb)
        step("call the replay")
        dr.sync_thread()
        step("K wait for the pass's kernels")
        with render_threads(r.assembly.scene.render.deterministic):
            step("resize the pool")
            block.put(position, [rgb.x, rgb.y, rgb.z, mi.Float(1.0)])
            step("trace the splat")
            dr.eval(block.tensor())
            dr.sync_thread()
            step("K splat (one thread)")
        step("resize the pool")
    film.put_block(block)
    image = r.to_film(np.array(film.develop(), dtype=np.float32))
    step("develop, to NumPy")
    return image


def column(ds: DrJitScene, values: dict[str, np.ndarray], key: str, seed: int, step: Steps) -> np.ndarray:
    """``ds.forward(values, {key: ones}, seed)`` step by step (a material's column: nothing moves): each pass's primal
    state made (the primal pass a Jacobian's columns share, :meth:`~spacefit.rendering.drjit_scene.DrJitScene.forward_columns`),
    then its forward pass."""
    r = ds.renderer
    tangent = {key: np.ones_like(values[key])}
    r.set_params(values, tangent)
    dr.set_grad(ds.params[key], to_value(ds.params[key], tangent[key]))
    step("set the values")
    film, image = r.scene.sensors()[0].film(), None
    _, state, derivative = r.frozen.functions(r.geometry)
    states: dict[tuple[int, int], tuple[object]] = {}
    ds._primal_states(state, seed, states)
    step("K the primal pass (one per Jacobian)")
    with errors_only():
        for i, (seed_i, count, weight) in enumerate(ds._passes(ds.spp_grad, seed)):
            position, value = derivative(r.scene, ds._integrator, dr.opaque(mi.UInt32, seed_i), count, *states[(i, r.geometry)])
            dr.eval(position, value)
            step("call the replay")
            dr.sync_thread()
            step("K wait for the pass's kernels")
            with render_threads(r.assembly.scene.render.deterministic):
                step("resize the pool")
                block = film.create_block()
                block.set_coalesce(block.coalesce() and count >= 4)
                block.put(position, [value.x, value.y, value.z, mi.Float(1.0)])
                step("trace the splat")
                dr.eval(block.tensor())
                dr.sync_thread()
                step("K splat (one thread)")
                film.put_block(block)
                developed = film.develop() * weight
                image = developed if image is None else image + developed
                dr.eval(image)
                step("develop")
            step("resize the pool")
    out = r.to_film(np.asarray(image, dtype=np.float32))
    r.set_params(values)
    step("to NumPy, detach the values")
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--calls", type=int, default=40, help="timed calls of each kind, after 5 unmeasured")
    args = p.parse_args()
    case = sf.load_case("panels").with_values({"render.spp": SPP})
    scene, names = case.scene(), list(case.free)
    x0 = np.array([case.start[n] for n in names])
    chain = render_chain(scene, names)
    ds = chain.drjit
    values = [{k: np.asarray(v) for k, v in chain.values_of(jnp.asarray(x0 * (1.0 + 0.01 * i))).items()} for i in range(args.calls + 5)]
    key = next(iter(values[0]))
    print(f"machine: {machine()}, {dr.thread_count()} Dr.Jit threads, load average {os.getloadavg()[0]:.1f}, commit {commit()}")
    kinds: dict[str, tuple[Callable[..., np.ndarray], Callable[[dict, int], np.ndarray]]] = {
        "primal": (lambda v, s, step: primal(ds, v, s, step), lambda v, s: ds.render_primal(v, s)),
        "derivative": (lambda v, s, step: column(ds, v, key, s, step), lambda v, s: ds.forward(v, {key: np.ones_like(v[key])}, s)),
    }
    for kind, (stepped, real) in kinds.items():
        for i in range(5):
            real(values[i], 100 + i)  # unfrozen, recorded, then replayed

        @on_drjit_thread
        def run(stepped: Callable[..., np.ndarray] = stepped) -> tuple[Steps, list[np.ndarray]]:
            step, images = Steps(), []
            with variant_scope(ds.variant):
                for i in range(5, len(values)):
                    step.start()
                    images.append(stepped(values[i], 100 + i, step))
            return step, images

        step, images = run()
        for i, image in zip(range(5, len(values)), images):
            assert np.array_equal(image, real(values[i], 100 + i)), f"{kind}: the steps no longer give the renderer's image"
        print(f"{kind} (load average {os.getloadavg()[0]:.1f}), ms per call, medians of {args.calls}:")
        outside = 0.0
        for name, rows in step.times.items():
            wall, cpu = np.median(np.array(rows), axis=0)
            outside += 0.0 if name.startswith("K") else cpu
            print(f"  {name:<32} wall {wall:7.2f}  CPU {cpu:6.2f}")
        print(f"  outside the kernels: CPU {outside:.2f} ms per call (a quiet machine's fixed cost but for its wake-ups)")


if __name__ == "__main__":
    main()
