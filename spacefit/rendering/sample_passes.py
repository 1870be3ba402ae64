"""A render's samples in passes: each pass's seed, sample count and pixel range, small enough for
memory (:data:`~spacefit.rendering.memory.MAX_SAMPLES_PER_PASS`), and the threads that add them into the film.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from spacefit.rendering.backend import dr
from spacefit.rendering.memory import MAX_SAMPLES_PER_PASS
from spacefit.scene.sampling import split_sample_count


def pass_seed(seed: int, i: int) -> int:
    """The seed of pass ``i`` of a render seeded ``seed`` (pass 0 keeps it)."""
    return (seed + i * 0x9E3779B1) % (1 << 32)


def pass_seeds(seed: int, spp: int, pixels: int, sampler: str = "independent") -> list[tuple[int, int, int, int]]:
    """Split a render of ``pixels`` pixels at ``spp`` into passes: the counts the sampler takes
    (:func:`~spacefit.scene.sampling.split_sample_count`), each over pixel ranges of at most
    :data:`MAX_SAMPLES_PER_PASS` samples (one pixel at least), a pixel's samples of one count in one
    pass so that a stratifying sampler keeps its pattern: (seed, spp, first pixel, pixels) each. No pixel: no pass (a
    target whose silhouette no pixel's samples reach, though its bounds pass the view's check, renders black)."""
    if pixels == 0:
        return []
    passes = []
    for count in split_sample_count(sampler, spp):
        n = max(1, math.ceil(pixels / max(1, MAX_SAMPLES_PER_PASS // count)))
        sizes = [pixels // n + (i < pixels % n) for i in range(n)]
        passes += [(count, int(start), size) for start, size in zip(np.cumsum([0, *sizes[:-1]]), sizes)]
    return [(pass_seed(seed, i), count, start, size) for i, (count, start, size) in enumerate(passes)]


@contextmanager
def render_threads(deterministic: bool) -> Iterator[None]:
    """Render on one thread when ``deterministic``: the film then adds samples in a fixed order.

    Parallel renders differ by float32 rounding (about 1e-7 relative) from call to call, which
    also breaks common random numbers for finite differences of small effects.
    """
    threads = dr.thread_count()
    resize = deterministic and threads > 1
    if resize:
        # Kernels run asynchronously on the LLVM backend: resizing the thread pool under a running one
        # crashed (SIGSEGV in set_thread_count) on a loaded machine, and one queued would run on the new size.
        dr.sync_thread()
        dr.set_thread_count(1)
    try:
        yield
    finally:
        if resize:
            dr.sync_thread()
            dr.set_thread_count(threads)
