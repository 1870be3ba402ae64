"""Observation files: simulated DN written as 16-bit PNG, TIFF or FITS; references read from EXR, FITS, PNG, TIFF.

Writing (:func:`write_observation`) stores integer DN (from :func:`spacefit.formation.observe`) and
every :class:`~spacefit.sensor.Sensor` value twice: in a JSON sidecar ``<file>.json`` and, for FITS,
in the header (standard keys where they exist, ``HIERARCH SPACEFIT SENSOR <FIELD>`` for all).

Reading (:func:`read_image`) returns an :class:`ObservedImage`: float data, its unit (``"DN"`` or
radiance), the metadata found, and the mask of usable pixels (not saturated, not transparent, in the user's
mask). What each format holds:

* EXR: radiance (W m^-2 sr^-1), as spacefit renders write it; a ``RENDSPP`` attribute in its header
  (:data:`RENDER_SPP_KEY`, which spacefit's simulated references carry) is read as in FITS.
* FITS: radiance if ``BUNIT`` says ``W m-2 sr-1``, otherwise DN. Every keyword with a sensor
  meaning is read (:data:`HEADER_KEYWORDS`; the first of a field's aliases present counts, and
  aliases that disagree are refused): ``EXPTIME`` / ``EXPOSURE`` (s), ``GAIN`` / ``EGAIN``
  (electrons per DN, the FITS convention, the inverse of ``Sensor.gain_dn_per_electron``),
  ``RDNOISE`` / ``READNOIS`` / ``RON`` (electrons rms), ``BIAS`` / ``PEDESTAL`` (the DN offset added
  to every pixel), ``SATURATE`` (DN), ``RADSCALE`` (DN per W m^-2 sr^-1, a calibrated camera),
  ``PSFSIGMA`` (px, the continuous Gaussian PSF's sigma), the bits of integer data (``BITPIX``),
  spacefit's ``HIERARCH SPACEFIT SENSOR <field>`` for every field, ``DATE-OBS`` (kept as an
  ISO time in ``metadata["date_obs"]``) and ``RENDSPP`` (:data:`RENDER_SPP_KEY`: a simulated
  observation's samples per pixel, whose Monte Carlo noise the goodness of fit expects; kept in
  ``metadata["render_spp"]``; a file without it, from another writer, is a real observation).
* Row order. spacefit's arrays run top-down. A FITS file's rows are read in the order it states,
  first found of: the ``row_order`` argument; ``ROWORDER = 'TOP-DOWN'`` or ``'BOTTOM-UP'``; a
  celestial WCS's parity (the sky seen from inside, north up and east left as sky images show it,
  has det(CD) < 0 with its first row at the bottom: det < 0 is read bottom-up, det > 0, a mirrored
  sky, top-down; optics with a mirror break this rule: give ``row_order``); else the FITS standard
  (4.0, section 8.1: the first row is the bottom, as DS9 shows it), with a warning and a note.
  ``metadata`` says which (``row_order``, ``row_order_source``, ``notes``).
* PNG and TIFF: integer values whose response must be named: ``"linear"`` (DN) or ``"srgb"`` (the
  sRGB encoding, IEC 61966-2-1, decoded to values linear in light, scaled to the file's full scale).
  A spacefit sidecar names it for its own files.

Saturated values are masked: at or above the FITS ``SATURATE`` keyword, else the sidecar's sensor
``saturation_dn``, else the integer type's full scale (2^bits - 1); float DN without either has no
saturation mask. Pixels a user mask or a PNG's alpha leaves out are not checked and read as 0.
:func:`sensor_of` gives the sensor of a DN image.

What is refused, naming the file (:class:`~spacefit.errors.InputError`): an image of other than 1
(grey) or 3 (RGB) channels, a FITS cube's planes (NAXIS3) included; alpha is read as a mask (0
leaves the pixel out, any other value keeps it as it is) in PNG and in TIFF with an unassociated
alpha (ExtraSamples = 2), and refused elsewhere (an RGBA EXR, a TIFF's unmarked fourth sample); a
FITS file shorter than its headers say (truncated); a sidecar that is not a JSON object, or whose
sensor values are not numbers (``"2.0"``) or not true / false; a mask with values other than 0 and 1
(or the integer type's full scale), NaN included, or one that leaves out every pixel.
"""

from __future__ import annotations

import dataclasses
import json
import warnings
from dataclasses import dataclass
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import colour
import numpy as np
import tifffile
from astropy.io import fits

from spacefit.errors import NEGATIVE_SIGMAS, InputError, InputTypeError, check_array, check_choice, check_count, check_path, check_range, check_type, negative_pixels, quote
from spacefit.sensor import Sensor, check_fields, missing_for_measurement, used_fields
from spacefit.units import DN_UNIT, RADIANCE_UNIT

