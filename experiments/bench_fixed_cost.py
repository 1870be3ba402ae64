"""Per-call fixed cost of a fit's renders (issue 33: at most 5 ms): the wall time of a render call less
the time its Dr.Jit kernels ran, for the primal render and a forward-mode derivative column of the
panels case at 128 x 128 px, 32 spp (the observed fit's setting, its three materials free), each call
at new material values and a new seed as a fit makes them. Frozen (the passes replayed,
:mod:`spacefit.rendering.frozen`) against traced (every pass traced anew, as before freezing), in
turn in one process; the kernels' times come from Dr.Jit's kernel history. Prints the machine, its
load average and the commit. Run: ``.venv/bin/python experiments/bench_fixed_cost.py [--calls N]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from studyio import machine

import spacefit as sf
from spacefit.rendering.backend import dr
from spacefit.rendering.derivatives import RenderChain, render_chain
from spacefit.rendering.frozen import FrozenPasses

TARGET_MS = 5.0
SPP = 32


def timed(call: Callable[[], object]) -> tuple[float, float]:
    """Wall time of ``call()`` and the summed execution time of the Dr.Jit kernels it launched, ms."""
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history_clear()
        t0 = time.perf_counter()
        call()
        wall = (time.perf_counter() - t0) * 1e3
        kernels = sum(k.get("execution_time", 0.0) for k in dr.kernel_history())
    return wall, kernels


def calls(chain: RenderChain, x0: np.ndarray, kind: str, n: int) -> list[tuple[float, float]]:
    """``n`` timed renders of ``kind`` (``primal`` or ``derivative``) at material values 1 % apart."""
    out = []
    for i in range(n):
        values = {k: np.asarray(v) for k, v in chain.values_of(jnp.asarray(x0 * (1.0 + 0.01 * i))).items()}
        key = next(iter(values))
        if kind == "primal":
            out.append(timed(lambda: chain.drjit.render_primal(values, 100 + i)))  # noqa: B023  (called at once)
        else:
            out.append(timed(lambda: chain.drjit.forward(values, {key: np.ones_like(values[key])}, 200 + i)))  # noqa: B023
    return out


def commit() -> str:
    """The checkout's commit (short hash), or 'unknown' outside git."""
    run = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=Path(__file__).parent, capture_output=True, text=True)
    return run.stdout.strip() or "unknown"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--calls", type=int, default=15, help="timed calls of each kind and mode, after 3 unmeasured")
    p.add_argument("--rounds", type=int, default=2, help="rounds of frozen and traced in turn")
    args = p.parse_args()
    case = sf.load_case("panels").with_values({"render.spp": SPP})
    scene, names = case.scene(), list(case.free)
    x0 = np.array([case.start[n] for n in names])
    print(f"machine: {machine()}, {dr.thread_count()} Dr.Jit threads, load average {os.getloadavg()[0]:.1f}, commit {commit()}")
    print(f"panels case {scene.render.resolution[0]} x {scene.render.resolution[1]} px, {SPP} spp, free {names}; "
          f"{args.calls} calls of each, {args.rounds} rounds in turn")
    chains = {"frozen": render_chain(scene, names), "traced": render_chain(scene, names)}
    chains["traced"].renderer.frozen = FrozenPasses(enabled=False)
    rows: dict[tuple[str, str], list[tuple[float, float]]] = {}
    for _ in range(args.rounds):
        for kind in ("primal", "derivative"):
            for mode, chain in chains.items():
                calls(chain, x0, kind, 3)  # the first traces and compiles, the next record
                rows.setdefault((kind, mode), []).extend(calls(chain, x0, kind, args.calls))
    print(f"{'render':<11} {'mode':<7} {'wall ms':>8} {'kernels ms':>10} {'fixed ms':>9}  (medians; fixed = wall - kernels per call)")
    fixed = {}
    for (kind, mode), samples in rows.items():
        walls, kernels = zip(*samples)
        fixed[kind, mode] = statistics.median(w - k for w, k in samples)
        print(f"{kind:<11} {mode:<7} {statistics.median(walls):>8.1f} {statistics.median(kernels):>10.1f} {fixed[kind, mode]:>9.1f}")
    for kind in ("primal", "derivative"):
        f = fixed[kind, "frozen"]
        print(f"per-call fixed cost, {kind}: {f:.1f} ms frozen (target {TARGET_MS:.0f} ms: {'met' if f <= TARGET_MS else 'NOT met'}), "
              f"{fixed[kind, 'traced']:.1f} ms traced")
    print(f"load average at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
