"""Memory of a process that fits again and again (issue 35): ``fits`` fits of one small observation
in one process, the resident set size (RSS, MiB) after each, and the growth per fit after the first
``warm`` (the first ones fill Dr.Jit's, LLVM's and the allocator's pools).

The case: the panels scene at 32 x 32 px, its legs' albedo fitted from 0.42 to a reference rendered at
0.5 (3 Levenberg-Marquardt steps, 4 spp). Figures in docs/measurements/reliability.md ("Memory per fit").

Usage: python experiments/fit_memory.py [FITS] [WARM]; ``make soak`` runs it with 50 and 5.
"""

from __future__ import annotations

import gc
import sys
import tempfile
import time
from pathlib import Path

import psutil

import spacefit as sf

fits, warm = (int(sys.argv[1]) if len(sys.argv) > 1 else 50), (int(sys.argv[2]) if len(sys.argv) > 2 else 5)
scene = sf.load_case("panels").scene().with_values({"render.resolution": [32, 32], "render.spp": 4})
with tempfile.TemporaryDirectory() as folder:
    reference = Path(folder) / "ref.exr"
    sf.write_exr(reference, sf.render(scene.with_values({"parts.legs.kd": 0.5, "render.spp": 16, "render.seed": 7})))
    observation = sf.Observation.from_file(reference, scene)
    process, rss, start = psutil.Process(), [], time.perf_counter()
    for k in range(fits):
        result = sf.fit(observation, ["parts.legs.kd"], start={"parts.legs.kd": 0.42}, max_steps=3)
        del result
        gc.collect()
        rss.append(process.memory_info().rss / 2**20)
        print(f"fit {k + 1:3d}: RSS {rss[-1]:7.1f} MiB  ({time.perf_counter() - start:6.1f} s)", flush=True)
growth = (rss[-1] - rss[warm - 1]) / (fits - warm)
print(f"growth per fit after the first {warm}: {growth:.2f} MiB ({rss[warm - 1]:.1f} -> {rss[-1]:.1f} MiB over "
      f"{fits - warm} fits); first fit {rss[0]:.1f} MiB")
