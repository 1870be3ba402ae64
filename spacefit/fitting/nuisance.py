"""The image formation's nuisances, applied to the render in JAX: differentiable and cheap.

The model image of a fit is ``scale * shift(blur(render)) + offset``: ``blur`` a continuous
Gaussian of ``image.blur_sigma_px`` (px, the optical convention: a blur on the focal plane before
the pixel integrates it; the render is already integrated over each pixel by its pixel filter, so
the blur is its transfer function ``exp(-2 pi^2 sigma^2 f^2)`` on the pixel grid, never a second
integration over the pixel), ``shift`` a sub-pixel translation by a Fourier phase (px; +x
rightwards along columns, +y downwards along rows); both in one Fourier transform
(:func:`spacefit.formation.fourier_filter`, as the sensor's PSF), the image padded with black sky
first, so nothing wraps round. Each may be one observation's own (``image.blur_sigma_px@k``,
:class:`~spacefit.scene.names.Name`). Only the free ones are applied; their
Jacobian columns are JAX's own derivatives (no render). The pose nuisances move vertices and are
rendered (:mod:`spacefit.rendering.values`, central differences with common random numbers).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from spacefit.formation import fourier_filter, gaussian_transfer
from spacefit.scene.names import Name
from spacefit.scene.parameters import IMAGE
from spacefit.scene.registered import PSF_SIGMA_MAX_PX
from spacefit.psf import GAUSSIAN_RADIUS_SIGMA

# Black sky added round the image before the blur and shift, px: 5 sigma of the widest blur a fit
# may try, and 8 px more for the shift.
PAD_PX = math.ceil(GAUSSIAN_RADIUS_SIGMA * PSF_SIGMA_MAX_PX) + 8

ImageModel = Callable[[Float[Array, "h w c"], Float[Array, " n"], int], Float[Array, "h w c"]]


def blur_and_shift(image: Float[Array, "h w c"], sigma_px: Float[Array, ""], dx_px: Float[Array, ""],
                   dy_px: Float[Array, ""], pad: int = PAD_PX, real: bool = False) -> Float[Array, "h w c"]:
    """``image`` blurred by a continuous Gaussian of ``sigma_px`` (px, >= 0) and moved by (dx, dy)
    px (+x rightwards, +y downwards), per channel, on black sky (``pad`` px on every side): no light enters from outside;
    ``real``: by the real FFT (:func:`~spacefit.formation.fourier_filter`'s, the same to the round-off)."""

    def transfer(fy: np.ndarray, fx: np.ndarray) -> Array:
        return gaussian_transfer(sigma_px, fy, fx) * jnp.exp(-2j * jnp.pi * (fx * dx_px + fy * dy_px))

    return fourier_filter(image, transfer, pad, real=real)


def blur(image: Float[Array, "h w c"], sigma_px: Float[Array, ""]) -> Float[Array, "h w c"]:
    """``image`` blurred by a continuous Gaussian of ``sigma_px`` (px) (:func:`blur_and_shift`)."""
    return blur_and_shift(image, sigma_px, 0.0, 0.0)


def shift(image: Float[Array, "h w c"], dx_px: Float[Array, ""], dy_px: Float[Array, ""]) -> Float[Array, "h w c"]:
    """``image`` moved by (dx, dy) px (+x rightwards, +y downwards) by a Fourier phase (:func:`blur_and_shift`)."""
    return blur_and_shift(image, 0.0, dx_px, dy_px)


def nuisance_index(names: Sequence[str], name: str, k: int) -> int | None:
    """Where observation k's image nuisance ``name`` is in the free ``names``: its own
    (``name@k``) if free, else the shared one, else None (not free)."""
    for candidate in (Name(name, k), name):
        if candidate in names:
            return list(names).index(candidate)
    return None


def nuisance_indices(names: Sequence[str], k: int) -> dict[str, int]:
    """Where observation k's free image nuisances are in the free ``names``, by registered name
    (:func:`nuisance_index`), in the order of :data:`~spacefit.scene.parameters.IMAGE`."""
    return {n: i for n in IMAGE if (i := nuisance_index(names, n, k)) is not None}


def with_nuisances(image: Float[Array, "h w c"], values: Mapping[str, Float[Array, ""]], pad: int = PAD_PX,
                   real: bool = False) -> Float[Array, "h w c"]:
    """``image`` with the image nuisances ``values`` (registered name -> value) applied, those absent left out
    (the blur and shift on ``pad`` px of black sky, by the real FFT where ``real``: :func:`blur_and_shift`)."""
    moves = ("image.blur_sigma_px", "image.shift_x_px", "image.shift_y_px")
    if any(n in values for n in moves):
        image = blur_and_shift(image, *(values[n] if n in values else 0.0 for n in moves), pad=pad, real=real)
    if "image.scale" in values:
        image = values["image.scale"] * image
    if "image.offset_w_m2_sr" in values:
        image = image + values["image.offset_w_m2_sr"]
    return image


def image_model(names: Sequence[str], pad: int = PAD_PX, real: bool = False) -> ImageModel:
    """``model(render, x, k)``: observation k's render with the image nuisances of the full vector
    ``x`` of the free parameters ``names`` applied (a per-observation value, ``image.scale@k``, where
    free, else the shared one); ``pad``: the black sky round it for the blur and shift (px); ``real``: those by the
    real FFT (:func:`with_nuisances`)."""

    def model(image: Float[Array, "h w c"], x: Float[Array, " n"], k: int) -> Float[Array, "h w c"]:
        return with_nuisances(image, {n: x[i] for n, i in nuisance_indices(names, k).items()}, pad, real)

    return model
