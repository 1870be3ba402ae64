"""The camera after the radiance render, described: optics' blur, photo-electrons, electronics, noise, digitising.

A render is entrance-pupil radiance L (W m^-2 sr^-1, per channel). The sensor turns it into digital
numbers (DN) in this order:

1. **Collected energy**: a pixel gathers ``E = L A cos(theta) Omega t`` joules, A the aperture's area
   (m^2), Omega the pixel's solid angle seen from the pinhole (sr, :func:`pixel_solid_angles`), theta
   the pixel centre's angle off the optical axis and t the exposure time (s). ``A cos(theta)`` is
   the aperture's area seen from the pixel, so off axis the image darkens as cos^4(theta)
   ("natural vignetting"); on the axis E = L A Omega t. The optics are taken as lossless. With
   ``vignetting`` off (a flat-fielded image) every pixel collects what the on-axis pixel does.
2. **Photo-electrons**: ``QE E / (h c / lambda)``. *Single-wavelength assumption*: each channel's
   radiance is taken as all at one wavelength ``Sensor.wavelength_m[channel]`` (the renders are
   band-integrated radiances of a grey sun, so a channel carries no spectrum to integrate over).
   *A calibrated camera* gives instead its radiometric scale s (DN per W m^-2 sr^-1, the FITS
   keyword ``RADSCALE``): ``DN = bias + s L``, with vignetting off unless asked for; exposure,
   aperture, QE and wavelength are then not used (the wavelength and aperture only for diffraction).
3. **Point spread function**, applied to the collected signal: the Airy pattern of a circular
   aperture (Airy 1835) at the channel's wavelength, convolved with a continuous Gaussian of
   ``psf_sigma_px`` for everything else (aberrations, jitter, charge diffusion): the optical
   convention, a PSF on the focal plane before the pixel integrates it. The render is already
   integrated over each pixel (its pixel filter), so the PSF is applied as its continuous transfer
   function on the pixel grid (:func:`~spacefit.formation.fourier_filter`): ``exp(-2 pi^2 sigma^2 f^2)`` for the
   Gaussian and, for the Airy pattern, the diffraction-limited MTF of a circular pupil (Goodman,
   "Introduction to Fourier Optics", 3rd ed., eq. 6-32), which a pixel grid samples only below its
   Nyquist frequency (half a cycle per px): an Airy disc far smaller than a pixel changes nothing.
   Taken as the same across the field (shift-invariant).
   A flat-field map (the detector's relative response, ``flat=``) multiplies the signal after it.
4. **Noise and digitising** (:func:`~spacefit.formation.observe`): Poisson shot noise in electrons, the full well's clip,
   Gaussian read noise (electrons rms), ``DN = bias + gain * electrons``, rounding to the nearest
   integer and the ADC's range [0, 2^bits - 1].

This module is NumPy only (reading a FITS file needs no JAX): the :class:`Sensor`, its units, its
fields as files and options give them (:func:`check_fields`, :func:`read_sensor_file`) and those a
measurement needs (:func:`used_fields`, :func:`missing_for_measurement`), the flat field's check and
:func:`saturated_mask`, which marks the pixels where the linear model does not hold. The per-pixel
factors of steps 1 and 2 and quantising are :mod:`spacefit.detector`'s; the PSF of step 3 (the Airy
pattern, its transfer function, the PSF's reach and width) is :mod:`spacefit.psf`'s. The image formation itself is in JAX, in
:mod:`spacefit.formation`: ``expected_dn`` (steps 1 to 3 in DN, the noise-free mean, linear
in the radiance, which a fit differentiates), ``noise_variance_dn`` (the Poisson-Gaussian variance of
step 4, Janesick 2007, "Photon Transfer", ch. 2) and ``observe`` (a simulated exposure).
"""

from __future__ import annotations

import dataclasses
import json
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from spacefit.errors import InputError, InputTypeError, check_array, check_choice, check_flag, check_path, check_range, check_type, quote

if TYPE_CHECKING:
    from jaxtyping import Bool, Float