if TYPE_CHECKING:
    from jaxtyping import Bool, Float

UNITS = {"DN": DN_UNIT, "radiance": RADIANCE_UNIT}
RESPONSES = ("linear", "srgb")
FORMATS = {".exr": "exr", ".fits": "fits", ".fit": "fits", ".fts": "fits", ".png": "png", ".tif": "tiff", ".tiff": "tiff"}
WRITABLE = (".fits", ".fit", ".fts", ".png", ".tif", ".tiff")
FITS_RADIANCE_UNIT = "W m-2 sr-1"
FITS_SENSOR_KEY = "SPACEFIT SENSOR"
ROW_ORDERS = ("top-down", "bottom-up")
CHANNELS = (1, 3)
"""The channels an image may hold: grey or RGB (a PNG's or TIFF's alpha besides, read as a mask)."""
SENSOR_DEFAULTS = ("illustrative",)
RENDER_SPP_KEY = "RENDSPP"
"""The FITS keyword and EXR header attribute (and, as ``render_spp``, the sidecar key) of a simulated
observation's samples per pixel: its render's Monte Carlo noise, which the goodness of fit counts
(:mod:`spacefit.fitting.goodness`)."""
HEADER_KEYWORDS = {
    "exposure_time_s": ("EXPTIME", "EXPOSURE"),
    "gain_dn_per_electron": ("GAIN", "EGAIN"),  # electrons per DN in the header: inverted
    "read_noise_electrons": ("RDNOISE", "READNOIS", "RON"),
    "bias_dn": ("BIAS", "PEDESTAL"),
    "saturation_level_dn": ("SATURATE",),
    "radiometric_scale_dn_per_w_m2_sr": ("RADSCALE",),
    "psf_sigma_px": ("PSFSIGMA",),
}
"""Standard FITS keywords of :class:`Sensor` fields, aliases in order of precedence; every field
also has spacefit's own ``HIERARCH SPACEFIT SENSOR <field>``, and ``bit_depth`` an integer image's ``BITPIX``."""


class RowOrderWarning(UserWarning):
    """A FITS image states no row order: it is read by the FITS standard (first row = bottom)."""


@dataclass(frozen=True)
class ObservedImage:
    """An image read from a file.

    Attributes:
        data: (height, width, channels) float64 values in ``unit``.
        unit: ``"DN"`` or ``"W m^-2 sr^-1"``.
        mask: (height, width, channels) bool, True where a value can be used.
        metadata: what the file said: ``format``, ``response``, ``saturation_dn`` (None: unknown),
            ``header`` (FITS cards), ``sensor_found`` (field -> [value, source], every sensor
            value the file gives: header keywords, the data type's bits, the sidecar),
            ``date_obs`` (ISO time, FITS ``DATE-OBS``), ``row_order`` and ``row_order_source``
            (FITS), ``notes`` (what a report should say about the file), ``sidecar`` (its content).
        path: the file read.
    """

    data: Float[np.ndarray, "h w c"]
    unit: str
    mask: Bool[np.ndarray, "h w c"]
    metadata: dict[str, Any]
    path: str


def sidecar_path(path: str | Path) -> Path:
    """The JSON sidecar of an observation file: ``obs.fits`` -> ``obs.fits.json``."""
    p = Path(path)
    return p.with_name(p.name + ".json")


def _format(path: Path, allowed: tuple[str, ...]) -> str:
    suffix = path.suffix.lower()
    if suffix not in allowed:
        raise InputError(f"{str(path)!r}: unknown image format {suffix or '(no extension)'!r}; supported: {', '.join(allowed)}.")
    return FORMATS[suffix]


