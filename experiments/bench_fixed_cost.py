"""Per-call fixed cost of a fit's renders (issue 33: at most 5 ms), for the primal render and a
forward-mode derivative column of the panels case at 128 x 128 px, 32 spp (the observed fit's setting,
its three materials free), each call at new material values and a new seed as a fit makes them.
Frozen (the passes replayed, :mod:`spacefit.rendering.frozen`) against traced (every pass traced anew,
as before freezing), in turn in one process. Measured two ways:

- **zero work** (the frozen calls' figure, the target's verdict): the same frozen call at 5, 10, 17 and 32 spp (each
  two multijitter passes, as 32 is: 30 + 2), a straight line through the median times against spp, read at 0 spp:
  what a call costs whatever its samples (the film's development, a per-pixel kernel, included). In wall time, in the
  process's CPU time (all threads) and in the Dr.Jit thread's, which a loaded machine does not
  inflate as it does wall time (the Dr.Jit thread also runs its share of the kernels' work units, whose
  per-spp part goes into the slope). ``profile_frozen_call.py`` splits a call's CPU time step by step.
- **kernel history** (the traced calls'): the wall time of a call (on the calling thread, the hop to the Dr.Jit
  thread included) less the run time of the Dr.Jit kernels it launched, from Dr.Jit's kernel history. Dr.Jit's
  flags are per thread and the renders run on the process's one Dr.Jit thread
  (:func:`~spacefit.rendering.backend.on_drjit_thread`), so the history is switched on and read there;
  on the LLVM backend an entry's ``execution_time`` is its task's run time on the thread pool, from its
  first work unit's start to its last one's end (ms), which reading the history waits for. A frozen pass runs with
  the history off (so that a counted render replays the recording an uncounted one made,
  :mod:`spacefit.rendering.frozen`): the history holds a frozen call's splat and development alone, not its
  samples' kernels, and wall less kernels is no fixed cost there (it read 9 to 19 ms, the samples' run included,
  from 6a0c743 until this benchmark's verdict moved to the zero-work line).

On a loaded machine a call's wall time also counts its waits for a core (between kernels, at each
wake-up of a thread); the quiet figure is the one to compare with the target. Prints the machine, its
load average and the commit. Run: ``.venv/bin/python experiments/bench_fixed_cost.py [--calls N]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from studyio import commit, machine

import spacefit as sf
from spacefit.rendering.backend import dr, on_drjit_thread
from spacefit.rendering.drjit_scene import DrJitScene
from spacefit.rendering.derivatives import render_chain
from spacefit.rendering.frozen import FrozenPasses
from spacefit.scene.sampling import split_sample_count

TARGET_MS = 5.0
SPP = 32
LINE_SPP = (5, 10, 17, 32)  # two multijitter passes each, as SPP
KINDS = ("primal", "derivative")


class Call(NamedTuple):
    """One timed render, ms: wall time on the calling thread, the process's CPU time, its kernels' run time,
    the Dr.Jit thread's CPU time."""

    wall: float
    cpu: float
    kernels: float
    thread: float


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


@on_drjit_thread
def thread_cpu_ms() -> float:
    """The Dr.Jit thread's CPU time so far, ms."""
    return time.thread_time() * 1e3


def timed(call: Callable[[], object], history: bool) -> Call:
    """``call()`` timed; its kernels' run time from the kernel history if ``history``, else NaN."""
    if history:
        history_start()
    thread = thread_cpu_ms()
    t0, c0 = time.perf_counter(), time.process_time()
    call()
    wall, cpu = (time.perf_counter() - t0) * 1e3, (time.process_time() - c0) * 1e3
    thread = thread_cpu_ms() - thread
    return Call(wall, cpu, history_stop() if history else float("nan"), thread)


