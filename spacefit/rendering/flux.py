"""The radiance of a loaded scene's samples pixel by pixel, without a film: what a target's flux needs.

A film's pixels (tent filter: each a weighted mean of the samples around it) sum, times their solid
angles, to the target's irradiance at the pinhole, the integral of radiance over solid angle (the
filter's weights sum to one everywhere). So does the box estimator over the same samples, the sum over
pixels of solid angle times the mean of the samples drawn uniformly in that pixel, and it lets each
pixel take its own number of samples, which a film cannot (a filtered pixel would lean towards its
denser neighbour). :func:`pixel_radiance` gives the samples; the light curve's sizing
(:mod:`spacefit.studies.lightcurve_sizing`) weighs them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from spacefit.rendering.backend import dr, mi, variant_scope
from spacefit.rendering.frozen import camera_samples
from spacefit.rendering.memory import MAX_SAMPLES_PER_PASS
from spacefit.rendering.sample_passes import pass_seed

if TYPE_CHECKING:
    from spacefit.rendering.renderer import Renderer


def pixel_radiance(renderer: Renderer, pixels: np.ndarray, seed: int, spp: int) -> np.ndarray:
    """(len(pixels),) float64: for each listed pixel of the renderer's window (row-major indices into it;
    a pixel listed k times gets k independent groups), the mean RGB-mean radiance (W m^-2 sr^-1) of a group
    of ``spp`` samples in it (the sampler's pattern in that pixel), traced as the renderer traces them
    (:func:`~spacefit.rendering.frozen.camera_samples`), seeded ``seed``, in passes of at most
    :data:`~spacefit.rendering.memory.MAX_SAMPLES_PER_PASS` samples (pass i seeded as a render's). Each
    group is summed in order on one thread (``dr.block_sum``): the same arguments give the same array."""
    pixels = np.ascontiguousarray(pixels, dtype=np.uint32)
    per_pass = max(1, MAX_SAMPLES_PER_PASS // spp)
    out = np.empty(len(pixels))
    with variant_scope(renderer.variant):
        listed = mi.UInt32(pixels)
        for i, start in enumerate(range(0, len(pixels), per_pass)):
            count = min(per_pass, len(pixels) - start)
            _, rgb = camera_samples(renderer.scene, listed, mi.UInt32(pass_seed(seed, i)), spp, start, count, renderer.window[2])
            out[start:start + count] = np.asarray(dr.block_sum(rgb.x + rgb.y + rgb.z, spp), dtype=float) / (3.0 * spp)
    return out
