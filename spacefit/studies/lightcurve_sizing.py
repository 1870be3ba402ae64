"""A light curve's samples per pixel sized point by point to a requested precision.

Points of one light curve differ in noise by a factor of 20 or more (the default lander: a per-seed
relative error of 0.3 % at 5 deg of phase, 6.8 % at 120 deg, at 16 spp): one sample count for every
point, set by the worst, spends most of a call on points that were precise long before. Here a pilot
sweep of :data:`PILOT_SEEDS` seeds at :data:`PILOT_SPP` samples per pixel measures each point's own
error, and each point is then rendered at the sample count that error asks for.

The rule: the relative standard error of a mean of ``n`` seeds at ``f`` spp is ``r sqrt(p / f) / sqrt(n)``
where ``r`` is a seed's relative standard deviation at the pilot's ``p`` spp, by the 1 / sqrt(samples) law
of independent samples. A stratified sampler (``multijitter``, the default) converges faster than that
(on the default lander the worst point's error at 466 spp was a third of the law's figure from 16 spp), so
above the pilot's count the law over-sizes, never under-sizes; below it, it would under-size, and no
point is rendered at fewer than the pilot's spp. ``r`` itself is measured from :data:`PILOT_SEEDS`
seeds: its variance is sized up by the one-sided :data:`CONFIDENCE` upper bound of a variance measured
with that many seeds (chi-squared, ``PILOT_SEEDS - 1`` degrees of freedom), so that a pilot that happened
to read low still sizes its point enough.

The pilot's seeds are others than the light curve's (:func:`pilot_seeds`): the final renders are
independent of the pilot that sized them, and the standard errors they report are measured from their
own seeds alone.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from spacefit.errors import InputError
from spacefit.scene.sampling import takes_sample_count
from spacefit.scene.sections import MAX_SPP

# The pilot: seeds and samples per pixel of each point's error measurement (module docstring).
PILOT_SEEDS = 8
PILOT_SPP = 16
# One-sided confidence that a point's sized error is within the precision asked, as far as the pilot's
# own scatter goes (the 1 / sqrt(samples) law adds its margin on top).
CONFIDENCE = 0.9
# Seeds of each point's final renders when a precision is asked without `seeds`.
DEFAULT_SEEDS = (0, 1, 2, 3)


def pilot_seeds(seeds: Sequence[int], count: int = PILOT_SEEDS) -> list[int]:
    """The ``count`` smallest seeds (>= 0) not among ``seeds``: the pilot's, independent of the final renders'."""
    taken = set(int(s) for s in seeds)
    found: list[int] = []
    candidate = 0
    while len(found) < count:
        if candidate not in taken:
            found.append(candidate)
        candidate += 1
    return found


def variance_margin(seeds: int, confidence: float = CONFIDENCE) -> float:
    """The factor by which a variance measured from ``seeds`` seeds is multiplied to bound the true one from
    above with one-sided ``confidence``: (seeds - 1) / chi2 quantile(1 - confidence, seeds - 1)."""
    from scipy.stats import chi2  # here: SciPy's statistics take 0.4 s to import, which a light curve without a precision never needs

    return float((seeds - 1) / chi2.ppf(1.0 - confidence, seeds - 1))


def sample_counts(pilot: np.ndarray, precision: float, seeds: int, sampler: str, labels: Sequence[str],
                  pilot_spp: int = PILOT_SPP) -> list[int]:
    """The samples per pixel of each point so that the mean of ``seeds`` seeds has a relative standard error
    of at most ``precision`` (module docstring), from ``pilot``: (pilot seeds, points) irradiance at
    ``pilot_spp``. A count ``sampler`` does not take is raised to the next it does; a dark point (no light
    in any pilot seed) keeps the pilot's count. ``labels`` name the points in errors.

    Raises:
        InputError: a point would need more than ``MAX_SPP`` samples per pixel.
    """
    pilot = np.asarray(pilot, dtype=float)
    mean = pilot.mean(axis=0)
    spread = pilot.std(axis=0, ddof=1)
    margin = variance_margin(pilot.shape[0])
    counts = []
    for label, m, s in zip(labels, mean, spread):
        relative = s / m if m > 0 else 0.0
        need = max(pilot_spp, math.ceil(margin * pilot_spp * relative**2 / (seeds * precision**2)))
        while not takes_sample_count(sampler, need) and need <= MAX_SPP:
            need += 1
        if need > MAX_SPP:
            raise InputError(f"the point {label} needs more than {MAX_SPP} spp for `precision` = {precision:g} with "
                             f"{seeds} seeds (its pilot's relative error: {relative:.1%} a seed at {pilot_spp} spp): "
                             "ask for a coarser precision or more seeds.")
        counts.append(need)
    return counts
