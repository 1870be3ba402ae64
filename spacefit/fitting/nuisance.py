"""The image formation's nuisances, applied to the render in JAX: differentiable and cheap.

The model image of a fit is ``gain * shift(psf * render) + offset``: ``psf`` the pixel-integrated
Gaussian of :func:`spacefit.sensor.gaussian_pixel_weights` (sigma in px), ``shift`` a sub-pixel
translation by a Fourier phase (px; +x rightwards along columns, +y downwards along rows; the image
is padded with black sky first, so nothing wraps round). Each may be one observation's own
(``image.psf_sigma_px@k``, :func:`~spacefit.scene.parameters.observation_name`). Only the free ones are applied; their
Jacobian columns are JAX's own derivatives (no render). The pose nuisances move vertices and are
rendered (:mod:`spacefit.rendering.values`, central differences with common random numbers).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from spacefit.scene.parameters import IMAGE, PSF_SIGMA_MAX_PX, observation_name
from spacefit.sensor import GAUSSIAN_RADIUS_SIGMA, gaussian_pixel_weights

# The blur kernel reaches out to 5 sigma of the widest PSF a fit may try (a static shape for JAX).
PSF_RADIUS_PX = math.ceil(GAUSSIAN_RADIUS_SIGMA * PSF_SIGMA_MAX_PX)
# Black sky added round the image before a Fourier shift, px.
SHIFT_PAD_PX = 8

ImageModel = Callable[[Float[Array, "h w c"], Float[Array, " n"], int], Float[Array, "h w c"]]


def blur(image: Float[Array, "h w c"], sigma_px: Float[Array, ""]) -> Float[Array, "h w c"]:
    """``image`` convolved with a pixel-integrated Gaussian of ``sigma_px`` (px, > 0), per channel; no light enters from outside."""
    k = gaussian_pixel_weights(sigma_px, PSF_RADIUS_PX)
    kernel = jnp.outer(k, k)
    return jnp.stack([jax.scipy.signal.fftconvolve(image[..., c], kernel, mode="same") for c in range(image.shape[-1])], axis=-1)


def shift(image: Float[Array, "h w c"], dx_px: Float[Array, ""], dy_px: Float[Array, ""]) -> Float[Array, "h w c"]:
    """``image`` moved by (dx, dy) px (+x rightwards, +y downwards) by a Fourier phase, on black sky."""
    p = SHIFT_PAD_PX
    padded = jnp.pad(image, ((p, p), (p, p), (0, 0)))
    fy = jnp.fft.fftfreq(padded.shape[0])[:, None, None]
    fx = jnp.fft.fftfreq(padded.shape[1])[None, :, None]
    phase = jnp.exp(-2j * jnp.pi * (fx * dx_px + fy * dy_px))
    moved = jnp.real(jnp.fft.ifft2(jnp.fft.fft2(padded, axes=(0, 1)) * phase, axes=(0, 1)))
    return moved[p:-p, p:-p]


def nuisance_index(names: Sequence[str], name: str, k: int) -> int | None:
    """Where observation k's image nuisance ``name`` is in the free ``names``: its own
    (``name@k``) if free, else the shared one, else None (not free)."""
    for candidate in (observation_name(name, k), name):
        if candidate in names:
            return list(names).index(candidate)
    return None


def image_model(names: Sequence[str]) -> ImageModel:
    """``model(render, x, k)``: observation k's render with the image nuisances of the full vector
    ``x`` of the free parameters ``names`` applied (a per-observation value, ``image.gain@k``, where
    free, else the shared one)."""

    def model(image: Float[Array, "h w c"], x: Float[Array, " n"], k: int) -> Float[Array, "h w c"]:
        index = {n: i for n in IMAGE if (i := nuisance_index(names, n, k)) is not None}
        if "image.psf_sigma_px" in index:
            image = blur(image, x[index["image.psf_sigma_px"]])
        if "image.shift_x_px" in index or "image.shift_y_px" in index:
            image = shift(image, *(x[index[n]] if n in index else 0.0 for n in ("image.shift_x_px", "image.shift_y_px")))
        if "image.gain" in index:
            image = x[index["image.gain"]] * image
        if "image.offset_w_m2_sr" in index:
            image = image + x[index["image.offset_w_m2_sr"]]
        return image

    return model
