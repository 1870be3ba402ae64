"""The first solver step of issue 33's 8-parameter observation fit (``bench_fit_process.py``'s files), its programs
compiled beside its renders (the driver, ``spacefit.fitting.drivers``) against after them (its renders made first,
as before the eighth session), and the standard errors' linearisation at its point with the independent seeds'
Jacobian rendered beside the fit's seeds' tangents (``Outside.render_ahead``) against after them: wall and CPU time
of each, each pair in processes of their own (JAX traces a program once per process), in turn, JAX's cache warm (a
warm-up pair first).
Run: ``.venv/bin/python experiments/bench_first_step.py [--pairs N]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import Future
from pathlib import Path

from bench_fit_process import write_inputs
from studyio import machine

from spacefit.fitting.compile_cache import ENV as JAX_CACHE_ENV

ROOT = Path(__file__).resolve().parent.parent


def cpu_s() -> float:
    """The process's CPU time so far, s (user + system, all threads)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def first_step(folder: Path, beside: bool) -> dict[str, float]:
    """The fit's set-up, then the driver to its first step: its wall and CPU time (s)."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from spacefit.fitting.compile_cache import use_compile_cache
    from spacefit.fitting.drivers import drive
    from spacefit.fitting.loop import _rendered_first
    from spacefit.fitting.observation_files import ObservationFiles
    from spacefit.fitting.problem import setup
    from spacefit.fitting.solvers import make_solver
    from spacefit.fitting.uncertainty import linearise

    args = json.loads((folder / "args.json").read_text())
    free = args[args.index("--free") + 1].split(",")
    start = {a.split("=")[0]: float(a.split("=")[1]) for i, a in enumerate(args) if i and args[i - 1] == "--start"}
    use_compile_cache()
    with jax.enable_x64(True):
        s = setup(ObservationFiles([str(folder / "obs.fits")], [str(folder / "scene.toml")]).load(), free, start=start)
        u = jnp.asarray(s.solver_params.to_unconstrained(jnp.asarray(s.x0)))
        given = _rendered_first(s)
        if not beside:
            def made_first(u: jax.Array) -> Future:
                done: Future = Future()
                done.set_result(given.render(u))
                return done

            given = dataclasses.replace(given, start=made_first)
        wall0, cpu0 = time.perf_counter(), cpu_s()
        step = next(drive(make_solver("lm"), lambda y: y, u, 1, None, given))
        wall, cpu = time.perf_counter() - wall0, cpu_s() - cpu0
        # the standard errors' linearisation at the first step's point, whose renders the solver kept (Outside.keep)
        x = np.asarray(s.solver_params.to_physical(jnp.asarray(step.u)))
        s.problem.outside.keep(x, 0, s.problem.outside.render(x, 0, True))
        if not beside:
            object.__setattr__(s.problem.outside, "render_ahead", lambda x, j: None)  # a frozen dataclass: its renders made in turn
        wall1, cpu1 = time.perf_counter(), cpu_s()
        lin = linearise(s.problem, x)
        r = np.asarray(lin.J2(jnp.ones(len(x))))
    return {"wall_s": wall, "cpu_s": cpu, "loss": float(step.loss), "u0": float(np.asarray(step.iterate)[0]),
            "lin_wall_s": time.perf_counter() - wall1, "lin_cpu_s": cpu_s() - cpu1, "r": float(np.sum(r))}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pairs", type=int, default=3, help="pairs counted, after a warm-up pair")
    p.add_argument("--child", choices=("beside", "after"), help=argparse.SUPPRESS)
    p.add_argument("--folder", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        print(json.dumps(first_step(Path(args.folder), args.child == "beside")))
        return
    print(f"machine: {machine()}; load {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "args.json").write_text(json.dumps(write_inputs(folder)))
        env = {**os.environ, "PYTHONPATH": str(ROOT), JAX_CACHE_ENV: str(folder / "jax")}
        rows: dict[str, list[dict[str, float]]] = {"beside": [], "after": []}
        for k in range(args.pairs + 1):
            for kind in rows:
                out = subprocess.run([sys.executable, __file__, "--child", kind, "--folder", str(folder)], env=env, cwd=ROOT,
                                     capture_output=True, text=True, check=True).stdout
                if k:  # the first pair fills JAX's cache
                    rows[kind].append(json.loads(out.splitlines()[-1]))
    for what, key in (("first step, programs compiled", ""), ("standard errors' linearisation, tangents traced", "lin_")):
        for kind, runs in rows.items():
            walls, cpus = [r[key + "wall_s"] for r in runs], [r[key + "cpu_s"] for r in runs]
            print(f"{what} {kind} its renders (median of {len(runs)}): {statistics.median(walls):.2f} s wall "
                  f"({', '.join(f'{w:.2f}' for w in walls)}), {statistics.median(cpus):.2f} s CPU ({', '.join(f'{c:.2f}' for c in cpus)})")
    same = all(r[k] == rows["after"][0][k] for r in rows["beside"] + rows["after"] for k in ("loss", "u0", "r"))
    print(f"the same first step in every run (loss and point, bit for bit): {same}; load {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
