"""Writing image files through Mitsuba's Bitmap (the EXR and PNG writers), its failures as OSError."""

from __future__ import annotations

import errno
import os
from pathlib import Path

from spacefit.rendering.backend import mi


def write_bitmap(bitmap: "mi.Bitmap", path: str | Path) -> None:
    """Write ``bitmap`` to ``path`` (the format from its suffix). Mitsuba reports a failed write as a
    RuntimeError ending in the system's message ("...: File too large" past a file-size limit, "No space
    left on device"): raised as the OSError of that cause, naming ``path``."""
    try:
        bitmap.write(str(path))
    except RuntimeError as err:
        cause = str(err).rsplit(": ", 1)[-1]
        code = next((e for e in errno.errorcode if os.strerror(e) == cause), errno.EIO)
        raise OSError(code, cause, str(path)) from None