MAX_EXPOSURE_S = 86400.0
"""The longest exposure a sensor takes (one day): longer is a unit slip (ms or us read as s); at 1e300 s a fit's
expected DN overflowed and the fit went NaN."""
MAX_PSF_SIGMA_PX = 100.0
"""The widest Gaussian PSF a sensor has (sigma, px): wider spreads a point over thousands of pixels, and the
image padded by its 5-sigma reach for the Fourier blur grows with it (at 1e300 px XLA aborted the process)."""
SATURATION_MARGIN_READ_SIGMA = 3.0
"""A pixel within this many read-noise sigmas of the full well's DN counts as saturated."""


@dataclass(frozen=True)
class Sensor:
    """A camera's aperture, blur and detector; SI units as in the names.

    Only ``aperture_diameter_m`` is from the thesis (Table 4-2, 10 mm); the other defaults describe
    an illustrative 14-bit scientific CMOS detector whose full well saturates before its ADC does.

    Attributes:
        exposure_time_s: integration time t (s), in (0, :data:`MAX_EXPOSURE_S`].
        aperture_diameter_m: entrance-pupil diameter D (m), > 0; area pi D^2 / 4.
        wavelength_m: effective wavelength (m) of each channel, or one for all: sets the photon
            energy h c / lambda and the Airy pattern's width.
        quantum_efficiency: photo-electrons per photon, in (0, 1].
        gain_dn_per_electron: DN per electron, > 0.
        bias_dn: the ADC's offset (DN) added to every pixel, in [0, 2^bits - 1).
        read_noise_electrons: rms of the Gaussian read noise (electrons), >= 0.
        full_well_electrons: charge a pixel holds (electrons), > 0; None: the ADC saturates first.
        bit_depth: the ADC's bits, 1 to 32: DN in [0, 2^bits - 1].
        psf_sigma_px: sigma (px) of a continuous Gaussian blur on the focal plane besides
            diffraction, before the pixel integrates it (the optical convention), in [0, 100] (0: none).
        diffraction: whether to blur with the aperture's Airy pattern.
        radiometric_scale_dn_per_w_m2_sr: a calibrated camera's DN per W m^-2 sr^-1 (> 0), used in
            place of exposure x aperture x QE / photon energy x gain; None: not calibrated.
        saturation_level_dn: the lowest saturated DN when known directly (FITS ``SATURATE``);
            None: from the full well and the ADC (:attr:`saturation_dn`).
        vignetting: whether the cos^4 fall-off off axis is in the image; None: yes, unless the
            camera is calibrated (``radiometric_scale_dn_per_w_m2_sr`` given: a flat-fielded image).

    Raises:
        InputError: a field outside its range, naming it (``Sensor.bit_depth``, say).

    Example:
        >>> import spacefit as sf
        >>> sensor = sf.Sensor(exposure_time_s=0.002)
        >>> sensor.saturation_dn  # the full well's DN, below the 14-bit ADC's 16383
        16088.0
        >>> try:
        ...     sf.Sensor(bit_depth=40)
        ... except sf.InputError as err:
        ...     print(err)
        `Sensor.bit_depth` must be an integer in [1, 32], got 40.
    """

    exposure_time_s: float = 1e-3
    aperture_diameter_m: float = 0.01
    wavelength_m: tuple[float, ...] = (550e-9,)
    quantum_efficiency: float = 0.6
    gain_dn_per_electron: float = 0.8
    bias_dn: float = 100.0
    read_noise_electrons: float = 5.0
    full_well_electrons: float | None = 20000.0
    bit_depth: int = 14
    psf_sigma_px: float = 0.0
    diffraction: bool = True
    radiometric_scale_dn_per_w_m2_sr: float | None = None
    saturation_level_dn: float | None = None
    vignetting: bool | None = None

    def __post_init__(self) -> None:
        def check(field: str, lo: float, hi: float = math.inf, *, lo_open: bool = False, unit: str = "") -> None:
            check_range(f"Sensor.{field}", getattr(self, field), lo, hi, lo_open=lo_open, unit=unit)

        if isinstance(self.bit_depth, bool) or not isinstance(self.bit_depth, (int, np.integer)) or not 1 <= self.bit_depth <= 32:
            raise InputError(f"`Sensor.bit_depth` must be an integer in [1, 32], got {self.bit_depth!r}.")
        check("exposure_time_s", 0.0, MAX_EXPOSURE_S, lo_open=True, unit="s")
        check("aperture_diameter_m", 0.0, lo_open=True, unit="m")
        check("quantum_efficiency", 0.0, 1.0, lo_open=True)
        check("gain_dn_per_electron", 0.0, lo_open=True, unit="DN per electron")
        check("read_noise_electrons", 0.0, unit="electrons")
        check("psf_sigma_px", 0.0, MAX_PSF_SIGMA_PX, unit="px")
        check_range("Sensor.bias_dn", self.bias_dn, 0.0, self.adc_max_dn, hi_open=True, unit="DN")
        if self.full_well_electrons is not None:
            check("full_well_electrons", 0.0, lo_open=True, unit="electrons")
        check_flag("Sensor.diffraction", self.diffraction)
        if self.vignetting is not None:
            check_flag("Sensor.vignetting", self.vignetting)
        if self.radiometric_scale_dn_per_w_m2_sr is not None:
            check("radiometric_scale_dn_per_w_m2_sr", 0.0, lo_open=True, unit="DN per W m^-2 sr^-1")
        if self.saturation_level_dn is not None:
            check_range("Sensor.saturation_level_dn", self.saturation_level_dn, self.bias_dn, lo_open=True, unit="DN")
        waves = np.atleast_1d(np.asarray(self.wavelength_m, dtype=object))
        if waves.ndim != 1 or waves.size == 0:
            raise InputError(f"`Sensor.wavelength_m` must be one wavelength (m) per channel, got {self.wavelength_m!r}.")
        for i, w in enumerate(waves):
            check_range(f"Sensor.wavelength_m[{i}]", w, 1e-8, 1e-4, unit="m")
        object.__setattr__(self, "wavelength_m", tuple(float(w) for w in waves))
        # the fields typed float held as Python floats whatever number type they are given in (None kept where allowed):
        # an integer past int32's range (a gain of 2**31 DN per electron) overflowed JAX's parsing of it
        for field in dataclasses.fields(self):
            if field.type in ("float", "float | None") and getattr(self, field.name) is not None:
                object.__setattr__(self, field.name, float(getattr(self, field.name)))

    @property
    def aperture_area_m2(self) -> float:
        """Area of the circular aperture, pi D^2 / 4 (m^2)."""
        return math.pi * self.aperture_diameter_m**2 / 4.0

    @property
    def adc_max_dn(self) -> int:
        """The largest DN the ADC writes, 2^bits - 1."""
        return 2**self.bit_depth - 1

    @property
    def calibrated(self) -> bool:
        """Whether the camera gives its radiometric scale (DN per W m^-2 sr^-1) directly."""
        return self.radiometric_scale_dn_per_w_m2_sr is not None

    @property
    def vignetted(self) -> bool:
        """Whether the cos^4 fall-off is applied: ``vignetting``, or by default unless :attr:`calibrated`."""
        return (not self.calibrated) if self.vignetting is None else self.vignetting

    @property
    def saturation_dn(self) -> float:
        """The lowest DN counted as saturated: ``saturation_level_dn`` if given, else the ADC's
        maximum, or the full well's DN less a margin of read noise."""
        if self.saturation_level_dn is not None:
            return float(self.saturation_level_dn)
        if self.full_well_electrons is None:
            return float(self.adc_max_dn)
        well = self.bias_dn + self.gain_dn_per_electron * (self.full_well_electrons - SATURATION_MARGIN_READ_SIGMA * self.read_noise_electrons)
        return float(min(self.adc_max_dn, well))

    def wavelengths(self, channels: int) -> tuple[float, ...]:
        """The wavelength (m) of each of ``channels`` channels; refuses a count that does not match."""
        if len(self.wavelength_m) == 1:
            return self.wavelength_m * channels
        if len(self.wavelength_m) != channels:
            raise InputError(f"`Sensor.wavelength_m` has {len(self.wavelength_m)} wavelengths for an image of {channels} channels; give one per channel or one for all.")
        return self.wavelength_m

    def to_dict(self) -> dict[str, Any]:
        """Every field as plain JSON values; :meth:`from_dict` rebuilds it."""
        d = dataclasses.asdict(self)
        d["wavelength_m"] = list(self.wavelength_m)
        return d

    @classmethod
    def from_dict(cls, fields: Mapping[str, Any], where: str = "sensor") -> Sensor:
        """A sensor from some or all of its fields (the others take their defaults), checked;
        ``where`` names the source in messages (a file, an argument)."""
        check_fields(fields, where)
        try:
            return cls(**fields)
        except InputError as err:
            raise type(err)(f"{where}: {err}") from None


