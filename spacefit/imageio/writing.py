"""Writing observation files: simulated DN as 16-bit PNG, TIFF or FITS with a JSON sidecar.

:func:`write_observation` stores integer DN (from :func:`observe`) and every
:class:`Sensor` value twice: in a JSON sidecar ``<file>.json`` and, for FITS, in the
header (standard keys where they exist, ``HIERARCH SPACEFIT SENSOR <FIELD>`` for all).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
from astropy.io import fits

from spacefit.errors import InputError, check_array, check_count
from spacefit.imageio.fits import fits_header
from spacefit.imageio.formats import RENDER_SPP_KEY, WRITABLE, file_format, sidecar_path
from spacefit.sensor import Sensor


def write_observation(path: str | Path, dn: np.ndarray, sensor: Sensor, metadata: dict[str, Any] | None = None, *,
                      render_spp: int | None = None) -> Path:
    """Write integer DN as 16-bit PNG, TIFF or FITS (by the extension) with its JSON sidecar.

    Args:
        path: ``.png``, ``.tif`` / ``.tiff`` or ``.fits`` / ``.fit`` / ``.fts``.
        dn: (height, width, channels) unsigned integers (1 or 3 channels for PNG) in the sensor's
            ADC range, as :func:`observe` returns.
        sensor: the sensor that made them; all its values go to the sidecar and the FITS header.
        metadata: anything JSON can hold, added to the sidecar under ``metadata``.
        render_spp: the samples per pixel of the render the DN were simulated from (FITS
            :data:`RENDER_SPP_KEY`, sidecar ``render_spp``); None: not a simulation.
    Returns:
        the sidecar's path.

    Raises:
        InputError: an unknown extension, DN that are not unsigned integers in the ADC's range, or a
            folder that does not exist.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> sensor, camera = sf.Sensor(), sf.Intrinsics(focal_length=0.05, pixel_pitch=1e-5, width=4, height=3)
        >>> dn = sf.observe(np.full((3, 4, 3), 1.0), sensor, camera, seed=0)
        >>> sf.write_observation("frame.fits", dn, sensor).name
        'frame.fits.json'
    """
    p = Path(path)
    kind = file_format(p, WRITABLE)
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
        import tifffile  # here: only TIFF files need it (10 ms to import, on every fit's path through spacefit.imageio)

        tifffile.imwrite(p, data if data.shape[2] > 1 else data[..., 0], photometric="rgb" if data.shape[2] == 3 else "minisblack")
    else:
        planes = np.moveaxis(data[::-1], -1, 0)  # FITS rows run bottom-up; channels are NAXIS3
        header = fits_header(sensor)
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
