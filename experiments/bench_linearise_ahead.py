"""The standard errors' linearisation of issue 33's 8-parameter observation fit (``bench_fit_process.py``'s files) at
its start, the fit's seeds' renders kept as a solve keeps them: the independent seeds' Jacobian rendered beside the
fit's seeds' tangents (``Outside.render_ahead``, as ``uncertainty.linearise`` does) against after them: wall and CPU
time of ``linearise``, each in a process of its own (JAX traces a program once per process), the two in turn, JAX's
cache warm (a warm-up pair first), and whether their tangents agree bit for bit.
Run: ``.venv/bin/python experiments/bench_linearise_ahead.py [--pairs N]``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_fit_process import write_inputs
from studyio import machine

from spacefit.fitting.compile_cache import ENV as JAX_CACHE_ENV

ROOT = Path(__file__).resolve().parent.parent


def cpu_s() -> float:
    """The process's CPU time so far, s (user + system, all threads)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def linearised(folder: Path, ahead: bool) -> dict[str, float]:
    """The fit's set-up, its start's renders kept, then ``linearise`` there: its wall and CPU time (s)."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from spacefit.fitting.compile_cache import use_compile_cache
    from spacefit.fitting.observation_files import ObservationFiles
    from spacefit.fitting.problem import setup
    from spacefit.fitting.uncertainty import linearise

    args = json.loads((folder / "args.json").read_text())
    free = args[args.index("--free") + 1].split(",")
    start = {a.split("=")[0]: float(a.split("=")[1]) for i, a in enumerate(args) if i and args[i - 1] == "--start"}
    use_compile_cache()
    with jax.enable_x64(True):
        s = setup(ObservationFiles([str(folder / "obs.fits")], [str(folder / "scene.toml")]).load(), free, start=start)
        outside, x = s.problem.outside, np.asarray(s.x0)
        outside.keep(x, 0, outside.render(x, 0, True))  # as a solve keeps its best point's renders
        if not ahead:
            object.__setattr__(outside, "render_ahead", lambda x, j: None)  # a frozen dataclass: its renders made in turn
        wall0, cpu0 = time.perf_counter(), cpu_s()
        lin = linearise(s.problem, x)
        wall, cpu = time.perf_counter() - wall0, cpu_s() - cpu0
        tangent = np.asarray(lin.J2(jnp.ones(len(x))))
    return {"wall_s": wall, "cpu_s": cpu, "tangent_sum": float(np.sum(tangent))}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pairs", type=int, default=3, help="pairs counted, after a warm-up pair")
    p.add_argument("--child", choices=("ahead", "in-turn"), help=argparse.SUPPRESS)
    p.add_argument("--folder", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        print(json.dumps(linearised(Path(args.folder), args.child == "ahead")))
        return
    print(f"machine: {machine()}; load {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "args.json").write_text(json.dumps(write_inputs(folder)))
        env = {**os.environ, "PYTHONPATH": str(ROOT), JAX_CACHE_ENV: str(folder / "jax")}
        rows: dict[str, list[dict[str, float]]] = {"ahead": [], "in-turn": []}
        for k in range(args.pairs + 1):
            for kind in rows:
                out = subprocess.run([sys.executable, __file__, "--child", kind, "--folder", str(folder)], env=env, cwd=ROOT,
                                     capture_output=True, text=True, check=True).stdout
                if k:  # the first pair fills JAX's cache
                    rows[kind].append(json.loads(out.splitlines()[-1]))
    for kind, runs in rows.items():
        walls, cpus = [r["wall_s"] for r in runs], [r["cpu_s"] for r in runs]
        print(f"linearise, the independent seeds' Jacobian rendered {kind} (median of {len(runs)}): {statistics.median(walls):.2f} s "
              f"wall ({', '.join(f'{w:.2f}' for w in walls)}), {statistics.median(cpus):.2f} s CPU ({', '.join(f'{c:.2f}' for c in cpus)})")
    same = len({r["tangent_sum"] for runs in rows.values() for r in runs}) == 1
    print(f"the same tangents in every run (bit for bit): {same}; load {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
