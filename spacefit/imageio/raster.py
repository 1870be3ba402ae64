"""PNG and TIFF observation files: integer values whose response must be named.

A PNG or TIFF holds ``"linear"`` values (DN) or ``"srgb"`` ones (the sRGB encoding, IEC 61966-2-1,
decoded to values linear in light, scaled to the file's full scale); a spacefit sidecar names it for
its own files. Alpha is read as a mask (0 leaves the pixel out, any other value keeps it as it is)
in PNG and in TIFF with an unassociated alpha (ExtraSamples = 2).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from spacefit.errors import InputError


def read_tiff(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """TIFF values and, when its last sample is an unassociated alpha (ExtraSamples = 2, as PNG's), the alpha channel."""
    import tifffile  # here: only TIFF files need it (10 ms to import, on every fit's path through spacefit.imageio)

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


def read_png(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """PNG values and, for grey-alpha or RGBA files, the alpha channel."""
    from spacefit.rendering import png  # deferred: Mitsuba (seconds to import), for its Bitmap: Pillow reduces 16-bit colour to 8 bits

    data = png.read_png(path)
    if data.shape[2] in (2, 4):
        return data[..., :-1], data[..., -1]
    return data, None
