"""The solver's step of issue 33's 8-parameter observation fit (``bench_fit_process.py``'s inputs) compiled at XLA's
backend optimisation levels 0 to 3 in one process: the CPU time of its first call (compilation and one run) and of
four runs after it, paired. The step calls back into Python for its Jacobian render, so no process finds it in
JAX's cache; its Jacobian is rendered once, before the levels are timed (each later call reuses it: the frames
keep their last Jacobian), so what is timed is XLA's. ``spacefit`` compiles it at
``spacefit.fitting.compile_cache.CALLBACK_COMPILER_OPTIONS``.
Run: ``.venv/bin/python experiments/bench_step_compile.py``.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
from bench_fit_process import loaded_inputs
from studyio import machine

from spacefit.fitting.problem import setup
from spacefit.fitting.solvers import make_solver


def main() -> None:
    jax.config.update("jax_enable_x64", True)  # as sf.fit runs
    print(f"machine: {machine()}; load {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as tmp:
        observations, free, start = loaded_inputs(Path(tmp))
        s = setup(observations, free, start=start)
    fp, problem = s.solver_params, s.problem

    def fn(y: jax.Array, _: object) -> tuple[jax.Array, None]:
        return problem.descent_x(fp.to_physical(y)).astype(y.dtype), None

    u = jnp.asarray(fp.to_unconstrained(jnp.asarray(s.x0)))
    solver, tags = make_solver("lm"), frozenset()
    state = solver.init(fn, u, None, {}, jax.eval_shape(lambda y: fn(y, None)[0], u), None, tags)
    for level in (3, 2, 1, 0):  # the first renders the Jacobian (and compiles Dr.Jit's kernels): not a figure
        step = eqx.filter_jit(solver.step, compiler_options={"xla_backend_optimization_level": level})
        t0 = time.process_time()
        jax.block_until_ready(step(fn, u, None, {}, state, tags)[0])
        first = time.process_time() - t0
        runs = []
        for _ in range(4):
            t0 = time.process_time()
            jax.block_until_ready(step(fn, u, None, {}, state, tags)[0])
            runs.append(time.process_time() - t0)
        note = " (renders the Jacobian: not comparable)" if level == 3 else ""
        print(f"level {level}: first call {first:.2f} s CPU{note}; a call after it {min(runs):.3f}-{max(runs):.3f} s CPU", flush=True)
    print(f"load {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
