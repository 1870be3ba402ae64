"""Where an adaptive render's second pass spends its samples: counts per pixel from the first pass's spread.

A render's error is the mean over pixels of sigma_i^2 / n_i (sigma_i a pixel's per-sample spread, n_i
its samples), which for a fixed total is smallest with n_i in proportion to sigma_i (Neyman
allocation; :mod:`spacefit.studies.costs` bounds what it can buy). The second pass gives every pixel at
least one sample, so that each pixel's estimate and its neighbours' filter weights exist, the rest in
proportion to the first pass's spread, averaged over the pixels a sample can reach through the filter
(the few samples of one pixel miss a glint that its neighbours catch); each pixel's count is then
rounded at random to a ladder of counts the sampler takes (:func:`to_ladder`), so that its samples are
one stratified set and the pass is a few wavefronts, one per count. The counts are any function of the
first pass (and of the seed): the second pass's samples are new, so its image is unbiased whatever they
are (:meth:`spacefit.rendering.renderer.Renderer.radiance`). NumPy only.
"""

from __future__ import annotations

import numpy as np

from spacefit.scene.schema import takes_sample_count


def neighbourhood_mean(values: np.ndarray, reach: int) -> np.ndarray:
    """The mean of ``values`` (h, w) over the square of side 2 ``reach`` + 1 around each pixel, zero beyond the edge."""
    if reach == 0:
        return values
    h, w = values.shape
    padded = np.pad(values, reach)
    side = 2 * reach + 1
    total = np.zeros((h, w))
    for dy in range(side):
        for dx in range(side):
            total += padded[dy:dy + h, dx:dx + w]
    return total / side**2


def allocate(sigma: np.ndarray, total: int) -> np.ndarray:
    """Samples per pixel (int, the shape of ``sigma``), ``total`` in all, at least one each (``total`` must be at
    least ``sigma.size``): ``max(1, lam sigma)`` with ``lam`` set so that they add up (water-filling), rounded to
    integers by the largest remainders. Uniform where no pixel has a spread."""
    flat = np.asarray(sigma, dtype=float).ravel()
    n = flat.size
    if total < n:
        raise ValueError(f"{total} samples cannot give each of {n} pixels one")
    if not np.any(flat > 0):
        share = np.full(n, total / n)
    else:
        floored = np.zeros(n, dtype=bool)
        while True:  # pixels whose share falls below one sample get one; the rest share what is left in proportion
            lam = (total - floored.sum()) / flat[~floored].sum()
            below = ~floored & (lam * flat < 1.0)
            if not below.any():
                break
            floored |= below
        share = np.where(floored, 1.0, lam * flat)
    counts = np.floor(share).astype(np.int64)
    rest = total - counts.sum()
    counts[np.argsort(counts - share, kind="stable")[:rest]] += 1
    return counts.reshape(np.shape(sigma))


def ladder(sampler: str, top: int) -> np.ndarray:
    """The counts a second pass rounds to: for each power of 2, the largest count up to it that ``sampler`` takes
    (:func:`~spacefit.scene.schema.takes_sample_count`), up to the first at or above ``top``."""
    rungs: list[int] = []
    k = 0
    while not rungs or rungs[-1] < top:
        rung = next(n for n in range(2**k, 0, -1) if takes_sample_count(sampler, n))
        if not rungs or rung > rungs[-1]:
            rungs.append(rung)
        k += 1
    return np.array(rungs)


def to_ladder(counts: np.ndarray, sampler: str, rng: np.random.Generator) -> np.ndarray:
    """``counts`` (int >= 1) each rounded to one of the two rungs of :func:`ladder` around it, the upper with the
    probability that keeps its expectation: the total stays the same on average."""
    rungs = ladder(sampler, int(counts.max(initial=1)))
    if len(rungs) == 1:
        return np.full(counts.shape, rungs[0])
    j = np.clip(np.searchsorted(rungs, counts, side="right") - 1, 0, len(rungs) - 2)
    low, high = rungs[j], rungs[j + 1]
    up = rng.random(counts.shape) < (counts - low) / (high - low)
    return np.where(up, high, low)
