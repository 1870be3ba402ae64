"""How closely a pass fitted on a local dask cluster repeats the in-process fit (issue 34 item 5).

For each frame count, the tests' reduced pass (tests/test_pass.py ``small_pass``: frames at 24 x 24 px,
64 spp, each turned off its table's attitude; the legs' albedo and each frame's attitude free, 8 spp)
is fitted in this process and on a new local cluster of 2 single-threaded worker processes; it
prints, per step, the loss of each and their relative difference (and their loss noises',
:func:`~spacefit.fitting.stopping.loss_noise`), then the largest relative
difference of the values and the standard errors (0: the same bit for bit).

With ``--dn`` the frames are DN through a sensor (tests/test_pass.py's ``PASS_SENSOR``) and each
frame frees its attitude about x, y and z and its image scale (5 parameters a frame, as the hidden
observations' passes were fitted).

Usage: python experiments/dask_bits.py [--dn] [FRAMES ...]   (default: 3 5)
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import spacefit as sf
from spacefit.executors import connect


def relative(a: float, b: float) -> float:
    """|a - b| relative to |a| (0 where both are 0)."""
    return 0.0 if a == b else abs(a - b) / max(abs(a), abs(b))


# A sensor of tests/test_pass.py's DN passes.
SENSOR = sf.Sensor(radiometric_scale_dn_per_w_m2_sr=500.0, gain_dn_per_electron=0.5, bias_dn=100.0, read_noise_electrons=5.0,
                   bit_depth=16, full_well_electrons=None, diffraction=False, psf_sigma_px=0.0)
PER_FRAME = {False: ["target.attitude_x_deg"], True: ["target.attitude_x_deg", "target.attitude_y_deg", "target.attitude_z_deg", "image.scale"]}


def compare(frames: int, folder: Path, dn: bool = False) -> None:
    base = sf.load_scene("spacefit/synthetic/panels.toml", {"render.resolution": [24, 24], "camera.pixel_pitch_mm": 100.0})
    offsets = [0.2 * np.cos(2.1 * k) for k in range(frames)]
    table = sf.simulate_pass(base, sf.arc_pass(frames), folder / f"frames{frames}{'dn' * dn}", spp=64,
                             errors=[{"target.attitude_x_deg": e} for e in offsets], sensor=SENSOR if dn else None)
    obs = [sf.Observation.from_file(f.file, s) for f, s in zip(table.frames, table.scenes(base))]
    free = ["parts.legs.kd", *table.per_frame(PER_FRAME[dn])]
    options = {"start": {"parts.legs.kd": 0.4}, "render": sf.FitRender(spp=8), "max_steps": 6}
    t0 = time.perf_counter()
    here = sf.fit(obs, free, **options)
    t1 = time.perf_counter()
    client, close = connect(2)
    try:
        there = sf.fit(obs, free, cluster=client, **options)
    finally:
        close()
    t2 = time.perf_counter()
    print(f"{frames} {'DN ' * dn}frames, {len(free)} free: in process {t1 - t0:.1f} s, on 2 workers {t2 - t1:.1f} s; status {here.status.value} / {there.status.value}")
    for a, b in zip(here.history, there.history):
        print(f"  step {a['step']:2d}  loss {a['loss']!r:>22} {b['loss']!r:>22}  relative difference {relative(a['loss'], b['loss']):.2e}; "
              f"loss noise {relative(a['loss_noise'], b['loss_noise']):.2e}")
    if len(here.history) != len(there.history):
        print(f"  steps differ: {len(here.history)} against {len(there.history)}")
    values = max(relative(here.values[n], there.values[n]) for n in here.values)
    errors = max(relative(here.stderr[n], there.stderr[n]) for n in here.stderr)
    print(f"  largest relative difference: values {values:.2e}, standard errors {errors:.2e}"
          f"{' (the same bit for bit)' if values == errors == 0.0 else ''}")


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as tmp:
        dn = "--dn" in sys.argv[1:]
        for n in [int(a) for a in sys.argv[1:] if a != "--dn"] or [3, 5]:
            compare(n, Path(tmp), dn)