def check_fields(fields: Any, where: str) -> dict[str, Any]:
    """``fields`` as a table of :class:`Sensor` fields, checked by name (the closest suggested) and
    by type: numbers, not strings (``gain_dn_per_electron = "2.0"`` is refused); ``diffraction`` and
    ``vignetting`` true or false; None (JSON ``null``) only where a field may be None. ``where``
    names the source (a file, an option) in messages; the ranges are :class:`Sensor`'s."""
    if not isinstance(fields, Mapping):
        raise InputTypeError(f"{where} must be a table of sf.Sensor's fields, got {quote(fields)}.")
    kinds = {f.name: str(f.type) for f in dataclasses.fields(Sensor)}
    for key, value in fields.items():
        kind = kinds[check_choice(f"{where}: field", key, kinds)]
        try:
            if value is None and "None" in kind:
                continue
            if kind.startswith("bool"):
                check_flag(key, value)
            elif kind.startswith("tuple"):  # wavelength_m: one number or one per channel
                for i, v in enumerate(value if isinstance(value, (list, tuple, np.ndarray)) else [value]):
                    check_range(f"{key}[{i}]", v)
            else:
                check_range(key, value)
        except InputError as err:
            raise type(err)(f"{where}: {err}") from None
    return dict(fields)


SCALE_FIELD = "radiometric_scale_dn_per_w_m2_sr"
RESPONSE_FIELDS = ("exposure_time_s", "aperture_diameter_m", "wavelength_m", "quantum_efficiency")
"""What an uncalibrated camera needs to turn radiance into electrons (a calibrated one: its :data:`SCALE_FIELD`)."""
DETECTOR_FIELDS = ("gain_dn_per_electron", "read_noise_electrons", "bias_dn", "psf_sigma_px")
"""What every measurement needs: the noise model's gain and read noise, the offset, the PSF's width."""


