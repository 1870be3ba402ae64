"""Where a pass fit's time and memory go: :mod:`bench_pass`'s fit of ``--frames`` frames in this process, with
the wall time of its frames' Jacobian and primal renders, of its set-up, solve, covariance (``estimate``, its
Jacobian renders included) and goodness of fit, the time JAX reports for tracing and XLA compilation, and the
peak resident memory in each of those phases (sampled every 50 ms). Figures in docs/measurements/performance.md
("A frame's own values: one product per kind, not per frame").
Run: ``.venv/bin/python experiments/profile_pass.py [--size PX] [--frames N]``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import tempfile
import threading
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np
import psutil
from bench_pass import SENSOR, SIMULATE_SPP, base, fit_frames
from studyio import machine

import spacefit as sf
import spacefit.fitting.frames as frames
import spacefit.fitting.loop as loop


class Profile:
    """Wall time and calls per wrapped function or JAX event, and the peak resident memory per phase."""

    def __init__(self) -> None:
        self.phase = "start"
        self.walls: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)
        self.peaks: dict[str, float] = defaultdict(float)
        threading.Thread(target=self._sample, daemon=True).start()
        jax.monitoring.register_event_duration_secs_listener(self._event)

    def _sample(self) -> None:
        process = psutil.Process()
        while True:
            self.peaks[self.phase] = max(self.peaks[self.phase], process.memory_info().rss / 2**20)
            time.sleep(0.05)

    def _event(self, event: str, duration: float, **_: Any) -> None:
        if event.endswith(("backend_compile_duration", "jaxpr_trace_duration", "jaxpr_to_mlir_module_duration")):
            self.walls[event] += duration
            self.calls[event] += 1

    def timed(self, name: str, fn: Callable[..., Any], phase: bool = False) -> Callable[..., Any]:
        """``fn`` timed under ``name`` (and, with ``phase``, its memory counted as that phase's)."""
        def wrapped(*args: Any, **kwargs: Any) -> Any:
            before, t0 = self.phase, time.perf_counter()
            self.phase = name if phase else before
            try:
                return fn(*args, **kwargs)
            finally:
                self.walls[name] += time.perf_counter() - t0
                self.calls[name] += 1
                self.phase = before
        return wrapped


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=64, help="frame width and height, px")
    p.add_argument("--frames", type=int, default=12, help="frames fitted")
    args = p.parse_args()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    print(f"machine: {machine()}; commit {commit}; {args.size} x {args.size} px, {args.frames} frames; load {os.getloadavg()[0]:.1f}",
          flush=True)
    profile = Profile()
    frames.frame_jacobian = profile.timed("frames' Jacobian renders", frames.frame_jacobian)
    frames.frame_primal = profile.timed("frames' primal renders", frames.frame_primal)
    loop.setup = profile.timed("set-up", loop.setup, phase=True)
    loop._solve = profile.timed("solve (covariance and goodness included)", loop._solve, phase=True)
    loop.estimate = profile.timed("covariance", loop.estimate, phase=True)
    loop.judged_goodness = profile.timed("goodness of fit", loop.judged_goodness, phase=True)
    rng = np.random.default_rng(3)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "pass"
        errors = [{"target.attitude_x_deg": float(a), "target.attitude_z_deg": float(b)} for a, b in rng.uniform(-0.3, 0.3, (args.frames, 2))]
        sf.simulate_pass(base(args.size), sf.arc_pass(args.frames), folder, errors=errors, sensor=SENSOR, spp=SIMULATE_SPP)
        profile.phase = "fit"
        t0, c0 = time.perf_counter(), time.process_time()
        fit_frames(folder, args.size, args.frames)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    print(f"fit: {wall:.1f} s wall, {cpu:.1f} s CPU; load {os.getloadavg()[0]:.1f}")
    for name in sorted(profile.walls, key=lambda k: -profile.walls[k]):
        print(f"  {name}: {profile.walls[name]:.1f} s wall in {profile.calls[name]} calls")
    for name, peak in profile.peaks.items():
        print(f"  peak memory during {name}: {peak:.0f} MiB")


if __name__ == "__main__":
    main()
