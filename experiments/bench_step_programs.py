"""The big programs of issue 33's 8-parameter observation fit (``bench_fit_process.py``'s inputs) in one process, as a
fit runs them: the solver's step with its renders made first (``spacefit.fitting.loop``'s rendered-first LM step) and the
pixel grid's programs at the result (the model made at 4x for the fixed point, ``fine``; its derivatives and the 2x
model, ``settled``). Printed, CPU s: the step's trace and lowering, its compilation (or read from JAX's cache) and its
later runs; each grid program's first call (trace, lowering, compilation or cache read, one run) and a later one. Run it
twice with one ``SPACEFIT_JAX_CACHE_DIR``: the second run's first calls are a fit's in a process after the first.
Run: ``SPACEFIT_JAX_CACHE_DIR=DIR .venv/bin/python experiments/bench_step_programs.py``.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from bench_fit_process import loaded_inputs
from studyio import commit, machine

from spacefit.fitting.compile_cache import use_compile_cache
from spacefit.fitting.loop import _rendered_first
from spacefit.fitting.problem import setup
from spacefit.fitting.residuals import column_owners
from spacefit.fitting.solvers import make_solver, with_owners

TRUTH = {"parts.panels.alpha_x": 0.15, "parts.panels.alpha_y": 0.03, "parts.legs.kd": 0.5, "image.blur_sigma_px": 0.8}


def cpu(call: object) -> tuple[object, float]:
    """``call()`` and its CPU s (its results ready)."""
    t0 = time.process_time()
    out = jax.block_until_ready(call())
    return out, time.process_time() - t0


def main() -> None:
    jax.config.update("jax_enable_x64", True)  # as sf.fit runs
    print(f"machine: {machine()}; commit {commit()}; JAX cache {use_compile_cache()}; load {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as tmp:
        loaded, free, start = loaded_inputs(Path(tmp))
        s = setup(loaded, free, start=start)
        grid_setup = setup(loaded, free, start={n: TRUTH.get(n, v) for n, v in zip(free, np.asarray(s.x0))})
    fp, given = s.solver_params, _rendered_first(s)
    solver = with_owners(make_solver("lm"), column_owners(fp, s.problem.blocks))
    u = jnp.asarray(fp.to_unconstrained(jnp.asarray(s.x0)))
    tags: frozenset = frozenset()

    def fn(y: jax.Array, renders: object) -> tuple[jax.Array, None]:
        return given.residual(y, renders), None

    renders = given.render(u, True)  # Dr.Jit's kernels compiled here: not timed
    r = jax.jit(given.residual)(u, renders)
    state = eqx.filter_jit(solver.init)(fn, u, renders, {}, jax.ShapeDtypeStruct(r.shape, r.dtype), None, tags)
    step = eqx.filter_jit(solver.step)
    lowered, lower_s = cpu(lambda: step.lower(fn, u, renders, {}, state, tags))
    _, compile_s = cpu(lowered.compile)
    (u1, state1, _), first_s = cpu(lambda: step(fn, u, renders, {}, state, tags))
    renders1 = given.render(state1.y_eval, True)
    runs = [cpu(lambda: step(fn, u1, renders1, {}, state1, tags))[1] for _ in range(5)]
    print(f"step: trace and lowering {lower_s:.2f} s CPU, compilation or cache read {compile_s:.2f}, first run {first_s:.3f}, "
          f"later runs {min(runs):.3f}-{max(runs):.3f} (median {np.median(runs):.3f})", flush=True)

    x = np.asarray(grid_setup.x0, dtype=float)
    changes = grid_setup.problem.pixel_grid(x)  # its renders at 4x: not timed
    columns = [free.index(n) for n in ("image.shift_x_px", "image.shift_y_px", "image.blur_sigma_px")]
    for name, call in (("fine", lambda: changes.fine(x)), ("settled", lambda: changes.settled(x, columns)[:2])):
        _, first = cpu(call)
        _, again = cpu(call)
        print(f"pixel grid's {name}: first call {first:.2f} s CPU, a later call {again:.2f}", flush=True)
    print(f"load {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
