"""The pixel grid's step (:func:`spacefit.fitting.pixel_grid.grid_step`) of issue 33's 8-parameter observation fit,
phase by phase: the fit of ``bench_fit_process.py``'s inputs run in this process (``spacefit.cli``'s own path), then its
step taken again ``--repeats`` times at the fit's result, each from a fresh :class:`~spacefit.fitting.pixel_grid.GridChanges`
(its two 4x renders, then its programs traced, lowered and read from JAX's cache or compiled afresh): the fit's own
step and each repeat's wall and CPU time, each call of its ``fine`` and ``settled`` evaluations, and JAX's trace,
lowering and compile time (``jax.monitoring``, wall). The fit's own figures are the fit process's; the repeats'
tracing is cheaper (JAX's own caches warm). ``--save``: the last step's outputs as
``.npz``, to compare two commits' to the round-off.
Run: ``.venv/bin/python experiments/bench_grid_step.py [--repeats N] [--save FILE.npz]``.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.monitoring
import numpy as np
from bench_fit_process import write_inputs
from studyio import commit, machine

import spacefit.fitting.conclusion as conclusion
import spacefit.fitting.uncertainty as uncertainty
from spacefit.cli import main as cli_main
from spacefit.fitting.pixel_grid import GridChanges

EVENTS = {"jaxpr_trace_duration": "trace", "jaxpr_to_mlir_module_duration": "lower", "backend_compile_duration": "compile"}


def timed(name: str, fn: Callable[..., Any], rows: list[tuple[str, float, float]]) -> Callable[..., Any]:
    """``fn``, each call's wall and CPU time appended to ``rows`` under ``name``."""
    def call(*args: Any, **kwargs: Any) -> Any:
        wall, cpu = time.perf_counter(), time.process_time()
        try:
            return fn(*args, **kwargs)
        finally:
            rows.append((name, time.perf_counter() - wall, time.process_time() - cpu))
    return call


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=3, help="steps taken again at the fit's result")
    p.add_argument("--save", type=Path, help="the last step's outputs (.npz)")
    args = p.parse_args()
    captured: dict[str, Any] = {}
    events: dict[str, float] = defaultdict(float)
    jax.monitoring.register_event_duration_secs_listener(
        lambda event, seconds, **kw: events.__setitem__(EVENTS[e], events[EVENTS[e]] + seconds) if (e := event.split("/")[-1]) in EVENTS else None)
    estimate, grid_step = conclusion.estimate, uncertainty.grid_step

    def capture_setup(s: Any, x: np.ndarray, correct: bool = True) -> Any:
        captured["problem"] = s.problem
        return estimate(s, x, correct)

    def capture_step(changes: GridChanges, step: Callable[[np.ndarray], np.ndarray], x: np.ndarray, stderr: np.ndarray,
                     columns: list[int]) -> Any:
        captured.update(step=step, x=x, stderr=stderr, columns=columns)
        return measured("in the fit", changes, captured)

    def measured(label: str, changes: GridChanges, at: dict[str, Any]) -> Any:
        """grid_step of ``changes`` at the fit's result, its calls' and JAX's times printed under ``label``."""
        rows: list[tuple[str, float, float]] = []
        events.clear()
        wall, cpu = time.perf_counter(), time.process_time()
        out = grid_step(GridChanges(timed("fine", changes.fine, rows), timed("settled", changes.settled, rows)), at["step"], at["x"],
                        at["stderr"], at["columns"])
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        calls = "  ".join(f"{name} {w:.3f}/{c:.3f}" for name, w, c in rows)
        print(f"{label}: step {wall:.3f} s wall, {cpu:.3f} s CPU; calls (wall/CPU s) {calls}; JAX (wall s) "
              + "  ".join(f"{k} {v:.3f}" for k, v in events.items()), flush=True)
        return out

    conclusion.estimate, uncertainty.grid_step = capture_setup, capture_step  # the names the fit calls them by
    print(f"{machine()}; commit {commit()}; load {os.getloadavg()[0]:.1f}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        try:
            cli_main(["fit", *write_inputs(Path(tmp)), "--out", str(Path(tmp) / "fit")])
        except SystemExit:
            pass
    with jax.enable_x64(True):  # the fit's estimate runs in 64-bit mode (spacefit.precision.float64)
        for repeat in range(args.repeats):
            wall = time.perf_counter()
            changes = captured["problem"].pixel_grid(captured["x"])
            print(f"repeat {repeat}: renders {time.perf_counter() - wall:.3f} s wall", flush=True)
            out = measured(f"repeat {repeat}", changes, captured)
    if args.save:
        np.savez(args.save, delta=out.delta, remainder=out.remainder, noise=out.noise, feedback=out.feedback, short=out.short,
                 evaluations=out.evaluations, stderr=captured["stderr"])


if __name__ == "__main__":
    main()