def write_observation(path: str | Path, dn: np.ndarray, sensor: Sensor, metadata: dict[str, Any] | None = None, *,
                      render_spp: int | None = None) -> Path:
    """Write integer DN as 16-bit PNG, TIFF or FITS (by the extension) with its JSON sidecar.

    Args:
        path: ``.png``, ``.tif`` / ``.tiff`` or ``.fits`` / ``.fit`` / ``.fts``.
        dn: (height, width, channels) unsigned integers (1 or 3 channels for PNG) in the sensor's
            ADC range, as :func:`spacefit.formation.observe` returns.
        sensor: the sensor that made them; all its values go to the sidecar and the FITS header.
        metadata: anything JSON can hold, added to the sidecar under ``metadata``.
        render_spp: the samples per pixel of the render the DN were simulated from (FITS
            :data:`RENDER_SPP_KEY`, sidecar ``render_spp``); None: not a simulation.
    Returns:
        the sidecar's path.
    """
    p = Path(path)
    kind = _format(p, WRITABLE)
    check_count("render_spp", render_spp)
    data = check_array("dn", dn)
    if data.ndim != 3 or data.dtype.kind != "u":
        raise InputError(f"`dn` must be (height, width, channels) unsigned integers, got {data.dtype} of shape {data.shape}.")
    if data.size and int(data.max()) > sensor.adc_max_dn:
        raise InputError(f"`dn` holds {int(data.max())}, above the sensor's 2^{sensor.bit_depth} - 1 = {sensor.adc_max_dn} DN.")
    if kind == "png":
        if sensor.bit_depth > 16 or data.shape[2] not in (1, 3):
            raise InputError(f"{str(p)!r}: a PNG holds 1 or 3 channels of up to 16 bits; this is {data.shape[2]} channels of {sensor.bit_depth} bits: write TIFF or FITS.")
        from spacefit.rendering.png import write_png  # deferred: Mitsuba (seconds to import), for its Bitmap: Pillow cannot write 16-bit colour

        write_png(p, data.astype(np.uint16))
    elif kind == "tiff":
        tifffile.imwrite(p, data if data.shape[2] > 1 else data[..., 0], photometric="rgb" if data.shape[2] == 3 else "minisblack")
    else:
        planes = np.moveaxis(data[::-1], -1, 0)  # FITS rows run bottom-up; channels are NAXIS3
        header = _fits_header(sensor)
        if render_spp is not None:
            header[RENDER_SPP_KEY] = (render_spp, "samples per pixel of the simulated render")
        fits.PrimaryHDU(np.ascontiguousarray(planes if data.shape[2] > 1 else planes[0]), header=header).writeto(p, overwrite=True)
    side = sidecar_path(p)
    defaults = [f.name for f in dataclasses.fields(Sensor) if getattr(sensor, f.name) == f.default]
    content = {"unit": "DN", "response": "linear", "saturation_dn": sensor.saturation_dn, "sensor": sensor.to_dict(),
               "sensor_defaults": defaults, "metadata": metadata or {},
               **({} if render_spp is None else {"render_spp": render_spp})}
    side.write_text(json.dumps(content, indent=2))
    return side


def _read_render_spp(meta: dict[str, Any], header: Mapping[str, Any], where: str) -> None:
    """Take a file header's :data:`RENDER_SPP_KEY` into ``meta["render_spp"]`` (the file outranks its
    sidecar), checked as a count (``where`` names it)."""
    if RENDER_SPP_KEY in header:
        meta["render_spp"] = header[RENDER_SPP_KEY]
        check_count(where, meta["render_spp"])


def _fits_header(sensor: Sensor) -> fits.Header:
    h = fits.Header()
    h["BUNIT"] = ("adu", "digital numbers (DN)")
    h["ROWORDER"] = ("BOTTOM-UP", "first row is the image's bottom (FITS standard)")
    h["EXPTIME"] = (sensor.exposure_time_s, "[s] exposure time")
    h["GAIN"] = (1.0 / sensor.gain_dn_per_electron, "[electron/adu] inverse of the ADC gain")
    h["RDNOISE"] = (sensor.read_noise_electrons, "[electron] read noise rms")
    h["BIAS"] = (sensor.bias_dn, "[adu] offset added to every pixel")
    h["PSFSIGMA"] = (sensor.psf_sigma_px, "[pixel] sigma of the continuous Gaussian PSF")
    if sensor.calibrated:
        h["RADSCALE"] = (sensor.radiometric_scale_dn_per_w_m2_sr, "[adu / (W m-2 sr-1)] radiometric scale")
    h["SATURATE"] = (sensor.saturation_dn, "[adu] lowest saturated value")
    for name, value in sensor.to_dict().items():
        if isinstance(value, list):
            for i, v in enumerate(value):
                h[f"HIERARCH {FITS_SENSOR_KEY} {name} {i}"] = v
        else:
            h[f"HIERARCH {FITS_SENSOR_KEY} {name}"] = value
    return h


def _sensor_from_header(header: fits.Header) -> dict[str, Any] | None:
    prefix = f"{FITS_SENSOR_KEY} "
    found = {k[len(prefix) :]: v for k, v in header.items() if k.startswith(prefix)}
    if not found:
        return None
    out: dict[str, Any] = {}
    for field in dataclasses.fields(Sensor):
        if field.name == "wavelength_m":
            indexed = sorted((int(k.split()[-1]), v) for k, v in found.items() if k.startswith("wavelength_m "))
            out["wavelength_m"] = [v for _, v in indexed]
        elif field.name in found:
            out[field.name] = found[field.name]
    return {**{k: v for k, v in found.items() if not k.startswith("wavelength_m ")}, **out}  # unknown keys kept: refused by name


