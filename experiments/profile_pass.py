"""Where a pass fit's time and memory go: :mod:`bench_pass`'s fit of ``--frames`` frames in this process, with
the wall and CPU time of its frames' Jacobian and primal renders, of its set-up, solve, covariance (``estimate``, its
Jacobian renders included; within it the second linearisation, the products of the sandwich, the pixel grid's 4x
renders, its step's fixed point and its feedback, and the Gauss-Newton steps they take) and goodness of fit, the time
JAX reports for tracing and XLA compilation, and the peak resident memory in each phase (sampled every 50 ms).
Figures in docs/measurements/performance-history.md ("A frame's own values: one product per kind, not per frame", "A pass on
every core").
Run: ``.venv/bin/python experiments/profile_pass.py [--size PX] [--frames N]``.
"""

from __future__ import annotations

import argparse
import os
import resource
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
from studyio import commit, machine

import spacefit as sf
import spacefit.fitting.conclusion as conclusion
import spacefit.fitting.fine_models as fine_models
import spacefit.fitting.frames as frames
import spacefit.fitting.loop as loop
import spacefit.fitting.residuals as residuals
import spacefit.fitting.uncertainty as uncertainty


def cpu_s() -> float:
    """This process's CPU time so far (all its threads), s."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


class Profile:
    """Wall time and calls per wrapped function or JAX event, and the peak resident memory per phase."""

    def __init__(self) -> None:
        self.phase = "start"
        self.walls: dict[str, float] = defaultdict(float)
        self.cpus: dict[str, float] = defaultdict(float)
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
            before, t0, c0 = self.phase, time.perf_counter(), cpu_s()
            self.phase = name if phase else before
            try:
                return fn(*args, **kwargs)
            finally:
                self.walls[name] += time.perf_counter() - t0
                self.cpus[name] += cpu_s() - c0
                self.calls[name] += 1
                self.phase = before
        return wrapped


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=64, help="frame width and height, px")
    p.add_argument("--frames", type=int, default=12, help="frames fitted")
    args = p.parse_args()
    print(f"machine: {machine()}; commit {commit()}; {args.size} x {args.size} px, {args.frames} frames; load {os.getloadavg()[0]:.1f}",
          flush=True)
    profile = Profile()
    frames.frame_jacobian = profile.timed("frames' Jacobian renders", frames.frame_jacobian)
    frames.frame_primal = profile.timed("frames' primal renders", frames.frame_primal)
    loop.setup = profile.timed("set-up", loop.setup, phase=True)
    loop._solve = profile.timed("solve (covariance and goodness included)", loop._solve, phase=True)
    conclusion.estimate = profile.timed("covariance", conclusion.estimate, phase=True)
    conclusion.judged_goodness = profile.timed("goodness of fit", conclusion.judged_goodness, phase=True)
    uncertainty.linearise = profile.timed("covariance: linearisations", uncertainty.linearise, phase=True)
    uncertainty.Linearisation.columns = profile.timed("covariance: sandwich products", uncertainty.Linearisation.columns, phase=True)
    uncertainty.grid_step = profile.timed("covariance: pixel grid's fixed point and feedback", uncertainty.grid_step, phase=True)
    uncertainty.Linearisation.step = profile.timed("covariance: Gauss-Newton steps", uncertainty.Linearisation.step)
    residuals.grid_error_models = profile.timed("covariance: pixel grid's 4x renders", residuals.grid_error_models, phase=True)
    fine_models.Renderer.render = profile.timed("pixel grid's renders alone", fine_models.Renderer.render)
    rng = np.random.default_rng(3)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "pass"
        errors = [{"target.attitude_x_deg": float(a), "target.attitude_z_deg": float(b)} for a, b in rng.uniform(-0.3, 0.3, (args.frames, 2))]
        sf.simulate_pass(base(args.size), sf.arc_pass(args.frames), folder, errors=errors, sensor=SENSOR, spp=SIMULATE_SPP)
        profile.phase = "fit"
        t0, c0 = time.perf_counter(), cpu_s()
        fit_frames(folder, args.size, args.frames)
        wall, cpu = time.perf_counter() - t0, cpu_s() - c0
    print(f"fit: {wall:.1f} s wall, {cpu:.1f} s CPU, peak {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB; "
          f"load {os.getloadavg()[0]:.1f}")
    for name in sorted(profile.walls, key=lambda k: -profile.walls[k]):
        cpu_part = f", {profile.cpus[name]:.1f} s CPU" if name in profile.cpus else ""  # JAX's events: wall only
        print(f"  {name}: {profile.walls[name]:.1f} s wall{cpu_part} in {profile.calls[name]} calls")
    for name, peak in profile.peaks.items():
        print(f"  peak memory during {name}: {peak:.0f} MiB")


if __name__ == "__main__":
    main()
