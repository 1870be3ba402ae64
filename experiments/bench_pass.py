"""Issue 33's pass figures: a pass of the panels case (frames along :func:`spacefit.arc_pass`, DN through a
sensor, each frame's target turned off its table's attitude) fitted in one process: the three materials and
the PSF width shared, each frame's attitude about x and z, shift and scale its own (12 frames: 3 + 1 + 12 x 5
= 64 parameters), LM at 16 spp, 12 steps at most. Each count of frames is fitted in a fresh child process whose
wall time, CPU time and peak memory (``ru_maxrss``) are printed; with two counts or more, the memory's growth
per frame (least-squares slope). Targets (quiet, 2 cores): 12 frames at 128 x 128 in at most 60 s wall and
1 GB peak, growing at most 20 MB per added 128 x 128 frame (measured at 12, 48 and 100 frames: ``--full``).
``--max-steps`` and ``--spp`` shorten a long run (the peak is in the standard errors after the last step).
Run: ``.venv/bin/python experiments/bench_pass.py [--size PX] [--frames N ...] [--full] [--max-steps N] [--spp N]``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from studyio import commit, machine

import spacefit as sf

MATERIALS = {"parts.panels.alpha_x": 0.15, "parts.panels.alpha_y": 0.03, "parts.legs.kd": 0.5}
START = {"parts.panels.alpha_x": 0.12, "parts.panels.alpha_y": 0.036, "parts.legs.kd": 0.42}
PER_FRAME = ["target.attitude_x_deg", "target.attitude_z_deg", "image.shift_x_px", "image.shift_y_px", "image.scale"]
SENSOR = sf.Sensor(radiometric_scale_dn_per_w_m2_sr=500.0, gain_dn_per_electron=0.5, bias_dn=100.0, read_noise_electrons=5.0,
                   bit_depth=16, full_well_electrons=None, diffraction=False, psf_sigma_px=0.0)
FIT_SPP, SIMULATE_SPP, MAX_STEPS = 16, 256, 12


def base(size: int) -> sf.Scene:
    """The panels case at ``size`` x ``size`` px over the 128 px one's field of view."""
    return sf.load_case("panels").truth_scene.with_values({"render.resolution": [size, size], "camera.pixel_pitch_mm": 37.5 * 128 / size})


def fit_frames(folder: Path, size: int, n: int, max_steps: int = MAX_STEPS, spp: int = FIT_SPP) -> None:
    """Fit the first ``n`` frames of the pass in ``folder`` (at most ``max_steps`` steps at ``spp``); print the step count and
    the free parameters' count."""
    frames = sf.Pass.read(folder / "frames.csv")
    obs = [sf.Observation.from_file(f.file, s) for f, s in list(zip(frames.frames, frames.scenes(base(size))))[:n]]
    free = [*MATERIALS, "image.blur_sigma_px", *[f"{name}@{k}" for k in range(n) for name in PER_FRAME]]
    result = sf.fit(obs, free, start=START, render=sf.FitRender(spp=spp), max_steps=max_steps)
    errors = ", ".join(f"{k.split('.')[-1]} {result.values[k] / v - 1:+.1%}" for k, v in MATERIALS.items())
    print(f"{len(free)} parameters, {result.steps} steps [{result.status.name}]; materials {errors}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=64, help="frame width and height, px (the target's: 128, --full)")
    p.add_argument("--frames", type=int, nargs="+", default=[12], help="counts of frames fitted, each in its own process")
    p.add_argument("--full", action="store_true", help="the targets' run: 128 x 128 px, 12, 48 and 100 frames")
    p.add_argument("--max-steps", type=int, default=MAX_STEPS, help="the fit's steps at most")
    p.add_argument("--spp", type=int, default=FIT_SPP, help="the fit's samples per pixel")
    args = p.parse_args()
    size, counts = (128, [12, 48, 100]) if args.full else (args.size, args.frames)
    print(f"machine: {machine()}; commit {commit()}; {size} x {size} px, {args.spp} spp, LM, at most {args.max_steps} steps; "
          f"load {os.getloadavg()[0]:.1f}", flush=True)
    rng = np.random.default_rng(3)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "pass"
        errors = [{"target.attitude_x_deg": float(a), "target.attitude_z_deg": float(b)} for a, b in rng.uniform(-0.3, 0.3, (max(counts), 2))]
        sf.simulate_pass(base(size), sf.arc_pass(max(counts)), folder, errors=errors, sensor=SENSOR, spp=SIMULATE_SPP)
        peaks = []
        for n in counts:
            t0 = time.perf_counter()
            proc = subprocess.Popen([sys.executable, __file__, "--one", str(folder), str(size), str(n), str(args.max_steps), str(args.spp)],
                                    stdout=subprocess.PIPE,
                                    stderr=subprocess.STDOUT, text=True)
            out = proc.stdout.read()
            _, status, usage = os.wait4(proc.pid, 0)
            wall = time.perf_counter() - t0
            if os.waitstatus_to_exitcode(status):
                raise RuntimeError(f"the fit of {n} frames failed:\n{out[-2000:]}")
            peaks.append(usage.ru_maxrss / 1024)
            print(f"{n:4d} frames: {wall:.1f} s wall (target 60 s for 12 at 128 px), {usage.ru_utime + usage.ru_stime:.1f} s CPU, "
                  f"peak {peaks[-1]:.0f} MiB (target 1 GB); {out.strip().splitlines()[-1]}; load {os.getloadavg()[0]:.1f}", flush=True)
    if len(counts) > 1:
        slope = np.polyfit(counts, peaks, 1)[0]
        print(f"memory per added {size} x {size} frame: {slope:.1f} MiB (target: 20 MB per 128 x 128 frame, measured with --full)")


if __name__ == "__main__":
    if sys.argv[1:2] == ["--one"]:
        fit_frames(Path(sys.argv[2]), *(int(a) for a in sys.argv[3:]))
    else:
        main()
