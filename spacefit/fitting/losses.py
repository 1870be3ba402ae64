"""Residuals that compare a rendered image with a reference; a fit minimises 0.5 * sum(r^2).

* ``pixel``: per-pixel differences, divided by a noise sigma (scalar or per pixel) if given;
* ``pyramid``: block means of the difference at 1, 2, 4, ... px blocks, each level scaled by its
  block size so that every level weighs alike for a smooth error; coarse levels see glints that
  moved a little and are less noisy;
* ``stats``: statistics of the pixels lit in the reference (mean, standard deviation, 50th, 90th
  and 99th percentile of the per-pixel channel mean), relative to the reference's mean, plus 8 x 8
  block means: they do not need glints to line up pixel for pixel (for the wrinkles).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from spacefit.errors import InputError, check_choice

Residual = Callable[[Float[Array, "h w 3"]], Float[Array, " m"]]
#: The losses ``sf.fit(loss=...)`` takes: ``pixel`` compares images pixel by pixel, divided by the
#: noise sigma where it is known (the default); ``pyramid`` compares block means of the difference at
#: 1, 2, 4, ... px blocks (coarse levels see glints that moved a little: a wider basin for a far
#: start); ``stats`` compares the lit pixels' mean, standard deviation and percentiles and 8 x 8 px
#: block means, which need no glint to line up pixel for pixel (for wrinkles, whose pattern is
#: random). Another name raises :class:`InputError`.
#:
#: Example:
#:     >>> import spacefit as sf
#:     >>> sf.LOSSES
#:     ('pixel', 'pyramid', 'stats')
LOSSES = ("pixel", "pyramid", "stats")
PYRAMID_LEVELS = 4
STATS_BLOCK = 8
STATS_QUANTILES = (0.5, 0.9, 0.99)


def _block_mean(image: Array, size: int) -> Array:
    h, w = (image.shape[0] // size) * size, (image.shape[1] // size) * size
    blocks = image[:h, :w].reshape(h // size, size, w // size, size, -1)
    return blocks.mean(axis=(1, 3))


def _statistics(image: Array, mask: np.ndarray) -> Array:
    lit = image.mean(axis=-1)[mask]
    return jnp.concatenate([jnp.stack([lit.mean(), lit.std()]), jnp.quantile(lit, jnp.asarray(STATS_QUANTILES))])


def residual_fn(reference: Float[np.ndarray, "h w 3"], loss: str = "pixel",
                sigma: float | np.ndarray | Callable[[Array], Array] | None = None,
                mask: Bool[np.ndarray, "h w 3"] | None = None) -> Residual:
    """The residual function ``image -> r`` of a loss against ``reference``.

    Args:
        reference: (h, w, 3) radiance, W m^-2 sr^-1.
        loss: one of :data:`LOSSES`.
        sigma: noise standard deviation of the reference (scalar or (h, w) / (h, w, 3)); residuals
            are divided by it, so at the truth they are unit normal and the reported standard
            errors are on the right scale; +inf leaves a pixel out (a saturated one). Or a function
            of the model image, the noise it predicts (held fixed in derivatives: a quasi-likelihood,
            unbiased where weights from the reference's own noisy values would favour low pixels).
            None: unweighted.
        mask: the values to compare (True) and those left out (their differences are 0 in every
            loss; the reference must be finite there); None: all.
    """
    check_choice("loss", loss, LOSSES)
    ref = jnp.asarray(reference, dtype=jnp.float32)
    keep = 1.0 if mask is None else jnp.asarray(np.broadcast_to(mask, ref.shape), dtype=jnp.float32)

    def weight(image: Array) -> Array | float:
        return 1.0

    if callable(sigma):
        predicted = sigma

        def weight(image: Array) -> Array | float:
            return 1.0 / jax.lax.stop_gradient(predicted(image))
    elif sigma is not None:
        s = np.broadcast_to(np.asarray(sigma, dtype=float)[..., None] if np.ndim(sigma) == 2 else np.asarray(sigma, dtype=float), ref.shape)
        if np.any(np.isnan(s)) or np.any(s <= 0) or np.all(np.isinf(s)):
            raise InputError("`sigma` must be positive everywhere (+inf leaves a pixel out) and finite somewhere.")
        fixed = jnp.asarray(1.0 / s, dtype=jnp.float32)

        def weight(image: Array) -> Array | float:
            return fixed

    def difference(image: Array) -> Array:
        return (image - ref) * weight(image) * keep

    if loss == "pixel":
        return lambda image: jnp.ravel(difference(image))
    if loss == "pyramid":
        sizes = [2**level for level in range(PYRAMID_LEVELS) if 2**level <= min(ref.shape[:2])]
        return lambda image: jnp.concatenate([jnp.ravel(_block_mean(difference(image), s) * s) for s in sizes])
    lit = np.asarray(reference).mean(axis=-1) > 0
    if mask is not None:
        lit &= np.all(np.broadcast_to(mask, ref.shape), axis=-1)
    if lit.sum() < 16:
        raise InputError("the `stats` loss needs at least 16 lit pixels (not masked out) in the reference.")
    ref_stats = _statistics(ref, lit)
    scale = float(np.asarray(reference)[lit].mean())
    n_stats = float(np.sqrt(lit.sum()))  # weigh the statistics like a block of that many pixels

    def stats(image: Array) -> Array:
        coarse = jnp.ravel(_block_mean((image - ref) * keep, STATS_BLOCK)) * STATS_BLOCK
        return jnp.concatenate([(_statistics(image, lit) - ref_stats) / scale * n_stats, coarse / scale])

    return stats
