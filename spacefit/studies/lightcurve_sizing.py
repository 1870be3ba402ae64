"""A light curve's points each rendered to a requested precision, with the samples it needs where it needs them.

A point's irradiance is the sum over pixels of solid angle times mean radiance (the box estimator of
:mod:`spacefit.rendering.flux`), and its Monte Carlo error lives in few pixels: on the default lander at
120 deg of phase, 29 of 4834 traced pixels (the glints of a few facets) held 90 % of it, at 20 deg 1415.
One sample count for every pixel, and for every point, set by the worst, spends most of the samples where
the estimate was precise long before. So each point is rendered in three steps:

1. a pilot of :data:`PILOT_SPP` samples in every traced pixel measures each pixel's standard deviation
   s; pixel p's share is its solid angle times s (Neyman 1934, J. R. Stat. Soc. 97, 558: a stratum's
   samples in proportion to its size times its standard deviation);
2. the allocation: 1 + round(N share / total share) groups of :data:`GROUP_SPP` samples in each pixel
   (N traced pixels): one group in every pixel whatever the pilot saw there (a glint it missed keeps
   samples), and as many again by share. :data:`REPLICATES` independent replicates of it measure a
   replicate's variance V and the irradiance E;
3. each of the light curve's seeds renders k copies of the allocation, k = ceil(m V / (seeds (precision
   E)^2)), m the one-sided :data:`CONFIDENCE` upper bound on a variance measured from REPLICATES
   replicates (chi-squared, REPLICATES - 1 degrees of freedom). Copies are independent: a seed's variance
   is V / k exactly, with no law of convergence assumed.

The point's irradiance is the mean of its seeds' estimates and its standard error their scatter over
sqrt(seeds), measured from them alone: the pilots use other seeds (:func:`pilot_seeds`), so the reported
error is independent of the steps that sized it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from spacefit.errors import InputError
from spacefit.geometry.frames import pixel_solid_angles
from spacefit.rendering.memory import MAX_SAMPLES_PER_PASS
from spacefit.scene.schema import Scene
from spacefit.studies.axes import units

if TYPE_CHECKING:  # types only: Mitsuba takes seconds to import
    from spacefit.rendering.renderer import Renderer

# Samples in every traced pixel of a point's pilot (step 1), in each group of the allocation (step 2), and
# the replicates that measure the allocation's variance (step 2).
PILOT_SPP = 32
GROUP_SPP = 4
REPLICATES = 16
# One-sided confidence of the bound on a replicate's variance. The chi-squared bound holds for normal
# replicates; a glint a pilot missed makes them heavy-tailed, their measured variance low more often than
# that: at 0.9 the default lander's 120 deg point reached 0.57 % for 0.5 % asked (four calls, 16 seeds).
CONFIDENCE = 0.99
# Seeds of each point when a precision is asked without `seeds`.
DEFAULT_SEEDS = (0, 1, 2, 3)


def pilot_seeds(seeds: Sequence[int], count: int = 2) -> list[int]:
    """The ``count`` smallest seeds (>= 0) not among ``seeds``: the pilots', independent of the final renders'."""
    taken = {int(s) for s in seeds}
    found: list[int] = []
    candidate = 0
    while len(found) < count:
        if candidate not in taken:
            found.append(candidate)
        candidate += 1
    return found


def variance_margin(replicates: int, confidence: float = CONFIDENCE) -> float:
    """The factor by which a variance measured from ``replicates`` independent values is multiplied to
    bound the true one from above with one-sided ``confidence``: (n - 1) / chi2 quantile(1 - confidence, n - 1),
    the quantile 2 P^-1(k / 2, q) of k degrees of freedom (P the regularised lower incomplete gamma function)."""
    from scipy.special import gammaincinv  # here: only a light curve at a precision needs SciPy; scipy.stats imports 0.3 s more than this

    return float((replicates - 1) / (2.0 * gammaincinv((replicates - 1) / 2.0, 1.0 - confidence)))


def allocation(omega: np.ndarray, spread: np.ndarray) -> np.ndarray:
    """Groups of samples per pixel (int, >= 1): 1 + round(N share / total share), a pixel's share its
    solid angle ``omega`` (sr) times its samples' standard deviation ``spread`` (step 2)."""
    share = np.asarray(omega, dtype=float) * np.asarray(spread, dtype=float)
    total = share.sum()
    extra = np.rint(len(share) * share / total) if total > 0 else np.zeros(len(share))
    return 1 + extra.astype(np.int64)