def used_fields(sensor: Sensor) -> tuple[str, ...]:
    """The fields of ``sensor`` that change a fit's likelihood (its expected DN, noise, saturation
    or PSF), in the order of :class:`Sensor`'s fields."""
    names = {SCALE_FIELD} if sensor.calibrated else set(RESPONSE_FIELDS)
    names |= {*DETECTOR_FIELDS, "diffraction", "vignetting"}
    names |= {"saturation_level_dn"} if sensor.saturation_level_dn is not None else {"full_well_electrons", "bit_depth"}
    if sensor.diffraction:
        names |= {"aperture_diameter_m", "wavelength_m"}
    return tuple(f.name for f in dataclasses.fields(Sensor) if f.name in names)


def missing_for_measurement(given: Mapping[str, Any]) -> list[str]:
    """What a fit of a sensor's observation needs and ``given`` (the fields the files and the user
    gave) lacks: the radiometric response (a scale, or exposure, aperture, wavelength and QE), gain,
    read noise, bias, the PSF's sigma, and a saturation level (``saturation_level_dn`` or
    ``bit_depth``); with ``diffraction`` the aperture and wavelength. Each as ``field`` or
    ``field (or other)``."""
    calibrated = given.get(SCALE_FIELD) is not None
    missing = [] if calibrated else [f"{n} (or {SCALE_FIELD})" for n in RESPONSE_FIELDS if n not in given]
    missing += [n for n in DETECTOR_FIELDS if n not in given]
    if given.get("saturation_level_dn") is None and "bit_depth" not in given:
        missing.append("saturation_level_dn (or bit_depth)")
    if given.get("diffraction") is True and calibrated:
        missing += [f"{n} (for diffraction)" for n in ("aperture_diameter_m", "wavelength_m") if n not in given]
    return missing