def _header_sensor(header: fits.Header, data: np.ndarray, path: Path) -> dict[str, tuple[Any, str]]:
    """Every sensor value of a FITS header as field -> (value, source): standard keywords, then
    the data's bits (``BITPIX``), then spacefit's own keys, each replacing the ones before."""
    found: dict[str, tuple[Any, str]] = {}
    for field, keys in HEADER_KEYWORDS.items():
        present = [(k, header[k]) for k in keys if k in header and header[k] is not None and not isinstance(header[k], fits.card.Undefined)]
        for key, value in present:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InputError(f"{str(path)!r}: the FITS header's {key} = {value!r} is not a number ({field}); correct it or give the value "
                                 "(`sensor=`, --sensor-value).")
        values = {float(v) for _, v in present}
        if len(values) > 1:
            raise InputError(f"{str(path)!r}: the FITS header gives {field} {len(values)} ways: {', '.join(f'{k} = {v}' for k, v in present)}; "
                             "make them agree or give the value (`sensor=`, --sensor-value).")
        if present:
            key, value = present[0]
            found[field] = (1.0 / float(value) if field == "gain_dn_per_electron" else float(value), f"header {key}")
    if data.dtype.kind in "ui":
        found["bit_depth"] = (8 * data.dtype.itemsize, "header BITPIX")
    own = check_fields(_sensor_from_header(header) or {}, f"{str(path)!r}: the FITS header's HIERARCH {FITS_SENSOR_KEY} cards")
    found.update({k: (v, f"header {FITS_SENSOR_KEY} {k}") for k, v in own.items()})
    return found


def _wcs_row_order(header: fits.Header) -> str | None:
    """The row order a celestial WCS implies by its parity (see the module), or None without one."""
    from astropy.wcs import WCS, FITSFixedWarning  # deferred: astropy.wcs takes 0.7 s; only a FITS header with a WCS needs it

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FITSFixedWarning)
        try:
            wcs = WCS(header, naxis=2)
        except (ValueError, KeyError, MemoryError):
            return None
    if not wcs.has_celestial or wcs.wcs.lng < 0 or wcs.wcs.lat < 0:
        return None
    det = float(np.linalg.det(wcs.pixel_scale_matrix)) * (1.0 if wcs.wcs.lng < wcs.wcs.lat else -1.0)
    if not np.isfinite(det) or det == 0.0:
        return None
    return "bottom-up" if det < 0 else "top-down"


def _row_order(header: fits.Header, row_order: str | None, path: Path) -> tuple[str, str, list[str]]:
    """The row order of a FITS image, its source and notes (see the module)."""
    notes = []
    implied = _wcs_row_order(header)
    stated = str(header.get("ROWORDER", "")).strip().lower() or None
    if stated is not None and stated not in ROW_ORDERS:
        raise InputError(f"{str(path)!r}: ROWORDER = {header['ROWORDER']!r} is neither 'TOP-DOWN' nor 'BOTTOM-UP'; "
                         "give the order (`row_order=`, --row-order).")
    if row_order is not None:
        return row_order, "option/argument", notes
    if stated is not None:
        if implied is not None and implied != stated:
            notes.append(f"ROWORDER = {stated.upper()!r} was used; the WCS's parity implies {implied}.")
        return stated, "header ROWORDER", notes
    if implied is not None:
        return implied, "header WCS (parity of the sky)", notes
    note = (f"{path.name}: no ROWORDER and no celestial WCS: rows read by the FITS standard (first row = bottom); "
            "give row_order= (--row-order) if it was written top-down.")
    warnings.warn(note, RowOrderWarning, stacklevel=4)
    return "bottom-up", "FITS standard (no ROWORDER, no WCS)", [note]


def _image_hdu(hdus: fits.HDUList, path: Path) -> fits.PrimaryHDU | fits.ImageHDU | fits.CompImageHDU:
    """The first HDU with an image of 2 or more axes, after checking that the file holds every byte
    its headers promise up to it (a truncated copy would fail inside astropy)."""
    size = path.stat().st_size
    for index, hdu in enumerate(hdus):
        expected = hdu.fileinfo()["datLoc"] + hdu.size
        if expected > size:
            raise InputError(f"{str(path)!r} is truncated: the header of HDU {index} promises data up to byte {expected}, "
                             f"the file holds {size} bytes.")
        if hdu.data is not None and hdu.data.ndim >= 2:
            return hdu
    raise InputError(f"{str(path)!r} holds no image (no HDU with 2 or 3 axes).")