def replicate_irradiance(renderer: Renderer, pixels: np.ndarray, omega: np.ndarray, groups: np.ndarray, copies: int,
                         replicates: int, seed: int) -> np.ndarray:
    """(replicates,) independent box estimates of the irradiance (W m^-2) at the pinhole, each of ``copies``
    x ``groups`` groups of :data:`GROUP_SPP` samples in each of the traced ``pixels`` (window indices,
    solid angles ``omega``), traced in one call seeded ``seed``."""
    from spacefit.rendering.flux import pixel_radiance  # here: Mitsuba takes seconds to import; a light curve's planning never renders

    per = groups * copies
    owner = np.tile(np.repeat(np.arange(len(pixels)), per), replicates)
    weights = pixel_radiance(renderer, pixels[owner], seed, GROUP_SPP) * (omega / per)[owner]
    return np.bincount(np.repeat(np.arange(replicates), per.sum()), weights=weights, minlength=replicates)


def point_irradiance(renderer: Renderer, pixels: np.ndarray, omega: np.ndarray, precision: float, seeds: Sequence[int],
                     label: str = "") -> tuple[np.ndarray, int, int]:
    """A point's irradiance (W m^-2) by each of ``seeds``, sized to ``precision`` (module docstring), the
    samples its seeds traced in all, and those its pilots traced.

    Raises:
        InputError: a seed would trace more than ``MAX_SAMPLES_PER_PASS`` samples (one pass's memory),
            naming the point by ``label``.
    """
    from spacefit.rendering.flux import pixel_radiance  # here: Mitsuba takes seconds to import

    first, second = pilot_seeds(seeds)
    spread = pixel_radiance(renderer, np.repeat(pixels, PILOT_SPP), first, 1).reshape(-1, PILOT_SPP).std(axis=1, ddof=1)
    groups = allocation(omega, spread)
    measured = replicate_irradiance(renderer, pixels, omega, groups, 1, REPLICATES, second)
    mean, variance = measured.mean(), measured.var(ddof=1)
    copies = 1 if mean <= 0 or variance == 0 else max(1, math.ceil(variance_margin(REPLICATES) * variance
                                                                   / (len(seeds) * (precision * mean) ** 2)))
    if groups.sum() * copies * GROUP_SPP > MAX_SAMPLES_PER_PASS:
        raise InputError(f"the point {label} needs {groups.sum() * copies * GROUP_SPP:,} samples a seed for `precision` = "
                         f"{precision:g} with {len(seeds)} seeds (more than {MAX_SAMPLES_PER_PASS:,}): ask a coarser precision "
                         "or more seeds.")
    values = np.array([replicate_irradiance(renderer, pixels, omega, groups, copies, 1, s)[0] for s in seeds])
    pilots = len(pixels) * PILOT_SPP + int(groups.sum()) * GROUP_SPP * REPLICATES
    return values, int(groups.sum() * copies * GROUP_SPP * len(seeds)), pilots


def precise_sweep(scene: Scene, against: str, points: Mapping[str, list[float]], seeds: Sequence[int], precision: float) -> Any:
    """The light curve's points (``points``: registered parameters set in place, one list each along
    ``against``) sized to ``precision``, as a Dataset like a sweep's: ``irradiance`` (W m^-2) of region
    ``target`` by point and seed, and the ``samples`` and ``pilot_samples`` traced by point."""
    import xarray as xr  # here: xarray takes a second to import

    from spacefit.rendering.renderer import Renderer  # here: Mitsuba takes seconds to import

    renderer = Renderer(scene)
    pixels = np.flatnonzero(renderer.traced)
    omega = renderer.to_window(pixel_solid_angles(renderer.assembly.intrinsics)).ravel()[pixels].astype(float)
    size = len(next(iter(points.values())))
    irradiance = np.zeros((size, len(seeds), 1))
    samples = np.zeros(size, dtype=np.int64)
    pilots = np.zeros(size, dtype=np.int64)
    for i in range(size):
        renderer.set_values({k: v[i] for k, v in points.items()})
        label = ", ".join(f"{k} = {v[i]:g}" for k, v in points.items())
        irradiance[i, :, 0], samples[i], pilots[i] = point_irradiance(renderer, pixels, omega, precision, seeds, label)
    coords = {k: (against, np.asarray(v), {"units": units(k)}) for k, v in points.items()}
    return xr.Dataset({"irradiance": ((against, "render.seed", "region"), irradiance,
                                      {"units": "W m^-2", "description": "box estimate at the pinhole, each seed's"}),
                       "samples": ((against,), samples, {"description": f"samples traced by the seeds, sized to {precision:g}"}),
                       "pilot_samples": ((against,), pilots, {"description": "samples traced by the pilots that sized them"})},
                      coords={**coords, "render.seed": list(seeds), "region": ["target"]},
                      attrs={"precision": precision, "scene_toml": scene.to_toml()})