def read_sensor_file(path: str | Path) -> dict[str, Any]:
    """The fields of :class:`Sensor` in a JSON or TOML file, checked (unknown fields and bad values
    refused, naming the file): a table of fields, or a file whose ``sensor`` table holds them (a
    spacefit sidecar ``obs.fits.json``). TOML has no null: a sensor without a full well
    (``full_well_electrons = null``) is written as JSON.

    Args:
        path: a ``.json`` or ``.toml`` file.

    Returns:
        The fields by name, as :class:`Sensor` takes them (``sf.Sensor(**fields)``).

    Raises:
        InputError: a missing or unreadable file, an unknown field or a bad value, naming the file.

    Example:
        >>> import json, spacefit as sf
        >>> with open("camera.json", "w") as f:
        ...     json.dump({"exposure_time_s": 0.002, "gain_dn_per_electron": 1.0}, f)
        >>> fields = sf.read_sensor_file("camera.json")
        >>> sf.Sensor(**fields).exposure_time_s
        0.002
    """
    p = check_path("path", path)
    if not p.is_file():
        raise InputError(f"sensor file {str(p)!r} does not exist.")
    suffix = p.suffix.lower()
    if suffix not in (".json", ".toml"):
        raise InputError(f"sensor file {str(p)!r} must be .json or .toml, got {suffix or '(no extension)'!r}.")
    try:
        data = json.loads(p.read_text()) if suffix == ".json" else tomllib.loads(p.read_text())
    except (ValueError, UnicodeDecodeError) as err:
        raise InputError(f"sensor file {str(p)!r} could not be read as {suffix[1:].upper()}: {err}") from None
    fields = data.get("sensor", data) if isinstance(data, dict) else data
    Sensor.from_dict(fields, f"sensor file {str(p)!r}")
    return dict(fields)


def check_flat(flat: Any, shape: tuple[int, ...], where: str = "`flat`") -> np.ndarray:
    """A flat-field map checked against an image of ``shape`` (h, w, c): (h, w) or (h, w, c or 1),
    finite and > 0; returned as (h, w, 1 or c) float64."""
    f = check_array(where.strip("`"), flat).astype(float)
    f = f[..., None] if f.ndim == 2 else f
    if f.ndim != 3 or f.shape[:2] != tuple(shape[:2]) or f.shape[2] not in (1, shape[2]):
        raise InputError(f"{where} has shape {np.shape(flat)}; the image is {tuple(shape)}: give (height, width) or (height, width, channels).")
    bad = int(np.count_nonzero(~(np.isfinite(f) & (f > 0))))
    if bad:
        raise InputError(f"{where} must be finite and > 0 (the detector's relative response); {bad} values are not.")
    return f


def saturated_mask(dn: Float[np.ndarray, "..."], sensor: Sensor) -> Bool[np.ndarray, "..."]:
    """True where a DN (observed or expected, any shape) is at or above ``sensor.saturation_dn``.

    Saturated pixels carry no information on the signal: a fit leaves them out.

    Args:
        dn: DN values, any shape.
        sensor: the sensor (:attr:`Sensor.saturation_dn`).

    Returns:
        A boolean array of ``dn``'s shape.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> sf.saturated_mask(np.array([100.0, 16383.0]), sf.Sensor())
        array([False,  True])
    """
    check_type("sensor", sensor, Sensor, "an sf.Sensor")
    return check_array("dn", dn) >= sensor.saturation_dn