def _read_fits(path: Path, row_order: str | None = None) -> tuple[np.ndarray, fits.Header, tuple[str, str, list[str]]]:
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", "File may have been truncated")  # refused below, in words
            with fits.open(path) as hdus:
                hdu = _image_hdu(hdus, path)
                data, header = np.array(hdu.data), hdu.header.copy()
    except (OSError, TypeError, ValueError) as err:  # astropy raises TypeError or ValueError for a damaged data unit
        raise InputError(f"{str(path)!r} could not be read as FITS: {err}") from None
    if data.ndim == 2:
        data = data[None]
    if data.ndim != 3:
        raise InputError(f"{str(path)!r}: a FITS image must have 2 or 3 axes (x, y, channel), it has {data.ndim}.")
    if data.shape[0] not in CHANNELS:
        raise InputError(f"{str(path)!r}: a FITS cube of {data.shape[0]} planes (NAXIS3 = {data.shape[0]}; numpy shape "
                         f"{data.shape}, planes first); an image holds 1 plane (grey) or 3 (RGB): write one of them per file.")
    order = _row_order(header, row_order, path)
    planes = np.moveaxis(data, 0, -1)
    return (planes[::-1] if order[0] == "bottom-up" else planes), header, order


def _read_tiff(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """TIFF values and, when its last sample is an unassociated alpha (ExtraSamples = 2, as PNG's), the alpha channel."""
    try:
        with tifffile.TiffFile(path) as tif:
            series = tif.series[0]
            data, axes = series.asarray(), series.axes
            alpha = tifffile.EXTRASAMPLE.UNASSALPHA in tuple(tif.pages[0].extrasamples or ())
    except (OSError, tifffile.TiffFileError) as err:
        raise InputError(f"{str(path)!r} could not be read as TIFF: {err}") from None
    if data.ndim == 2:
        data = data[..., None]
    elif axes == "SYX":
        data = np.moveaxis(data, 0, -1)
    elif axes != "YXS":
        raise InputError(f"{str(path)!r}: a TIFF must hold one image (axes YX, YXS or SYX), it has axes {axes}.")
    return (data[..., :-1], data[..., -1]) if alpha and data.shape[2] in (2, 4) else (data, None)


def _read_png(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """PNG values and, for grey-alpha or RGBA files, the alpha channel."""
    from spacefit.rendering.png import read_png  # deferred: Mitsuba (seconds to import), for its Bitmap: Pillow reduces 16-bit colour to 8 bits

    data = read_png(path)
    if data.shape[2] in (2, 4):
        return data[..., :-1], data[..., -1]
    return data, None


def _user_mask(mask: str | Path | np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """A (height, width) bool from a mask image or array of 0 (leave the pixel out) and 1 or the
    integer type's full scale (use it), in any channel; NaN, other values, and a mask that leaves
    out every pixel are refused (NaN would otherwise read as "use")."""
    where = "`mask`"
    if isinstance(mask, (str, Path)):
        p = Path(mask)
        where = f"mask file {str(p)!r}"
        if not p.is_file():
            raise InputError(f"{where} does not exist.")
        kind = _format(p, (".fits", ".fit", ".fts", ".png", ".tif", ".tiff"))
        values = _read_fits(p)[0] if kind == "fits" else _read_tiff(p)[0] if kind == "tiff" else _read_png(p)[0]
    else:
        values = np.asarray(mask)
    values = values[..., None] if values.ndim == 2 else values
    if values.ndim != 3:
        raise InputError(f"{where} must be (height, width) or (height, width, channels), got shape {values.shape}.")
    if values.shape[:2] != shape[:2]:
        raise InputError(f"{where} is {values.shape[1]} x {values.shape[0]} px, the image {shape[1]} x {shape[0]} px.")
    use = [1, np.iinfo(values.dtype).max] if values.dtype.kind in "ui" else [1]
    bad = ~np.isin(values, [0, *use]) if values.dtype != bool else np.zeros(values.shape, bool)
    if bad.any():
        raise InputError(f"{where}: {int(np.count_nonzero(bad))} values are neither 0 (leave the pixel out) nor "
                         f"{' or '.join(map(str, use))} (use it), e.g. {quote(values[bad][0].item())}; a mask is binary.")
    included = np.any(values != 0, axis=-1)
    if not included.any():
        raise InputError(f"{where} leaves out all {included.size} pixels: nothing would be fitted.")
    return included


def read_image(path: str | Path, *, unit: str | None = None, response: str | None = None, mask: str | Path | np.ndarray | None = None,
               sigma: float | np.ndarray | None = None, row_order: str | None = None) -> ObservedImage:
    """Read a reference or observation, refusing what cannot be used as asked.

    Args:
        path: ``.exr``, ``.fits`` / ``.fit`` / ``.fts``, ``.png``, ``.tif`` / ``.tiff``.
        unit: ``"radiance"`` or ``"DN"`` to require one; None takes the file's.
        response: for PNG and TIFF, ``"linear"`` or ``"srgb"``; not needed for spacefit's own files.
        mask: a mask image (FITS, PNG, TIFF) or (height, width) array: 0 leaves the pixel out, 1 (or
            the integer type's full scale, 255 in an 8-bit PNG; True) uses it; other values are refused.
            Pixels it (or a PNG's alpha) leaves out may hold anything, NaN included: they read as 0.
        sigma: the noise standard deviation of a radiance image (W m^-2 sr^-1, scalar or per
            pixel): its values may then dip below 0 by up to :data:`NEGATIVE_SIGMAS` sigma.
        row_order: ``"top-down"`` or ``"bottom-up"``: how a FITS file's rows run, whatever it says
            (None: as it states, see the module).
    Returns:
        the data, unit, metadata and usable-pixel mask (see :class:`ObservedImage`).
    Raises:
        InputError: missing file, unknown format, a display image asked for as radiance, PNG / TIFF
            without a response, NaN or infinity (any unit), negative radiance, other than 1 or 3
            channels, a truncated FITS, a malformed sidecar, a mask of another size, not binary or
            empty; each naming the file and the number of pixels or values.
    """
    wanted = UNITS[check_choice("unit", unit, UNITS)] if unit is not None else None
    if response is not None:
        check_choice("response", response, RESPONSES)
    if row_order is not None:
        check_choice("row_order", row_order, ROW_ORDERS)
    p = check_path("path", path)
    if not p.is_file():
        raise InputError(f"image file {str(p)!r} does not exist.")
    kind = _format(p, tuple(FORMATS))
    sidecar = _read_sidecar(sidecar_path(p))
    meta: dict[str, Any] = {"format": kind, "response": "linear", "saturation_dn": None, "notes": [], "sensor_found": {},
                            "render_spp": None}
    if sidecar is not None:
        meta["sidecar"] = sidecar
        meta["saturation_dn"] = sidecar.get("saturation_dn")
        meta["render_spp"] = sidecar.get("render_spp")
    alpha = None
    if kind in ("exr", "fits") and response not in (None, "linear"):
        raise InputError(f"{str(p)!r}: `response` applies to PNG and TIFF; {kind.upper()} data are linear.")
    if kind == "exr":
        if wanted == "DN":
            raise InputError(f"{str(p)!r}: an EXR holds radiance (W m^-2 sr^-1), not DN; read it with unit='radiance'.")
        from spacefit.rendering.exr import read_exr_with_header  # deferred: it imports Mitsuba (seconds), only for EXR

        (raw, header), found_unit = read_exr_with_header(p), RADIANCE_UNIT
        _read_render_spp(meta, header, f"{str(p)!r}: the EXR header's {RENDER_SPP_KEY}")
    elif kind == "fits":
        raw, header, (meta["row_order"], meta["row_order_source"], notes) = _read_fits(p, row_order)
        found_unit = _fits_unit(header, wanted, p)
        meta["notes"] += notes
        meta["header"] = {k: v for k, v in header.items() if k not in ("COMMENT", "HISTORY", "")}
        meta["sensor_found"] = _header_sensor(header, raw, p)
        if "DATE-OBS" in header:
            meta["date_obs"] = _iso_time(header["DATE-OBS"], p)
        if "SATURATE" in header:
            meta["saturation_dn"] = float(header["SATURATE"])
        _read_render_spp(meta, header, f"{str(p)!r}: the FITS header's {RENDER_SPP_KEY}")
    else:
        raw, alpha = _read_tiff(p) if kind == "tiff" else _read_png(p)
        bits = 8 * raw.dtype.itemsize if raw.dtype.kind in "ui" else None
        what = f"an {bits}-bit {kind.upper()}" if bits else f"a floating-point {kind.upper()}"
        if wanted == RADIANCE_UNIT:
            hint = "a display image; " if bits == 8 else ""
            raise InputError(f"{str(p)!r} is {what}: {hint}it holds digital numbers, not radiance (W m^-2 sr^-1). Give the render's radiance .exr, or read it as DN with its response (response='linear' or 'srgb').")
        response = response or (sidecar or {}).get("response")
        if response is None:
            raise InputError(f"{str(p)!r} is {what} of unknown response; say how its values encode light: response='linear' (DN) or response='srgb' (sRGB-encoded).")
        meta["response"] = response
        found_unit = "DN"
        if bits:
            meta["sensor_found"]["bit_depth"] = (bits, f"file data type ({raw.dtype})")
    if sidecar is not None and sidecar.get("sensor") is not None:
        in_header = {k for k, (_, source) in meta["sensor_found"].items() if source.startswith("header")}  # the file outranks its sidecar
        found = {**meta["sensor_found"], **{k: (v, "spacefit sidecar") for k, v in sidecar["sensor"].items() if k not in in_header}}
        illustrative = set(sidecar.get("sensor_defaults", ()))
        meta["sensor_found"] = {k: (v, source + (" (simulated with an illustrative default)" if k in illustrative else ""))
                                for k, (v, source) in found.items()}
    if raw.shape[2] not in CHANNELS:  # a FITS cube is refused where it is read, naming its axes
        raise InputError(f"{str(p)!r}: {kind.upper()} image of {raw.shape[2]} channels (shape {raw.shape}, channels last); "
                         "an image holds 1 channel (grey) or 3 (RGB); an alpha channel is read as a mask only in PNG and in TIFF "
                         "(unassociated alpha).")
    values = np.asarray(raw, dtype=float)
    full_scale = float(np.iinfo(raw.dtype).max) if raw.dtype.kind in "ui" else None
    if meta["saturation_dn"] is None:
        meta["saturation_dn"] = full_scale if found_unit == "DN" else None
    included = np.ones(values.shape[:2], dtype=bool)
    if alpha is not None:
        included &= alpha > 0
    if mask is not None:
        included &= _user_mask(mask, values.shape)
    _check_values(values, found_unit, p, included, sigma)
    values[~included] = 0.0
    usable = np.broadcast_to(included[..., None], values.shape).copy()
    if meta["saturation_dn"] is not None:
        usable &= values < meta["saturation_dn"]
    if meta["response"] == "srgb":
        scale = full_scale or 1.0
        values = np.asarray(colour.cctf_decoding(values / scale, function="sRGB")) * scale
    return ObservedImage(values, found_unit, usable, meta, str(p))


def _read_sidecar(path: Path) -> dict[str, Any] | None:
    """An observation's JSON sidecar (None if there is none), checked: a JSON object whose
    ``sensor`` is a table of :class:`Sensor` fields (numbers, not strings), ``response`` one of
    :data:`RESPONSES`, ``saturation_dn`` a number or null and ``sensor_defaults`` a list of field names."""
    if not path.is_file():
        return None
    where = f"sidecar {str(path)!r}"
    try:
        content = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as err:  # json.JSONDecodeError is a ValueError
        raise InputError(f"{where} is not valid JSON: {err}") from None
    if not isinstance(content, dict):
        raise InputTypeError(f"{where} must hold a JSON object (unit, response, saturation_dn, sensor, ...), got {quote(content)}.")
    if content.get("sensor") is not None:
        check_fields(content["sensor"], f"{where}, its sensor")
    if "response" in content:
        check_choice(f"{where}: response", content["response"], RESPONSES)
    if content.get("saturation_dn") is not None:
        check_range(f"{where}: saturation_dn", content["saturation_dn"], 0.0, unit="DN")
    check_count(f"{where}: render_spp", content.get("render_spp"))
    defaults = content.get("sensor_defaults", [])
    if not isinstance(defaults, list):
        raise InputTypeError(f"{where}: sensor_defaults must be a list of sensor field names, got {quote(defaults)}.")
    for name in defaults:
        check_choice(f"{where}: sensor_defaults", name, [f.name for f in dataclasses.fields(Sensor)])
    return content


def _iso_time(value: Any, path: Path) -> str:
    """A FITS ``DATE-OBS`` as an ISO time (astropy Time, UTC unless it says otherwise)."""
    from astropy.time import Time  # deferred: astropy.time takes 0.2 s; only a FITS DATE-OBS needs it

    try:
        return Time(str(value).strip()).isot
    except ValueError as err:
        raise InputError(f"{str(path)!r}: DATE-OBS = {value!r} is not an ISO time ({err}).") from None


def _fits_unit(header: fits.Header, wanted: str | None, path: Path) -> str:
    bunit = str(header.get("BUNIT", "")).strip()
    if not bunit:
        return wanted or "DN"
    found = RADIANCE_UNIT if bunit.replace(".", " ").split() == FITS_RADIANCE_UNIT.split() else "DN"
    if wanted is not None and wanted != found:
        raise InputError(f"{str(path)!r}: its BUNIT = {bunit!r} is {found}, but {wanted} was asked for.")
    return found


def _check_values(values: np.ndarray, unit: str, path: Path, included: np.ndarray, sigma: float | np.ndarray | None) -> None:
    """Refuse NaN or infinity (any unit) and negative radiance in the pixels not masked out (``included``, (h, w))."""
    nonfinite = int(np.count_nonzero(~np.all(np.isfinite(values), axis=-1) & included))
    if nonfinite:
        raise InputError(f"{str(path)!r}: {nonfinite} pixels are NaN or infinite; a reference must be finite where it is used: "
                         "exclude them with a mask image (`mask=`, --mask: zero there).")
    if unit == RADIANCE_UNIT:
        negative = negative_pixels(values, sigma, np.broadcast_to(included[..., None], values.shape))
        if negative:
            noise = "" if sigma is None else f" by more than {NEGATIVE_SIGMAS:g} of its stated sigma"
            raise InputError(f"{str(path)!r}: {negative} pixels have negative radiance{noise}; radiance must be >= 0 W m^-2 sr^-1 "
                             "(give the image's noise sigma, or mask them out).")


def _ways(field: str) -> str:
    """The three ways to give a sensor field, for an error message."""
    keys = [*HEADER_KEYWORDS.get(field, ()), *(("BITPIX (integer data)",) if field == "bit_depth" else ()),
            f"HIERARCH {FITS_SENSOR_KEY} {field}"]
    return (f"header keyword {' / '.join(keys)}; sensor file key {field} (--sensor FILE); "
            f"option --sensor-value {field}=VALUE (Python: sensor={{{field!r}: ...}})")


def sensor_of(image: ObservedImage, sensor: Sensor | Mapping[str, Any] | None = None, *,
              sensor_file: Mapping[str, Any] | None = None, defaults: str | None = None) -> tuple[Sensor, dict[str, str]]:
    """The sensor that measured a DN image, and where each value it uses came from.

    ``sensor`` given as an :class:`Sensor` is taken whole. Otherwise the values are, each
    replacing the ones before: the illustrative defaults (only with ``defaults="illustrative"``),
    the file's (its integer type's bits, a spacefit sidecar, the FITS header's keywords,
    :data:`HEADER_KEYWORDS`), ``sensor_file`` (the fields of a sensor file,
    :func:`~spacefit.sensor.read_sensor_file`), and the mapping ``sensor`` (an option or argument).
    Without defaults, the values not given follow documented rules, not illustrative numbers: no
    full well (the ``SATURATE`` level or the ADC's range saturates); diffraction only when both the
    aperture and the wavelength are given; vignetting off for a calibrated camera (a radiometric
    scale), on otherwise.

    Returns:
        the sensor and, for each field it uses (:func:`~spacefit.sensor.used_fields`), its source:
        ``"header KEY"``, ``"spacefit sidecar"``, ``"sensor file"``, ``"option/argument"``,
        ``"default (illustrative)"`` or ``"rule: ..."``.
    Raises:
        InputError: a value a fit needs (:func:`~spacefit.sensor.missing_for_measurement`) that no
            source gives, naming each and the three ways to give it.
    """
    check_type("image", image, ObservedImage, "an sf.ObservedImage (what sf.read_image returns)")
    if isinstance(sensor, Sensor):
        return sensor, {name: "option/argument" for name in used_fields(sensor)}
    if sensor is not None:
        check_fields(sensor, "the sensor values of --sensor-value (Python: sensor=)")
    if defaults is not None:
        check_choice("sensor_defaults", defaults, SENSOR_DEFAULTS)
    layers: list[tuple[Mapping[str, Any], str]] = []
    if defaults is not None:
        layers.append(({f.name: getattr(Sensor(), f.name) for f in dataclasses.fields(Sensor)}, "default (illustrative)"))
    found = image.metadata.get("sensor_found", {})
    layers += [({k: v[0] for k, v in found.items()}, ""), (sensor_file or {}, "sensor file"), (sensor or {}, "option/argument")]
    fields: dict[str, Any] = {}
    sources: dict[str, str] = {}
    for values, source in layers:
        fields.update(values)
        sources.update({k: source or found[k][1] for k in values})
    missing = missing_for_measurement(fields)
    if missing:
        names = "; ".join(f"{m}: {_ways(m.split()[0])}" for m in missing)
        raise InputError(f"{image.path!r} holds DN (digital numbers), and a fit of them needs {len(missing)} sensor value(s) that "
                         f"neither the file nor the options give: {names}. Or ask for the illustrative defaults by name: "
                         "sensor_defaults='illustrative' (--sensor-defaults illustrative).")
    optics = "aperture_diameter_m" in fields and "wavelength_m" in fields
    rules = {"full_well_electrons": (None, "rule: none given (the saturation level or the ADC's range saturates)"),
             "diffraction": (optics, "rule: " + ("on, the aperture and wavelength given" if optics else
                                                 "off, no aperture and wavelength given"))}
    for name, (value, source) in rules.items():
        if name not in fields:
            fields[name], sources[name] = value, source
    result = Sensor.from_dict(fields, f"the sensor of {image.path!r}")
    if "vignetting" not in fields:
        sources["vignetting"] = f"rule: {'off for a calibrated camera' if result.calibrated else 'on (cos^4) without a radiometric scale'}"
    return result, {name: sources[name] for name in used_fields(result)}


def format_sensor_sources(sensor: Sensor, sources: Mapping[str, str]) -> str:
    """The values of ``sensor`` that a fit uses with their sources (:func:`sensor_of`), one line each."""
    width = max(map(len, sources), default=0)
    lines = [f"  {name:<{width}} = {getattr(sensor, name) if name != 'vignetting' else sensor.vignetted}  ({source})"
             for name, source in sources.items()]
    return "\n".join(["sensor values and their sources:", *lines])
