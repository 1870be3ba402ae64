"""PNG files of 8 or 16 bits per channel through Mitsuba's Bitmap: Pillow reduces 16-bit colour PNGs to 8 bits."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from spacefit.errors import InputError
from spacefit.rendering.backend import mi
from spacefit.rendering.bitmap import write_bitmap

_FORMATS = {1: "Y", 2: "YA", 3: "RGB", 4: "RGBA"}


def write_png(path: str | Path, image: np.ndarray) -> None:
    """Write a (height, width, channels) uint8 or uint16 array, 1 to 4 channels (Y, YA, RGB, RGBA), as PNG."""
    data = np.asarray(image)
    if data.ndim == 2:
        data = data[..., None]
    if data.dtype not in (np.uint8, np.uint16) or data.ndim != 3 or data.shape[2] not in _FORMATS:
        raise InputError(f"a PNG holds uint8 or uint16 with 1 to 4 channels, got {data.dtype} of shape {np.shape(image)}.")
    fmt = getattr(mi.Bitmap.PixelFormat, _FORMATS[data.shape[2]])
    write_bitmap(mi.Bitmap(np.ascontiguousarray(data), pixel_format=fmt), path)


def read_png(path: str | Path) -> np.ndarray:
    """Read a PNG's stored values as a (height, width, channels) uint8 or uint16 array (no gamma applied)."""
    p = Path(path)
    try:
        data = np.array(mi.Bitmap(str(p)))
    except Exception as err:  # Mitsuba raises RuntimeError subclasses for unreadable files
        raise InputError(f"image file {str(p)!r} could not be read as PNG: {err}") from None
    return data.reshape(data.shape[0], data.shape[1], -1)
