"""Residuals that compare a rendered image with a reference; a fit minimises 0.5 * sum(r^2).

* ``pixel``: per-pixel differences, divided by a noise sigma (scalar or per pixel) if given;
* ``pyramid``: block means of the difference at 1, 2, 4, ... px blocks, each level scaled by its
  block size so that every level weighs alike for a smooth error; coarse levels see glints that
  moved a little and are less noisy;
* ``stats``: statistics of the pixels lit in the reference (mean, standard deviation, 50th, 90th
  and 99th percentile of the per-pixel channel mean), relative to the reference's mean, plus 8 x 8
  block means: they do not need glints to line up pixel for pixel (for the wrinkles).

A noise whose variance V(mu) grows with the model's mean mu (a sensor's shot noise,
:class:`AffineVariance`) weights each difference by the noise at the model, held fixed in
derivatives: a quasi-likelihood (McCullagh & Nelder 1989, Generalized Linear Models, ch. 9), whose
estimating equation sum (mu - y) / V(mu) dmu/dtheta = 0 is unbiased, where weights from the data's own noisy
values favour low pixels and the derivative of the weights (the chi^2 minimum) biases the estimate by
about sqrt(pixels / electrons per pixel) / 2 standard errors. Its Jacobian is not that of its loss 0.5 sum r^2,
though: far from the data (a pose error) a Gauss-Newton step along it raised that loss at every
length (issue 34). So a solver descends the *quasi-deviance* D = sum int_y^mu (t - y) / V(t) dt
instead (``descent=True``), whose gradient is exactly the quasi-likelihood's estimating function: the
same estimate, and a loss its steps are judged by that each step's direction descends. Its residuals
are the deviance residuals sign(mu - y) sqrt(2 D_i) (:meth:`AffineVariance.deviance_residual`);
at a constant variance both are (mu - y) / sigma. The fit's verdict and standard errors keep the
weighted differences (chi^2, the Fisher information sum dmu dmu^T / V(mu)).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from spacefit.errors import InputError, check_choice
from spacefit.precision import on_device

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


# Below this |z| the deviance's functions of z take their Taylor series (float64: 1e-13 relative).
SERIES_BELOW = 1e-2


def _phi(z: Array) -> Array:
    """(z - ln(1 + z)) / z^2 = int_0^1 u / (1 + z u) du, for z > -1; 1/2 at 0."""
    small = jnp.abs(z) < SERIES_BELOW
    zs, zl = jnp.where(small, z, 0.0), jnp.where(small, 1.0, z)
    series = 0.5 + zs * (-1.0 / 3.0 + zs * (0.25 + zs * (-0.2 + zs * (1.0 / 6.0 - zs / 7.0))))
    return jnp.where(small, series, (zl - jnp.log1p(zl)) / zl**2)


def _psi(z: Array) -> Array:
    """ln(1 + z) / z = int_0^1 1 / (1 + z u) du, for z > -1; 1 at 0."""
    small = jnp.abs(z) < SERIES_BELOW
    zs, zl = jnp.where(small, z, 0.0), jnp.where(small, 1.0, z)
    series = 1.0 + zs * (-0.5 + zs * (1.0 / 3.0 + zs * (-0.25 + zs * (0.2 - zs / 6.0))))
    return jnp.where(small, series, jnp.log1p(zl) / zl)


@dataclass(frozen=True)
class AffineVariance:
    """A noise whose variance is affine in the mean above an offset, V(mu) = floor + slope * max(mu - offset, 0):
    a sensor's shot, read and rounding noise in DN (:func:`~spacefit.formation.noise_variance_terms`).

    Attributes:
        floor: the variance at and below ``offset`` (> 0), the data's unit squared.
        slope: its growth per unit of the mean above ``offset`` (>= 0; a sensor's gain, DN per electron).
        offset: where it starts growing (a sensor's bias, DN).
    """

    floor: float
    slope: float
    offset: float

    def sigma(self, mu: Array) -> Array:
        """The noise's standard deviation at the mean ``mu`` (NumPy's for a NumPy array: no program)."""
        xp = np if isinstance(mu, np.ndarray) else jnp
        return xp.sqrt(self.floor + self.slope * xp.maximum(mu - self.offset, 0.0))

    def deviance_residual(self, mu: Array, y: Array) -> Array:
        """sign(mu - y) sqrt(2 D), D = int_y^mu (t - y) / V(t) dt, the quasi-deviance of the mean ``mu`` for the value
        ``y``; its derivative in mu is (mu - y) / (V(mu) r). Computed as (mu - y) sqrt(2 Q), Q = D / (mu - y)^2 =
        int_0^1 u / V(y + u (mu - y)) du in closed form on each side of ``offset`` (in float64 where JAX's 64-bit mode
        is on, as in a fit; finite, with finite derivatives, everywhere, mu = y included)."""
        wide = jax.dtypes.canonicalize_dtype(jnp.float64)
        mu, y = jnp.asarray(mu, wide), jnp.asarray(y, wide)
        c, g = self.floor, self.slope
        d, a_y, a_mu = mu - y, y - self.offset, mu - self.offset
        v_y = c + g * jnp.maximum(a_y, 0.0)
        # both above the offset: V(y + u d) = V(y) (1 + z u) (d taken 0 in the other cases, where 1 + z may be <= 0)
        above = _phi(g * jnp.where((a_y >= 0) & (a_mu >= 0), d, 0.0) / v_y) / v_y
        # y below, mu above: below for the fraction f of the way, then V = c (1 + w (u - f) / (1 - f))
        up = jnp.where((a_y < 0) & (a_mu >= 0), d, 1.0)
        f = jnp.clip(-a_y / up, 0.0, 1.0)
        w = g * jnp.maximum(a_mu, 0.0) / c
        rising = (f**2 / 2 + (1 - f) ** 2 * _phi(w) + f * (1 - f) * _psi(w)) / c
        # y above, mu below: V(y) (1 + z u) down to the offset at u*, then c
        down = jnp.where((a_y >= 0) & (a_mu < 0), -d, 1.0)
        u_star = jnp.clip(a_y / down, 0.0, 1.0)
        falling = u_star**2 * _phi(-g * jnp.maximum(a_y, 0.0) / v_y) / v_y + (1 - u_star**2) / (2 * c)
        q = jnp.where(a_y >= 0, jnp.where(a_mu >= 0, above, falling), jnp.where(a_mu >= 0, rising, 1.0 / (2 * c)))
        return d * jnp.sqrt(2.0 * q)


def residual_fn(reference: Float[np.ndarray, "h w 3"], loss: str = "pixel",
                sigma: float | np.ndarray | AffineVariance | None = None,
                mask: Bool[np.ndarray, "h w 3"] | None = None, descent: bool = False) -> Residual:
    """The residual function ``image -> r`` of a loss against ``reference``.

    Args:
        reference: (h, w, 3) radiance, W m^-2 sr^-1.
        loss: one of :data:`LOSSES`.
        sigma: noise standard deviation of the reference (scalar or (h, w) / (h, w, 3)); residuals
            are divided by it, so at the truth they are unit normal and the reported standard
            errors are on the right scale; +inf leaves a pixel out (a saturated one). Or an
            :class:`AffineVariance`, the noise the model image predicts (held fixed in derivatives:
            the quasi-likelihood of the module's docstring). None: unweighted.
        mask: the values to compare (True) and those left out (their differences are 0 in every
            loss; the reference must be finite there); None: all.
        descent: with an :class:`AffineVariance`, the deviance residuals a solver descends (the
            module's docstring) in place of the weighted differences; the same otherwise.
    """
    check_choice("loss", loss, LOSSES)
    ref = on_device(reference, np.float32)
    keep = 1.0 if mask is None else on_device(np.broadcast_to(mask, ref.shape), np.float32)

    def weight(image: Array) -> Array | float:
        return 1.0

    if isinstance(sigma, AffineVariance):
        predicted = sigma

        def weight(image: Array) -> Array | float:
            return 1.0 / jax.lax.stop_gradient(predicted.sigma(image))
    elif sigma is not None:
        s = np.broadcast_to(np.asarray(sigma, dtype=float)[..., None] if np.ndim(sigma) == 2 else np.asarray(sigma, dtype=float), ref.shape)
        if np.any(np.isnan(s)) or np.any(s <= 0) or np.all(np.isinf(s)):
            raise InputError("`sigma` must be positive everywhere (+inf leaves a pixel out) and finite somewhere.")
        fixed = jnp.asarray(1.0 / s, dtype=jnp.float32)

        def weight(image: Array) -> Array | float:
            return fixed

    deviance = descent and isinstance(sigma, AffineVariance)

    def difference(image: Array) -> Array:
        if deviance:
            return sigma.deviance_residual(image, ref) * keep
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
