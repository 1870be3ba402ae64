"""Peak memory of a pass fit against its number of frames (issue 35): a pass of the panels scene is
simulated once, then each count of its first frames is fitted in a fresh process (the legs' albedo and
each frame's attitude about x free, 2 Levenberg-Marquardt steps, 4 spp) and the process's peak
resident set size (ru_maxrss) printed; the growth per frame is the least-squares slope, and per
pixel that slope over the frame's pixels. Figures in docs/measurements/reliability.md ("Memory per frame").

Usage: python experiments/pass_memory.py [SIZE_PX] [COUNTS...]   (default: 64 px, 2 4 8 16 frames)
"""

from __future__ import annotations

import datetime
import os
import platform
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from studyio import commit

import spacefit as sf

FIT_STEPS, FIT_SPP, SIMULATE_SPP = 2, 4, 16


def scene(size: int) -> sf.Scene:
    """The panels scene at ``size`` x ``size`` px over the same field of view (the 128 px one)."""
    return sf.load_scene("spacefit/synthetic/panels.toml", {"render.resolution": [size, size], "camera.pixel_pitch_mm": 75.0 * 32 / size})


def fit_peak(folder: Path, size: int, n: int) -> None:
    """Fit the first ``n`` frames of the pass in ``folder``; print this process's peak RSS (bytes)."""
    base = scene(size)
    frames = sf.Pass.read(folder / "frames.csv")
    obs = [sf.Observation.from_file(f.file, s) for f, s in list(zip(frames.frames, frames.scenes(base)))[:n]]
    free = ["parts.legs.kd", *[f"target.attitude_x_deg@{k}" for k in range(n)]]
    sf.fit(obs, free, start={"parts.legs.kd": 0.4}, render=sf.FitRender(spp=FIT_SPP), max_steps=FIT_STEPS)
    print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)  # kB on Linux


def main() -> None:
    size = int(sys.argv[1]) if len(sys.argv) > 1 else 64
    counts = [int(a) for a in sys.argv[2:]] or [2, 4, 8, 16]
    print(f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, commit {commit()}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}; {size} x {size} px, {FIT_SPP} spp, {FIT_STEPS} steps", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "pass"
        errors = [{"target.attitude_x_deg": 0.1 * (-1) ** k} for k in range(max(counts))]
        sf.simulate_pass(scene(size), sf.arc_pass(max(counts)), folder, errors=errors, spp=SIMULATE_SPP)
        peaks = []
        for n in counts:
            out = subprocess.run([sys.executable, __file__, "--one", str(folder), str(size), str(n)], capture_output=True, text=True, check=True)
            peaks.append(int(out.stdout.split()[-1]))
            print(f"{n:4d} frames: peak RSS {peaks[-1] / 2**20:8.1f} MiB", flush=True)
    slope, intercept = np.polyfit(counts, peaks, 1)
    print(f"growth per frame: {slope / 2**20:.2f} MiB ({slope / size**2:.0f} B per pixel); at 0 frames {intercept / 2**20:.0f} MiB; "
          f"per 128 x 128 px frame at that rate per pixel: {slope / size**2 * 128**2 / 1e6:.1f} MB")


if __name__ == "__main__":
    if sys.argv[1:2] == ["--one"]:
        fit_peak(Path(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]))
    else:
        main()
