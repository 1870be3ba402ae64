"""The image a sensor forms from a radiance render, in JAX: the noise-free mean a fit differentiates,
its noise variance, and a simulated exposure.

The sensor's description, its units and the NumPy parts of the model (the etendue, the electrons
per radiance, the Airy pattern and its MTF, the PSF's reach and width, quantising, saturation) are
in :mod:`spacefit.sensor`, whose docstring gives the model's steps; here they are put together:

- :func:`fourier_filter` applies a transfer function on the pixel grid (the sensor's PSF,
  :func:`psf_transfer`, and the fit's blur and shift, :mod:`spacefit.fitting.nuisance`);
- :func:`expected_dn` (steps 1 to 3 in DN, linear in the radiance) and :func:`noise_variance_dn`
  (the Poisson-Gaussian variance of step 4, Janesick 2007, "Photon Transfer", ch. 2), with
  :func:`dn_fn` setting the model up once for a fit;
- :func:`observe`: one simulated exposure through :func:`expected_electrons` (step 4's noise, the
  full well and the ADC);
- :func:`distort_image`: a pinhole render resampled into a distorted camera's pixels
  (:mod:`spacefit.geometry.distortion` describes the lens).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.ndimage import map_coordinates
from jaxtyping import Array, Bool, Float

from spacefit.errors import InputError, check_array, check_count, check_range, check_type
from spacefit.geometry.distortion import Distortion, undistort
from spacefit.geometry.frames import Intrinsics
from spacefit.detector import electrons_per_radiance, quantise, target_pixels, warn_if_saturated
from spacefit.sensor import Sensor, check_flat
from spacefit.psf import airy_transfer, diffraction_cutoff_px, psf_reach_px


def _check_image(image: Any, intrinsics: Intrinsics, name: str = "image") -> None:
    """Check an image's type and shape, (height, width, channels), against ``intrinsics``."""
    check_type("intrinsics", intrinsics, Intrinsics, "an sf.Intrinsics")
    shape = np.shape(image) if isinstance(image, jax.Array) else check_array(name, image).shape
    if len(shape) != 3 or shape[:2] != (intrinsics.height, intrinsics.width):
        raise InputError(f"`{name}` must be (height, width, channels) = ({intrinsics.height}, {intrinsics.width}, c) for these intrinsics, got shape {shape}.")


def _check_radiance(radiance: Any, sensor: Sensor, intrinsics: Intrinsics) -> None:
    check_type("sensor", sensor, Sensor, "an sf.Sensor")
    _check_image(radiance, intrinsics, "radiance")
    if isinstance(radiance, jax.core.Tracer):
        return  # values are unknown while JAX traces; they were checked where they came from
    values = np.asarray(radiance)
    bad = int(np.count_nonzero(~np.isfinite(values))) + int(np.count_nonzero(values < 0))
    if bad:
        raise InputError(f"`radiance` must be finite and >= 0 W m^-2 sr^-1; {bad} values are negative, NaN or infinite.")


def gaussian_transfer(sigma_px: Float[Array, ""], fy: Float[Array, "..."], fx: Float[Array, "..."]) -> Float[Array, "..."]:
    """The Fourier transform of a continuous 2-D Gaussian of ``sigma_px`` at frequencies (cycles
    per px) fy, fx: ``exp(-2 pi^2 sigma^2 (fx^2 + fy^2))``. JAX, differentiable in sigma; the squared frequencies
    summed in JAX, so that a program forms their grid from the two axes (NumPy's sum of :func:`fourier_filter`'s axes
    was a constant of the padded image's size in it: 2.65 MB at 4x a 128 px image)."""
    return jnp.exp(-2.0 * jnp.pi**2 * sigma_px**2 * (jnp.asarray(fx) ** 2 + jnp.asarray(fy) ** 2))


FFT_FACTORS = (2, 3, 5, 7)
"""The prime factors of the sizes the FFT is fast for (a padded 128 x 128 image at 4x, 556 px = 4 x 139, took
2.5 times as long per transform as 560 = 2^4 x 5 x 7)."""


def fast_pad(shape: tuple[int, ...], pad: int) -> int:
    """The least pad >= ``pad`` (px, on every side) that makes each of ``shape``'s first two sizes padded a product of
    :data:`FFT_FACTORS`: for :func:`fourier_filter` where a wider band of black sky changes nothing but the round-off
    (a kernel that has fallen to nothing by ``pad``)."""
    def smooth(n: int) -> bool:
        for f in FFT_FACTORS:
            while n % f == 0:
                n //= f
        return n == 1

    while not all(smooth(n + 2 * pad) for n in shape[:2]):
        pad += 1
    return pad


