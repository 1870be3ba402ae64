"""Where an adaptive render's second pass spends its samples: slots per pixel from the first pass's spread.

A render's error is the mean over pixels of sigma_i^2 / n_i (sigma_i a pixel's per-sample spread, n_i
its samples), which for a fixed total is smallest with n_i in proportion to sigma_i (Neyman
allocation; :mod:`spacefit.studies.costs` bounds what it can buy). The second pass hands out slots of
equal size (each one stratified set of the sampler's) so that it is one wavefront: every pixel at
least one slot, so that each pixel's estimate and its neighbours' filter weights exist, the rest in
proportion to the first pass's spread, averaged over the pixels a sample can reach through the
filter (the few samples of one pixel miss a glint that its neighbours catch). The counts are any
function of the first pass: the second pass's samples are new, so its image is unbiased whatever they
are (:meth:`spacefit.rendering.renderer.Renderer.radiance`). NumPy only.
"""

from __future__ import annotations

import numpy as np


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


def allocate_slots(sigma: np.ndarray, slots: int) -> np.ndarray:
    """Slots per pixel (int, the shape of ``sigma``), ``slots`` in all, at least one each (``slots`` must be at
    least ``sigma.size``): ``max(1, lam sigma)`` with ``lam`` set so that they add up (water-filling), rounded to
    integers by the largest remainders. Uniform where no pixel has a spread."""
    flat = np.asarray(sigma, dtype=float).ravel()
    n = flat.size
    if slots < n:
        raise ValueError(f"{slots} slots cannot give each of {n} pixels one")
    if not np.any(flat > 0):
        share = np.full(n, slots / n)
    else:
        floored = np.zeros(n, dtype=bool)
        while True:  # pixels whose share falls below one slot get one; the rest share what is left in proportion
            lam = (slots - floored.sum()) / flat[~floored].sum()
            below = ~floored & (lam * flat < 1.0)
            if not below.any():
                break
            floored |= below
        share = np.where(floored, 1.0, lam * flat)
    counts = np.floor(share).astype(np.int64)
    rest = slots - counts.sum()
    counts[np.argsort(counts - share, kind="stable")[:rest]] += 1
    return counts.reshape(np.shape(sigma))
