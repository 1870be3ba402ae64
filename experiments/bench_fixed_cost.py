"""Per-call fixed cost of a fit's renders (issue 33: at most 5 ms), for the primal render and a
forward-mode derivative column of the panels case at 128 x 128 px, 32 spp (the observed fit's setting,
its three materials free), each call at new material values and a new seed as a fit makes them.
Frozen (the passes replayed, :mod:`spacefit.rendering.frozen`) against traced (every pass traced anew,
as before freezing), in turn in one process. Measured two ways:

- **kernel history**: the wall time of a call (on the calling thread, the hop to the Dr.Jit thread
  included) less the run time of the Dr.Jit kernels it launched, from Dr.Jit's kernel history. Dr.Jit's
  flags are per thread and the renders run on the process's one Dr.Jit thread
  (:func:`~spacefit.rendering.backend.on_drjit_thread`), so the history is switched on and read there;
  on the LLVM backend an entry's ``execution_time`` is its task's run time on the thread pool (ms),
  which reading the history waits for. Kernels that overlap Python work would make this a lower bound.
- **zero work**: the same frozen call at 5, 10, 17 and 32 spp (each two multijitter passes, as 32 is:
  30 + 2), a straight line through the median wall times against spp, read at 0 spp: what a call
  costs whatever its samples, kernel work per pixel (the film's development) included, so an upper
  bound of the first.

Prints the machine, its load average and the commit. Run: ``.venv/bin/python experiments/bench_fixed_cost.py [--calls N]``.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import time
from collections.abc import Callable

import jax.numpy as jnp
import numpy as np
from studyio import machine

import spacefit as sf
from spacefit.rendering.backend import dr, on_drjit_thread
from spacefit.rendering.bridge import DrJitScene
from spacefit.rendering.derivatives import render_chain
from spacefit.rendering.frozen import FrozenPasses
from spacefit.scene.sampling import split_sample_count

TARGET_MS = 5.0
SPP = 32
LINE_SPP = (5, 10, 17, 32)  # two multijitter passes each, as SPP


@on_drjit_thread
def history_start() -> None:
    """Switch Dr.Jit's kernel history on, empty, on the thread that renders (flags are per thread)."""
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history_clear()


@on_drjit_thread
def history_stop() -> float:
    """The summed run time (ms) of the kernels launched since :func:`history_start`, waiting for them; history off."""
    ms = sum(k["execution_time"] for k in dr.kernel_history())
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    return ms


def timed(call: Callable[[], object]) -> tuple[float, float]:
    """Wall time of ``call()`` on this thread and the summed run time of the Dr.Jit kernels it launched, ms."""
    history_start()
    t0 = time.perf_counter()
    call()
    wall = (time.perf_counter() - t0) * 1e3
    return wall, history_stop()


def calls(scene: DrJitScene, x0: np.ndarray, values_of: Callable, kind: str, n: int, history: bool = True) -> list[tuple[float, float]]:
    """``n`` timed renders of ``kind`` (``primal`` or ``derivative``) at material values 1 % apart
    (wall, kernels ms; kernels NaN without the ``history``)."""
    out = []
    for i in range(n):
        values = {k: np.asarray(v) for k, v in values_of(jnp.asarray(x0 * (1.0 + 0.01 * i))).items()}
        key = next(iter(values))
        if kind == "primal":
            call = lambda: scene.render_primal(values, 100 + i)  # noqa: B023, E731  (called at once)
        else:
            call = lambda: scene.forward(values, {key: np.ones_like(values[key])}, 200 + i)  # noqa: B023, E731
        if history:
            out.append(timed(call))
        else:
            t0 = time.perf_counter()
            call()
            out.append(((time.perf_counter() - t0) * 1e3, float("nan")))
    return out


def cpu_s() -> float:
    """CPU time of this process so far (user + system, all threads), s."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def commit() -> str:
    """The checkout's commit (short hash), or 'unknown' outside git."""
    run = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=os.path.dirname(__file__), capture_output=True, text=True)
    return run.stdout.strip() or "unknown"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--calls", type=int, default=15, help="timed calls of each kind and mode, after 3 unmeasured")
    p.add_argument("--rounds", type=int, default=2, help="rounds of frozen and traced in turn")
    args = p.parse_args()
    assert all(len(split_sample_count("multijitter", n)) == len(split_sample_count("multijitter", SPP)) for n in LINE_SPP)
    case = sf.load_case("panels").with_values({"render.spp": SPP})
    scene, names = case.scene(), list(case.free)
    x0 = np.array([case.start[n] for n in names])
    print(f"machine: {machine()}, {dr.thread_count()} Dr.Jit threads, load average {os.getloadavg()[0]:.1f}, commit {commit()}")
    print(f"panels case {scene.render.resolution[0]} x {scene.render.resolution[1]} px, {SPP} spp, free {names}; "
          f"{args.calls} calls of each, {args.rounds} rounds in turn")
    chains = {"frozen": render_chain(scene, names), "traced": render_chain(scene, names)}
    chains["traced"].renderer.frozen = FrozenPasses(enabled=False)
    rows: dict[tuple[str, str], list[tuple[float, float]]] = {}
    cpu0, wall0 = cpu_s(), time.perf_counter()
    for _ in range(args.rounds):
        for kind in ("primal", "derivative"):
            for mode, chain in chains.items():
                calls(chain.drjit, x0, chain.values_of, kind, 3)  # the first traces and compiles, the next record
                rows.setdefault((kind, mode), []).extend(calls(chain.drjit, x0, chain.values_of, kind, args.calls))
    print(f"(CPU {cpu_s() - cpu0:.1f} s in {time.perf_counter() - wall0:.1f} s wall for these calls)")
    print(f"{'render':<11} {'mode':<7} {'wall ms':>8} {'kernels ms':>10} {'fixed ms':>9} {'least':>6}  (medians; fixed = wall - kernels "
          "per call; least: the call with the least, the one a loaded machine delayed least)")
    fixed = {}
    for (kind, mode), samples in rows.items():
        walls, kernels = zip(*samples)
        fixed[kind, mode] = statistics.median(w - k for w, k in samples)
        print(f"{kind:<11} {mode:<7} {statistics.median(walls):>8.1f} {statistics.median(kernels):>10.1f} {fixed[kind, mode]:>9.1f} "
              f"{min(w - k for w, k in samples):>6.1f}")
    frozen = chains["frozen"]
    line = {}
    for kind in ("primal", "derivative"):
        walls = []
        for spp in LINE_SPP:
            ds = DrJitScene(frozen.renderer, spp, spp)  # the same loaded scene and recordings, another sample count
            calls(ds, x0, frozen.values_of, kind, 3, history=False)
            walls.append(statistics.median(w for w, _ in calls(ds, x0, frozen.values_of, kind, args.calls, history=False)))
        slope, intercept = np.polyfit(LINE_SPP, walls, 1)
        line[kind] = intercept
        print(f"{kind:<11} frozen wall ms at {', '.join(f'{s} spp {w:.1f}' for s, w in zip(LINE_SPP, walls))}: "
              f"{slope:.2f} ms per spp, {intercept:.1f} ms at 0 spp")
    for kind in ("primal", "derivative"):
        f = fixed[kind, "frozen"]
        print(f"per-call fixed cost, {kind}: {f:.1f} ms frozen (target {TARGET_MS:.0f} ms: {'met' if f <= TARGET_MS else 'NOT met'}; "
              f"zero-work line {line[kind]:.1f} ms), {fixed[kind, 'traced']:.1f} ms traced")
    print(f"load average at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
