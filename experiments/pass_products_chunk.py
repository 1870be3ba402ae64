"""The peak memory of one covariance product of :mod:`bench_pass`'s pass by how many directions it applies at once
(issue 33): the pass fitted one LM step at 4 spp, then at its result the information sym(J1^T J2) formed twice at each
``CHUNK_ELEMENTS`` (:mod:`spacefit.fitting.normal_equations`), the resident memory sampled every 10 ms, glibc's freed
pages handed back before each. Linux with glibc only. Figures: experiments/results/pass_memory/products_chunk_*.txt.
Run: ``python experiments/pass_products_chunk.py SIZE_PX FRAMES CHUNK_ELEMENTS[,CHUNK_ELEMENTS...]``.
"""

from __future__ import annotations

import ctypes
import os
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from bench_pass import SENSOR, base, fit_frames
from studyio import commit, machine

import spacefit as sf
import spacefit.fitting.uncertainty as uncertainty
from spacefit.fitting import normal_equations

LIBC = ctypes.CDLL(None)


def rss() -> float:
    """This process's resident set size now, MiB."""
    return int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


class Peak:
    """The resident memory's peak since :meth:`reset`, sampled every 10 ms."""

    def __init__(self) -> None:
        self.value = 0.0
        threading.Thread(target=self._sample, daemon=True).start()

    def _sample(self) -> None:
        while True:
            self.value = max(self.value, rss())
            time.sleep(0.01)

    def reset(self) -> float:
        LIBC.malloc_trim(0)
        self.value = rss()
        return self.value


def measured(counts: list[int]) -> Any:
    """A stand-in for :func:`~spacefit.fitting.uncertainty.linearise` that measures the products at ``counts`` and ends the process."""
    linearise, peak = uncertainty.linearise, Peak()

    def measure(problem: Any, x: np.ndarray) -> Any:
        lin = linearise(problem, x)
        for elements in counts:
            normal_equations.CHUNK_ELEMENTS = elements
            for _ in range(2):
                start, cpu = peak.reset(), time.process_time()
                information = lin.cross(lambda v: v)
                time.sleep(0.05)
                print(f"rows {lin.r.size}, CHUNK_ELEMENTS 2^{int(np.log2(elements))} (chunk {normal_equations.chunk_for(lin.r.size)}): "
                      f"start {start:.0f} MiB, peak {peak.value:.0f} MiB (+{peak.value - start:.0f}), {time.process_time() - cpu:.1f} s CPU; "
                      f"sum of J^T J {np.sum(information)!r}; load {os.getloadavg()[0]:.1f}", flush=True)
        os._exit(0)

    return measure


def main() -> None:
    size, n, counts = int(sys.argv[1]), int(sys.argv[2]), [int(c) for c in sys.argv[3].split(",")]
    print(f"machine: {machine()}; commit {commit()}; {size} x {size} px, {n} frames; load {os.getloadavg()[0]:.1f}", flush=True)
    uncertainty.linearise = measured(counts)
    rng = np.random.default_rng(3)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "pass"
        errors = [{"target.attitude_x_deg": float(a), "target.attitude_z_deg": float(b)} for a, b in rng.uniform(-0.3, 0.3, (n, 2))]
        sf.simulate_pass(base(size), sf.arc_pass(n), folder, errors=errors, sensor=SENSOR, spp=16)
        fit_frames(folder, size, n, 1, 4)


if __name__ == "__main__":
    main()
