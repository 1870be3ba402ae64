"""FITS observation files: the header's sensor values, the row order, the reader.

A FITS image holds radiance if ``BUNIT`` says ``W m-2 sr-1``, otherwise DN. Every keyword with a sensor
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

Row order. spacefit's arrays run top-down. A FITS file's rows are read in the order it states,
first found of: the ``row_order`` argument; ``ROWORDER = 'TOP-DOWN'`` or ``'BOTTOM-UP'``; a
celestial WCS's parity (the sky seen from inside, north up and east left as sky images show it,
has det(CD) < 0 with its first row at the bottom: det < 0 is read bottom-up, det > 0, a mirrored
sky, top-down; optics with a mirror break this rule: give ``row_order``); else the FITS standard
(4.0, section 8.1: the first row is the bottom, as DS9 shows it), with a warning and a note.
``metadata`` says which (``row_order``, ``row_order_source``, ``notes``).

spacefit writes every :class:`~spacefit.sensor.Sensor` value in the header (:func:`fits_header`):
standard keys where they exist, ``HIERARCH SPACEFIT SENSOR <FIELD>`` for all. A FITS file shorter
than its headers say (truncated; a tile-compressed image counted by its compressed bytes, so it is
read) and a cube of other than 1 or 3 planes (NAXIS3) are refused, naming the file.
"""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from astropy.io import fits

from spacefit.errors import InputError
from spacefit.imageio.formats import CHANNELS
from spacefit.sensor import Sensor, check_fields
from spacefit.units import RADIANCE_UNIT
from spacefit.timescales import quiet_future_utc

FITS_RADIANCE_UNIT = "W m-2 sr-1"
FITS_SENSOR_KEY = "SPACEFIT SENSOR"
ROW_ORDERS = ("top-down", "bottom-up")
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


def fits_header(sensor: Sensor) -> fits.Header:
    """The FITS header of DN that ``sensor`` made: its values under standard keys and spacefit's own."""
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


def header_sensor(header: fits.Header, data: np.ndarray, path: Path) -> dict[str, tuple[Any, str]]:
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
            if field == "gain_dn_per_electron" and not float(value) > 0.0:
                raise InputError(f"{str(path)!r}: the FITS header's {key} = {value!r} electrons per DN must be > 0 (the ADC's gain is its "
                                 "inverse); correct it or give the value (`sensor=`, --sensor-value).")
            found[field] = (1.0 / float(value) if field == "gain_dn_per_electron" else float(value), f"header {key}")
    if data.dtype.kind in "ui":
        found["bit_depth"] = (8 * data.dtype.itemsize, "header BITPIX")
    own = check_fields(_sensor_from_header(header) or {}, f"{str(path)!r}: the FITS header's HIERARCH {FITS_SENSOR_KEY} cards")
    found.update({k: (v, f"header {FITS_SENSOR_KEY} {k}") for k, v in own.items()})
    return found


def _wcs_row_order(header: fits.Header) -> str | None:
    """The row order a celestial WCS implies by its parity (see the module), or None without one."""
    if "CTYPE1" not in header and "CTYPE2" not in header:  # no type for either axis: no celestial WCS (astropy.wcs not imported)
        return None
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


def _stored_bytes(hdu: Any, path: Path, index: int) -> int:
    """Bytes of HDU ``index``'s data as the file stores them: for a tile-compressed image (Rice, GZIP...;
    FITS 4.0 section 10), its binary table of compressed tiles, not the larger image it decompresses to."""
    if isinstance(hdu, fits.CompImageHDU):
        with fits.open(path, disable_image_compression=True) as raw:
            return raw[index].size
    return hdu.size


def _image_hdu(hdus: fits.HDUList, path: Path) -> fits.PrimaryHDU | fits.ImageHDU | fits.CompImageHDU:
    """The first HDU with an image of 2 or more axes, after checking that the file holds every byte
    its headers promise up to it (a truncated copy would fail inside astropy)."""
    size = path.stat().st_size
    for index, hdu in enumerate(hdus):
        expected = hdu.fileinfo()["datLoc"] + _stored_bytes(hdu, path, index)
        if expected > size:
            raise InputError(f"{str(path)!r} is truncated: the header of HDU {index} promises data up to byte {expected}, "
                             f"the file holds {size} bytes.")
        if hdu.data is not None and hdu.data.ndim >= 2:
            return hdu
    raise InputError(f"{str(path)!r} holds no image (no HDU with 2 or 3 axes).")


def read_fits(path: Path, row_order: str | None = None) -> tuple[np.ndarray, fits.Header, tuple[str, str, list[str]]]:
    """A FITS image as (height, width, channels) top-down values, its header, and its row order,
    the order's source and notes (see the module)."""
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", "File may have been truncated")  # refused below, in words
            with fits.open(path) as hdus:
                hdu = _image_hdu(hdus, path)
                data, header = np.array(hdu.data), hdu.header.copy()
    except InputError:
        raise  # already in the user's words
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


@quiet_future_utc
def iso_time(value: Any, path: Path) -> str:
    """A FITS ``DATE-OBS`` as an ISO time (astropy Time, UTC unless it says otherwise)."""
    from astropy.time import Time  # deferred: astropy.time takes 0.2 s; only a FITS DATE-OBS needs it

    try:
        return Time(str(value).strip()).isot
    except ValueError as err:
        raise InputError(f"{str(path)!r}: DATE-OBS = {value!r} is not an ISO time ({err}).") from None


def fits_unit(header: fits.Header, wanted: str | None, path: Path) -> str:
    """The unit of a FITS image by its ``BUNIT`` (none: ``wanted``, else DN), refused if not ``wanted``."""
    bunit = str(header.get("BUNIT", "")).strip()
    if not bunit:
        return wanted or "DN"
    found = RADIANCE_UNIT if bunit.replace(".", " ").split() == FITS_RADIANCE_UNIT.split() else "DN"
    if wanted is not None and wanted != found:
        raise InputError(f"{str(path)!r}: its BUNIT = {bunit!r} is {found}, but {wanted} was asked for.")
    return found
