"""The sensor's point-spread function: the Airy pattern of its circular aperture and a Gaussian, in
pixels (NumPy; the image a sensor forms with it is :mod:`spacefit.formation`'s)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from spacefit.geometry.frames import Intrinsics
from spacefit.sensor import Sensor

if TYPE_CHECKING:  # annotations only: jaxtyping's Array imports JAX (0.6 s), which a render does not need
    from jaxtyping import Float


AIRY_FIRST_ZERO = 3.8317059702075125
"""First zero of the Bessel function J1: the Airy pattern's first dark ring is at x = pi D theta / lambda = 3.8317, theta = 1.21967 lambda / D."""
PSF_ENERGY = 0.99
"""The Airy kernel reaches out to the radius that encloses this fraction of the energy (then it is normalised)."""
AIRY_RADIUS_X = 64.02354017718858
"""x = pi D theta / lambda within which the Airy pattern holds :data:`PSF_ENERGY` of its energy: the root of
1 - J0(x)^2 - J1(x)^2 = 0.99 (Rayleigh 1881), written out (SciPy's root finder and Bessel functions cost a fit 0.3 s
of imports; tests/test_sensor.py solves it again)."""
AIRY_RMS_X = 4.52385485717649
"""The rms width per axis, in x, of the Airy pattern within :data:`AIRY_RADIUS_X` X: ``X sqrt((J1^2 - J0 J2) /
(2 (1 - J0^2 - J1^2)))`` at X (from the integral of x J1(x)^2, Watson 1944, 5.11); tests/test_sensor.py computes it again."""
GAUSSIAN_RADIUS_SIGMA = 5.0
"""The Gaussian kernel reaches out to this many sigma (2.9e-7 of its energy lies beyond, per axis)."""


def airy_psf(theta_rad: Float[np.ndarray, "..."], wavelength_m: float, aperture_diameter_m: float) -> Float[np.ndarray, "..."]:
    """The Airy pattern of a circular aperture as a density over directions (sr^-1), integrating to 1.

    ``(pi D^2 / (4 lambda^2)) [2 J1(x) / x]^2`` with ``x = pi D theta / lambda`` (small angles).
    Its first zero is at theta = 1.21967 lambda / D. References: Airy (1835); Born & Wolf,
    "Principles of Optics", section 8.5.2.
    """
    from scipy import special  # here: SciPy's import (0.3 s) is only this density's, which a fit never evaluates

    x = np.pi * aperture_diameter_m * np.abs(np.asarray(theta_rad, dtype=float)) / wavelength_m
    safe = np.where(x == 0.0, 1.0, x)  # 2 J1(x) / x -> 1 as x -> 0
    amplitude = np.where(x == 0.0, 1.0, 2.0 * special.j1(safe) / safe)
    return np.pi * aperture_diameter_m**2 / (4.0 * wavelength_m**2) * amplitude**2


def _airy_px(sensor: Sensor, intrinsics: Intrinsics, wavelength_m: float) -> float:
    """Pixels per unit of x = pi D theta / lambda (theta in radians, a pixel ``pitch / focal length``)."""
    return wavelength_m / (np.pi * sensor.aperture_diameter_m * intrinsics.pixel_pitch / intrinsics.focal_length)


def airy_transfer(rho: Float[np.ndarray, "..."], xp: Any = np) -> Float[np.ndarray, "..."]:
    """The MTF of a diffraction-limited circular pupil at ``rho`` = frequency / cut-off (D / lambda
    cycles per radian): ``(2 / pi) (acos rho - rho sqrt(1 - rho^2))``, 0 beyond 1 (Goodman,
    "Introduction to Fourier Optics", 3rd ed., eq. 6-32): the Fourier transform of :func:`airy_psf`.
    ``xp``: the array module, NumPy or ``jax.numpy`` (a program's transfer computed as it runs, not held as a constant)."""
    r = xp.clip(xp.abs(xp.asarray(rho, dtype=float)), 0.0, 1.0)
    return 2.0 / np.pi * (xp.arccos(r) - r * xp.sqrt(1.0 - r**2))


def diffraction_cutoff_px(sensor: Sensor, intrinsics: Intrinsics, wavelength_m: float) -> float:
    """The circular pupil's cut-off frequency D / lambda in cycles per px at one wavelength: where
    :func:`airy_transfer` reaches 0."""
    return 1.0 / (np.pi * _airy_px(sensor, intrinsics, wavelength_m))


def psf_reach_px(sensor: Sensor, intrinsics: Intrinsics, wavelength_m: float) -> int:
    """How far (px) the PSF reaches: 5 sigma of the Gaussian plus the radius holding 99 % of the Airy pattern's energy."""
    airy = AIRY_RADIUS_X * _airy_px(sensor, intrinsics, wavelength_m) if sensor.diffraction else 0.0
    return math.ceil(GAUSSIAN_RADIUS_SIGMA * sensor.psf_sigma_px + airy)


def psf_rms_px(sensor: Sensor, intrinsics: Intrinsics, channels: int) -> float:
    """The rms width (px, per axis) of the widest channel's PSF: sqrt(sigma^2 + a^2), a the Airy
    pattern's within the radius that holds 99 % of its energy (:data:`AIRY_RMS_X`), in px."""
    widths = []
    for wavelength in sensor.wavelengths(channels):
        airy = _airy_px(sensor, intrinsics, wavelength) * AIRY_RMS_X if sensor.diffraction else 0.0
        widths.append(math.hypot(sensor.psf_sigma_px, airy))
    return max(widths)