def calls(scene: DrJitScene, x0: np.ndarray, values_of: Callable, kind: str, n: int, history: bool = True) -> list[Call]:
    """``n`` timed renders of ``kind`` (``primal`` or ``derivative``) at material values 1 % apart."""
    out = []
    for i in range(n):
        values = {k: np.asarray(v) for k, v in values_of(jnp.asarray(x0 * (1.0 + 0.01 * i))).items()}
        key = next(iter(values))
        if kind == "primal":
            out.append(timed(lambda: scene.render_primal(values, 100 + i), history))  # noqa: B023  (called at once)
        else:
            out.append(timed(lambda: scene.forward(values, {key: np.ones_like(values[key])}, 200 + i), history))  # noqa: B023
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--calls", type=int, default=15, help="timed calls of each kind, mode and spp, after 3 unmeasured")
    p.add_argument("--rounds", type=int, default=2, help="rounds of frozen and traced in turn")
    args = p.parse_args()
    assert all(len(split_sample_count("multijitter", n)) == len(split_sample_count("multijitter", SPP)) for n in LINE_SPP)
    case = sf.load_case("panels").with_values({"render.spp": SPP})
    scene, names = case.scene(), list(case.free)
    x0 = np.array([case.start[n] for n in names])
    load = os.getloadavg()[0]
    print(f"machine: {machine()}, {dr.thread_count()} Dr.Jit threads, load average {load:.1f}, commit {commit()}")
    print(f"panels case {scene.render.resolution[0]} x {scene.render.resolution[1]} px, {SPP} spp, free {names}; "
          f"{args.calls} calls of each, {args.rounds} rounds in turn")
    chains = {"frozen": render_chain(scene, names), "traced": render_chain(scene, names)}
    chains["traced"].renderer.frozen = FrozenPasses(enabled=False)
    rows: dict[tuple[str, str], list[Call]] = {}
    for _ in range(args.rounds):
        for kind in KINDS:
            for mode, chain in chains.items():
                calls(chain.drjit, x0, chain.values_of, kind, 3)  # the first traces and compiles, the next record
                rows.setdefault((kind, mode), []).extend(calls(chain.drjit, x0, chain.values_of, kind, args.calls, mode == "traced"))
    print(f"{'render':<11} {'mode':<7} {'wall ms':>8} {'CPU ms':>7} {'kernels ms':>10} {'fixed ms':>9} {'least':>6}  (medians; "
          "fixed = wall - kernels per call; least: the call with the least, the one a loaded machine delayed least)")
    traced = {}  # per kind, the traced calls' median wall less kernels (a frozen call's history lacks its samples' kernels)
    for (kind, mode), samples in rows.items():
        if mode == "traced":
            traced[kind] = statistics.median(c.wall - c.kernels for c in samples)
            kernels, least = statistics.median(c.kernels for c in samples), min(c.wall - c.kernels for c in samples)
            counted = f"{kernels:>10.1f} {traced[kind]:>9.1f} {least:>6.1f}"
        else:
            counted = f"{'-':>10} {'-':>9} {'-':>6}  (its samples' kernels run with the history off: the zero-work line below)"
        print(f"{kind:<11} {mode:<7} {statistics.median(c.wall for c in samples):>8.1f} {statistics.median(c.cpu for c in samples):>7.1f} {counted}")
    frozen, line = chains["frozen"], {}
    for kind in KINDS:
        medians = []
        for spp in LINE_SPP:
            ds = DrJitScene(frozen.renderer, spp, spp)  # the same loaded scene and recordings, another sample count
            calls(ds, x0, frozen.values_of, kind, 3, history=False)
            samples = calls(ds, x0, frozen.values_of, kind, args.calls, history=False)
            medians.append(tuple(statistics.median([getattr(c, f) for c in samples]) for f in ("wall", "cpu", "thread")))
        (wall_slope, wall0), (cpu_slope, cpu0), (thread_slope, thread0) = (np.polyfit(LINE_SPP, column, 1) for column in zip(*medians))
        line[kind] = wall0, cpu0
        print(f"{kind:<11} frozen, median wall / process CPU / Dr.Jit thread CPU ms at {', '.join(f'{s} spp {w:.1f} / {c:.1f} / {t:.1f}' for s, (w, c, t) in zip(LINE_SPP, medians))}: "
              f"per spp {wall_slope:.2f} / {cpu_slope:.2f} / {thread_slope:.2f}, at 0 spp {wall0:.1f} / {cpu0:.1f} / {thread0:.1f}")
    load = max(load, os.getloadavg()[0])
    for kind in KINDS:
        f = line[kind][0]
        print(f"per-call fixed cost, {kind}: {f:.1f} ms wall frozen, the zero-work line at 0 spp (target {TARGET_MS:.0f} ms: "
              f"{'met' if f <= TARGET_MS else 'NOT met'} at load {load:.1f}; {line[kind][1]:.1f} ms CPU), "
              f"{traced[kind]:.1f} ms traced (wall less its kernels)")
    if load > os.cpu_count():
        print(f"the machine was loaded (load average up to {load:.1f} on {os.cpu_count()} cores): a call's wall time counted "
              "its waits for a core; the target is for a quiet machine")
    print(f"load average at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
