"""Render cost against accuracy: the configurations worth their time, and what spending samples
where radiance varies could buy.

:func:`pareto_front` picks the non-dominated (time, error) configurations of the forward-cost
study (``experiments/forward_pareto.py``). :func:`allocation_gains` is the bound on adaptive
sampling of ``experiments/sample_allocation.py``: the error of a render is the mean over lit pixels
of sigma_i^2 / n_i at n_i samples, which for a fixed total is smallest with n_i proportional to
sigma_i (Neyman allocation), (mean sigma)^2 / n against mean(sigma^2) / n for uniform sampling; a
practical two-pass sampler spends :data:`PILOT_FRACTION` uniformly, then the rest in proportion to
the spread its first pass measured.
"""

from __future__ import annotations

import numpy as np

# Share of the samples a two-pass sampler spends on its uniform first pass.
PILOT_FRACTION = 0.25


def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the non-dominated (time, error) points, sorted by time (errors then strictly fall).

    A point is dominated when another is no slower and no less accurate; of identical points the
    first is kept.
    """
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1], i))
    front: list[int] = []
    for i in order:
        if not front or points[i][1] < points[front[-1]][1]:
            front.append(i)
    return front


def allocation_gains(sigma: np.ndarray, pilot_sigma: np.ndarray) -> dict[str, float]:
    """Samples needed at equal error relative to uniform sampling: ideal (n_i proportional to the
    true ``sigma``) and two-pass (a uniform :data:`PILOT_FRACTION`, then the rest in proportion to
    ``pilot_sigma``, one noisy estimate), for the pixels given (lit ones)."""
    uniform = np.mean(sigma**2)
    ideal = np.mean(sigma) ** 2 / uniform
    share = pilot_sigma / pilot_sigma.sum() if pilot_sigma.sum() > 0 else np.full(sigma.shape, 1.0 / sigma.size)
    n = PILOT_FRACTION + (1.0 - PILOT_FRACTION) * share * sigma.size  # samples per pixel, mean 1
    return {"ideal": float(ideal), "two_pass": float(np.mean(sigma**2 / n) / uniform)}
