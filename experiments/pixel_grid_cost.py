"""The pixel grid's cost in ``estimate`` (spacefit.fitting.pixel_grid): the 8-parameter observation fit of
``bench_fit_process.py`` (the panels case at 128 x 128 px, 32 spp, through a sensor) set up at its truth, where
``estimate`` is timed with its pixel grid's fixed point and feedback (``grid_step``) apart, and the pixel grid's
two evaluations alone: the changes to the model made at 4x (one iteration of the fixed point) and, at the fixed
point, the change to the model made at 2x with the derivatives in the image nuisances. CPU and wall seconds, the
first call (a program's trace and compilation or cache read) and the least of the later ones; JAX's compilation
cache as ``SPACEFIT_JAX_CACHE_DIR`` says (run twice for a warm one). Run:
``.venv/bin/python experiments/pixel_grid_cost.py [--repeats N]``.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable

import numpy as np
from bench_fit import observed
from studyio import commit, machine

import spacefit.fitting.uncertainty as uncertainty
from spacefit.fitting.compile_cache import use_compile_cache
from spacefit.fitting.problem import setup
from spacefit.scene.parameters import is_image


def timed(name: str, fn: Callable[[], object], repeats: int) -> object:
    """``fn()`` called ``repeats`` times; prints the first call's seconds and the least of the others'."""
    runs, out = [], None
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        runs.append((time.perf_counter() - t0, time.process_time() - c0))
    later = runs[1:] or runs
    print(f"{name}: first {runs[0][1]:.3f} s CPU ({runs[0][0]:.3f} s wall); then at least {min(c for _, c in later):.3f} s CPU "
          f"({min(w for w, _ in later):.3f} s wall); load {os.getloadavg()[0]:.1f}", flush=True)
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=3, help="calls of each evaluation")
    args = p.parse_args()
    print(f"machine: {machine()}; commit {commit()}; JAX's cache {use_compile_cache()}; load {os.getloadavg()[0]:.1f}")
    _, obs, truths, _ = observed()
    s = setup(obs, list(truths), start=truths)
    x = np.asarray(s.x0, dtype=float)
    real = uncertainty.grid_step
    uncertainty.grid_step = lambda *a: timed("  the pixel grid in estimate (grid_step)", lambda: real(*a), 1)
    timed("estimate", lambda: uncertainty.estimate(s, x), args.repeats)
    uncertainty.grid_step = real
    changes = s.problem.pixel_grid(x)
    columns = [i for i, n in enumerate(s.solver_params.names) if is_image(n)]
    timed("the changes to the 4x model, both renders (an iteration of the fixed point)", lambda: changes.fine(x), args.repeats)
    timed("at the fixed point: the 2x model and the derivatives", lambda: changes.settled(x, columns), args.repeats)


if __name__ == "__main__":
    main()
