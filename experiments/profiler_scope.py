"""Forward-mode Jacobian columns rendered while dask's worker profiler samples the rendering thread:
how many fail with Dr.Jit's "... outside of the current dr.isolate_grad() scope" (docs/how-to/dask.md).

A dask worker's profiler (``Worker.trigger_profile``, every 10 ms) takes ``sys._current_frames()``
and walks the task thread's stack with ``distributed.profile.process``; a frame it still holds when
the thread returns from it keeps that call's locals, Dr.Jit AD variables among them, alive. Here the
main thread does the same to a thread that renders the three material columns of the panels case
with its pose free (as in a pass: the vertex positions are scene values), and keeps the frames
``--hold-ms`` longer (as when the profiling thread is switched out while it holds them). Prints the
renders that failed with that error, failed otherwise, and gave a column other than the one
rendered undisturbed.

    python experiments/profiler_scope.py --renders 600
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time

import jax
import numpy as np
from distributed import profile

import spacefit as sf
from spacefit.precision import float64
from spacefit.rendering.derivatives import render_chain
from spacefit.scene.parameters import scene_value

# Dr.Jit's message (the bridge's OUTSIDE_SCOPE, spelled out so that the script runs on checkouts before it)
OUTSIDE_SCOPE = "outside of the current dr.isolate_grad() scope"
NAMES = ["parts.panels.alpha_x", "parts.panels.alpha_y", "parts.legs.kd", "target.attitude_x_deg"]  # the last by differences


@float64
def columns(size: int, spp: int) -> tuple[object, dict[str, np.ndarray], list[dict[str, np.ndarray]]]:
    """The Dr.Jit scene, its values and the tangents of the three forward-mode columns."""
    scene = sf.load_case("panels").scene().with_values({"render.resolution": [size, size], "camera.pixel_pitch_mm": 18.75 * 128 / size})
    chain = render_chain(scene, NAMES, spp=spp, spp_grad=spp)
    x = np.array([scene_value(scene, n) for n in NAMES])
    values = {k: np.asarray(v, np.float32).ravel() for k, v in chain.values_of(x).items()}
    jac = {k: np.asarray(v, np.float32).reshape(-1, len(NAMES)) for k, v in jax.jacfwd(chain.values_of)(x).items()}
    return chain.drjit, values, [{k: t[:, j] for k, t in jac.items()} for j in range(3)]


def cause_text(err: BaseException | None) -> str:
    text = ""
    while err is not None:
        text, err = text + str(err), err.__cause__ or err.__context__
    return text


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--renders", type=int, default=600)
    p.add_argument("--interval-ms", type=float, default=10.0, help="between samples (dask's default)")
    p.add_argument("--hold-ms", type=float, default=5.0, help="the sampled frames kept after processing (Python's thread switch interval)")
    p.add_argument("--size", type=int, default=32)
    p.add_argument("--spp", type=int, default=16)
    args = p.parse_args()
    scene, values, tangents = columns(args.size, args.spp)
    reference = [scene.forward(values, t, 5) for t in tangents]
    counts = {"renders": args.renders, "scope_error": 0, "other_error": 0, "differs": 0}
    done = threading.Event()

    def work() -> None:
        for i in range(args.renders):
            try:
                counts["differs"] += not np.array_equal(scene.forward(values, tangents[i % 3], 5), reference[i % 3])
            except RuntimeError as err:
                counts["scope_error" if OUTSIDE_SCOPE in cause_text(err) else "other_error"] += 1
        done.set()

    thread = threading.Thread(target=work)
    state, samples, t0 = profile.create(), 0, time.perf_counter()
    thread.start()
    while not done.is_set():
        frame = sys._current_frames().get(thread.ident)
        if frame is not None:
            profile.process(frame, True, state)
            samples += 1
            time.sleep(args.hold_ms / 1e3)
        del frame
        time.sleep(args.interval_ms / 1e3)
    thread.join()
    print(f"{counts} samples {samples} in {time.perf_counter() - t0:.0f} s; load average {os.getloadavg()} at "
          f"{time.strftime('%Y-%m-%d %H:%M', time.gmtime())} UTC")


if __name__ == "__main__":
    main()