def fourier_filter(image: Float[Array, "h w c"], transfer: Callable[[np.ndarray, np.ndarray], Array], pad: int,
                   even: bool = False, real: bool = False) -> Float[Array, "h w c"]:
    """``image`` multiplied in Fourier space by ``transfer(fy, fx)`` (frequencies in cycles per px,
    shaped (H, 1, 1) and (1, W, 1); the result broadcasts against (H, W, channels)), after
    ``pad`` px of black sky on every side so that nothing wraps round: a convolution with a kernel
    that reaches ``pad`` px at most, no light entering from outside. The fit's blur and shift
    (:mod:`spacefit.fitting.nuisance`) and the sensor's PSF share it. ``even``: the transfer is real and
    even, ``T(-f) = T(f)`` (a symmetric kernel's, a PSF's), applied by the real FFT: half the work, the same
    result to the round-off (which the FFTs' own differs by: kept off where an image's exact values matter,
    a simulated observation's draws). ``real``: any transfer by the real FFT, as its Hermitian part
    ``(T(f) + conj T(-f)) / 2`` (-f of the Nyquist frequency, -1/2 cycle per px, is itself): the part of the
    product whose transform is the real part the complex FFT's result is taken as, so the same result to the
    round-off, the transforms half the work (the fine models' blur and shift, :mod:`spacefit.fitting.fine_models`)."""
    h, w = image.shape[:2]
    padded = jnp.pad(image, ((pad, pad), (pad, pad), (0, 0)))
    fy = np.fft.fftfreq(padded.shape[0])[:, None, None]  # NumPy: known while JAX traces, for NumPy transfers too
    fx = np.fft.fftfreq(padded.shape[1])[None, :, None]
    if even:
        filtered = jnp.fft.irfft2(jnp.fft.rfft2(padded, axes=(0, 1)) * transfer(fy, np.fft.rfftfreq(padded.shape[1])[None, :, None]),
                                  s=padded.shape[:2], axes=(0, 1))
    elif real:
        half = fx[:, : padded.shape[1] // 2 + 1]  # the real FFT's frequencies as the complex FFT's (its Nyquist -1/2)
        hermitian = 0.5 * (transfer(fy, half) + jnp.conj(transfer(_negated(fy), _negated(half))))
        filtered = jnp.fft.irfft2(jnp.fft.rfft2(padded, axes=(0, 1)) * hermitian, s=padded.shape[:2], axes=(0, 1))
    else:
        filtered = jnp.real(jnp.fft.ifft2(jnp.fft.fft2(padded, axes=(0, 1)) * transfer(fy, fx), axes=(0, 1)))
    return filtered[pad : pad + h, pad : pad + w]


def _negated(f: np.ndarray) -> np.ndarray:
    """The FFT's frequencies ``f`` (cycles per px) negated as the FFT takes them, modulo 1: the Nyquist -1/2 is itself."""
    return np.where(f == -0.5, f, -f)


def psf_transfer(sensor: Sensor, intrinsics: Intrinsics, wavelength_m: float) -> Callable[[np.ndarray, np.ndarray], Array]:
    """The PSF's transfer function ``(fy, fx) -> T`` (cycles per px) at one wavelength: the
    continuous Gaussian's times, with diffraction, the circular pupil's MTF (:func:`~spacefit.psf.airy_transfer`);
    NumPy's or JAX's as the frequencies are."""
    cutoff = diffraction_cutoff_px(sensor, intrinsics, wavelength_m)  # D / lambda in cycles per px

    def transfer(fy: np.ndarray, fx: np.ndarray) -> Array:
        gauss = gaussian_transfer(sensor.psf_sigma_px, fy, fx)
        if not sensor.diffraction:
            return gauss
        xp = np if isinstance(fx, np.ndarray) else jnp  # JAX's frequencies: formed in the program, no constant of the image's size
        return gauss * airy_transfer(xp.hypot(fx, fy) / cutoff, xp)

    return transfer


def electrons_fn(sensor: Sensor, intrinsics: Intrinsics, channels: int,
                 flat: Float[np.ndarray, "h w c"] | None = None) -> Callable[[Float[Array, "h w c"]], Float[Array, "h w c"]]:
    """:func:`expected_electrons` as a JAX function of radiance, with the sensor's per-pixel factors
    and PSF transfer computed once and no check of the values (a fit's model may dip below zero).
    ``flat``: a flat-field map (checked, :func:`~spacefit.sensor.check_flat`) multiplying the signal after the PSF."""
    factor = electrons_per_radiance(sensor, intrinsics, channels)
    response = 1.0 if flat is None else check_flat(flat, (intrinsics.height, intrinsics.width, channels))
    waves = sensor.wavelengths(channels)
    transfers = [psf_transfer(sensor, intrinsics, w) for w in waves]
    pad = max(psf_reach_px(sensor, intrinsics, w) for w in waves)

    def electrons(radiance: Float[Array, "h w c"]) -> Float[Array, "h w c"]:
        e = jnp.asarray(radiance) * factor
        if pad == 0:
            return e * response
        return fourier_filter(e, lambda fy, fx: jnp.concatenate([t(fy, fx) for t in transfers], axis=-1), pad) * response

    return electrons


def dn_fn(sensor: Sensor, intrinsics: Intrinsics, channels: int,
          flat: Float[np.ndarray, "h w c"] | None = None) -> Callable[[Float[Array, "h w c"]], Float[Array, "h w c"]]:
    """:func:`expected_dn` as a JAX function of radiance, set up once (see :func:`electrons_fn`). The
    electrons are taken at 0 where the PSF's ringing next to a bright edge dips below (by 15 DN at a
    glint's edge, 0.8 px PSF), as :func:`observe`'s Poisson mean is: a model that dipped judged a correct
    fit a misfit (chi^2 per value 1.9 in those pixels)."""
    electrons = electrons_fn(sensor, intrinsics, channels, flat)
    return lambda radiance: sensor.bias_dn + sensor.gain_dn_per_electron * jnp.maximum(electrons(radiance), 0.0)


def expected_electrons(radiance: Float[Array, "h w c"], sensor: Sensor, intrinsics: Intrinsics) -> Float[Array, "h w c"]:
    """Mean photo-electrons per pixel (steps 1 to 3 of :mod:`spacefit.sensor`): collected, converted, blurred.

    Args:
        radiance: (height, width, channels) entrance-pupil radiance, W m^-2 sr^-1, >= 0; NumPy or
            JAX (linear in it; light outside the image is not blurred in).
    Returns:
        (height, width, channels) float64 JAX array of electrons. Not clipped at the full well.
    """
    _check_radiance(radiance, sensor, intrinsics)
    return electrons_fn(sensor, intrinsics, np.shape(radiance)[2])(radiance)


def expected_dn(radiance: Float[Array, "h w c"], sensor: Sensor, intrinsics: Intrinsics,
                flat: Float[np.ndarray, "..."] | None = None) -> Float[Array, "h w c"]:
    """Noise-free mean DN, ``bias + gain * expected_electrons``: not rounded, not clipped (see :func:`saturated_mask`).

    Args:
        radiance: (height, width, channels) entrance-pupil radiance, W m^-2 sr^-1 (NumPy or JAX).
        flat: a flat-field map, (height, width) or (height, width, channels), > 0: the detector's
            relative response, multiplying the signal above the bias (None: uniform).
    Returns:
        (height, width, channels) float64 JAX array, DN.

    Raises:
        InputError: ``radiance`` not (height, width, channels) of the camera's size, or a bad ``flat``.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> camera = sf.Intrinsics(focal_length=0.05, pixel_pitch=1e-5, width=4, height=3)
        >>> dn = sf.expected_dn(np.full((3, 4, 3), 1.0), sf.Sensor(), camera)
        >>> dn.shape
        (3, 4, 3)
    """
    _check_radiance(radiance, sensor, intrinsics)
    return _finite(dn_fn(sensor, intrinsics, np.shape(radiance)[2], flat)(radiance), radiance)


def _finite(expected: Array, radiance: Any) -> Array:
    """``expected`` (electrons or DN of ``radiance``), refused where the sensor model overflowed (radiance
    near float32's largest value; a render never comes near it). Values being traced pass unchecked."""
    if not isinstance(expected, jax.core.Tracer) and not bool(jnp.all(jnp.isfinite(expected))):
        raise InputError(f"`radiance` up to {float(np.max(radiance)):.3g} W m^-2 sr^-1 overflows the sensor model; "
                         "renders never come near it: check the image's unit.")
    return expected


def noise_variance_dn(expected: Float[Array, "..."], sensor: Sensor) -> Float[Array, "..."]:
    """Predicted variance (DN^2) of an observed DN about its mean ``expected`` (any shape, DN).

    ``gain^2 (electrons + read_noise^2) + 1/12``: Poisson shot noise (variance = mean electrons,
    ``(expected - bias) / gain``), Gaussian read noise and the rounding to integers (uniform, 1/12).
    Meaningless where :func:`saturated_mask` holds.

    Args:
        expected: mean DN (:func:`expected_dn`), any shape.
        sensor: the sensor (its bias, gain and read noise).

    Returns:
        The variance (DN^2), ``expected``'s shape.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> sf.noise_variance_dn(np.array([100.0, 1000.0]), sf.Sensor())  # bias alone: read noise and rounding
        Array([ 16.08..., 736.08...], dtype=float32)
    """
    check_type("sensor", sensor, Sensor, "an sf.Sensor")
    if not isinstance(expected, jax.Array):
        check_array("expected", expected)
    floor, slope, offset = noise_variance_terms(sensor)
    return slope * jnp.maximum(jnp.asarray(expected) - offset, 0.0) + floor


def noise_variance_terms(sensor: Sensor) -> tuple[float, float, float]:
    """:func:`noise_variance_dn` as floor + slope * max(expected - offset, 0): the floor (read and rounding
    noise, DN^2), the slope (the gain, DN per electron: shot noise) and the offset (the bias, DN)."""
    g = sensor.gain_dn_per_electron
    return (g * sensor.read_noise_electrons) ** 2 + 1.0 / 12.0, g, sensor.bias_dn


def observe(radiance: Float[np.ndarray, "h w c"], sensor: Sensor, intrinsics: Intrinsics, seed: int) -> np.ndarray:
    """One simulated exposure: DN with shot and read noise, the full well, rounding and the ADC's range.
    Warns (``UserWarning``) when more than 0.1 % of the
    target's pixels (those with radiance > 0) saturate; :func:`choose_exposure` picks
    an exposure that leaves them unsaturated.

    Args:
        radiance: (height, width, channels) entrance-pupil radiance, W m^-2 sr^-1.
        seed: seed of the noise (NumPy's default generator); the same seed gives the same image.
    Returns:
        (height, width, channels) uint16 (bit_depth <= 16) or uint32 DN.

    Raises:
        InputError: a bad ``radiance`` (shape, negative or non-finite values) or ``seed``.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> camera = sf.Intrinsics(focal_length=0.05, pixel_pitch=1e-5, width=4, height=3)
        >>> dn = sf.observe(np.full((3, 4, 3), 1.0), sf.Sensor(), camera, seed=0)
        >>> dn.shape, dn.dtype
        ((3, 4, 3), dtype('uint16'))
    """
    check_count("seed", seed, 0, optional=False)
    mean = np.maximum(np.asarray(_finite(expected_electrons(radiance, sensor, intrinsics), radiance)), 0.0)  # FFT round-off leaves -1e-12 in black pixels
    rng = np.random.default_rng(seed)
    saturating = sensor.full_well_electrons if sensor.full_well_electrons is not None else (sensor.adc_max_dn - sensor.bias_dn) / sensor.gain_dn_per_electron
    # A mean of 4 saturation levels saturates with certainty; the cap keeps Poisson's argument finite.
    electrons = rng.poisson(np.minimum(mean, 4.0 * saturating + 1e3)).astype(float)
    if sensor.full_well_electrons is not None:
        electrons = np.minimum(electrons, sensor.full_well_electrons)
    electrons += rng.normal(0.0, sensor.read_noise_electrons, size=electrons.shape)
    dn = quantise(sensor.bias_dn + sensor.gain_dn_per_electron * electrons, sensor)
    warn_if_saturated(dn, radiance, sensor)
    return dn


def distort_image(image: Float[Array, "h w c"], intrinsics: Intrinsics, coefficients: Distortion) -> Float[Array, "h w c"]:
    """Resample a rendered pinhole image into the pixels of the distorted camera (bilinear).

    Each output pixel's centre is undistorted to the pinhole image and the radiance there is
    interpolated bilinearly from the four nearest pixel centres; points outside the image (or where
    the distortion has no inverse) read 0, black space. Linear in ``image`` (NumPy or JAX), so a
    fit can differentiate through it.

    Returns:
        (height, width, channels) float JAX array.

    Args:
        image: (height, width, channels) pinhole render (any unit: radiance, DN).
        intrinsics: the camera (:class:`Intrinsics`), of the image's size.
        coefficients: the lens's :class:`Distortion`.

    Raises:
        InputError: an image of another size than ``intrinsics``.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> camera = sf.Intrinsics(focal_length=0.05, pixel_pitch=1e-5, width=4, height=3)
        >>> sf.distort_image(np.ones((3, 4, 3)), camera, sf.Distortion(k1=-0.1)).shape
        (3, 4, 3)
    """
    check_type("coefficients", coefficients, Distortion, "an sf.Distortion")
    _check_image(image, intrinsics)
    f_px = intrinsics.focal_px
    u0, v0 = intrinsics.principal_point
    v, u = np.mgrid[0 : intrinsics.height, 0 : intrinsics.width] + 0.5
    ideal = undistort(np.stack([(u - u0) / f_px, (v - v0) / f_px], axis=-1), coefficients)
    ideal = np.nan_to_num(ideal, nan=-1e6)  # no inverse: far outside the image, so it reads 0
    rows = ideal[..., 1] * f_px + v0 - 0.5  # array index of the pixel whose centre is at v
    cols = ideal[..., 0] * f_px + u0 - 0.5
    img = jnp.asarray(image)
    return jnp.stack(
        [map_coordinates(img[..., c], [rows, cols], order=1, mode="constant", cval=0.0) for c in range(img.shape[-1])],
        axis=-1,
    )


def choose_exposure(radiance: Float[np.ndarray, "h w c"], sensor: Sensor, intrinsics: Intrinsics, fraction: float = 0.8,
                    percentile: float = 99.9, target: Bool[np.ndarray, "h w"] | None = None) -> Sensor:
    """``sensor`` with the exposure time that puts the ``percentile``-th percentile of the target's
    pixels at ``fraction`` of full scale: noise-free DN (:func:`expected_dn`,
    its brightest channel) ``= bias + fraction (saturation_dn - bias)``, with
    :attr:`Sensor.saturation_dn` the full well's or the ADC's limit. The DN above the bias is linear
    in the exposure time, so one evaluation at the sensor's own time gives it.

    Args:
        radiance: a render of the scene, (height, width, channels) W m^-2 sr^-1.
        fraction: of full scale, in (0, 1]; the default leaves 20 % for noise and brighter glints.
        percentile: in (0, 100]; at the default 99.9 at most 0.1 % of the target's pixels saturate
            (:data:`SATURATED_WARNING_FRACTION`).
        target: the target's pixels (boolean, height x width); None: those brighter than 0.

    Returns:
        A copy of ``sensor`` with the chosen ``exposure_time_s``.

    Raises:
        InputError: a bad ``radiance``, ``fraction``, ``percentile`` or ``target``, or a target
            without a lit pixel.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> camera = sf.Intrinsics(focal_length=0.05, pixel_pitch=1e-5, width=4, height=3)
        >>> sensor = sf.choose_exposure(np.full((3, 4, 3), 1.0), sf.Sensor(), camera)
        >>> f"{sensor.exposure_time_s:.3g} s"
        '0.00313 s'
    """
    check_type("sensor", sensor, Sensor, "an sf.Sensor")
    if sensor.calibrated:
        raise InputError(f"`sensor` is calibrated (`radiometric_scale_dn_per_w_m2_sr` = {sensor.radiometric_scale_dn_per_w_m2_sr:g}): "
                         "its DN per radiance is fixed and its exposure time is not used; scale the radiance or the scale instead.")
    check_range("fraction", fraction, 0.0, 1.0, lo_open=True)
    check_range("percentile", percentile, 0.0, 100.0, lo_open=True)
    mask = target_pixels(radiance, target)
    if not mask.any():
        raise InputError("`radiance` has no target pixels (none brighter than 0, or `target` is all false): nothing to expose for.")
    signal = (np.asarray(expected_dn(radiance, sensor, intrinsics)) - sensor.bias_dn).max(axis=-1)[mask]
    level = float(np.percentile(signal, percentile))
    if not level > 0.0:
        raise InputError(f"the target's {percentile:g}th percentile of radiance is 0: too few of its pixels are lit to expose for.")
    time_s = sensor.exposure_time_s * fraction * (sensor.saturation_dn - sensor.bias_dn) / level
    return dataclasses.replace(sensor, exposure_time_s=time_s)
