"""Observation files' formats: the extensions read and written, the units and responses a file's
values may have, and the JSON sidecar beside each file spacefit writes."""

from __future__ import annotations

from pathlib import Path

from spacefit.errors import InputError
from spacefit.units import DN_UNIT, RADIANCE_UNIT

UNITS = {"DN": DN_UNIT, "radiance": RADIANCE_UNIT}
RESPONSES = ("linear", "srgb")
FORMATS = {".exr": "exr", ".fits": "fits", ".fit": "fits", ".fts": "fits", ".png": "png", ".tif": "tiff", ".tiff": "tiff"}
WRITABLE = (".fits", ".fit", ".fts", ".png", ".tif", ".tiff")
CHANNELS = (1, 3)
"""The channels an image may hold: grey or RGB (a PNG's or TIFF's alpha besides, read as a mask)."""
RENDER_SPP_KEY = "RENDSPP"
"""The FITS keyword and EXR header attribute (and, as ``render_spp``, the sidecar key) of a simulated
observation's samples per pixel: its render's Monte Carlo noise, which the goodness of fit counts
(:mod:`spacefit.fitting.goodness`)."""


def sidecar_path(path: str | Path) -> Path:
    """The JSON sidecar of an observation file: ``obs.fits`` -> ``obs.fits.json``."""
    p = Path(path)
    return p.with_name(p.name + ".json")


def file_format(path: Path, allowed: tuple[str, ...]) -> str:
    """The format of ``path`` by its extension, one of ``allowed`` (refused naming the file otherwise)."""
    suffix = path.suffix.lower()
    if suffix not in allowed:
        raise InputError(f"{str(path)!r}: unknown image format {suffix or '(no extension)'!r}; supported: {', '.join(allowed)}.")
    return FORMATS[suffix]
