"""What a sensor's pixels make of radiance, in NumPy: the per-pixel factors of steps 1 and 2 of
:mod:`spacefit.sensor`'s model, quantising (step 4's ADC), and the warning when the target saturates.

Step 1, the collected energy: a pixel's etendue ``A cos(theta) Omega`` through the aperture
(:func:`pixel_etendue`; the cos^4 fall-off off axis, or none where the image is flat-fielded). Step
2, the photo-electrons per unit radiance, ``QE t A cos(theta) Omega lambda / (h c)`` at one
wavelength per channel, or a calibrated camera's scale over its gain
(:func:`electrons_per_radiance`). The JAX image formation that puts them together with the PSF and
the noise is :mod:`spacefit.formation`'s.
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import TYPE_CHECKING

import numpy as np

from spacefit.errors import InputError, check_array
from spacefit.geometry.frames import Intrinsics, pixel_solid_angles
from spacefit.sensor import Sensor, saturated_mask

if TYPE_CHECKING:
    from jaxtyping import Bool, Float

PLANCK_J_S = 6.62607015e-34
"""The Planck constant, J s (exact in the SI since 2019; SciPy's constants module costs a fit 0.2 s of imports)."""
LIGHT_M_S = 299792458.0
"""The speed of light in vacuum, m/s (exact in the SI)."""
SATURATED_WARNING_FRACTION = 1e-3
""":func:`~spacefit.formation.observe` warns when more than this fraction of the target's pixels saturate."""


def pixel_etendue(sensor: Sensor, intrinsics: Intrinsics) -> Float[np.ndarray, "h w"]:
    """Etendue ``A cos(theta) Omega`` (m^2 sr) of each pixel through the aperture.

    Omega from :func:`~spacefit.geometry.frames.pixel_solid_angles` (cos^3 off axis), times the
    aperture's area seen along the pixel's centre ray: together the cos^4 law. Without
    :attr:`Sensor.vignetted`, every pixel's is that of a pixel centred on the axis.
    """
    f, p = intrinsics.focal_length, intrinsics.pixel_pitch
    if not sensor.vignetted:
        on_axis = pixel_solid_angles(Intrinsics(f, p, 1, 1))[0, 0]
        return np.full((intrinsics.height, intrinsics.width), sensor.aperture_area_m2 * on_axis)
    u0, v0 = intrinsics.principal_point
    x = (np.arange(intrinsics.width) + 0.5 - u0) * p
    y = (np.arange(intrinsics.height) + 0.5 - v0) * p
    cos_theta = f / np.sqrt(x[None, :] ** 2 + y[:, None] ** 2 + f**2)
    return sensor.aperture_area_m2 * cos_theta * pixel_solid_angles(intrinsics)


def electrons_per_radiance(sensor: Sensor, intrinsics: Intrinsics, channels: int) -> Float[np.ndarray, "h w c"]:
    """Mean photo-electrons per W m^-2 sr^-1 of each pixel and channel, before the PSF.

    ``QE t A cos(theta) Omega lambda / (h c)``, single wavelength per channel; for a calibrated
    camera, its radiometric scale over its gain (times the cos^4 fall-off relative to the axis if
    :attr:`Sensor.vignetted`).
    """
    if sensor.calibrated:
        shading = pixel_etendue(sensor, intrinsics) / pixel_etendue(dataclasses.replace(sensor, vignetting=False), intrinsics)
        per_dn = sensor.radiometric_scale_dn_per_w_m2_sr / sensor.gain_dn_per_electron
        return np.repeat(per_dn * shading[..., None], channels, axis=-1)
    photon_energy = PLANCK_J_S * LIGHT_M_S / np.asarray(sensor.wavelengths(channels))
    return (sensor.quantum_efficiency * sensor.exposure_time_s * pixel_etendue(sensor, intrinsics))[..., None] / photon_energy


def quantise(dn: Float[np.ndarray, "..."], sensor: Sensor) -> np.ndarray:
    """Round DN to the nearest integer (halves to even) and clip to the ADC's [0, 2^bits - 1].

    Returns:
        the same shape as uint16 (bit_depth <= 16) or uint32.
    """
    dtype = np.uint16 if sensor.bit_depth <= 16 else np.uint32
    return np.clip(np.rint(np.asarray(dn, dtype=float)), 0, sensor.adc_max_dn).astype(dtype)


def target_pixels(radiance: Float[np.ndarray, "h w c"], target: Bool[np.ndarray, "h w"] | None = None) -> Bool[np.ndarray, "h w"]:
    """The target's pixels: ``target`` when given (checked against the image), else those of
    ``radiance`` brighter than 0 in any channel (the target against black space)."""
    radiance = check_array("radiance", radiance)
    if target is None:
        return np.asarray(radiance.max(axis=-1) > 0.0)
    mask = np.asarray(target)
    if mask.dtype != bool or mask.shape != radiance.shape[:2]:
        raise InputError(f"`target` must be a boolean (height, width) = {radiance.shape[:2]} mask, got {mask.dtype} {mask.shape}.")
    return mask


def warn_if_saturated(dn: np.ndarray, radiance: Float[np.ndarray, "h w c"], sensor: Sensor) -> None:
    """Warn when more than :data:`SATURATED_WARNING_FRACTION` of the target's pixels (:func:`target_pixels`)
    saturate in an observation ``dn`` of ``radiance``: a fit leaves them out, and their mean is clipped."""
    mask = target_pixels(radiance)
    saturated = int(np.count_nonzero(saturated_mask(dn, sensor).any(axis=-1) & mask))
    if saturated > SATURATED_WARNING_FRACTION * np.count_nonzero(mask):
        warnings.warn(f"{saturated} of the target's {np.count_nonzero(mask)} pixels ({100 * saturated / np.count_nonzero(mask):.3g} %, "
                      f"more than {100 * SATURATED_WARNING_FRACTION:g} %) saturate at {sensor.saturation_dn:g} DN: their DN is clipped. "
                      "Shorten `Sensor.exposure_time_s`; sf.choose_exposure(radiance, sensor, intrinsics) picks one.",
                      UserWarning, stacklevel=3)
