"""OpenEXR input and output of float radiance images through Mitsuba's Bitmap."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from spacefit.errors import InputError, check_array, check_path
from spacefit.rendering.backend import mi
from spacefit.rendering.bitmap import write_bitmap


def write_exr(path: str | Path, image: np.ndarray, header: Mapping[str, int | float | str] | None = None) -> None:
    """Write a (height, width, 3) float radiance image as a 32-bit float RGB OpenEXR file, with
    ``header``'s attributes in its header (a simulated reference's ``{"RENDSPP": spp}``, say).

    Args:
        path: the file to write, ending in ``.exr``; its folder must exist.
        image: (height, width, 3) radiance, W m^-2 sr^-1 (any float array; written as float32).
        header: attributes for the file's header: names to int, float or str values.

    Raises:
        InputError: ``path`` does not end in ``.exr``, or ``image`` is not a real (h, w, 3) array.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> sf.write_exr("flat.exr", np.full((4, 6, 3), 0.5))
        >>> sf.read_exr("flat.exr").shape
        (4, 6, 3)
    """
    path = check_path("path", path)
    if path.suffix.lower() != ".exr":
        raise InputError(f"`path` must end in .exr, got {str(path)!r}.")
    image = check_array("image", image)
    if image.ndim != 3 or image.shape[2] != 3 or not image.size:
        raise InputError(f"`image` must be (height, width, 3) RGB, got shape {image.shape}.")
    bitmap = mi.Bitmap(np.ascontiguousarray(image, dtype=np.float32), pixel_format=mi.Bitmap.PixelFormat.RGB)
    for key, value in (header or {}).items():
        bitmap.metadata()[key] = value
    write_bitmap(bitmap, path)


def read_exr(path: str | Path) -> np.ndarray:
    """Read an OpenEXR file as a (height, width, channels) float32 array: a render's radiance.exr,
    say. For a reference to fit, :func:`read_image` reads EXR, FITS, PNG and TIFF with their units
    and usable-pixel mask.

    Args:
        path: an OpenEXR file.

    Returns:
        The pixel values as stored (radiance in W m^-2 sr^-1 for spacefit's own renders).

    Raises:
        InputError: the file does not exist or is not OpenEXR.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> sf.write_exr("flat.exr", np.full((4, 6, 3), 0.5))
        >>> image = sf.read_exr("flat.exr")
        >>> image.dtype, float(image.max())
        (dtype('float32'), 0.5)
    """
    return read_exr_with_header(path)[0]


def read_exr_with_header(path: str | Path) -> tuple[np.ndarray, dict[str, object]]:
    """Read an OpenEXR file once: its (height, width, channels) float32 array and the attributes of its
    header that Mitsuba reads, a writer's own (``RENDSPP``) and the standard ones it knows
    (``pixelAspectRatio``, ...)."""
    p = check_path("path", path)
    if not p.is_file():
        raise InputError(f"image file {str(p)!r} does not exist.")
    try:
        bitmap = mi.Bitmap(str(p))
    except Exception as err:  # Mitsuba raises RuntimeError subclasses for unreadable files
        raise InputError(f"image file {str(p)!r} could not be read as OpenEXR: {err}") from None
    metadata = bitmap.metadata()
    return np.array(bitmap, dtype=np.float32), {key: metadata[key] for key in metadata.keys()}
