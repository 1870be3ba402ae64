"""Reading observation files: :func:`read_image` with its masks and the sidecar.

:func:`read_image` returns an :class:`ObservedImage`: float data, its unit (``"DN"`` or
radiance), the metadata found, and the mask of usable pixels (not saturated, not transparent, in the user's
mask). What each format holds:

* EXR: radiance (W m^-2 sr^-1), as spacefit renders write it; a ``RENDSPP`` attribute in its header
  (:data:`RENDER_SPP_KEY`, which spacefit's simulated references carry) is read as in FITS.
* FITS: radiance or DN by ``BUNIT``, the sensor values of its header, its row order
  (:mod:`spacefit.imageio.fits`).
* PNG and TIFF: integer values whose response must be named (:mod:`spacefit.imageio.raster`).

Saturated values are masked: at or above the FITS ``SATURATE`` keyword, else the sidecar's sensor
``saturation_dn``, else the integer type's full scale (2^bits - 1); float DN without either has no
saturation mask. Pixels a user mask or a PNG's alpha leaves out are not checked and read as 0.

What is refused, naming the file (:class:`InputError`): an image of other than 1
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
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from spacefit.errors import NEGATIVE_SIGMAS, InputError, InputTypeError, check_choice, check_count, check_path, check_range, negative_pixels, quote
from spacefit.imageio.fits import ROW_ORDERS, fits_unit, header_sensor, iso_time, read_fits
from spacefit.imageio.formats import CHANNELS, FORMATS, RENDER_SPP_KEY, RESPONSES, UNITS, file_format, sidecar_path
from spacefit.imageio.raster import read_png, read_tiff
from spacefit.output import srgb_decode
from spacefit.sensor import Sensor, check_fields
from spacefit.units import RADIANCE_UNIT

if TYPE_CHECKING:
    from jaxtyping import Bool, Float


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

    Example:
        >>> import numpy as np, spacefit as sf
        >>> sf.write_exr("reference.exr", np.full((4, 6, 3), 0.5))
        >>> sf.read_image("reference.exr").metadata["format"]
        'exr'
    """

    data: Float[np.ndarray, "h w c"]
    unit: str
    mask: Bool[np.ndarray, "h w c"]
    metadata: dict[str, Any]
    path: str


def _read_render_spp(meta: dict[str, Any], header: Mapping[str, Any], where: str) -> None:
    """Take a file header's :data:`RENDER_SPP_KEY` into ``meta["render_spp"]`` (the file outranks its
    sidecar), checked as a count (``where`` names it)."""
    if RENDER_SPP_KEY in header:
        meta["render_spp"] = header[RENDER_SPP_KEY]
        check_count(where, meta["render_spp"])


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
        kind = file_format(p, (".fits", ".fit", ".fts", ".png", ".tif", ".tiff"))
        values = read_fits(p)[0] if kind == "fits" else read_tiff(p)[0] if kind == "tiff" else read_png(p)[0]
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
            (None: as it states).
    Returns:
        the data, unit, metadata and usable-pixel mask (see :class:`ObservedImage`).
    Raises:
        InputError: missing file, unknown format, a display image asked for as radiance, PNG / TIFF
            without a response, NaN or infinity (any unit), negative radiance, other than 1 or 3
            channels, a truncated FITS, a malformed sidecar, a mask of another size, not binary or
            empty; each naming the file and the number of pixels or values.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> sf.write_exr("reference.exr", np.full((4, 6, 3), 0.5))
        >>> image = sf.read_image("reference.exr")
        >>> image.unit, image.data.shape, bool(image.mask.all())
        ('W m^-2 sr^-1', (4, 6, 3), True)
    """
    wanted = UNITS[check_choice("unit", unit, UNITS)] if unit is not None else None
    if response is not None:
        check_choice("response", response, RESPONSES)
    if row_order is not None:
        check_choice("row_order", row_order, ROW_ORDERS)
    p = check_path("path", path)
    if not p.is_file():
        raise InputError(f"image file {str(p)!r} does not exist.")
    kind = file_format(p, tuple(FORMATS))
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
        raw, header, (meta["row_order"], meta["row_order_source"], notes) = read_fits(p, row_order)
        found_unit = fits_unit(header, wanted, p)
        meta["notes"] += notes
        meta["header"] = {k: v for k, v in header.items() if k not in ("COMMENT", "HISTORY", "")}
        meta["sensor_found"] = header_sensor(header, raw, p)
        if "DATE-OBS" in header:
            meta["date_obs"] = iso_time(header["DATE-OBS"], p)
        if "SATURATE" in header:
            meta["saturation_dn"] = float(header["SATURATE"])
        _read_render_spp(meta, header, f"{str(p)!r}: the FITS header's {RENDER_SPP_KEY}")
    else:
        raw, alpha = read_tiff(p) if kind == "tiff" else read_png(p)
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
        values = srgb_decode(values / scale) * scale
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
