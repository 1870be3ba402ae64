"""Where a pass fit's native memory goes, phase by phase (issue 33): :mod:`bench_pass`'s fit (the panels case, 3
materials and the PSF width shared, 5 own values a frame) with, at the edges of the set-up, each batch of frame
renders, the covariance's linearisation, products, the pixel grid's fixed point and feedback and the goodness of fit:
the resident memory (and its peak since the edge before, sampled every 20 ms), glibc's heap in use, held free and
mapped (``mallinfo2``: memory freed but kept by the allocator shows as "free"), the XLA programs compiled so far and
the bytes of JAX's live arrays. A fit's memory is native (XLA's programs and buffers, Dr.Jit, the allocator's held
pages): neither JAX's live arrays nor Python's own allocations reach 100 MiB. Linux with glibc only.
Figures: docs/measurements/performance-history.md, "A pass's memory: programs and the allocator".
The pixel grid's phase shows each evaluation of its changes at 4x, its settled changes and its feedback. With
``ANALYSE=1``, XLA's memory analysis of each pixel-grid program (compiled once more for it); with ``TRIM=major``
(``TRIM=all``: at the render batches' edges too) glibc's ``malloc_trim`` at each edge, with ``TRIM=major,drjit`` Dr.Jit's
malloc cache flushed there too, with ``TRIM=major,clear`` JAX's compiled programs dropped before the pixel grid's
fixed point and the goodness of fit. Figures also in experiments/results/pass_memory/.
Run: ``[ANALYSE=1] [TRIM=...] python experiments/pass_memory_phases.py SIZE_PX FRAMES [MAX_STEPS]`` (default 12 steps, as bench_pass).
"""

from __future__ import annotations

import ctypes
import importlib
import os
import resource
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import drjit as dr
import equinox as eqx
import jax
import numpy as np
import psutil
from bench_pass import MAX_STEPS, SENSOR, base, fit_frames
from studyio import commit, machine

import spacefit as sf
import spacefit.fitting.frames as frames
import spacefit.fitting.loop as loop
import spacefit.fitting.pixel_grid as pixel_grid
import spacefit.fitting.render_batches as render_batches
import spacefit.fitting.uncertainty as uncertainty
import spacefit.programs as programs
from spacefit.rendering.backend import on_drjit_thread


TRIM = os.environ.get("TRIM", "")


class MallInfo2(ctypes.Structure):
    """glibc's ``struct mallinfo2`` (bytes)."""

    _fields_ = [(name, ctypes.c_size_t) for name in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
                                                      "fordblks", "keepcost")]


