"""The whole ``spacefit fit`` process of issue 33's 8-parameter observation fit (target: at most 5 s wall and
10 s of CPU on a quiet 2-core machine): the observation of ``bench_fit.py --observed`` (the panels case at
128 x 128, 32 spp; materials, PSF width, shift and two attitude angles free) written as a 16-bit FITS file
with its sensor, then fitted by ``python -m spacefit.cli fit`` in a child process whose wall time, CPU time
(user + system, ``os.wait4``) and peak memory are printed. Runs: JAX's compilation cache empty (a fresh
``SPACEFIT_JAX_CACHE_DIR``), then warm (the same folder: its programs read back), then with it off.
Run: ``.venv/bin/python experiments/bench_fit_process.py [--repeats N]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_fit import observed
from studyio import machine

import spacefit as sf
from spacefit.fitting.compile_cache import ENV as JAX_CACHE_ENV
from spacefit.fitting.observation_files import ObservationFiles

ROOT = Path(__file__).resolve().parent.parent


def write_inputs(folder: Path) -> list[str]:
    """The observation as ``obs.fits`` and its scene as ``scene.toml`` in ``folder``; the fit's arguments after ``fit``."""
    case, obs, truths, start = observed()
    sf.write_observation(folder / "obs.fits", np.rint(obs.reference).astype(np.uint16), obs.sensor)
    (folder / "scene.toml").write_text(case.scene().to_toml())
    return [str(folder / "obs.fits"), "--scene", str(folder / "scene.toml"), "--free", ",".join(truths),
            *[a for n, v in start.items() for a in ("--start", f"{n}={v!r}")], "--quiet", "--overwrite"]


def loaded_inputs(folder: Path) -> tuple[list, list[str], dict[str, float]]:
    """The fit's inputs written in ``folder`` (:func:`write_inputs`) and read back as ``spacefit fit`` reads them: the
    observations, the free parameters and the start values, for a benchmark of its programs in one process."""
    args = write_inputs(folder)
    free = args[args.index("--free") + 1].split(",")
    start = {a.split("=")[0]: float(a.split("=")[1]) for before, a in zip(args, args[1:]) if before == "--start"}
    return ObservationFiles([args[0]], [args[2]]).load(), free, start


def run_fit(args: list[str], out: Path, cache: str) -> tuple[float, float, float, int]:
    """One ``spacefit fit`` process: wall s, CPU s (user + system), peak MiB and exit code."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), JAX_CACHE_ENV: cache}
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "spacefit.cli", "fit", *args, "--out", str(out)], cwd=ROOT, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    code = os.waitstatus_to_exitcode(status)
    if code not in (0, 3, 4, 5, 6, 9):  # a fit's verdicts; anything else is a failure of the run
        raise RuntimeError(f"spacefit fit failed ({code}):\n{err[-2000:]}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024, code


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=3, help="warm runs (their median is the figure)")
    args = p.parse_args()
    print(f"machine: {machine()}; load {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as tmp:
        folder, cache = Path(tmp), str(Path(tmp) / "jax")
        fit_args = write_inputs(folder)
        rows = {"JAX cache empty": [run_fit(fit_args, folder / "out", cache)]}
        rows["JAX cache warm"] = [run_fit(fit_args, folder / "out", cache) for _ in range(args.repeats)]
        rows["JAX cache off"] = [run_fit(fit_args, folder / "out", "off")]
        entries = len(list(Path(cache).iterdir()))
    for name, runs in rows.items():
        wall, cpu = statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs)
        print(f"spacefit fit, 8 free, 128 x 128, 32 spp ({name}, median of {len(runs)}): {wall:.1f} s wall (target 5 s), "
              f"{cpu:.1f} s CPU (target 10 s), peak {max(r[2] for r in runs):.0f} MiB, exit {runs[-1][3]}")
    print(f"JAX cache entries written: {entries}; load {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
