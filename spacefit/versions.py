"""Installed versions of packages, read from the header of their metadata.

``importlib.metadata.version`` parses the whole metadata file, long description included (7 ms for
SciPy's, 4 ms for colour-science's), and a render asks for 13 versions: its sidecar's and its mesh
cache's keys; importing ``importlib.metadata`` alone takes a render 0.015 to 0.02 s. The
distribution is found as ``importlib.metadata`` finds it, the first ``*.dist-info`` or ``*.egg-info``
folder of a matching normalised name along ``sys.path``; its header's ``Version`` field is the same
string, read in 0.1 ms. A distribution not found that way (inside a zip file, or by an installed
finder) is asked of ``importlib.metadata``.
"""

from __future__ import annotations

import functools
import os
import re
import sys
from pathlib import Path


def normalised(name: str) -> str:
    """A distribution's name as its metadata folder spells it (PEP 503, ``-`` and ``.`` as ``_``)."""
    return re.sub(r"[-_.]+", "_", name).lower()


@functools.cache
def _metadata_folders(entry: str) -> dict[str, Path]:
    """The metadata folders in the ``sys.path`` entry ``entry``, by normalised distribution name (the first of each)."""
    found: dict[str, Path] = {}
    try:
        names = sorted(os.listdir(entry or "."))
    except OSError:
        return found
    for child in names:
        stem, _, suffix = child.rpartition(".")
        if suffix in ("dist-info", "egg-info") and stem:
            found.setdefault(normalised(stem.split("-")[0]), Path(entry or ".") / child)
    return found


def _header_version(text: str) -> str | None:
    """The ``Version`` field of a metadata file's header (which ends at the first blank line)."""
    for line in text.splitlines():
        if not line.strip():
            break
        if line[0] in " \t":  # a folded line of the field before
            continue
        key, sep, value = line.partition(":")
        if sep and key.strip().lower() == "version":
            return value.strip()
    return None


@functools.cache
def package_version(name: str) -> str | None:
    """The installed version of distribution ``name`` (what ``importlib.metadata.version`` gives), or None
    when it is not installed."""
    wanted = normalised(name)
    for entry in sys.path:
        folder = _metadata_folders(entry).get(wanted)
        if folder is None:
            continue
        for filename in ("METADATA", "PKG-INFO"):
            try:
                version = _header_version((folder / filename).read_text(encoding="utf-8", errors="replace"))
            except OSError:
                continue
            if version is not None:
                return version
        break
    from importlib import metadata  # deferred: a distribution the folders do not show (a zip, a finder)

    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None