class Phases:
    """RSS (and its sampled peak between edges), glibc's heap and XLA's compilations, printed at each phase's edges."""

    def __init__(self) -> None:
        self.process, self.compiles, self.peak, self.t0 = psutil.Process(), 0, 0.0, time.perf_counter()
        self.at_peak = (0.0, 0.0)
        self.libc = ctypes.CDLL("libc.so.6")
        self.libc.mallinfo2.restype = MallInfo2
        jax.monitoring.register_event_duration_secs_listener(self._event)
        threading.Thread(target=self._sample, daemon=True).start()

    def _event(self, event: str, duration: float, **_: Any) -> None:
        self.compiles += event.endswith("backend_compile_duration")

    def rss(self) -> float:
        return self.process.memory_info().rss / 2**20

    def _sample(self) -> None:
        while True:
            if (rss := self.rss()) > self.peak:
                m = self.libc.mallinfo2()
                self.peak, self.at_peak = rss, (m.uordblks / 2**20, m.hblkhd / 2**20)
            time.sleep(0.02)

    def show(self, name: str) -> None:
        """One line: the edge's name, RSS and its peak since the edge before, the heap, the compilations, JAX's live arrays (MiB)."""
        m, rss = self.libc.mallinfo2(), self.rss()
        live = sum(a.nbytes for a in jax.live_arrays()) / 2**20
        print(f"[{time.perf_counter() - self.t0:6.1f} s] {name:26s} RSS {rss:5.0f} (peak since {max(self.peak, rss):5.0f}), heap in use "
              f"{m.uordblks / 2**20:5.0f}, held free {m.fordblks / 2**20:5.0f}, mapped {m.hblkhd / 2**20:4.0f}; {self.compiles:3d} XLA programs; "
              f"live JAX arrays {live:4.0f}; at the peak heap in use {self.at_peak[0]:4.0f}, mapped {self.at_peak[1]:4.0f}", flush=True)
        self.peak, self.at_peak = rss, (m.uordblks / 2**20, m.hblkhd / 2**20)
        if os.environ.get("LIVE") and name.endswith(">"):
            groups: dict[tuple[Any, ...], list[float]] = {}
            for a in jax.live_arrays():
                g = groups.setdefault((a.shape, str(a.dtype)), [0, 0.0])
                g[0], g[1] = g[0] + 1, g[1] + a.nbytes / 2**20
            for (shape, dtype), (count, mib) in sorted(groups.items(), key=lambda kv: -kv[1][1])[:8]:
                print(f"      live {count:3d} x {shape} {dtype}: {mib:6.1f} MiB", flush=True)
        if TRIM and (TRIM == "all" or not name.startswith("  ")):
            if "drjit" in TRIM:
                on_drjit_thread(dr.flush_malloc_cache)()
            if "clear" in TRIM and name in ("pixel grid's fixed point <", "goodness of fit <"):
                jax.clear_caches()
            self.libc.malloc_trim(0)

    def marked(self, name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        """``fn`` with its edges shown."""
        def wrapped(*args: Any, **kwargs: Any) -> Any:
            self.show(f"{name} <")
            try:
                return fn(*args, **kwargs)
            finally:
                self.show(f"{name} >")
        return wrapped


def analyse_alike_programs() -> None:
    """Print XLA's memory analysis of each program of :class:`~spacefit.programs.AlikePrograms` (the pixel
    grid's) at its first call (compiled once more for it)."""
    call, seen = programs.AlikePrograms.__call__, set()

    def analysed(self: Any, key: object, fn: Callable[..., object], *args: Any) -> Any:
        out = call(self, key, fn, *args)
        program, consts, _ = self._traced[key]
        if id(program) not in seen:
            seen.add(id(program))
            m = program.lower(consts, *args).compile().memory_analysis()
            print(f"  program {getattr(key[0], '__name__', key[0])}: temporaries {m.temp_size_in_bytes / 2**20:.1f}, arguments "
                  f"{m.argument_size_in_bytes / 2**20:.1f}, outputs {m.output_size_in_bytes / 2**20:.1f} MiB", flush=True)
        return out

    programs.AlikePrograms.__call__ = analysed


def main() -> None:
    size, n = int(sys.argv[1]), int(sys.argv[2])
    steps = int(sys.argv[3]) if len(sys.argv) > 3 else MAX_STEPS
    print(f"machine: {machine()}; commit {commit()}; {size} x {size} px, {n} frames, at most {steps} steps; load {os.getloadavg()[0]:.1f}",
          flush=True)
    phases = Phases()
    setup = phases.marked("set-up", loop.setup)

    def marked_setup(*args: Any, **kwargs: Any) -> Any:
        s = setup(*args, **kwargs)
        if s.problem.pixel_grid is not None:
            s.problem.pixel_grid = phases.marked("pixel grid's renders", s.problem.pixel_grid)
        return s

    loop.setup = marked_setup
    uncertainty.weight_bias = phases.marked("noise weights' bias", uncertainty.weight_bias)
    # the conclusion's home: loop.py at 51b17e1, conclusion.py since its split
    concluding = loop if hasattr(loop, "estimate") else importlib.import_module("spacefit.fitting.conclusion")
    concluding.estimate = phases.marked("covariance", concluding.estimate)
    concluding.judged_goodness = phases.marked("goodness of fit", concluding.judged_goodness)
    uncertainty.linearise = phases.marked("linearisation", uncertainty.linearise)
    uncertainty.Linearisation.columns = phases.marked("products", uncertainty.Linearisation.columns)
    grid_step = phases.marked("pixel grid's fixed point", uncertainty.grid_step)
    # inside it: each evaluation of the changes at 4x, the settled changes and derivatives, the feedback's steps
    uncertainty.grid_step = lambda changes, *args: grid_step(pixel_grid.GridChanges(phases.marked("  changes at 4x", changes.fine),
                                                                                   phases.marked("  settled", changes.settled)), *args)
    pixel_grid.concurrently = phases.marked("  feedback", pixel_grid.concurrently)
    if hasattr(uncertainty, "grid_feedback"):  # a commit before the feedback was taken inside grid_step (51b17e1)
        uncertainty.grid_feedback = phases.marked("pixel grid's feedback", uncertainty.grid_feedback)
    run_frames = frames.run_frames
    # the batches' home: frames.py before 821ef45's merge, render_batches.py since
    batches = render_batches if hasattr(render_batches, "run_frames") else frames
    batches.run_frames = lambda executor, fn, specs, *args: phases.marked(f"  {fn.__name__}", run_frames)(executor, fn, specs, *args)
    filter_jit = eqx.filter_jit  # the solver's step program (drivers.py jits it per solve)

    def step_program(fn: Callable[..., Any], **kw: Any) -> Callable[..., Any]:
        jitted = filter_jit(fn, **kw)
        if getattr(fn, "__name__", "") != "step":
            return jitted
        if os.environ.get("ANALYSE"):
            def analysed(*args: Any, **kwargs: Any) -> Any:
                compiled = jitted.lower(*args, **kwargs).compile()
                m = compiled.compiled.memory_analysis()
                print(f"  program step: temporaries {m.temp_size_in_bytes / 2**20:.1f}, arguments {m.argument_size_in_bytes / 2**20:.1f}, "
                      f"outputs {m.output_size_in_bytes / 2**20:.1f}, aliased {m.alias_size_in_bytes / 2**20:.1f} MiB", flush=True)
                cpu, wall = time.process_time(), time.perf_counter()
                out = jax.block_until_ready(compiled(*args, **kwargs))
                print(f"  step: {time.process_time() - cpu:.2f} s CPU, {time.perf_counter() - wall:.2f} s wall", flush=True)
                if os.environ.get("ANALYSE") == "step":  # the step's analysis alone
                    os._exit(0)
                return out
            return phases.marked("  solver's step", analysed)
        return phases.marked("  solver's step", jitted)

    eqx.filter_jit = step_program
    if os.environ.get("ANALYSE"):
        analyse_alike_programs()
    rng = np.random.default_rng(3)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "pass"
        errors = [{"target.attitude_x_deg": float(a), "target.attitude_z_deg": float(b)} for a, b in rng.uniform(-0.3, 0.3, (n, 2))]
        sf.simulate_pass(base(size), sf.arc_pass(n), folder, errors=errors, sensor=SENSOR, spp=64)
        phases.show("simulated")
        fit_frames(folder, size, n, steps)
    phases.show("end")
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB; load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
